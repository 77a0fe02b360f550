"""cocotb side of ``bench/finemb.py``: one line of FinEmbP nodes (tb/finemb_line_top.py) with
the cycle-accurate master of tb/finemb_tb.py; for each polling mode the fastest cycle, then
cycles at that fixed period (jitter at the far end), and the hop latency of node 0. Writes a
JSON record to ``ROSGATE_BENCH_OUT``."""

import json
import os
import random

import cocotb
from cocotb.triggers import First, RisingEdge, Timer
from cocotb.utils import get_sim_time
from scapy.layers.l2 import Ether
from scapy.packet import Raw

from host.simulator import clock_cycles
from tb.finemb_tb import CLOCK_NS, LineMaster

NODES = int(os.environ["ROSGATE_FINEMB_NODES"])
WARMUP, FREE, FIXED = 5, 20, 40
#: periods tried above the first guess before the bench gives up
MAX_LONGER = 16


def wire_ns(frame_bytes):
    """Time a frame (without FCS) takes on Gigabit Ethernet: padding, FCS, preamble and SFD,
    inter-frame gap (a minimum frame: 672 ns)."""
    return (max(frame_bytes + 4, 64) + 8 + 12) * 8


async def soc_times(dut, times, stop):
    """Append the simulated time (ns) of every SoC pulse of the last node until ``stop``."""
    soc = getattr(dut, f"soc{NODES - 1}")
    while not stop:
        await First(RisingEdge(soc), Timer(20_000, "ns"))
        if int(soc.value):
            times.append(int(get_sim_time("ns")))


async def hop_latency(dut, master):
    """First byte into node 0 to first byte out of its far port, for a frame it forwards only
    (another node's MAC), on an idle line."""
    await clock_cycles(dut.gmii_clk, 2000)
    master.send(Ether(src="02:00:00:00:00:01", dst="02:00:00:00:46:99", type=0x88B5) /
                Raw(bytes(100)))
    await RisingEdge(dut.hop_in)
    t_in = get_sim_time("ns")
    await RisingEdge(dut.hop_out)
    return get_sim_time("ns") - t_in


async def fixed_cycles(dut, master, rng, polling, period):
    """FIXED cycles at ``period``: the late answers, the SoC times seen at the last node and
    the first cycle's frame sizes."""
    late_before = sum(master.late.values())
    times, stop = [], []
    cocotb.start_soon(soc_times(dut, times, stop))
    first = master.now() + 10
    sizes = None
    for k in range(FIXED):
        await clock_cycles(dut.gmii_clk, first + k * period - master.now())
        start, last, got = await master.cycle(rng, polling=polling,
                                              deadline=first + (k + 1) * period)
        assert start == first + k * period, (start, first + k * period)
        if sizes is None:
            sizes = {"tx": [len(bytes(f)) for f in master.last_sent],
                     "rx": [14 + 20 + 8 + 16 + len(m["body"]) for m in got.values()]}
    stop.append(True)
    # the last cycle's late answers arrive in this one: let them pass before the next try
    await clock_cycles(dut.gmii_clk, 2 * period)
    return sum(master.late.values()) - late_before, times, sizes


@cocotb.test()
async def measure_line(dut):
    master = LineMaster(dut, NODES)
    await master.reset()
    found = await master.init()
    assert len(found) == NODES, found
    rng = random.Random(1)
    record = {"nodes": NODES, "modes": {}}
    for polling in ("sequential", "pipelined"):
        for _ in range(WARMUP):
            await master.cycle(rng, polling=polling, deadline=master.now() + 100_000)
        longest = 0
        for _ in range(FREE):
            start, last, got = await master.cycle(rng, polling=polling,
                                                  deadline=master.now() + 100_000)
            assert len(got) == NODES
            longest = max(longest, last - start)
        # the fixed period: from the longest free-running cycle, plus the one cycle in which
        # the last answer's end is seen, up until FIXED cycles in a row have no late answer.
        # A free-running cycle starts at the same phase of the core clock every time; a fixed
        # period can start at the other, whose clock crossings take a cycle or two longer
        period = longest + 1
        for _ in range(MAX_LONGER):
            late, times, sizes = await fixed_cycles(dut, master, rng, polling, period)
            if not late:
                break
            period += 1
        else:
            raise AssertionError(f"{polling}: answers still late at {period - 1} cycles "
                                 f"(free-running: {longest})")
        intervals = [b - a for a, b in zip(times, times[1:])]
        tx_ns = sum(wire_ns(n) for n in sizes["tx"])
        rx_ns = sum(wire_ns(n) for n in sizes["rx"])
        record["modes"][polling] = {
            "period_cycles": period, "late": late, "soc_seen": len(times),
            "jitter_ns": max(intervals) - min(intervals) if intervals else None,
            "tx_ns": tx_ns, "rx_ns": rx_ns, "frames_tx": sizes["tx"], "frames_rx": sizes["rx"],
        }
        dut._log.info("%d nodes %s: period %d cycles (%.1f kHz), late %d, jitter %s ns",
                      NODES, polling, period, 1e6 / (period * CLOCK_NS), late,
                      record["modes"][polling]["jitter_ns"])
    record["hop_latency_ns"] = await hop_latency(dut, master)
    record["lost"] = int(dut.lost.value)
    with open(os.environ["ROSGATE_BENCH_OUT"], "w") as f:
        json.dump(record, f)
