"""Protocol conformance of the network engine with scapy-built frames through cocotbext-eth
GMII models (docs/network.md "Protocol"): ARP, ICMP echo, RBCP (reference replies from
sitcpy's pseudo device), bad frames and their drop counters, TCP against a scripted peer.

Golden models: scapy (frame dissection and checksums), zlib via cocotbext-eth (FCS), sitcpy's
RBCP header encoder, RFC 9293 rules written into the scripted peer's expectations."""

import random
import zlib

import cocotb
from cocotb.utils import get_sim_time
from scapy.layers.inet import ICMP, IP, TCP, UDP
from scapy.layers.l2 import ARP, Ether
from scapy.packet import Raw
from sitcpy.rbcp_server import _make_header as sitcpy_rbcp_header

from hdl.net.frames import DEFAULT_RBCP_PORT, DROP_REASONS, IFG, MIN_FRAME, PREAMBLE
from hdl.net.stack import GLOBAL_BASE, GLOBAL_OFFSETS, STACK_COUNTERS, global_register
from host.ros1.rbcp import rbcp_request
from tb.harness import cocotb_bench
from tb.net_tb import (
    CLOCK_NS,
    GMII_NS,
    NET_CONFIGS,
    PEER_IP,
    PEER_MAC,
    WIDE_USER_CONFIGS,
    NetTB,
    checksums_ok,
    eth,
    rbcp,
)

CONFIGS = NET_CONFIGS
#: make test: Verilator (whose build the fuzz test shares); Icarus in test-full
test_net = cocotb_bench("net", CONFIGS, long=[("stack", "icarus")])
#: Sessions with 32-bit user streams (``user_width``): the tests that move data through the
#: user ports run on it, on Verilator in the long matrix only.
WIDE_USER = WIDE_USER_CONFIGS
test_net_wide_user = cocotb_bench("net", WIDE_USER, testcases=[
    "run_tcp_server_scripted", "run_tcp_user_streams_random"],
    long=[("stack_w32", "verilator")])
#: A transmit ring of 4 descriptors (3 segments), where the window after a fast retransmit
#: (ssthresh + 3) must be capped at the ring; only the fast-retransmit test runs on it.
SMALL_RING = {"stack_ring4": dict(NET_CONFIGS["stack"], descriptors=4)}
test_net_small_ring = cocotb_bench("net", SMALL_RING, testcases=["run_tcp_fast_retransmit"],
                                   long=[("stack_ring4", "verilator")])


#: Core cycles a minimum-size frame (a pure ACK, a RST) occupies the wire: preamble, SFD, the
#: frame padded to its minimum with FCS, at a byte per GMII cycle
WIRE_MIN_FRAME = (PREAMBLE + 1 + MIN_FRAME) * GMII_NS // CLOCK_NS
#: Core cycles from the end of one peer frame to the end of a pure ACK sent right after it
WIRE_ACK = (IFG + PREAMBLE + 1 + MIN_FRAME) * GMII_NS // CLOCK_NS


def sim_cycle():
    """The current simulated time in clock cycles."""
    return int(get_sim_time("ns")) // CLOCK_NS


def assert_counts(before, after, **expected):
    """Only the named counters moved, by the given amounts (frames_in by their sum)."""
    moved = {k: after[k] - before[k] for k in STACK_COUNTERS if after[k] != before[k]}
    want = dict(expected)
    want["frames_in"] = sum(v for k, v in expected.items() if k in ("delivered",) + DROP_REASONS)
    want = {k: v for k, v in want.items() if v}
    assert moved == want, f"counters moved {moved}, expected {want}"


@cocotb.test()
async def run_arp(dut):
    tb = NetTB(dut)
    await tb.reset()
    before = await tb.counters()
    await tb.send(eth(tb, "ff:ff:ff:ff:ff:ff") /
                  ARP(op=1, hwsrc=PEER_MAC, psrc=PEER_IP, pdst=tb.ip))
    reply = await tb.recv()
    assert reply is not None, "no ARP reply"
    assert reply.dst == PEER_MAC and reply.src == tb.mac and reply.type == 0x0806
    arp = reply[ARP]
    assert (arp.op, arp.hwsrc, arp.psrc, arp.hwdst, arp.pdst) == (2, tb.mac, tb.ip, PEER_MAC,
                                                                    PEER_IP)
    # requests for another address and gratuitous ARP get nothing
    await tb.send(eth(tb, "ff:ff:ff:ff:ff:ff") /
                  ARP(op=1, hwsrc=PEER_MAC, psrc=PEER_IP, pdst="192.168.10.99"))
    await tb.send(eth(tb, "ff:ff:ff:ff:ff:ff") /
                  ARP(op=1, hwsrc=PEER_MAC, psrc=PEER_IP, pdst=PEER_IP))
    await tb.expect_silence()
    assert_counts(before, await tb.counters(), delivered=1, not_mine=2, frames_out=1)


@cocotb.test()
async def run_icmp_echo(dut):
    tb = NetTB(dut)
    await tb.reset()
    rng = random.Random(1)
    before = await tb.counters()
    for seq, size in enumerate((0, 1, 56, 333, 1472)):
        data = rng.randbytes(size)
        await tb.send(eth(tb) / IP(src=PEER_IP, dst=tb.ip, id=seq) /
                      ICMP(type=8, id=0x1234, seq=seq) / Raw(data))
        reply = await tb.recv()
        assert reply is not None, f"no echo reply to {size} bytes"
        assert checksums_ok(reply), reply.show(dump=True)
        ip, icmp = reply[IP], reply[ICMP]
        assert (ip.src, ip.dst, ip.ttl, ip.flags.DF) == (tb.ip, PEER_IP, 64, True)
        assert (icmp.type, icmp.code, icmp.id, icmp.seq) == (0, 0, 0x1234, seq)
        assert bytes(icmp.payload) == data, f"echo data differs at {size} bytes"
    # a bad ICMP checksum and a fragment get no reply
    bad = eth(tb) / IP(src=PEER_IP, dst=tb.ip) / ICMP(type=8, chksum=0x1234) / Raw(b"x" * 8)
    await tb.send(bad)
    await tb.send(eth(tb) / IP(src=PEER_IP, dst=tb.ip, flags="MF") / ICMP(type=8) / Raw(b"y" * 8))
    await tb.send(eth(tb) / IP(src=PEER_IP, dst=tb.ip, frag=10) / ICMP(type=8) / Raw(b"y" * 8))
    await tb.expect_silence()
    assert_counts(before, await tb.counters(), delivered=5, l4_checksum=1, fragment=2, frames_out=5)


@cocotb.test()
async def run_bad_frames(dut):
    tb = NetTB(dut)
    await tb.reset()
    before = await tb.counters()
    ping = eth(tb) / IP(src=PEER_IP, dst=tb.ip) / ICMP(type=8) / Raw(b"p" * 20)
    raw = bytes(ping)
    await tb.send(raw[:-1] + bytes([raw[-1] ^ 1]) + b"\x00" * 0, fcs=True)   # checksum broken
    from cocotbext.eth import GmiiFrame
    good = GmiiFrame.from_payload(raw)
    good.data[-1] ^= 0xFF                                     # bad FCS
    await tb.source.send(good)
    await tb.send(raw, error=True)                            # RX_ER in the frame
    await tb.send(raw[:40], fcs=False)                        # runt (44 bytes with no pad)
    await tb.send(bytes(eth(tb) / IP(src=PEER_IP, dst=tb.ip) / ICMP(type=8) /
                        Raw(b"L" * 1480)))                     # 1522 bytes: too long
    await tb.send(bytes(eth(tb) / IP(src=PEER_IP, dst=tb.ip) / ICMP(type=8) /
                        Raw(b"L" * 1473)))                     # 1519 bytes: one too many
    await tb.send(raw[:59] + zlib.crc32(raw[:59]).to_bytes(4, "little"),
                  fcs=False)                                  # 63 bytes, good FCS: too short
    await tb.send(eth(tb, "02:00:00:00:00:77") / IP(src=PEER_IP, dst=tb.ip) / ICMP(type=8))
    await tb.send(eth(tb) / IP(src=PEER_IP, dst="192.168.10.77") / ICMP(type=8))
    await tb.send(eth(tb) / IP(src=PEER_IP, dst=tb.ip, proto=99) / Raw(b"z" * 20))
    hdr = bytearray(bytes(eth(tb) / IP(src=PEER_IP, dst=tb.ip) / ICMP(type=8)))
    hdr[24] ^= 0x40                                           # IP header checksum
    await tb.send(bytes(hdr))
    # IP total length 4096 beyond the frame, checksums right: the datagram's end taken
    # modulo 4096 would fall on the frame's end (found by tb/test_net_formal.py)
    await tb.send(eth(tb) / IP(src=PEER_IP, dst=tb.ip, len=20 + 8 + 20 + 4096) / ICMP(type=8) /
                  Raw(b"p" * 20))
    await tb.send(eth(tb) / IP(src=PEER_IP, dst=tb.ip) / UDP(sport=1, dport=9) / Raw(b"u"))
    await tb.expect_silence()
    assert_counts(before, await tb.counters(), l4_checksum=1, fcs=1, rx_er=1, size=4, not_mine=2,
                  protocol=1, ip_header=2, no_port=1)
    # still answering afterwards
    await tb.send(ping)
    assert (await tb.recv()) is not None


