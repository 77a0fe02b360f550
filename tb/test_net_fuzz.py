"""Fuzzing the engine with a live TCP session (docs/network.md "Fuzzing"): scapy ``fuzz()``
frames per layer and seeded mutations of valid frames (bit flips, truncation at every offset,
bad IP/UDP lengths, TCP data offsets below 5 or past the end, SYN+FIN, SYN+RST, no flags,
sequence and acknowledgement numbers at the window edges), interleaved with a transfer in
both directions through a Linux-like peer model.

Oracles: the session's streams arrive byte-exact in both directions; ICMP and RBCP are still
answered afterwards; every frame sent is counted once (``frames_in``) and ends either
delivered or in one drop counter; every frame the engine sends has a good FCS and goes to a
MAC address it has heard from (or broadcast). 50 frames in make test, 10,000 in test-full;
the seed is logged.
"""

import os
import random

import cocotb
import pytest
from cocotb.triggers import ClockCycles
from cocotbext.eth import GmiiFrame
from scapy.layers.inet import ICMP, IP, TCP, UDP
from scapy.layers.l2 import ARP, Ether
from scapy.packet import Raw, fuzz
from scapy.utils import checksum

from hdl.net.frames import DEFAULT_RBCP_PORT, DROP_REASONS, TCP_ACK, TCP_FIN, TCP_RST, TCP_SYN
from host.ros1.rbcp import rbcp_request
from host.simulator import clock_cycles
from tb.harness import run_bench
from tb.models.tcp_peer import TcpPeerModel, fix_ip_checksum, fix_tcp_checksum, tcp_frame
from tb.net_tb import NET_CONFIGS, PEER_IP, PEER_MAC, NetTB, SessionPort, checksums_ok, rbcp

FRAMES = int(os.environ.get("ROSGATE_FUZZ_FRAMES", 100))


@pytest.mark.parametrize("frames", [pytest.param(50, id="50"),
                                    pytest.param(10_000, id="10k", marks=pytest.mark.full)])
def test_net_fuzz(frames):
    run_bench(__name__, "net", "stack", NET_CONFIGS["stack"], "verilator",
              extra_env={"ROSGATE_FUZZ_FRAMES": str(frames)}, run_name=str(frames))


class FuzzTB(NetTB):
    def __init__(self, dut):
        super().__init__(dut)
        self.rng = random.Random(cocotb.RANDOM_SEED)
        dut._log.info("fuzz seed %d, %d frames", cocotb.RANDOM_SEED, FRAMES)
        self.frames_sent = 0
        self.learned = {PEER_MAC, "ff:ff:ff:ff:ff:ff"}

    async def put(self, frame, *, fcs=True, error=False):
        raw = bytes(frame)
        # the engine may answer the frame's source, or an ARP request's sender
        if len(raw) >= 12:
            self.learned.add(":".join(f"{b:02x}" for b in raw[6:12]))
        if len(raw) >= 28 and raw[12:14] == b"\x08\x06":
            self.learned.add(":".join(f"{b:02x}" for b in raw[22:28]))
        gf = GmiiFrame.from_payload(raw) if fcs else GmiiFrame.from_raw_payload(raw)
        if error:
            gf.error = [0] * len(gf.data)
            gf.error[self.rng.randrange(len(gf.data))] = 1
        self.frames_sent += 1
        await self.source.send(gf)

    def check_frame(self, payload):
        dst = ":".join(f"{b:02x}" for b in payload[0:6])
        assert dst in self.learned, f"engine sent to unknown MAC {dst}"


def difference(got, want):
    """Where ``got`` first differs from ``want``, for the failure message."""
    n = next((i for i, (x, y) in enumerate(zip(got, want)) if x != y), min(len(got), len(want)))
    return (f"{len(got)} bytes, expected {len(want)}; first difference at {n}: "
            f"{got[n:n + 16].hex()} instead of {want[n:n + 16].hex()}")


