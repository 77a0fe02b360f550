"""Bench of one FinEmbP node (``finemb_node``: the PID benchmark node, docs/finemb.md) with a
master on port 0 and a peer on port 1: initialisation (ID, address, IO descriptor), cyclic
exchange checked against the AVR221 model, forwarding between the ports (cut-through, byte
exact, bad frames ended with TX_ER), ARP and ICMP on the assigned address, the cycle watchdog,
a master restart, two nodes claiming one id, and bad input of every kind: each dropped and
counted, the next request answered."""

import random
import struct

import cocotb
from cocotb.triggers import ClockCycles
from scapy.layers.inet import ICMP, IP, UDP
from scapy.layers.l2 import ARP, Ether
from scapy.packet import Raw

from hdl.finemb import IoDescriptor
from hdl.finemb.protocol import (
    BROADCAST_IP, BROADCAST_MAC, NODE_ALL, Direction, Flag, MsgType, NodeState, ReinitReason,
)
from host.simulator import clock_cycles
from tb.harness import cocotb_bench
from tb.models.finemb import MASTER_IP, MASTER_MAC, body_of, finemb_frame
from tb.models.pid import AvrPid

from .finemb_tb import PID_IO, NodeTB, node_ip

CONFIGS = {"pid": dict(io=PID_IO, mac="02:00:00:00:46:01", serial=7, app_deadline=256)}
#: make test: Icarus; Verilator in test-full
test_finemb_node = cocotb_bench("finemb_node", CONFIGS, long=[("pid", "verilator")])

GAINS = dict(p_gain=256, i_gain=64, d_gain=32)


async def started(dut, node_id=1):
    tb = NodeTB(dut)
    await tb.reset()
    desc = await tb.init(node_id)
    await tb.drain(1, 100)         # the broadcast requests, forwarded
    return tb, desc


@cocotb.test()
async def init_and_cycles_match_the_pid_model(dut):
    """ID_RES (broadcast, from 0.0.0.0, the node's MAC and page sizes), ADDR_RES, the IO
    descriptor read in 40-byte chunks equal to the description file's; then 30 cycles whose
    ISEND_RES carry the AVR221 model's output for each cycle's set point and measurement,
    the update count, the state OP and the request's cycle number."""
    tb = NodeTB(dut)
    await tb.reset()
    assert tb.state == NodeState.INIT
    res = await tb.exchange(tb.request(MsgType.ID_REQ, NODE_ALL, body_of(MsgType.ID_REQ, 1),
                                       dst_mac=BROADCAST_MAC, dst_ip=BROADCAST_IP))
    assert res["type"] == MsgType.ID_RES and res["state"] == NodeState.INIT
    assert (res["dst_mac"], res["dst_ip"], res["src_ip"]) == \
        (BROADCAST_MAC, BROADCAST_IP, "0.0.0.0"), res
    assert res["ttl"] == 1, "FinEmbP frames stay in the layer-2 domain (TTL 1)"
    mac, vendor, serial, n_ports, caps, page_in, page_out = \
        struct.unpack("<6sHIBBHH", res["body"])
    assert mac == bytes.fromhex(tb.node_mac.replace(":", ""))
    assert (serial, n_ports, caps & 1) == (7, 2, 1)
    assert (page_in, page_out) == (tb.io.page_in_bytes, tb.io.page_out_bytes)
    await tb.reset()
    desc = await tb.init(3)
    assert desc == tb.io.encode()
    assert IoDescriptor.decode(desc) == tb.io
    assert tb.state == NodeState.PREOP and int(dut.node_id.value) == 3
    assert dut.local_ip.value == int.from_bytes(bytes([198, 18, 0, 19]), "big")
    model = AvrPid(GAINS["p_gain"], GAINS["i_gain"], GAINS["d_gain"])
    rng = random.Random(cocotb.RANDOM_SEED)
    for cycle in range(30):
        sp, pv = rng.randrange(-3000, 3000), rng.randrange(-3000, 3000)
        await tb.send(tb.soc(cycle=cycle))
        res = await tb.isend(3, dict(set_point=sp, measurement=pv, **GAINS), cycle=cycle)
        assert res["type"] == MsgType.ISEND_RES and res["node_id"] == 3, res
        assert res["cycle"] == cycle and res["state"] == NodeState.OP, res
        assert not res["flags"] & Flag.ERROR
        values = tb.io.unpack(Direction.IN, res["body"])
        assert values == {"output": model.update(sp, pv), "updates": cycle + 1}, \
            (cycle, values)
    counters = await tb.counters()
    assert counters["late_app"] == 0 and counters["bad_header"] == 0, counters