async def write_global(tb, name, value):
    """Write one of the stack's registers (:data:`GLOBAL_REGS`) through RBCP; the next
    ``tb.reset()`` gives it back its configured value."""
    address, size = global_register(name)
    data = value.to_bytes(size, "big")
    reply = await rbcp(tb, rbcp_request(0x80, 0x5A, address, size, data))
    assert reply == sitcpy_rbcp_header("w", 0x5A, address, size) + data, reply


#: the configuration's retransmission timeout, which tests that shorten or lengthen it restore
CONFIG_RTO_CYCLES = NET_CONFIGS["stack"]["rto_us"] * 1000 // CLOCK_NS
CONFIG_MSL_CYCLES = NET_CONFIGS["stack"]["msl_us"] * 1000 // CLOCK_NS


@cocotb.test()
async def run_rbcp(dut):
    tb = NetTB(dut)
    await tb.reset()
    rng = random.Random(2)
    for ident, (addr, n) in enumerate([(0x10, 1), (0x100, 4), (0x1000, 255), (0xFF01, 255)]):
        data = rng.randbytes(n)
        reply = await rbcp(tb, rbcp_request(0x80, ident, addr, n, data))
        assert reply == sitcpy_rbcp_header("w", ident, addr, n) + data, reply.hex()
        assert bytes(tb.bus.mem[addr:addr + n]) == data
        reply = await rbcp(tb, rbcp_request(0xC0, ident + 100, addr, n))
        assert reply == sitcpy_rbcp_header("r", ident + 100, addr, n) + data, reply.hex()
    writes = tb.bus.writes
    # bus errors: Length 0, outside the decoded window, range wrapping, short write data
    for ident, (addr, n, data) in enumerate([(0x20, 0, b""), (0x00FF0000, 4, b"abcd"),
                                             (0xFFFFFFFE, 4, b"abcd"), (0x30, 4, b"ab")]):
        reply = await rbcp(tb, rbcp_request(0x80, 200 + ident, addr, n, data))
        assert reply is not None and reply[1] == 0x89 and reply[2] == 200 + ident, reply
        assert len(reply) == 8 + n
    reply = await rbcp(tb, rbcp_request(0xC0, 7, 0x01000000, 3))
    assert reply == sitcpy_rbcp_header("re", 7, 0x01000000, 3) + bytes(3), reply.hex()
    assert tb.bus.writes == writes, "a rejected request wrote to the bus"
    # no reply: bad version, unknown command, short header
    for payload in (b"\xfe\x80\x01\x01\x00\x00\x00\x00\x00", b"\xff\x81\x01\x01\x00\x00\x00\x00",
                    b"\xff\x80\x01"):
        assert await rbcp(tb, payload) is None
    # the stack's own registers: read the IP, write it, read the counters
    ip_off = GLOBAL_OFFSETS["ip"]
    reply = await rbcp(tb, rbcp_request(0xC0, 9, GLOBAL_BASE + ip_off, 4))
    assert reply[8:] == bytes(int(b) for b in tb.ip.split("."))
    cnt_off = GLOBAL_OFFSETS["counters"]
    reply = await rbcp(tb, rbcp_request(0xC0, 10, GLOBAL_BASE + cnt_off, 8))
    frames_in = int.from_bytes(reply[8:12], "big")
    # the request itself may not have reached the counter when it was read
    assert frames_in in ((await tb.counters())["frames_in"] - 1, (await tb.counters())["frames_in"])