def is_live_segment(frame, peer):
    """Whether ``frame`` is a well-formed data or FIN segment of the live connection: the
    engine must take it as data if it lands at RCV.NXT, so such a mutant (bit flips that
    keep the checksum) is not fuzz and is regenerated."""
    if len(frame) < 54 or frame[12:14] != b"\x08\x00" or frame[23] != 6:
        return False
    ihl = (frame[14] & 0xF) * 4
    total = int.from_bytes(frame[16:18], "big")
    if ihl < 20 or total < ihl + 20 or 14 + total > len(frame) or checksum(frame[14:14 + ihl]):
        return False
    seg = frame[14 + ihl:14 + total]
    pseudo = frame[26:34] + bytes([0, 6]) + len(seg).to_bytes(2, "big")
    if checksum(pseudo + seg):
        return False
    sport, dport = int.from_bytes(seg[0:2], "big"), int.from_bytes(seg[2:4], "big")
    doff = (seg[12] >> 4) * 4
    flags = seg[13]
    carries = len(seg) > doff or flags & TCP_FIN
    return ((sport, dport) == (peer.port, peer.eport) and
            frame[26:30] == peer.ip.to_bytes(4, "big") and flags & TCP_ACK and
            not flags & (TCP_RST | TCP_SYN) and bool(carries))


def valid_frames(tb, peer):
    """Valid frames of every kind, to mutate."""
    base = Ether(src=PEER_MAC, dst=tb.mac) / IP(src=PEER_IP, dst=tb.ip)
    return [
        base / ICMP(type=8, id=7, seq=1) / Raw(b"fuzz" * 8),
        base / UDP(sport=50001, dport=DEFAULT_RBCP_PORT) /
        Raw(rbcp_request(0xC0, 1, 0x10, 4)),
        Ether(src=PEER_MAC, dst="ff:ff:ff:ff:ff:ff") /
        ARP(op=1, hwsrc=PEER_MAC, psrc=PEER_IP, pdst=tb.ip),
        base / TCP(sport=40000, dport=24, flags="S", seq=5),
        Ether(tcp_frame(peer.mac, peer.emac, peer.ip, peer.eip, peer.port, peer.eport,
                        peer.snd_nxt + 3000, peer.rcv_nxt or 0, TCP_ACK, 65535,
                        b"x" * 100)),
    ]


def mutant(tb, peer, rng):
    """One fuzz frame and whether it must carry a good FCS."""
    kind = rng.randrange(10)
    base = Ether(src=PEER_MAC, dst=tb.mac) / IP(src=PEER_IP, dst=tb.ip)
    if kind == 0:
        layer = rng.choice([TCP(dport=rng.choice([24, 25, 80])), UDP(dport=DEFAULT_RBCP_PORT),
                            ICMP(), UDP()])
        return bytes(base / fuzz(layer)), True
    if kind == 1:
        return bytes(Ether(src=PEER_MAC, dst=tb.mac) / fuzz(IP(dst=tb.ip) / TCP())), True
    if kind == 2:
        return bytes(Ether(src=PEER_MAC, dst="ff:ff:ff:ff:ff:ff") / fuzz(ARP(pdst=tb.ip))), True
    raw = bytearray(bytes(rng.choice(valid_frames(tb, peer))))
    if kind == 3:                                     # bit flips
        for _ in range(rng.randint(1, 8)):
            raw[rng.randrange(14, len(raw))] ^= 1 << rng.randrange(8)
        return bytes(raw), True
    if kind == 4:                                     # truncated, good FCS
        return bytes(raw[:rng.randrange(1, len(raw))]), True
    if kind == 5:                                     # bad FCS / RX_ER
        return bytes(raw), False
    if kind == 6 and len(raw) > 40:                   # IP total length / UDP length
        field = rng.choice([16, 38])
        value = rng.choice([0, 1, 19, 20, 21, len(raw), 1500, 65535])
        raw[field:field + 2] = value.to_bytes(2, "big")
        if rng.random() < 0.5:
            fix_ip_checksum(raw)
        return bytes(raw), True
    if kind == 7:                                     # TCP data offset, flags, live 4-tuple
        seq = rng.choice([peer.snd_nxt + 1000, peer.snd_una - 1, peer.snd_nxt + 65535,
                          peer.snd_nxt + 2**31])
        ack = rng.choice([0, peer.rcv_nxt or 0, (peer.rcv_nxt or 0) + 2**20, 2**32 - 1])
        flags = rng.choice([TCP_SYN | TCP_FIN, TCP_SYN | TCP_RST, 0, TCP_RST | TCP_ACK,
                            TCP_SYN, TCP_FIN])
        f = bytearray(tcp_frame(peer.mac, peer.emac, peer.ip, peer.eip, peer.port, peer.eport,
                                seq, ack, flags, rng.randrange(65536),
                                rng.randbytes(rng.choice([0, 0, 3, 40]))))
        if rng.random() < 0.5:
            f[46] = rng.choice([0x00, 0x10, 0x40, 0xF0]) | (f[46] & 0x0F)   # data offset
            fix_tcp_checksum(f)
        return bytes(f), True
    if kind == 8:                                     # random bytes
        return rng.randbytes(rng.randint(1, 1600)), rng.random() < 0.5
    # data on the live connection with a bad checksum
    f = bytearray(tcp_frame(peer.mac, peer.emac, peer.ip, peer.eip, peer.port, peer.eport,
                            peer.snd_nxt, peer.rcv_nxt or 0, TCP_ACK, 65535, b"BAD!" * 10))
    f[50] ^= 0x5A
    return bytes(f), True