@cocotb.test()
async def forwarding_is_byte_exact_and_cut_through(dut):
    """Frames for other MACs go from port 0 to port 1 and back unchanged (FCS included),
    one frame for the node's MAC is not forwarded, broadcast and the FinEmbP group are
    consumed and forwarded; the first byte leaves at most 21 cycles after the first byte
    arrived (the queue's reader follows a kept frame from the cycle after its decision); a
    frame with a bad FCS is forwarded ending with TX_ER."""
    tb, _ = await started(dut)
    rng = random.Random(cocotb.RANDOM_SEED)
    for src, dst in ((0, 1), (1, 0)):
        frames = []
        for _ in range(12):
            n = rng.randrange(46, 600)
            frames.append(Ether(src="02:aa:00:00:00:01", dst="02:bb:00:00:00:02",
                                type=0x88B5) / Raw(rng.randbytes(n)))
        for f in frames:
            await tb.send(f, src)
        got = await tb.drain(dst, 12 * 700)
        assert [bytes(g) for g in got] == [bytes(f).ljust(60, b"\0") for f in frames]
    # cut-through latency: first byte in (the preamble) to first byte out
    start = tb.cycle
    await tb.ports[0].send(Ether(src="02:aa:00:00:00:01", dst="02:cc:00:00:00:03",
                                 type=0x88B5) / Raw(bytes(800)))
    while not int(dut.port1_tx_en.value):
        await ClockCycles(dut.gmii_clk, 1)
    latency = tb.cycle - start
    dut._log.info("hop latency: %d cycles (%d ns)", latency, latency * 8)
    assert latency <= 21, latency
    await tb.drain(1, 1000)
    # own MAC: consumed, not forwarded (an ARP request for its address)
    await tb.send(Ether(src=MASTER_MAC, dst=tb.node_mac) /
                  ARP(op=1, hwsrc=MASTER_MAC, psrc=MASTER_IP, pdst=node_ip(1)))
    assert (await tb.recv(0, finemb=False))[ARP].op == 2
    assert await tb.drain(1, 300) == []
    # a bad FCS: forwarded, ended with TX_ER
    await tb.ports[0].send(None, raw=bytes(Ether(dst="02:bb:00:00:00:02") / Raw(bytes(80))) +
                           b"\x00\x00\x00\x00")
    await clock_cycles(dut.gmii_clk, 400)
    gf, frame = tb.ports[1].take()
    assert frame is None and any(gf.error), "a bad frame left without TX_ER"
    counters = await tb.counters()
    assert counters["forwarded0"] >= 14 and counters["forwarded1"] == 12, counters


