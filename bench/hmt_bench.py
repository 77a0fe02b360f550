"""cocotb module of the topic benchmark: runs the cases given in ROSGATE_BENCH_CASES on a
:class:`tb.topic_traffic.TopicTrafficBench` top and writes the records to ROSGATE_BENCH_OUT."""

import json
import os

import cocotb
from cocotb.triggers import ClockCycles, RisingEdge, Timer

from bench.pace import PaceMeter
from host.simulator import start_clock
from tb.harness import bench_params

CLOCK_NS = 10
POLL_CYCLES = 4096


def read_array(dut, name, n):
    return [int(getattr(dut, f"{name}{k}").value) for k in range(n)]


@cocotb.test()
async def measure(dut):
    params = bench_params()
    pubs, subs = params["pubs"], params["subs"]
    cases = json.loads(os.environ["ROSGATE_BENCH_CASES"])
    start_clock(dut.aclk, CLOCK_NS)
    pace = PaceMeter(CLOCK_NS)
    dut.start.value = 0
    for i in range(pubs):
        getattr(dut, f"beats{i}").value = 1
        getattr(dut, f"count{i}").value = 0
    dut.aresetn.value = 0
    await ClockCycles(dut.aclk, 4)
    dut.aresetn.value = 1
    await ClockCycles(dut.aclk, 2)
    records = []
    for case in cases:
        for i in range(pubs):
            getattr(dut, f"beats{i}").value = case["beats"][i]
            getattr(dut, f"count{i}").value = case["count"][i]
        await RisingEdge(dut.aclk)
        dut.start.value = 1
        await RisingEdge(dut.aclk)
        dut.start.value = 0
        expected = sum(b * c for b, c in zip(case["beats"], case["count"]))
        limit = 4 * expected * max(1, pubs) + 10 * POLL_CYCLES
        waited = 0
        while True:
            await Timer(POLL_CYCLES * CLOCK_NS, "ns")
            waited += POLL_CYCLES
            if int(dut.done.value):
                break
            assert waited < limit, f"case {case['name']}: not done after {waited} cycles"
        record = dict(case)
        record.update(
            pub_first=read_array(dut, "pub_first", pubs),
            sub_first=read_array(dut, "sub_first", subs),
            sub_last=read_array(dut, "sub_last", subs),
            sub_beats=read_array(dut, "sub_beats", subs),
            sub_messages=read_array(dut, "sub_messages", subs),
            sub_errors=read_array(dut, "sub_errors", subs),
        )
        assert record["sub_errors"] == [0] * subs, f"case {case['name']}: corrupted delivery"
        assert record["sub_beats"] == [expected] * subs, f"case {case['name']}: beats lost"
        records.append(record)
    pace.write()
    with open(os.environ["ROSGATE_BENCH_OUT"], "w") as f:
        json.dump(records, f)