@cocotb.test()
async def run_fuzz_live_session(dut):
    tb = FuzzTB(dut)
    await tb.reset()
    rng = tb.rng
    s = SessionPort(dut, 0, random.Random(rng.random()))
    s.set_pauses(0.1, 0.1)
    s.set(active=0, local_port=24, open_req=1)
    await ClockCycles(dut.aclk, 20)
    peer = TcpPeerModel(mac=PEER_MAC, ip=PEER_IP, port=40000, engine_mac=tb.mac,
                        engine_ip=tb.ip, engine_port=24, isn=rng.randrange(2**32),
                        rto=100_000)
    await tb.put(peer.syn())
    peer_task = cocotb.start_soon(tb.run_peer(peer))
    for _ in range(200):
        if peer.established:
            break
        await clock_cycles(dut.aclk, 100)
    assert peer.established, "no connection"
    up = rng.randbytes(64 * 1024)
    down = rng.randbytes(64 * 1024)
    peer.queue(up)
    cocotb.start_soon(s.write(down))
    for i in range(FRAMES):
        frame, good_fcs = mutant(tb, peer, rng)
        while good_fcs and is_live_segment(frame, peer):
            frame, good_fcs = mutant(tb, peer, rng)
        # fuzz shares the link with the peer: queue a frame only when the link is nearly idle
        while tb.source.count() > 1:
            await ClockCycles(dut.aclk, 32)
        await tb.put(frame, fcs=good_fcs, error=not good_fcs and rng.random() < 0.5)
        if i % 50 == 49:
            await clock_cycles(dut.aclk, rng.randrange(200, 2000))
    for _ in range(4000):
        if len(s.received) >= len(up) and len(peer.received) >= len(down):
            break
        await clock_cycles(dut.aclk, 500)
    dut._log.info("end: state %d, engine %s, stack %s, peer snd_una %d snd_nxt %d window %d "
                  "retransmissions %d rst %d", s.get("state"), await tb.session_counters(0),
                  await tb.counters(), peer.snd_una, peer.snd_nxt, peer.peer_window,
                  peer.retransmissions, peer.rst_received)
    assert bytes(s.received) == up, "engine received: " + difference(bytes(s.received), up)
    assert bytes(peer.received) == down, "peer received: " + difference(bytes(peer.received),
                                                                        down)
    peer_task.cancel()
    await clock_cycles(dut.aclk, 3000)
    # still answering
    await tb.send(Ether(src=PEER_MAC, dst=tb.mac) / IP(src=PEER_IP, dst=tb.ip) /
                  ICMP(type=8, id=1, seq=2) / Raw(b"alive"))
    tb.frames_sent += 1
    reply = await tb.recv(20000)
    while reply is not None and ICMP not in reply:
        reply = await tb.recv(20000)
    assert reply is not None and checksums_ok(reply) and bytes(reply[ICMP].payload) == b"alive"
    answer = await rbcp(tb, rbcp_request(0xC0, 3, 0x10, 4))
    tb.frames_sent += 1
    assert answer is not None and answer[1] == 0xC8
    await clock_cycles(dut.aclk, 200)
    counts = await tb.counters()
    accounted = counts["delivered"] + sum(counts[r] for r in DROP_REASONS)
    dut._log.info("counters %s, session %s", counts, await tb.session_counters(0))
    assert counts["frames_in"] == tb.frames_sent, (counts["frames_in"], tb.frames_sent)
    assert accounted == counts["frames_in"], f"{accounted} accounted of {counts['frames_in']}"
