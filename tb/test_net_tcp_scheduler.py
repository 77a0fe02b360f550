# amaranth: UnusedElaboratable=no
"""TcpRequestScheduler (hdl/net/tcp/scheduler.py) in amaranth.sim: among random due
requests the highest-priority one is chosen (RST, ARP, SYN, data, FIN, probe, ACK), one
request at a time reaches the frame builder with the flags scapy gives for it and the
connection's addresses, nothing is offered while held, a withdrawn or stale request is
dropped, and ``sent`` pulses once per request taken."""

import random

from scapy.layers.inet import TCP

from hdl.net.rx import FrameKind
from hdl.net.tcp import TcpRequest, TcpRequestScheduler

from .streamsim import simulate

R = TcpRequest
PRIORITY = [R.RST, R.ARP, R.SYN, R.DATA, R.FIN, R.PROBE, R.ACK]


def expected_flags(kind, syn_only):
    names = {R.RST: "R", R.SYN: "S" if syn_only else "SA", R.DATA: "PA", R.FIN: "FA",
             R.PROBE: "A", R.ACK: "A"}
    return TCP(flags=names[kind]).flags.value


def test_tcp_scheduler_priority_and_requests():
    rng = random.Random(41)
    dut = TcpRequestScheduler()
    taken = []
    offered = []

    async def bench(ctx):
        addresses = dict(remote_mac=0x0200_0000_0001, remote_ip=0x0A00_0002, local_port=24,
                         remote_port=50000, ack=0xFFFF_FFF0, window=4096, ctl_seq=0x1234_5678,
                         data_seq=0x8000_0010, data_len=100, data_sum=0xBEEF)
        for name, value in addresses.items():
            ctx.set(getattr(dut, name), value)
        ctx.set(dut.unsent, 1)
        for _ in range(400):
            due = {kind: rng.random() < 0.3 for kind in R}
            for kind, value in due.items():
                ctx.set(getattr(dut, f"{kind.name.lower()}_due"), value)
            syn_only = rng.random() < 0.5
            ctx.set(dut.syn_only, syn_only)
            wanted = next((kind for kind in PRIORITY if due[kind]), None)
            assert ctx.get(dut.next_due) == (wanted is not None)
            if wanted is not None:
                assert ctx.get(dut.next_kind) == wanted
            pending = ctx.get(dut.pending)
            if not pending and wanted is not None and rng.random() < 0.7:
                ctx.set(dut.choose, 1)
                await ctx.tick()
                ctx.set(dut.choose, 0)
                assert ctx.get(dut.pending) == 1 and ctx.get(dut.kind) == wanted
                kind = wanted
                hold = rng.random() < 0.3
                ctx.set(dut.hold, hold)
                assert ctx.get(dut.valid) == (not hold)
                ctx.set(dut.hold, 0)
                if rng.random() < 0.2:
                    ctx.set(dut.withdraw, 1)
                    await ctx.tick()
                    ctx.set(dut.withdraw, 0)
                    assert ctx.get(dut.pending) == 0
                    continue
                request = ctx.get(dut.request)
                offered.append(kind)
                if kind == R.ARP:
                    assert request.kind == FrameKind.ARP
                    assert request.eth_dst == 0xFFFF_FFFF_FFFF
                    assert request.ip_dst == addresses["remote_ip"]
                else:
                    assert request.kind == FrameKind.TCP
                    assert request.flags == expected_flags(kind, syn_only)
                    assert (request.eth_dst, request.ip_dst, request.src_port,
                            request.dst_port) == (addresses["remote_mac"], addresses["remote_ip"],
                                                  24, 50000)
                    assert request.ack == addresses["ack"]
                    assert request.window == (0 if kind == R.RST else 4096)
                    assert request.mss == (kind == R.SYN)
                    if kind == R.DATA:
                        assert (request.seq, request.length, request.payload_sum,
                                request.payload_addr) == (0x8000_0010, 100, 0xBEEF, 0x0010)
                    else:
                        assert request.seq == addresses["ctl_seq"] and request.length == 0
                ctx.set(dut.ready, 1)
                assert ctx.get(dut.sent) == 1
                await ctx.tick()
                ctx.set(dut.ready, 0)
                taken.append(kind)
                assert ctx.get(dut.pending) == 0 and ctx.get(dut.valid) == 0
            else:
                await ctx.tick()

    simulate(dut, bench)
    assert taken == offered and len(set(taken)) == len(R)


def test_tcp_scheduler_drops_a_stale_data_request():
    dut = TcpRequestScheduler()

    async def bench(ctx):
        ctx.set(dut.data_due, 1)
        ctx.set(dut.unsent, 1)
        ctx.set(dut.choose, 1)
        await ctx.tick()
        ctx.set(dut.choose, 0)
        assert ctx.get(dut.valid) == 1
        ctx.set(dut.unsent, 0)          # its segment was acknowledged and freed
        assert ctx.get(dut.valid) == 0
        ctx.set(dut.ready, 1)
        assert ctx.get(dut.sent) == 0
        await ctx.tick()
        assert ctx.get(dut.pending) == 0

    simulate(dut, bench)