class ScriptedPeer:
    """A TCP peer whose every segment the test writes: it tracks its own sequence number
    and builds scapy segments to the engine."""

    def __init__(self, tb, sport, dport, isn):
        self.tb, self.sport, self.dport = tb, sport, dport
        self.seq = isn
        self.ack = 0

    def segment(self, flags, data=b"", *, seq=None, ack=None, options=(), raw_options=b"",
                window=65535):
        """``options`` as scapy's list, or ``raw_options`` as bytes (a multiple of 4) that go
        out as written, malformed or not."""
        return (eth(self.tb) / IP(src=PEER_IP, dst=self.tb.ip) /
                TCP(sport=self.sport, dport=self.dport, flags=flags,
                    seq=(self.seq if seq is None else seq) % 2**32,
                    ack=(self.ack if ack is None else ack) % 2**32,
                    window=window, options=list(options),
                    dataofs=5 + len(raw_options) // 4 if raw_options else None) /
                Raw(raw_options + data))

    async def send(self, flags, data=b"", advance=True, **kw):
        await self.tb.send(self.segment(flags, data, **kw))
        if advance and "seq" not in kw:
            self.seq += len(data) + ("S" in flags) + ("F" in flags)

    async def expect(self, flags, *, seq=None, ack=None, data=b"", timeout=6000):
        frame = await self.tb.recv(timeout)
        assert frame is not None, f"no segment (expected {flags})"
        assert checksums_ok(frame), frame.show(dump=True)
        tcp = frame[TCP]
        assert str(tcp.flags) == flags, f"flags {tcp.flags}, expected {flags}"
        assert (tcp.sport, tcp.dport) == (self.dport, self.sport)
        if seq is not None:
            assert tcp.seq == seq % 2**32, f"seq {tcp.seq}, expected {seq % 2**32}"
        if ack is not None:
            assert tcp.ack == ack % 2**32, f"ack {tcp.ack}, expected {ack % 2**32}"
        if data is not None:
            assert bytes(tcp.payload) == data, (bytes(tcp.payload), data)
        return tcp


@cocotb.test()
async def run_tcp_server_scripted(dut):
    from hdl.net.tcp import TcpState
    from tb.net_tb import SessionPort
    tb = NetTB(dut)
    await tb.reset()
    s = SessionPort(dut, 0, random.Random(3))
    s.set(active=0, local_port=24, open_req=1)
    await s.wait_state(TcpState.LISTEN)
    peer = ScriptedPeer(tb, 40000, 24, isn=0xFFFFFFF0)     # wraps 2**32 during the test
    await peer.send("S", options=[("MSS", 1400), ("NOP", None), ("WScale", 7),
                                  ("SAckOK", b""), ("Timestamp", (1, 0))])
    synack = await peer.expect("SA", ack=peer.seq)
    assert synack.options == [("MSS", 1460)], synack.options
    assert synack.window == NET_CONFIGS["stack"]["rx_depth"] - 1
    iss = synack.seq
    peer.ack = iss + 1
    await peer.send("A")
    await s.wait_state(TcpState.ESTABLISHED)
    assert s.get("open_ack") == 1
    # data in, acknowledged at once because of PSH
    await peer.send("PA", b"hello world, ")
    await peer.expect("A", ack=peer.seq, seq=iss + 1)
    assert await s.wait_received(13, 2000) == b"hello world, "
    # data out
    await s.write(b"reply")
    await peer.expect("PA", seq=iss + 1, ack=peer.seq, data=b"reply")
    peer.ack += 5
    # a duplicate and an out-of-order segment: duplicate ACKs, nothing delivered twice
    await peer.send("PA", b"world, ", seq=peer.seq - 7)
    await peer.expect("A", ack=peer.seq)
    await peer.send("PA", b"later", seq=peer.seq + 100)
    await peer.expect("A", ack=peer.seq)
    await peer.send("PA", b"again")
    await peer.expect("A", ack=peer.seq)
    assert s.received == b"hello world, again"
    # peer closes: ACK of the FIN, CLOSE-WAIT, user's close_ack sends our FIN
    await peer.send("FA")
    await peer.expect("A", ack=peer.seq)
    await s.wait_state(TcpState.CLOSE_WAIT)
    assert s.get("close_req") == 1
    s.set(close_ack=1)
    await peer.expect("FA", seq=iss + 6, ack=peer.seq)
    s.set(close_ack=0)
    peer.ack += 1
    await peer.send("A")
    await s.wait_state(TcpState.LISTEN)
    # a segment for a port nobody listens on gets RST (RFC 9293 §3.10.7.1)
    other = ScriptedPeer(tb, 40001, 25, isn=77)
    await other.send("A", ack=1234)
    await other.expect("R", seq=1234)
    await other.send("S")
    await other.expect("RA", seq=0, ack=78)
    assert (await tb.session_counters(0))["bytes_rx"] == 18


@cocotb.test()
async def run_tcp_malformed_options(dut):
    """docs/network.md: a malformed option (length below 2, or running past the data offset)
    stops the option walk, the segment is processed all the same and ``tcp_bad_options``
    counts it; an MSS option before the fault is used, one after it is not. Without an MSS
    option the peer's MSS is 536."""
    from hdl.net.tcp import TcpState
    from tb.net_tb import SessionPort
    tb = NetTB(dut)
    await tb.reset()
    s = SessionPort(dut, 0, random.Random(5))
    s.set(active=0, local_port=24, open_req=1)
    await s.wait_state(TcpState.LISTEN)
    before = await tb.counters()
    peer = ScriptedPeer(tb, 40002, 24, isn=1000)
    # MSS 300, SACK-permitted with length 0, two NOPs, MSS 100
    await peer.send("S", raw_options=b"\x02\x04\x01\x2c\x04\x00\x01\x01\x02\x04\x00\x64")
    synack = await peer.expect("SA", ack=peer.seq)
    peer.ack = synack.seq + 1
    await peer.send("A")
    await s.wait_state(TcpState.ESTABLISHED)
    # data behind a timestamp option that the data offset cuts
    await peer.send("PA", b"still delivered", raw_options=b"\x01\x01\x08\x0a\x00\x00\x00\x01")
    await peer.expect("A", ack=peer.seq)
    assert await s.wait_received(15, 2000) == b"still delivered"
    # well-formed options: processed, not counted
    await peer.send("PA", b"!", raw_options=b"\x01\x01\x08\x0a" + bytes(8))
    await peer.expect("A", ack=peer.seq)
    assert await s.wait_received(16, 2000) == b"still delivered!"
    # the peer's MSS of 300 cuts what the user writes
    data = bytes(range(256)) * 3
    await s.write(data)
    sent = b""
    for want in (300, 300, 168):
        seg = await peer.expect("PA", seq=synack.seq + 1 + len(sent), ack=peer.seq, data=None)
        assert len(seg.payload) == want, (len(seg.payload), want)
        sent += bytes(seg.payload)
    assert sent == data
    assert_counts(before, await tb.counters(), delivered=4, tcp_bad_options=2, frames_out=6)
    # a SYN without options: the peer's MSS is 536 (RFC 9293 §3.7.1)
    s.set(abort=1)
    await peer.expect("R", seq=synack.seq + 1 + len(data))
    s.set(abort=0)
    await s.wait_state(TcpState.LISTEN)
    peer = ScriptedPeer(tb, 40010, 24, isn=2000)
    await peer.send("S")
    synack = await peer.expect("SA", ack=peer.seq)
    peer.ack = synack.seq + 1
    await peer.send("A")
    await s.wait_state(TcpState.ESTABLISHED)
    await s.write(data[:1000])
    for start, stop in ((0, 536), (536, 1000)):
        await peer.expect("PA", seq=synack.seq + 1 + start, ack=peer.seq, data=data[start:stop])


@cocotb.test()
async def run_tcp_user_streams_random(dut):
    """8 KiB each way between a Linux-like peer model and the user streams, with random idle
    on ``tx`` and random backpressure on ``rx``, and a stretch in which the user reads
    nothing (the 4 KiB receive ring fills, the window shrinks below a segment and reopens):
    byte-exact both ways. On wider user streams every ``rx`` beat has ``tkeep`` contiguous
    from byte 0, partial only with ``tlast``."""
    from hdl.net.tcp import TcpState
    from tb.models.tcp_peer import TcpPeerModel
    from tb.net_tb import SessionPort
    tb = NetTB(dut)
    await tb.reset()
    rng = random.Random(21)
    s = SessionPort(dut, 0, random.Random(22))
    s.set_pauses(0.3, 0.3)
    s.set(active=0, local_port=24, open_req=1)
    await s.wait_state(TcpState.LISTEN)
    peer = TcpPeerModel(mac=PEER_MAC, ip=PEER_IP, port=40030, engine_mac=tb.mac,
                        engine_ip=tb.ip, engine_port=24, isn=rng.randrange(2**32))
    await tb.put(peer.syn())
    peer_task = cocotb.start_soon(tb.run_peer(peer))
    await s.wait_state(TcpState.ESTABLISHED, 20000)
    # (the odd length leaves a partial last beat on wider streams: it must not wait)
    up, down = rng.randbytes(8 * 1024 + 3), rng.randbytes(8 * 1024)
    peer.queue(up)
    # chunks of random sizes, each closed by tlast (a PSH on the byte stream)
    chunks, at = [], 0
    while at < len(down):
        size = rng.choice([1, 2, 3, 5, 64, 700, 1500, 3000])
        chunks.append(down[at:at + size])
        at += size

    async def write_all():
        for chunk in chunks:
            await s.write(chunk)

    cocotb.start_soon(write_all())
    s.set_pauses(0.3, 1.0)
    await tb.idle(10000)
    # the peer sends full segments only, so the ring stops one segment short of full
    assert peer.peer_window < 1460, f"window {peer.peer_window} with the user not reading"
    s.set_pauses(0.3, 0.3)
    for _ in range(400):
        if len(s.received) >= len(up) and len(peer.received) >= len(down):
            break
        await tb.idle(500)
    peer_task.cancel()
    assert s.received == up, f"engine delivered {len(s.received)} of {len(up)} bytes"
    assert bytes(peer.received) == down, f"peer got {len(peer.received)} of {len(down)} bytes"
    width = len(dut.tcp0_rx_tdata) // 8
    packets = s.sink.packets + [s.sink.current]
    for packet in packets:
        for n, (_, keep, _) in enumerate(packet.beats):
            count = bin(keep).count("1")
            assert keep == (1 << count) - 1 and count, f"rx tkeep {keep:#x}"
            assert count == width or n == len(packet.beats) - 1, \
                f"a partial rx beat ({count} of {width} bytes) without tlast"


@cocotb.test()
async def run_tcp_default_port_and_shared_listen(dut):
    """Sessions listening with ``local_port`` 0 use the stack's TCP port, SiTCP's 24 by
    default (a register, read back over RBCP); two sessions on one port serve two
    connections: a SYN goes to the lowest-numbered listener, a retransmitted SYN to the
    session whose connection it belongs to (one SYN-ACK, the other session keeps
    listening); a third SYN finds no listener and gets RST. A new value of the register
    applies at the next listen."""
    from hdl.net.tcp import TcpState
    from tb.net_tb import SessionPort
    tb = NetTB(dut)
    await tb.reset()
    reply = await rbcp(tb, rbcp_request(0xC0, 11, GLOBAL_BASE + GLOBAL_OFFSETS["tcp_port"], 2))
    assert reply is not None and reply[8:] == (24).to_bytes(2, "big"), reply
    sessions = [SessionPort(dut, k, random.Random(31 + k)) for k in range(2)]
    for s in sessions:
        s.set(active=0, local_port=0, open_req=1)
        await s.wait_state(TcpState.LISTEN)
    peers = []
    for k, s in enumerate(sessions):
        peer = ScriptedPeer(tb, 41000 + k, 24, isn=1000 * (k + 1))
        await peer.send("S", options=[("MSS", 1460)])
        synack = await peer.expect("SA", ack=peer.seq)
        await tb.expect_silence(500)
        assert TcpState(s.get("state")) == TcpState.SYN_RECEIVED
        if k == 0:
            assert TcpState(sessions[1].get("state")) == TcpState.LISTEN
            await peer.send("S", seq=peer.seq - 1, advance=False, options=[("MSS", 1460)])
            await peer.expect("SA", seq=synack.seq, ack=peer.seq)
            await tb.expect_silence(500)
            assert TcpState(sessions[1].get("state")) == TcpState.LISTEN
        peer.ack = synack.seq + 1
        await peer.send("A")
        await s.wait_state(TcpState.ESTABLISHED)
        peers.append(peer)
    third = ScriptedPeer(tb, 41002, 24, isn=9000)
    await third.send("S")
    await third.expect("RA", seq=0, ack=9001)
    for k, (s, peer) in enumerate(zip(sessions, peers)):
        message = f"to session {k}".encode()
        await peer.send("PA", message)
        await peer.expect("A", ack=peer.seq)
        assert await s.wait_received(len(message), 2000) == message
    await write_global(tb, "tcp_port", 8024)
    for s, peer in zip(sessions, peers):
        s.set(abort=1)
        await peer.expect("R", seq=peer.ack)
        s.set(abort=0)
        await s.wait_state(TcpState.LISTEN)
    moved = ScriptedPeer(tb, 41003, 8024, isn=1)
    await moved.send("S")
    await moved.expect("SA", ack=moved.seq)
    assert TcpState(sessions[0].get("state")) == TcpState.SYN_RECEIVED
    old = ScriptedPeer(tb, 41004, 24, isn=1)
    await old.send("S")
    await old.expect("RA", seq=0, ack=2)


@cocotb.test()
async def run_tcp_peer_mss_floor(dut):
    """A peer MSS below 48 is raised to 48, Linux's floor (``net.ipv4.tcp_min_snd_mss``,
    CVE-2019-11479), in both handshakes: MSS 1 in a client's SYN (server mode) and MSS 0 in
    a server's SYN-ACK (client mode) give 48-byte segments, not 1-byte ones or none."""
    from hdl.net.tcp import TcpState
    linux_min_snd_mss = 48
    data = bytes(range(100))
    cuts = [(start, min(start + linux_min_snd_mss, len(data)))
            for start in range(0, len(data), linux_min_snd_mss)]
    tb = NetTB(dut)
    await tb.reset()
    peer = ScriptedPeer(tb, 40020, 24, isn=3000)
    s, iss = await establish(tb, 0, 24, peer, mss=1)
    await s.write(data)
    for start, stop in cuts:
        await peer.expect("PA", seq=iss + 1 + start, ack=peer.seq, data=data[start:stop])
    s.set(abort=1)
    await peer.expect("R", seq=iss + 1 + len(data))
    s.set(abort=0, open_req=0)
    c, syn = await client_open(tb, 1, 5002, 9)
    server = ScriptedPeer(tb, 5002, syn.sport, isn=9000)
    server.ack = syn.seq + 1
    await server.send("SA", options=[("MSS", 0)])
    await server.expect("A", seq=syn.seq + 1, ack=server.seq)
    await c.wait_state(TcpState.ESTABLISHED, 500)
    await c.write(data)
    for start, stop in cuts:
        await server.expect("PA", seq=syn.seq + 1 + start, ack=server.seq,
                            data=data[start:stop])
    c.set(abort=1)
    await server.expect("R", seq=syn.seq + 1 + len(data))
    c.set(abort=0, open_req=0)


async def establish(tb, k, port, peer, *, window=65535, mss=1460):
    """Session ``k`` listening on ``port``; ``peer`` completes the handshake (announcing
    ``mss``); returns the session port and the ISS."""
    from hdl.net.tcp import TcpState
    from tb.net_tb import SessionPort
    s = SessionPort(tb.dut, k, random.Random(k))
    s.set(active=0, local_port=port, open_req=1)
    await s.wait_state(TcpState.LISTEN)
    await peer.send("S", options=[("MSS", mss)], window=window)
    synack = await peer.expect("SA", ack=peer.seq)
    peer.ack = synack.seq + 1
    await peer.send("A", window=window)
    await s.wait_state(TcpState.ESTABLISHED)
    return s, synack.seq


async def client_open(tb, k, port, seed):
    """Session ``k`` opens a client connection to the peer's ``port``: the engine broadcasts
    an ARP request for the peer, which is answered; returns the session port and the
    engine's SYN (its TCP layer)."""
    from hdl.net.frames import ip_to_int
    from tb.net_tb import SessionPort
    c = SessionPort(tb.dut, k, random.Random(seed))
    c.set(active=1, remote_ip=ip_to_int(PEER_IP), remote_port=port, local_port=0, open_req=1)
    request = await tb.recv()
    assert request is not None and ARP in request, f"no ARP request: {request!r}"
    assert request[ARP].op == 1 and request[ARP].pdst == PEER_IP
    assert request.dst == "ff:ff:ff:ff:ff:ff"
    await tb.send(Ether(src=PEER_MAC, dst=tb.mac) /
                  ARP(op=2, hwsrc=PEER_MAC, psrc=PEER_IP, hwdst=tb.mac, pdst=tb.ip))
    syn = await tb.recv()
    assert syn is not None and TCP in syn, f"no SYN: {syn!r}"
    assert str(syn[TCP].flags) == "S" and syn[TCP].dport == port
    return c, syn[TCP]


@cocotb.test()
async def run_tcp_fin_wait_2_timeout(dut):
    """docs/network.md: FIN-WAIT-2 does not last forever (the spec proposes a 60 s timer; here
    2**FIN_WAIT_2_SCALE MSL of silence from the peer). Data still arrives after our FIN and
    restarts the timer; when the peer stays silent the engine sends RST, closes and
    reports TIMEOUT."""
    from hdl.net.tcp import FIN_WAIT_2_SCALE, TcpError, TcpState
    tb = NetTB(dut)
    await tb.reset()
    peer = ScriptedPeer(tb, 40003, 24, isn=5000)
    msl = 300                   # cycles: a short bench (CONFIG_MSL_CYCLES is longer)
    await write_global(tb, "msl_cycles", msl)
    s, iss = await establish(tb, 0, 24, peer)
    s.set(open_req=0)
    await peer.expect("FA", seq=iss + 1, ack=peer.seq)
    peer.ack = iss + 2
    await peer.send("A")
    await s.wait_state(TcpState.FIN_WAIT_2)
    limit = 2**FIN_WAIT_2_SCALE * msl
    await tb.expect_silence(limit * 3 // 4)
    assert TcpState(s.get("state")) == TcpState.FIN_WAIT_2
    sent_at = sim_cycle()
    await peer.send("PA", b"late data")
    await peer.expect("A", seq=iss + 2, ack=peer.seq)
    assert await s.wait_received(9, 2000) == b"late data"
    assert TcpState(s.get("state")) == TcpState.FIN_WAIT_2
    # the timer restarts when the segment arrives (after sent_at) and counts ticks of
    # 2**FIN_WAIT_2_SCALE cycles: it cannot expire a tick before the limit
    elapsed = sim_cycle() - sent_at
    await tb.expect_silence(limit - 2**FIN_WAIT_2_SCALE - elapsed)
    assert TcpState(s.get("state")) == TcpState.FIN_WAIT_2
    await peer.expect("R", seq=iss + 2, ack=None, timeout=elapsed + 1000)
    assert TcpState(s.get("state")) == TcpState.CLOSED
    assert TcpError(s.get("error_code")) == TcpError.TIMEOUT
    # the peer's late FIN now finds no connection
    await peer.send("FA")
    await peer.expect("R", seq=iss + 2)


@cocotb.test()
async def run_tcp_fin_wait_2_last_cycle(dut):
    """docs/network.md: FIN-WAIT-2 ends after 2**FIN_WAIT_2_SCALE MSL *without a segment from the
    peer*, also when the peer's segment arrives in the very cycle the timer runs out.

    The timer counts ticks, so the last cycle cannot be aimed at from outside; it is swept
    instead. Each round closes a fresh connection to FIN-WAIT-2 with the peer's ACK sent at
    the same phase of a 64-cycle grid, so the timeout falls at the same distance from that
    ACK every round. A first round without a second segment measures that distance; the
    rounds after it send one more segment whose end walks cycle by cycle across where the
    timeout fell. The engine's RST may come sooner after the peer's last segment than the
    rule allows only if the timer ran out before that segment arrived, and then the segment
    finds no connection and is answered with a RST of its own. Before the fix, a segment in
    the last cycle restarted nothing: one RST, 96 cycles after it."""
    from hdl.net.tcp import FIN_WAIT_2_SCALE, TcpError, TcpState
    tb = NetTB(dut)
    await tb.reset()
    msl = 3                         # cycles: FIN-WAIT-2 lasts 3 ticks of 64 cycles
    tick = 2**FIN_WAIT_2_SCALE
    await write_global(tb, "msl_cycles", msl)
    rst_frame = WIRE_MIN_FRAME      # the RST is seen when complete
    # the timer restarts at the segment and needs msl ticks, the first of them may come at
    # once; a RST sooner than that after the peer's segment must mean the timer ran out
    # before the segment arrived, which the segment's own RST then shows
    least = (msl - 1) * tick + rst_frame

    async def round_(k, second_after=None):
        """Close a connection to FIN-WAIT-2; a second segment (a pure ACK) is sent to end
        about ``second_after`` cycles after the end of the peer's ACK of our FIN. Return the
        cycles from the ACK's end to the second segment's end (or None), and from the end of
        the peer's last segment to the end of the engine's RST."""
        peer = ScriptedPeer(tb, 41000 + k, 24, isn=1000 * k)
        s, iss = await establish(tb, 0, 24, peer)
        s.set(open_req=0)
        await peer.expect("FA", seq=iss + 1, ack=peer.seq)
        peer.ack = iss + 2
        await tb.source.wait()
        await tb.idle(tick - sim_cycle() % tick)
        await peer.send("A")
        await tb.source.wait()
        ack_end = last_end = sim_cycle()
        after = None
        if second_after is not None:
            await tb.idle(second_after - WIRE_ACK)
            await peer.send("A")
            await tb.source.wait()
            last_end = sim_cycle()
            after = last_end - ack_end
        await peer.expect("R", seq=iss + 2, ack=None, timeout=2000)
        gap = sim_cycle() - last_end
        assert TcpState(s.get("state")) == TcpState.CLOSED
        assert TcpError(s.get("error_code")) == TcpError.TIMEOUT
        if gap < least:
            # the timeout came first: the segment found no connection and is refused
            refusal = await tb.recv(2000)
            assert refusal is not None, (
                f"RST {gap} cycles after the peer's segment (ending {after} cycles after its "
                f"ACK of our FIN), sooner than {least}, and the segment was not refused: the "
                "connection took it and timed out all the same")
            assert str(refusal[TCP].flags) == "R" and refusal[TCP].seq == (iss + 2) % 2**32
        await tb.expect_silence(200)
        return after, gap

    _, first = await round_(0)
    assert first >= least, f"RST {first} cycles after the peer's ACK, before {least}"
    # the timeout fell about ``first - rst_frame`` cycles after the ACK's end, less the
    # engine's latency to the RST's first preamble byte and the 16-cycle grain of ``recv``
    target = first - rst_frame
    covered = set()
    early = 0
    span = range(max(WIRE_ACK, target - 32), target + 1)
    for k, second_after in enumerate(span, start=1):
        after, gap = await round_(k, second_after)
        covered.add(after)
        early += gap < least
    # one round per cycle (the GMII source starts a cycle after it is asked)
    assert sorted(covered) == list(range(min(covered), min(covered) + len(span))), covered
    # the sweep crossed the timeout: rounds on both sides
    assert 0 < early < len(span), (early, len(span))


@cocotb.test()
async def run_tcp_close_cases(dut):
    """docs/network.md "close" and "loss" with RFC 9293's states: a FIN that is not acknowledged is
    resent after the RTO; both sides closing at once go FIN-WAIT-1, CLOSING, TIME-WAIT; a
    repeated FIN in TIME-WAIT is acknowledged again and restarts the 2 MSL, after which the
    session is CLOSED; a FIN that acknowledges ours goes from FIN-WAIT-1 straight to
    TIME-WAIT. A lost SYN-ACK is resent after the RTO, and at once for the peer's repeated
    SYN, with the same ISS."""
    from hdl.net.tcp import TcpState
    from tb.net_tb import SessionPort
    tb = NetTB(dut)
    await tb.reset()
    rto = 4000
    await write_global(tb, "rto_cycles", rto)
    two_msl = 2 * CONFIG_MSL_CYCLES

    async def time_wait_ends(s, since):
        """TIME-WAIT lasts 2 MSL from ``since`` (its tick is 2 cycles)."""
        while TcpState(s.get("state")) == TcpState.TIME_WAIT:
            await tb.idle(16)
        assert TcpState(s.get("state")) == TcpState.CLOSED
        assert two_msl - 2 <= sim_cycle() - since <= two_msl + 200, (sim_cycle() - since, two_msl)

    # simultaneous close, with our first FIN lost
    peer = ScriptedPeer(tb, 40004, 24, isn=9000)
    s, iss = await establish(tb, 0, 24, peer)
    s.set(open_req=0)
    await peer.expect("FA", seq=iss + 1, ack=peer.seq)
    start = sim_cycle()
    await peer.expect("FA", seq=iss + 1, ack=peer.seq, timeout=2 * rto)
    assert sim_cycle() - start >= rto - 64, sim_cycle() - start
    await peer.send("FA", ack=iss + 1)              # the peer's FIN, not acknowledging ours
    await peer.expect("A", seq=iss + 2, ack=peer.seq)
    await s.wait_state(TcpState.CLOSING, 200)
    await peer.send("A", ack=iss + 2)
    await s.wait_state(TcpState.TIME_WAIT, 500)
    await tb.idle(two_msl // 2)
    await peer.send("FA", seq=peer.seq - 1, ack=iss + 2, advance=False)
    await peer.expect("A", seq=iss + 2, ack=peer.seq)
    await time_wait_ends(s, sim_cycle() - 150)

    # FIN-WAIT-1 to TIME-WAIT: the peer's FIN acknowledges ours
    peer = ScriptedPeer(tb, 40005, 24, isn=0xFFFFFFFF)
    s, iss = await establish(tb, 0, 24, peer)
    s.set(open_req=0)
    await peer.expect("FA", seq=iss + 1, ack=peer.seq)
    await peer.send("FA", ack=iss + 2)
    await peer.expect("A", seq=iss + 2, ack=peer.seq)
    await time_wait_ends(s, sim_cycle() - 150)

    # a lost SYN-ACK
    peer = ScriptedPeer(tb, 40006, 24, isn=123)
    s = SessionPort(dut, 0, random.Random(6))
    s.set(active=0, local_port=24, open_req=1)
    await s.wait_state(TcpState.LISTEN)
    await peer.send("S", options=[("MSS", 1460)])
    first = await peer.expect("SA", ack=peer.seq)
    start = sim_cycle()
    again = await peer.expect("SA", ack=peer.seq, timeout=2 * rto)
    assert sim_cycle() - start >= rto - 64 and again.seq == first.seq
    await peer.send("S", seq=peer.seq - 1, advance=False, options=[("MSS", 1460)])
    repeated = await peer.expect("SA", ack=peer.seq, timeout=1000)
    assert repeated.seq == first.seq
    peer.ack = first.seq + 1
    await peer.send("A")
    await s.wait_state(TcpState.ESTABLISHED, 500)
    s.set(abort=1)
    await peer.expect("R", seq=first.seq + 1)
    s.set(abort=0, open_req=0)


@cocotb.test()
async def run_tcp_receive_window_closes_and_reopens(dut):
    """docs/network.md "window" (0 advertised, update on reopen): while the user reads nothing
    the advertised window shrinks by what arrives, down to 0 when the receive ring is full;
    data beyond it is dropped and answered with the unchanged ACK; once the user has read
    enough (SWS avoidance: min(2 MSS, half the ring)) a window update goes out by itself,
    and the data sent again is delivered once, in order."""
    tb = NetTB(dut)
    await tb.reset()
    ring = NET_CONFIGS["stack"]["rx_depth"] - 1           # bytes the ring can hold
    peer = ScriptedPeer(tb, 40007, 24, isn=77)
    s, iss = await establish(tb, 0, 24, peer)
    s.set_pauses(0, 1.0)                                   # the user reads nothing
    data = random.Random(7).randbytes(ring + 100)
    before = await tb.session_counters(0)
    third = ring // 3
    for k in range(3):
        await peer.send("PA", data[k * third:(k + 1) * third])
        ack = await peer.expect("A", seq=iss + 1, ack=peer.seq)
        assert ack.window == ring - (k + 1) * third, (k, ack.window)
    await peer.send("PA", data[ring:], advance=False)
    ack = await peer.expect("A", seq=iss + 1, ack=peer.seq)
    assert ack.window == 0
    await tb.expect_silence(2000)
    assert s.received == b""
    s.set_pauses(0, 0)
    update = await peer.expect("A", seq=iss + 1, ack=peer.seq, timeout=ring + 2000)
    assert update.window >= min(2 * 1460, (ring + 1) // 2), update.window
    await peer.send("PA", data[ring:])
    await peer.expect("A", seq=iss + 1, ack=peer.seq)
    assert await s.wait_received(len(data), 10_000) == data
    after = await tb.session_counters(0)
    assert after["dropped_segments"] - before["dropped_segments"] == 1
    assert after["bytes_rx"] - before["bytes_rx"] == len(data)


@cocotb.test()
async def run_tcp_send_sequence_wraps(dut):
    """docs/network.md "Tests MUST wrap 2**32 inside a transfer", on the send side (the peers of
    the other tests wrap the receive side): 24 KiB leave across SND.NXT = 2**32 in segments
    of the peer's MSS of 400 bytes, so that the 4 KiB buffer holds enough of them in flight
    for three duplicate ACKs; the segment that holds the wrap is lost once and comes again
    by fast retransmit; the peer gets every byte once, in order, and the engine frees its
    buffer across the wrap."""
    tb = NetTB(dut)
    await tb.reset()
    peer = ScriptedPeer(tb, 40008, 24, isn=1)
    await write_global(tb, "rto_cycles", 4000)
    s, iss = await establish(tb, 0, 24, peer, mss=400)
    data = random.Random(9).randbytes(24 * 1024)
    first = iss + 1
    wrap = 2**32 - first                        # offset of the byte with sequence number 0
    assert 0 < wrap < len(data) // 2, f"ISS {iss:#x}: the transfer would not cross 2**32"
    before = await tb.session_counters(0)
    writer = cocotb.start_soon(s.write(data))
    got = bytearray()
    lost = False
    while len(got) < len(data):
        seg = await peer.expect("PA", ack=peer.seq, data=None, timeout=40_000)
        payload = bytes(seg.payload)
        offset = (seg.seq - first) % 2**32
        if not lost and offset <= wrap < offset + len(payload):
            lost = True
            continue
        if offset == len(got):
            got += payload
            peer.ack = first + len(got)
        await peer.send("A")                    # a duplicate ACK for out-of-order data
    await writer
    assert bytes(got) == data and lost
    after = await tb.session_counters(0)
    moved = {k: after[k] - before[k] for k in ("fast_retransmit", "rto", "dup_acks")}
    dut._log.info("ISS %#x, wrap after %d bytes, %s", iss, wrap, moved)
    assert moved["fast_retransmit"] >= 1, moved
    await tb.idle(200)
    assert s.get("tx_fill") == 0, "acknowledged bytes not freed across the wrap"
    await write_global(tb, "rto_cycles", CONFIG_RTO_CYCLES)
    s.set(open_req=0)
    await peer.expect("FA", seq=first + len(data))


@cocotb.test()
async def run_tcp_ack_every_second_segment(dut):
    """docs/network.md "data": at most 2 full segments per ACK (RFC 5681 §4.2, RFC 9293
    §3.8.6.3): four in-order segments without PSH get an ACK after the second and the
    fourth; a single one waits for the delayed ACK, sent within 20 us."""
    from hdl.net.tcp.connection import DELAYED_ACK_US
    tb = NetTB(dut)
    await tb.reset()
    peer = ScriptedPeer(tb, 40009, 24, isn=300)
    s, iss = await establish(tb, 0, 24, peer)
    data = random.Random(10).randbytes(5 * 1460)
    for k in range(4):
        await peer.send("A", data[k * 1460:(k + 1) * 1460])
    for k in (2, 4):
        await peer.expect("A", seq=iss + 1, ack=peer.seq - (4 - k) * 1460)
    await tb.expect_silence(3000)
    start = sim_cycle()
    await peer.send("A", data[4 * 1460:])
    await peer.expect("A", seq=iss + 1, ack=peer.seq, timeout=5000)
    delay = sim_cycle() - start
    # the segment takes about 1,530 byte times to arrive; then the ACK waits 20 us
    delayed = DELAYED_ACK_US * 1000 // CLOCK_NS
    assert delayed <= delay <= (1600 * GMII_NS + 300 * CLOCK_NS) // CLOCK_NS + delayed, delay
    assert await s.wait_received(len(data), 4000) == data


@cocotb.test()
async def run_tcp_rst_rules(dut):
    """RFC 9293 §3.10.7.4 with RFC 5961: an in-window inexact RST and a SYN on a live
    connection get challenge ACKs, an RST outside the window nothing, an exact RST aborts
    (error RESET) and the listener comes back."""
    from hdl.net.tcp import TcpError, TcpState
    tb = NetTB(dut)
    await tb.reset()
    peer = ScriptedPeer(tb, 41000, 26, isn=5000)
    s, iss = await establish(tb, 0, 26, peer)
    await peer.send("R", seq=peer.seq + 100, advance=False)
    await peer.expect("A", seq=iss + 1, ack=peer.seq)
    await peer.send("S", seq=peer.seq + 7, advance=False)
    await peer.expect("A", seq=iss + 1, ack=peer.seq)
    await peer.send("R", seq=peer.seq + 100_000, advance=False)
    await tb.expect_silence(1000)
    assert s.get("state") == TcpState.ESTABLISHED.value
    errors = {"n": 0}
    from tb.streams import count_pulses
    cocotb.start_soon(count_pulses(dut.tcp0_error, errors, "n"))
    await peer.send("R", advance=False)
    await s.wait_state(TcpState.LISTEN, 2000)
    assert errors["n"] == 1 and s.get("error_code") == TcpError.RESET.value
    assert (await tb.session_counters(0))["rst_rx"] >= 2
    s.set(open_req=0)


#: segments with neither SYN, ACK nor RST (port scanners' probes): flags, payload
NO_SYN_PROBES = [("", b""), ("F", b""), ("FPU", b""), ("P", b"data"), ("FP", b"bye"),
                 ("U", b""), ("FPUEC", b"")]


@cocotb.test()
async def run_tcp_listen_drops_segments_without_syn(dut):
    """RFC 9293 §3.10.7.2: a listening port drops a segment with neither SYN, ACK nor RST (a
    NULL, FIN or Xmas probe, with or without data) silently and counts it as
    ``listen_no_syn``; the same segments to a closed port get RST+ACK (§3.10.7.1), an ACK to
    the listening port gets a RST, and the listener still accepts a SYN afterwards."""
    from hdl.net.tcp import TcpState
    from tb.net_tb import SessionPort
    tb = NetTB(dut)
    await tb.reset()
    s = SessionPort(dut, 0, random.Random(5))
    s.set(active=0, local_port=27, open_req=1)
    await s.wait_state(TcpState.LISTEN)
    for k, (flags, data) in enumerate(NO_SYN_PROBES):
        before = await tb.counters()
        probe = ScriptedPeer(tb, 42000 + k, 27, isn=1000 * k)
        await probe.send(flags, data)
        await tb.expect_silence(1000)
        assert s.get("state") == TcpState.LISTEN.value, flags
        assert_counts(before, await tb.counters(), listen_no_syn=1)
        closed = ScriptedPeer(tb, 42000 + k, 28, isn=1000 * k)
        await closed.send(flags, data, advance=False)
        fin = "F" in flags
        await closed.expect("RA", seq=0, ack=1000 * k + len(data) + fin)
    acker = ScriptedPeer(tb, 42100, 27, isn=9)
    await acker.send("A", ack=777)
    await acker.expect("R", seq=777)
    peer = ScriptedPeer(tb, 42101, 27, isn=50)
    await peer.send("S")
    await peer.expect("SA", ack=51)
    s.set(open_req=0)


@cocotb.test()
async def run_tcp_request_withdrawn_by_arrival(dut):
    """A segment waiting for the frame builder is withdrawn when a segment arrives, and the
    next one is chosen with the arrival's values: queued data waits behind a 1,472-byte echo
    reply while the peer's data arrives with a zero window; when the builder is free only the
    ACK of that data leaves (data sent now would exceed the peer's window); a window update
    then brings the data with the current ACK number."""
    tb = NetTB(dut)
    await tb.reset()
    peer = ScriptedPeer(tb, 41002, 28, isn=123_456)
    s, iss = await establish(tb, 0, 28, peer)
    echo = bytes(range(256)) * 5 + bytes(192)           # 1472 bytes: ~1,520 cycles of reply
    await tb.send(eth(tb) / IP(src=PEER_IP, dst=tb.ip) / ICMP(type=8, id=7, seq=1) /
                  Raw(echo))
    await tb.source.wait()
    await tb.idle(40)                                   # the reply has taken the builder
    queued = b"queued while the builder is busy"
    await s.write(queued)
    await tb.idle(40)                                   # its data request waits
    await peer.send("PA", b"arrives while the request waits", window=0)
    reply = await tb.recv()
    assert reply is not None and ICMP in reply and bytes(reply[ICMP].payload) == echo, \
        "the echo reply must come first (it held the builder)"
    await peer.expect("A", seq=iss + 1, ack=peer.seq)
    await tb.expect_silence(3000)
    assert await s.wait_received(31, 2000) == b"arrives while the request waits"
    await peer.send("A", window=65535)
    await peer.expect("PA", seq=iss + 1, ack=peer.seq, data=queued)
    peer.ack = iss + 1 + len(queued)
    await peer.send("A")
    s.set(open_req=0)
    await peer.expect("FA", seq=peer.ack, ack=peer.seq)


@cocotb.test()
async def run_tcp_retransmit_and_zero_window(dut):
    """An unacknowledged segment is sent again with the same sequence number after the RTO,
    then after twice and four times the RTO (back-off); a zero window stops new data and
    brings window probes (SEG.SEQ = SND.UNA - 1) on the persist timer; reopening the window
    lets the rest through, never beyond the window. The RTO is shortened through its RBCP
    register for the test."""
    from hdl.net.tcp import TcpState
    tb = NetTB(dut)
    await tb.reset()
    rto_cycles = 4000
    await write_global(tb, "rto_cycles", rto_cycles)
    peer = ScriptedPeer(tb, 41001, 27, isn=9000)
    s, iss = await establish(tb, 0, 27, peer, window=3000)
    data = bytes(range(256)) * 20                     # 5120 bytes
    await s.write(data[:1000])
    await peer.expect("PA", seq=iss + 1, ack=peer.seq, data=data[:1000])
    # unacknowledged, it comes again after the RTO, 2 RTO, 4 RTO (RFC 6298 §5.5)
    rto_ns = rto_cycles * CLOCK_NS
    sent_at = [get_sim_time("ns")]
    rtos_before = (await tb.session_counters(0))["rto"]
    for k in range(3):
        await peer.expect("PA", seq=iss + 1, ack=peer.seq, data=data[:1000],
                          timeout=(rto_ns << k) // CLOCK_NS + 5000)
        sent_at.append(get_sim_time("ns"))
    intervals = [b - a for a, b in zip(sent_at, sent_at[1:])]
    for k, interval in enumerate(intervals):
        assert abs(interval - (rto_ns << k)) <= 1000, f"retransmission intervals {intervals} ns"
    assert (await tb.session_counters(0))["rto"] - rtos_before == 3
    # acknowledge it with a zero window; queue the rest
    peer.ack = iss + 1001
    await peer.send("A", window=0)
    await s.write(data[1000:])
    probe = await peer.expect("A", seq=iss + 1000, ack=peer.seq, timeout=80_000)
    assert probe is not None
    await peer.send("A", window=0)                    # still closed: keep probing
    await peer.expect("A", seq=iss + 1000, ack=peer.seq, timeout=160_000)
    # open 2000 bytes: the whole segments that fit come (segments are cut when written:
    # 1460, 1460, 1200), nothing beyond the window
    await peer.send("A", window=2000)
    seg = await peer.expect("PA", seq=iss + 1001, ack=peer.seq, data=data[1000:2460],
                            timeout=20_000)
    got = bytearray(bytes(seg.payload))
    await tb.expect_silence(3000)
    peer.ack = iss + 2461
    await peer.send("A", window=65535)
    while len(got) < len(data) - 1000:       # the peer acknowledges each segment
        seg = await peer.expect("PA", ack=peer.seq, data=None, timeout=20_000)
        got += bytes(seg.payload)
        peer.ack = seg.seq + len(seg.payload)
        await peer.send("A")
    assert bytes(got) == data[1000:] and peer.ack == iss + 1 + len(data)
    assert s.get("state") == TcpState.ESTABLISHED.value
    await write_global(tb, "rto_cycles", CONFIG_RTO_CYCLES)
    s.set(open_req=0)
    await peer.expect("FA", seq=iss + 1 + len(data))


@cocotb.test()
async def run_tcp_fast_retransmit(dut):
    """RFC 5681 §3.2: the third duplicate ACK (same ACK number and window, no data, data
    outstanding) resends the first unacknowledged segment at once, long before the RTO; the
    first two resend nothing. The window after it is ssthresh + 3 segments with ssthresh half
    the segments in flight, at least 2: with three in flight, all three may go again and do
    (the engine goes back to SND.UNA), on a ring of 4 descriptors as on one of 64. The
    session counts three duplicate ACKs, one fast retransmit and no timeout."""
    from hdl.net.tcp import TcpState
    tb = NetTB(dut)
    await tb.reset()
    await write_global(tb, "rto_cycles", 1_000_000)      # 16 ms: no timeout in the test
    peer = ScriptedPeer(tb, 41002, 29, isn=0x7FFFFF00)
    s, iss = await establish(tb, 0, 29, peer)
    rng = random.Random(11)
    chunks = [rng.randbytes(900) for _ in range(4)]       # one segment each (tlast)
    starts = [iss + 1 + 900 * k for k in range(4)]
    for chunk in chunks:
        await s.write(chunk)
    # the initial window is 3 segments (RFC 5681 §3.1 as Linux counts it)
    for k in range(3):
        await peer.expect("PA", seq=starts[k], ack=peer.seq, data=chunks[k], timeout=20_000)
    await tb.expect_silence(3000)
    peer.ack = starts[1]
    await peer.send("A")
    await peer.expect("PA", seq=starts[3], ack=peer.seq, data=chunks[3])
    before = await tb.session_counters(0)
    for _ in range(2):
        await peer.send("A")
    await tb.expect_silence(3000)
    await peer.send("A")
    # segments 1..3 again, the first at once (the RTO is 1,000,000 cycles away)
    for k in (1, 2, 3):
        await peer.expect("PA", seq=starts[k], ack=peer.seq, data=chunks[k], timeout=3000)
    after = await tb.session_counters(0)
    moved = {name: after[name] - before[name] for name in ("dup_acks", "fast_retransmit", "rto")}
    assert moved == {"dup_acks": 3, "fast_retransmit": 1, "rto": 0}, moved
    peer.ack = starts[3] + 900
    await peer.send("A")
    await tb.expect_silence(3000)
    assert s.get("state") == TcpState.ESTABLISHED.value
    await write_global(tb, "rto_cycles", CONFIG_RTO_CYCLES)
    s.set(open_req=0)
    await peer.expect("FA", seq=peer.ack, ack=peer.seq)


@cocotb.test()
async def run_tcp_peer_mac_refreshed_by_arp(dut):
    """docs/network.md (RFC 826): an ARP frame from the connected peer's IP refreshes its MAC,
    whoever the ARP is for (a gratuitous ARP gets no answer but moves the connection); ARP
    from other addresses changes nothing; an ARP request for the engine moves it back and is
    answered at the requester's address."""
    tb = NetTB(dut)
    await tb.reset()
    peer = ScriptedPeer(tb, 41003, 30, isn=123)
    s, iss = await establish(tb, 0, 30, peer)
    moved_mac = "02:00:00:00:00:77"
    sent = 0

    async def exchange(expected_mac):
        nonlocal sent
        data = f"segment {sent}".encode()
        await s.write(data)
        seg = await peer.expect("PA", seq=iss + 1 + sent, ack=peer.seq, data=data)
        assert seg.underlayer.underlayer.dst == expected_mac
        sent += len(data)
        peer.ack = iss + 1 + sent
        await peer.send("A")

    def arp(op, hwsrc, psrc, pdst):
        return Ether(src=hwsrc, dst="ff:ff:ff:ff:ff:ff") / ARP(op=op, hwsrc=hwsrc, psrc=psrc,
                                                                pdst=pdst)

    await exchange(PEER_MAC)
    before = await tb.counters()
    await tb.send(arp(2, moved_mac, "198.18.0.99", "198.18.0.99"))      # someone else
    await tb.expect_silence(2000)
    await exchange(PEER_MAC)
    await tb.send(arp(2, moved_mac, PEER_IP, PEER_IP))                  # gratuitous: moved
    await tb.expect_silence(2000)
    await exchange(moved_mac)
    assert_counts(before, await tb.counters(), not_mine=2, delivered=2, frames_out=2)
    await tb.send(arp(1, PEER_MAC, PEER_IP, tb.ip))                     # back, asking us
    reply = await tb.recv()
    assert reply is not None and ARP in reply and reply[ARP].op == 2
    assert (reply.dst, reply[ARP].hwdst) == (PEER_MAC, PEER_MAC)
    await exchange(PEER_MAC)
    s.set(open_req=0)
    await peer.expect("FA", seq=peer.ack, ack=peer.seq)


@cocotb.test()
async def run_arp_pending_blocks_nothing(dut):
    """docs/network.md (verilog-ethernet #11, #42, #155) (back-to-back frames): while a client
    session waits for an ARP reply that never comes, 1,000 (Icarus: 100) ICMP echo and RBCP
    read requests (3 to 1) sent back to back at the minimum inter-frame gap are each
    answered once, at their source MAC, or counted as ``busy`` (the one reply slot): none
    lost, none doubled, no other frame. The session's four ARP requests go out meanwhile,
    then it fails with error ARP."""
    from hdl.net.frames import RBCP_READ, ip_to_int
    from hdl.net.tcp import TcpError, TcpState
    from tb.net_tb import SessionPort
    tb = NetTB(dut)
    await tb.reset()
    s = SessionPort(dut, 1, random.Random(1))
    s.set(active=1, remote_ip=ip_to_int("198.18.0.99"), remote_port=5000, local_port=0,
          open_req=1)
    arp_requests = 0
    first = await tb.recv()
    assert ARP in first and first[ARP].pdst == "198.18.0.99" and first[ARP].op == 1
    arp_requests += 1
    before = await tb.counters()
    rng = random.Random(5)
    expected = {}
    ip_bytes = ip_to_int(tb.ip).to_bytes(4, "big")
    requests = 1000 if cocotb.SIM_NAME.lower().startswith("verilator") else 100
    for k in range(requests):
        if k % 4:
            payload = rng.randbytes(rng.randrange(0, 64))
            await tb.send(eth(tb) / IP(src=PEER_IP, dst=tb.ip) / ICMP(type=8, id=7, seq=k) /
                          Raw(payload))
            expected[("icmp", k)] = payload
        else:
            rbcp_id = k // 4                    # one byte: unique up to 1,024 requests
            request = rbcp_request(RBCP_READ, rbcp_id, GLOBAL_BASE + GLOBAL_OFFSETS["ip"], 4)
            await tb.send(eth(tb) / IP(src=PEER_IP, dst=tb.ip) /
                          UDP(sport=50000, dport=DEFAULT_RBCP_PORT) / Raw(request))
            expected[("rbcp", rbcp_id)] = sitcpy_rbcp_header(
                "r", rbcp_id, GLOBAL_BASE + GLOBAL_OFFSETS["ip"], 4) + ip_bytes
    answered = set()
    while (frame := await tb.recv(8000)) is not None:
        assert checksums_ok(frame), frame.show(dump=True)
        if ARP in frame:
            assert frame[ARP].op == 1 and frame[ARP].pdst == "198.18.0.99"
            arp_requests += 1
            continue
        assert frame.dst == PEER_MAC, frame.summary()
        if ICMP in frame:
            key, body = ("icmp", frame[ICMP].seq), bytes(frame[ICMP].payload)
            assert frame[ICMP].type == 0 and frame[ICMP].id == 7
        else:
            body = bytes(frame[UDP].payload)
            key = ("rbcp", body[2])
        assert key in expected and key not in answered, (key, frame.summary())
        assert body == expected[key], (key, body.hex())
        answered.add(key)
    after = await tb.counters()
    busy = after["busy"] - before["busy"]
    dut._log.info("back to back during ARP: %d answered, %d busy", len(answered), busy)
    assert len(answered) + busy == requests and len(answered) > 0, (len(answered), busy)
    assert_counts(before, after, delivered=len(answered), busy=busy,
                  frames_out=len(answered) + arp_requests - 1)
    assert arp_requests == 4, arp_requests
    assert s.get("state") == TcpState.CLOSED.value
    assert s.get("error_code") == TcpError.ARP.value
    s.set(open_req=0)


@cocotb.test()
async def run_tcp_client_syn_sent_rules(dut):
    """Client mode, docs/network.md SYN-SENT, loss and RST rules: a lost SYN is resent after
    the RTO with the same ISS; an RST without ACK is ignored; an ACK that does not
    acknowledge the SYN gets an RST at its ACK number; a bare SYN (simultaneous open) leads
    to SYN-RECEIVED and a SYN-ACK, its ACK to ESTABLISHED; data then moves both ways."""
    from hdl.net.tcp import TcpState
    tb = NetTB(dut)
    await tb.reset()
    rto = 4000
    await write_global(tb, "rto_cycles", rto)
    s, syn = await client_open(tb, 1, 5001, 8)
    iss = syn.seq
    peer = ScriptedPeer(tb, 5001, syn.sport, isn=0x7FFFFFF0)
    peer.sport, peer.dport = 5001, syn.sport
    again = await peer.expect("S", seq=iss, ack=None, timeout=2 * rto)
    assert again.options == [("MSS", 1460)]
    await peer.send("R", ack=0, advance=False)
    await tb.expect_silence(500)
    assert TcpState(s.get("state")) == TcpState.SYN_SENT
    await peer.send("A", ack=iss + 100, advance=False)
    await peer.expect("R", seq=iss + 100, ack=None)
    assert TcpState(s.get("state")) == TcpState.SYN_SENT
    await peer.send("S", ack=0, options=[("MSS", 1400)])
    await peer.expect("SA", seq=iss, ack=peer.seq)
    assert TcpState(s.get("state")) == TcpState.SYN_RECEIVED
    peer.ack = iss + 1
    await peer.send("A")
    await s.wait_state(TcpState.ESTABLISHED, 500)
    await s.write(b"client data")
    await peer.expect("PA", seq=iss + 1, ack=peer.seq, data=b"client data")
    peer.ack += 11
    await peer.send("PA", b"server data")
    await peer.expect("A", seq=iss + 12, ack=peer.seq)
    assert await s.wait_received(11, 2000) == b"server data"
    s.set(abort=1)
    await peer.expect("R", seq=iss + 12)
    s.set(abort=0, open_req=0)


@cocotb.test()
async def run_tcp_client_refused_and_arp_timeout(dut):
    """Client mode: ARP for the server, SYN, a RST acking the SYN -> CLOSED with error
    REFUSED; a server that never answers ARP -> four requests, then error ARP."""
    from hdl.net.frames import ip_to_int
    from hdl.net.tcp import TcpError, TcpState
    tb = NetTB(dut)
    await tb.reset()
    s, syn = await client_open(tb, 1, 5000, 1)
    assert syn.sport >= 49152 and syn.options == [("MSS", 1460)]
    await tb.send(eth(tb) / IP(src=PEER_IP, dst=tb.ip) /
                  TCP(sport=5000, dport=syn.sport, flags="RA", seq=0, ack=syn.seq + 1))
    await s.wait_state(TcpState.CLOSED, 2000)
    assert s.get("error_code") == TcpError.REFUSED.value
    # nobody answers ARP for this address
    s.set(open_req=0)
    await tb.idle(10)
    s.set(remote_ip=ip_to_int("198.18.0.99"), open_req=1)
    requests = 0
    for _ in range(6):
        frame = await tb.recv(8000)
        if frame is None:
            break
        assert ARP in frame and frame[ARP].pdst == "198.18.0.99"
        requests += 1
    assert requests == 4, requests
    assert s.get("state") == TcpState.CLOSED.value
    assert s.get("error_code") == TcpError.ARP.value
    s.set(open_req=0)