@cocotb.test()
async def arp_and_ping_on_the_assigned_address_only(dut):
    """Before its address the node answers neither ARP nor ping; afterwards both, the echo
    reply byte for byte what scapy expects."""
    tb = NodeTB(dut)
    await tb.reset()
    arp = Ether(src=MASTER_MAC, dst=BROADCAST_MAC) / ARP(op=1, hwsrc=MASTER_MAC, psrc=MASTER_IP,
                                                         pdst="0.0.0.0")
    await tb.send(arp)
    await tb.expect_silence(0, 1000)
    await tb.init(1)
    await tb.send(Ether(src=MASTER_MAC, dst=BROADCAST_MAC) /
                  ARP(op=1, hwsrc=MASTER_MAC, psrc=MASTER_IP, pdst=node_ip(1)))
    reply = await tb.recv(0, finemb=False)
    assert reply[ARP].op == 2 and reply[ARP].psrc == node_ip(1) and \
        reply[ARP].hwsrc == tb.node_mac
    data = bytes(range(256)) * 3
    ping = (Ether(src=MASTER_MAC, dst=tb.node_mac) / IP(src=MASTER_IP, dst=node_ip(1)) /
            ICMP(type=8, id=0x1234, seq=5) / Raw(data))
    await tb.send(ping)
    reply = await tb.recv(0, finemb=False)
    assert reply[ICMP].type == 0 and bytes(reply[ICMP].payload) == data
    assert (reply[ICMP].id, reply[ICMP].seq) == (0x1234, 5)
    rebuilt = Ether(bytes(reply))
    del rebuilt[ICMP].chksum, rebuilt[IP].chksum
    assert Ether(bytes(rebuilt))[ICMP].chksum == reply[ICMP].chksum


@cocotb.test()
async def bad_input_is_dropped_counted_and_the_next_request_answered(dut):
    """Bad magic, version and length fields, a bad UDP and a bad IP checksum, a truncated
    frame, an ISEND page of the wrong size (answered with ERROR, nothing written), other
    UDP ports, another multicast group, non-IP traffic and an ARP storm for other addresses,
    on both ports: each dropped and counted, nothing forwarded that should not be, and the
    next ISEND_REQ answered correctly."""
    tb, _ = await started(dut)
    model = AvrPid(GAINS["p_gain"], GAINS["i_gain"], GAINS["d_gain"])
    res = await tb.isend(1, dict(set_point=100, measurement=0, **GAINS))
    assert tb.io.unpack(Direction.IN, res["body"])["output"] == model.update(100, 0)
    page = tb.io.pack(Direction.OUT, dict(set_point=5, measurement=1, **GAINS))
    before = await tb.counters()
    unicast = dict(dst_mac=tb.node_mac, dst_ip=node_ip(1))
    bad = [
        ("bad_header", tb.request(MsgType.ISEND_REQ, 1, page, magic=0x1234, **unicast)),
        ("bad_header", tb.request(MsgType.ISEND_REQ, 1, page, version=9, **unicast)),
        ("bad_header", tb.request(MsgType.ISEND_REQ, 1, page, length=3, **unicast)),
    ]
    bad_udp = tb.request(MsgType.ISEND_REQ, 1, page, **unicast)
    bad_udp[UDP].chksum = 0x1234
    bad_ip = tb.request(MsgType.ISEND_REQ, 1, page, **unicast)
    bad_ip[IP].chksum = 0x4321
    bad += [("l4_checksum", bad_udp), ("ip_header", bad_ip),
            ("no_port", finemb_frame(MsgType.ISEND_REQ, 1, page, dport=61921, **unicast)),
            ("not_mine", finemb_frame(MsgType.SOC, NODE_ALL, b"\0" * 16,
                                      dst_mac="01:00:5e:7f:46:46", dst_ip="239.255.70.70"))]
    for _, frame in bad:
        await tb.send(frame)
        await clock_cycles(dut.gmii_clk, 200)
    await tb.ports[0].send(None, raw=bytes(bad_ip)[:30])           # truncated (runt)
    # wrong page size: ERROR, nothing written
    res = await tb.exchange(tb.request(MsgType.ISEND_REQ, 1, page + b"\0\0", **unicast))
    assert res["flags"] & Flag.ERROR, res
    # foreign traffic on both ports, an ARP storm for other addresses
    for port in (0, 1):
        for k in range(40):
            await tb.send(Ether(src="02:aa:00:00:00:09", dst=BROADCAST_MAC) /
                          ARP(op=1, psrc="198.18.0.99", pdst=f"198.18.0.{100 + k}"), port)
        await tb.send(Ether(src="02:aa:00:00:00:09", dst=BROADCAST_MAC, type=0x88CC) /
                      Raw(bytes(50)), port)
    await clock_cycles(dut.gmii_clk, 8000)
    await tb.drain(0, 10)
    await tb.drain(1, 10)
    after = await tb.counters()
    moved = {k: after[k] - before[k] for k in after if after[k] != before[k]}
    for name, _ in bad:
        assert moved.get(name, 0) >= 1, (name, moved)
    assert moved.get("size", 0) + moved.get("fcs", 0) >= 1, moved
    assert moved["bad_page"] == 1 and moved["bad_header"] == 3, moved
    # the next request: answered with the model's output (the wrong-size page was not used)
    res = await tb.isend(1, dict(set_point=5, measurement=1, **GAINS))
    assert not res["flags"] & Flag.ERROR
    assert tb.io.unpack(Direction.IN, res["body"])["output"] == model.update(5, 1)


@cocotb.test()
async def watchdog_restart_and_id_conflict(dut):
    """Three cycle periods without SoC or ISEND_REQ, or a REINIT with reason 1: REINIT, which
    the next ISEND_RES reports while the node returns to OP (the one after reports OP). A
    master that restarts (REINIT to all): INIT, and the node is initialised again without a
    reset. An ADDR_REQ giving the node's id to another
    MAC: the node gives up its address."""
    tb, _ = await started(dut)
    await tb.send(tb.soc(period_ns=8_000))            # 1000 cycles
    res = await tb.isend(1, dict(set_point=1, measurement=0, **GAINS))
    assert res["state"] == NodeState.OP
    # the watchdog runs from the last SoC or ISEND_REQ, at most 400 cycles before its answer
    await clock_cycles(dut.gmii_clk, 2500)
    assert tb.state == NodeState.OP, "the watchdog fired before three periods"
    await clock_cycles(dut.gmii_clk, 600)
    assert tb.state == NodeState.REINIT
    # the first answer after the watchdog fired reports REINIT, the node is in OP again and
    # the next answer says so
    res = await tb.isend(1, dict(set_point=1, measurement=0, **GAINS))
    assert res["state"] == NodeState.REINIT and tb.state == NodeState.OP
    res = await tb.isend(1, dict(set_point=1, measurement=0, **GAINS))
    assert res["state"] == NodeState.OP
    assert (await tb.counters())["missed_cycles"] == 1
    # the same after a REINIT with reason 1 (application request) to this node
    await tb.send(tb.request(MsgType.REINIT, 1, body_of(MsgType.REINIT,
                                                        ReinitReason.APPLICATION)))
    await clock_cycles(dut.gmii_clk, 200)
    assert tb.state == NodeState.REINIT
    res = await tb.isend(1, dict(set_point=1, measurement=0, **GAINS))
    assert res["state"] == NodeState.REINIT and tb.state == NodeState.OP
    res = await tb.isend(1, dict(set_point=1, measurement=0, **GAINS))
    assert res["state"] == NodeState.OP
    await tb.send(tb.reinit_all())
    await clock_cycles(dut.gmii_clk, 200)
    assert tb.state == NodeState.INIT and int(dut.local_ip.value) == 0
    await tb.init(2)
    res = await tb.isend(2, dict(set_point=1, measurement=0, **GAINS))
    assert res["state"] == NodeState.OP and res["node_id"] == 2
    other_mac = bytes.fromhex("020000004699")
    await tb.send(tb.request(MsgType.ADDR_REQ, NODE_ALL, body_of(
        MsgType.ADDR_REQ, other_mac, bytes([198, 18, 0, 40]), bytes(4), 2),
        dst_mac=BROADCAST_MAC, dst_ip=BROADCAST_IP))
    await clock_cycles(dut.gmii_clk, 300)
    assert tb.state == NodeState.INIT and int(dut.node_id.value) == NODE_ALL
    assert (await tb.counters())["id_conflict"] == 1

