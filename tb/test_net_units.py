# amaranth: UnusedElaboratable=no
"""Network unit blocks in amaranth.sim against independent references (docs/network.md "Unit"):
Crc32 against ``zlib.crc32`` (check value, lengths 0..80 and full frames, 1, 4
and 8 bytes per beat with partial last beats, the good-frame residue), InternetChecksum
against scapy's ``checksum`` (RFC 1071; odd lengths, a preset pseudo-header sum), and the
FrameParser (with GmiiRx) against scapy's dissection: every captured field, the payload
bytes, TCP options, IP options, UDP without checksum, and the checksum verdict; the
EventCounters bank against a count kept in Python (docs/network.md counters)."""

import random
import re
import zlib

import pytest
from amaranth.hdl import ClockDomain, DomainRenamer, Elaboratable, Module, Signal, Value
from amaranth.lib import wiring
from scapy.utils import checksum as scapy_checksum

from hdl.net import Crc32, FrameBuilder, FrameParser, GmiiRx, InternetChecksum, NetStack
from hdl.net.counters import EventCounters
from hdl.net.frames import ip_to_int, mac_to_int
from hdl.net.mac import RxBeatBridge, RxBeatSignature
from hdl.net.tcp.banks import ByteBanks
from hdl.params import ParameterError

from .models.inet import ones_sum
from .streamsim import simulate


def crc_of(data_bytes, messages):
    """Run ``messages`` (bytes) through a Crc32; return each one's ``crc`` and residue
    flag after its last beat."""
    dut = Crc32(data_bytes)
    out = []

    async def bench(ctx):
        for msg in messages:
            ctx.set(dut.clear, 1)
            await ctx.tick()
            ctx.set(dut.clear, 0)
            for i in range(0, len(msg), data_bytes):
                chunk = msg[i:i + data_bytes]
                ctx.set(dut.data, int.from_bytes(chunk.ljust(data_bytes, b"\x5a"), "little"))
                ctx.set(dut.count, len(chunk))
                ctx.set(dut.valid, 1)
                await ctx.tick()
            ctx.set(dut.valid, 0)
            await ctx.tick()
            out.append((ctx.get(dut.crc), ctx.get(dut.residue_ok)))

    simulate(dut, bench)
    return out


@pytest.mark.parametrize("data_bytes", [1, 4, 8])
def test_crc32_matches_zlib(data_bytes):
    rng = random.Random(data_bytes)
    messages = [b"123456789", b""] + [rng.randbytes(n) for n in range(1, 40)]
    messages += [rng.randbytes(n) for n in (60, 64, 1514)]
    got = crc_of(data_bytes, messages)
    assert got[0][0] == 0xCBF43926
    for msg, (crc, _) in zip(messages, got):
        assert crc == zlib.crc32(msg), (len(msg), hex(crc), hex(zlib.crc32(msg)))


def test_crc32_residue_of_good_frames():
    rng = random.Random(5)
    frames = [rng.randbytes(n) for n in (60, 61, 100, 1514)]
    good = [f + zlib.crc32(f).to_bytes(4, "little") for f in frames]
    bad = [g[:-1] + bytes([g[-1] ^ 0x01]) for g in good]
    got = crc_of(1, good + bad)
    assert [r for _, r in got] == [1] * len(good) + [0] * len(bad)
    assert all(crc == 0x2144DF1C for crc, _ in got[:len(good)])


def test_internet_checksum_matches_scapy():
    rng = random.Random(7)
    messages = [rng.randbytes(n) for n in list(range(0, 24)) + [1499, 1500]]
    presets = [0, 0x1234, 0xFFFF]
    dut = InternetChecksum()
    got = []

    async def bench(ctx):
        for n, msg in enumerate(messages):
            ctx.set(dut.preset, presets[n % 3])
            ctx.set(dut.clear, 1)
            await ctx.tick()
            ctx.set(dut.clear, 0)
            for byte in msg:
                ctx.set(dut.data, byte)
                ctx.set(dut.valid, 1)
                await ctx.tick()
            ctx.set(dut.valid, 0)
            await ctx.tick()
            got.append(ctx.get(dut.checksum))

    simulate(dut, bench)
    for n, (msg, value) in enumerate(zip(messages, got)):
        preset = presets[n % 3]
        # scapy sums the preset as two leading bytes (one's complement addition commutes)
        want = scapy_checksum(preset.to_bytes(2, "big") + msg)
        assert value == want, (len(msg), hex(preset), hex(value), hex(want))


def test_bad_parameter_names_the_value():
    with pytest.raises(ParameterError, match="data_bytes must be an integer in 1..16, not 0"):
        Crc32(0)
    with pytest.raises(ParameterError,
                       match="descriptors must be a power of two in 4..256, not 6"):
        NetStack(descriptors=6)
    with pytest.raises(ParameterError, match=r"user_width must be an integer in 8\.\.1024 and a "
                                             r"multiple of 8, not 12"):
        NetStack(user_width=12)


@pytest.mark.parametrize("make, message", [
    (lambda: NetStack(lanes=3), "lanes must be an integer in 1..2, not 3"),
    # two lanes need a core clock of at least half the GMII clock for the line rate
    (lambda: NetStack(lanes=2, clock_hz=50_000_000),
     "clock_hz must be an integer in 62500000..1000000000, not 50000000"),
    (lambda: NetStack(lanes=1, clock_hz=100_000_000),
     "clock_hz must be an integer in 125000000..1000000000, not 100000000"),
    (lambda: RxBeatSignature(4), "lanes must be an integer in 1..2, not 4"),
    (lambda: FrameParser(lanes=4), "lanes must be an integer in 1..2, not 4"),
    (lambda: FrameBuilder(2, lanes=0), "lanes must be an integer in 1..2, not 0"),
    (lambda: ByteBanks(1000, lanes=2), "depth must be a power of two in 2048..65536, not 1000"),
    (lambda: ByteBanks(4096, lanes=4), "lanes must be an integer in 1..2, not 4"),
])
def test_lane_parameters_name_the_bad_value(make, message):
    with pytest.raises(ParameterError, match=re.escape(message)):
        make()


class _ResetHarness(Elaboratable):
    """Gives a testbench the ``sync`` domain's reset."""

    def __init__(self, dut):
        self.dut = dut
        self.rst = Signal()

    def elaborate(self, platform):
        m = Module()
        m.domains.sync = cd = ClockDomain()
        m.d.comb += cd.rst.eq(self.rst)
        m.submodules.dut = self.dut
        return m


@pytest.mark.parametrize("pattern,spacing", [
    ("sparse", 1), ("every_cycle", 1), ("every_other_cycle", 2),
    # per counter: "frames" every 3rd cycle (a 2-bit accumulator for 5 counters), "rare"
    # every 5th (1 bit), the others every cycle
    ("per_counter", {"frames": 3, "rare": 5})])
@pytest.mark.parametrize("block_ram", [False, True])
def test_event_counters_match_a_python_count(pattern, spacing, block_ram):
    """Random events (on all counters as often as ``spacing`` allows in two patterns, a byte
    amount included) reach their counters within ``len(names)`` cycles (one more with
    ``block_ram``), wrap at the width, and both read ports return them; a reset in the
    middle, and ``clear`` (also twice within one round, and while events arrive), start
    every count from zero."""
    names = ("frames", "bytes", "drops", "rare", "other")
    dut = EventCounters(names, width=12, amounts={"bytes": 11}, readers=2, spacing=spacing,
                        block_ram=block_ram)
    top = _ResetHarness(dut)
    rng = random.Random(pattern)
    expected = dict.fromkeys(names, 0)
    seen = []
    clears = {902, 1296, 1298, 2403}

    def amount(name, cycle):
        if cycle % (spacing.get(name, 1) if isinstance(spacing, dict) else spacing):
            return 0
        busy = pattern != "sparse"
        if name == "bytes":
            return rng.randrange(2048) if busy or rng.random() < 0.1 else 0
        return int(busy or rng.random() < 0.05)

    async def bench(ctx):
        for cycle in range(3000):
            if cycle == 1700:
                ctx.set(top.rst, 1)
                for name in names:
                    ctx.set(dut.events[name], 0)
                    expected[name] = 0
                await ctx.tick()
                ctx.set(top.rst, 0)
            ctx.set(dut.clear, cycle in clears)
            for name in names:
                value = amount(name, cycle)
                ctx.set(dut.events[name], value)
                expected[name] = (value if cycle in clears else expected[name] + value) % 4096
            await ctx.tick()
            ctx.set(dut.clear, 0)
            if cycle % 500 == 499 or cycle == 1702:
                for name in names:
                    ctx.set(dut.events[name], 0)
                await ctx.tick().repeat(len(names) + block_ram)
                for k, name in enumerate(names):
                    ctx.set(dut.rd_addr[0], k)
                    ctx.set(dut.rd_addr[1], len(names) - 1 - k)
                    if block_ram:
                        await ctx.tick()
                    seen.append((name, ctx.get(dut.rd_data[0]), expected[name],
                                 ctx.get(dut.rd_data[1]), expected[names[len(names) - 1 - k]]))

    simulate(top, bench)
    assert len(seen) == 7 * len(names)
    for name, got, want, other, other_want in seen:
        assert (got, other) == (want, other_want), (name, got, want, other, other_want)


@pytest.mark.parametrize("block_ram", [False, True])
def test_event_counters_read_while_clearing(block_ram):
    """Reads in every cycle, also during the round that a ``clear`` starts (and with clears
    closer together than a round): a counter reads as a count it held, never a mixture. Each
    read is a count since the last clear, at most ``len(names) + 1`` cycles behind (two more
    with ``block_ram``: the write-back and the registered read), or (until the clear has had
    as many cycles) a value that was allowed just before the clear."""
    names = ("frames", "bytes", "drops", "rare", "other")
    n = len(names)
    lag = n + 2 * block_ram
    dut = EventCounters(names, width=12, amounts={"bytes": 11}, readers=2, spacing=1,
                        block_ram=block_ram)
    rng = random.Random(5)
    cycles = 1500
    clears = sorted({rng.randrange(20, cycles - 20) for _ in range(40)} | {700, 702, 705})
    events = {name: [(rng.randrange(2048) if name == "bytes" else 1) if rng.random() < 0.6
                     else 0 for _ in range(cycles)] for name in names}
    reads = []

    async def bench(ctx):
        for cycle in range(cycles):
            ctx.set(dut.clear, cycle in clears)
            for name in names:
                ctx.set(dut.events[name], events[name][cycle])
            ctx.set(dut.rd_addr[0], cycle % n)
            ctx.set(dut.rd_addr[1], (cycle + 2) % n)
            await ctx.tick()
            reads.append((ctx.get(dut.rd_data[0]), ctx.get(dut.rd_data[1])))

    simulate(dut, bench)

    def count(name, start, stop):
        return sum(events[name][start:stop]) % 4096

    def allowed(name, t, memo={}):
        """Values counter ``name`` may read after the tick of cycle ``t``."""
        if (name, t) in memo:
            return memo[(name, t)]
        last = max([c for c in clears if c <= t], default=None)
        start = 0 if last is None else last
        values = {count(name, start, u) for u in range(max(start, t - lag), t + 2)}
        if last is not None and t <= last + lag + 1:
            values |= allowed(name, last - 1) if last > 0 else {0}
        memo[(name, t)] = values
        return values

    checked = 0
    for t, (first, second) in enumerate(reads):
        if t < lag + 2:
            continue                            # the clearing round after reset
        for k, got in ((t % n, first), ((t + 2) % n, second)):
            assert got in allowed(names[k], t), (t, names[k], got, sorted(allowed(names[k], t)))
            checked += 1
    assert checked > 2 * (cycles - lag - 2) - 1


@pytest.mark.parametrize("block_ram", [False, True])
def test_one_event_counter_counts_every_cycle(block_ram):
    """A bank of one counter (the service visits it every cycle, and in block RAM reads the
    word written the cycle before) counts events in every cycle exactly."""
    dut = EventCounters(("only",), width=16, block_ram=block_ram)
    rng = random.Random(1)
    events = [rng.random() < 0.7 for _ in range(500)]
    seen = []

    async def bench(ctx):
        ctx.set(dut.rd_addr[0], 0)
        for k, event in enumerate(events):
            ctx.set(dut.events.only, event)
            await ctx.tick()
            seen.append((k, ctx.get(dut.rd_data[0])))

    simulate(dut, bench)
    lag = 2 + 2 * block_ram       # the accumulator, the write (and the write-back, the read)
    for k, got in seen[lag:]:
        assert got == sum(events[:k + 2 - lag]), (k, got)


def test_event_counters_reject_bad_parameters():
    with pytest.raises(ParameterError, match="amounts"):
        EventCounters(("a", "b"), amounts={"c": 4})
    with pytest.raises(ParameterError, match="names"):
        EventCounters(("a", "a"))
    with pytest.raises(ParameterError, match=re.escape("spacing must be one of the counters "
                                                       "('a', 'b'), not 'c'")):
        EventCounters(("a", "b"), spacing={"a": 2, "c": 4})
    with pytest.raises(ParameterError, match=re.escape("spacing['b'] must be an integer")):
        EventCounters(("a", "b"), spacing={"b": 0})


class _ParserHarness(Elaboratable):
    """GmiiRx + FrameParser with fixed local addresses, for amaranth.sim; with 2 lanes the
    GmiiRx runs in domain ``gmii`` and an RxBeatBridge brings its frames to ``sync``."""

    def __init__(self, mac, ip, lanes=1):
        self.lanes = lanes
        self.rx = GmiiRx()
        self.parser = FrameParser(lanes=lanes)
        self.mac, self.ip = mac, ip

    def elaborate(self, platform):
        m = Module()
        m.submodules.parser = self.parser
        if self.lanes == 1:
            m.submodules.rx = self.rx
            wiring.connect(m, self.rx.rx, self.parser.rx)
        else:
            m.domains.gmii = ClockDomain()
            m.submodules.rx = DomainRenamer("gmii")(self.rx)
            m.submodules.bridge = bridge = RxBeatBridge()
            wiring.connect(m, self.rx.rx, bridge.gmii)
            wiring.connect(m, bridge.rx, self.parser.rx)
        m.d.comb += [self.parser.local_mac.eq(self.mac), self.parser.local_ip.eq(self.ip)]
        return m


#: the GMII clock and, with 2 lanes, the core clock at half its rate (seconds)
GMII_PERIOD, CORE_PERIOD = 8e-9, 16e-9


def parse_frames(frames, mac, ip, lanes=1):
    """Run frames (bytes with FCS) through the parser; return per frame the verdict, kind,
    fields, payload bytes seen, ``arp_seen`` and ``options_malformed``."""
    from hdl.net.rx import RX_FIELDS
    dut = _ParserHarness(mac, ip, lanes)
    p = dut.parser
    gmii = "sync" if lanes == 1 else "gmii"
    out = []

    async def drive(ctx):
        for frame in frames:
            for byte in b"\x55" * 7 + b"\xd5" + frame:
                ctx.set(dut.rx.gmii_rxd, byte)
                ctx.set(dut.rx.gmii_rx_dv, 1)
                await ctx.tick(gmii)
            ctx.set(dut.rx.gmii_rx_dv, 0)
            for _ in range(24):
                await ctx.tick(gmii)
        for _ in range(40):
            await ctx.tick(gmii)

    async def watch(ctx):
        payload = bytearray()
        while True:
            await ctx.tick()
            if ctx.get(p.payload_valid):
                data, keep = ctx.get(p.payload_data), ctx.get(p.payload_keep)
                payload += bytes((data >> 8 * k) & 0xFF for k in range(lanes) if keep >> k & 1)
            if ctx.get(p.done):
                fields = {name: ctx.get(Value.cast(getattr(p.fields, name)))
                          for name in RX_FIELDS.members}
                out.append((ctx.get(p.accept), ctx.get(p.reason), ctx.get(p.kind),
                            fields, bytes(payload), ctx.get(p.arp_seen),
                            ctx.get(p.options_malformed)))
                payload = bytearray()

    simulate(dut, drive, background=[watch],
             clocks={"sync": GMII_PERIOD} if lanes == 1 else
             {"sync": CORE_PERIOD, "gmii": GMII_PERIOD})
    return out


@pytest.mark.parametrize("lanes", [1, 2])
def test_frame_parser_matches_scapy(lanes):
    """Every header field the parser captures equals scapy's dissection of the same frame;
    checksums, lengths and options decide the verdict as scapy's checksums say (docs/network.md)."""
    from scapy.layers.inet import ICMP, IP, TCP, UDP, in4_chksum
    from scapy.layers.l2 import ARP, Ether
    from scapy.packet import Raw
    from scapy.utils import checksum

    from hdl.net.frames import DROP_REASONS, int_to_ip, ip_to_int, mac_to_int
    from hdl.net.rx import FrameKind
    from tb.models.tcp_peer import tcp_options_mss
    mac, ip = "02:00:c0:a8:0a:10", "192.168.10.16"
    peer = Ether(src="02:00:00:00:00:01", dst=mac) / IP(src="192.168.10.1", dst=ip)
    rng = random.Random(11)
    pkts = [
        peer / TCP(sport=40000, dport=24, seq=0xFFFFFFF0, ack=77, flags="S", window=29200,
                   options=[("MSS", 1400), ("SAckOK", b""), ("Timestamp", (1, 0)),
                            ("NOP", None), ("WScale", 7)]),
        peer / TCP(sport=1, dport=2, flags="PA", options=[("NOP", None)] * 3) /
        Raw(rng.randbytes(33)),
        peer / TCP(sport=5, dport=6, flags="A", options=[("MSS", 536)]) / Raw(b"x"),
        peer / UDP(sport=50000, dport=4660) / Raw(rng.randbytes(13)),
        peer / UDP(sport=1, dport=2, chksum=0) / Raw(b"no checksum"),
        peer / ICMP(type=8, id=3, seq=4) / Raw(rng.randbytes(57)),
        # a sender hardware address other than the Ethernet source: the answer goes to it
        Ether(src="02:00:00:00:00:01", dst="ff:ff:ff:ff:ff:ff") /
        ARP(op=1, hwsrc="02:00:00:00:00:2a", psrc="192.168.10.42", pdst=ip),
        # gratuitous ARP and a reply to someone else: not for this node, but their sender
        # is reported (RFC 826 refreshes a known sender first)
        Ether(src="02:00:00:00:00:07", dst="ff:ff:ff:ff:ff:ff") /
        ARP(op=2, hwsrc="02:00:00:00:00:07", psrc="192.168.10.1", pdst="192.168.10.1"),
        Ether(src="02:00:00:00:00:08", dst="ff:ff:ff:ff:ff:ff") /
        ARP(op=2, hwsrc="02:00:00:00:00:08", psrc="192.168.10.8", pdst="192.168.10.9",
            hwdst="02:00:00:00:00:09"),
        # not IPv4 over Ethernet: not an ARP frame this node understands
        Ether(src="02:00:00:00:00:01", dst="ff:ff:ff:ff:ff:ff") /
        ARP(op=1, hwsrc="02:00:00:00:00:01", psrc="192.168.10.1", pdst=ip, hwlen=6, plen=5),
        Ether(src="02:00:00:00:00:01", dst=mac) / IP(src="192.168.10.1", dst=ip, ihl=7,
                                                   options=b"\x01" * 8) /
        TCP(sport=9, dport=10, flags="A") / Raw(b"ip options"),
    ]
    # option bytes as written (scapy would re-encode them): malformed ones (docs/network.md:
    # length 0 or 1, or past the data offset; an MSS before the fault counts), an MSS of
    # the wrong length, junk after EOL, one option of 40 bytes, an unknown kind before MSS
    scapy_options = len(pkts)
    for options in (b"\x02\x04\x03\xe8\x04\x00\x00\x00", b"\x01\x01\x08\x0a\x00\x00\x00\x01",
                    b"\x01\x01\x01\x03", b"\x02\x05\x04\xb0", b"\x02\x03\x05\x01\x01\x01\x01\x01",
                    b"\x00\x02\x01\x00", b"\x03\x03\x07\x02\x04\x02\x18\x00",
                    b"\x1e\x01\x01\x01", b"\xfe\x28" + bytes(range(38)),
                    b"\x01\x1e\x06\x00\x00\x00\x00\x02\x04\x05\xb4\x00"):
        pkts.append(peer / TCP(sport=7, dport=8, flags="PA", dataofs=5 + len(options) // 4) /
                    Raw(options + rng.randbytes(rng.randrange(1, 20))))
    frames = [bytes(pkt).ljust(60, b"\0") for pkt in pkts]
    bad = bytearray(frames[1])
    bad[-1] ^= 0x40                                        # TCP payload: bad checksum
    frames.append(bytes(bad))
    with_fcs = [f + zlib.crc32(f).to_bytes(4, "little") for f in frames]
    got = parse_frames(with_fcs, mac_to_int(mac), ip_to_int(ip), lanes)
    assert len(got) == len(frames)
    malformed_seen = 0
    for n, (frame, (accept, reason, kind, f, payload, arp_seen, malformed)) in enumerate(
            zip(frames, got)):
        pkt = Ether(frame)
        if ARP in pkt:
            a = pkt[ARP]
            understood = (a.hwtype, a.ptype, a.hwlen, a.plen) == (1, 0x0800, 6, 4)
            assert kind == FrameKind.ARP and arp_seen == understood, a.summary()
            assert bool(accept) == (understood and a.pdst == ip), a.summary()
            if not accept:
                assert DROP_REASONS[reason] == "not_mine"
            if understood:
                assert (f["arp_oper"], f["sender_ip"], f["arp_tpa"], f["sender_mac"]) == (
                    a.op, ip_to_int(a.psrc), ip_to_int(a.pdst), mac_to_int(a.hwsrc))
            continue
        assert not arp_seen
        i = pkt[IP]
        assert (int_to_ip(f["sender_ip"]), int_to_ip(f["ip_dst"]), f["ip_proto"], f["ip_len"]) \
            == (i.src, i.dst, i.proto, i.len)
        assert f["sender_mac"] == mac_to_int(pkt.src)
        l4 = bytes(i.payload)[:i.len - i.ihl * 4]
        if TCP in pkt:
            t = pkt[TCP]
            assert (f["src_port"], f["dst_port"], f["seq"], f["ack"], f["flags"], f["window"],
                    f["doff"]) == (t.sport, t.dport, t.seq, t.ack, int(t.flags), t.window,
                                   t.dataofs)
            mss, bad_options = tcp_options_mss(l4[20:t.dataofs * 4])
            if n < scapy_options:       # the option walk agrees with scapy's dissection
                assert mss == dict((k, v) for k, v in t.options if k == "MSS").get("MSS")
            assert (f["has_mss"], f["mss"] if f["has_mss"] else None) == (mss is not None, mss)
            assert malformed == bad_options, l4[20:t.dataofs * 4].hex()
            malformed_seen += bad_options
            body = l4[t.dataofs * 4:]
            assert kind == FrameKind.TCP
        elif UDP in pkt:
            u = pkt[UDP]
            assert (f["src_port"], f["dst_port"], f["udp_len"]) == (u.sport, u.dport, u.len)
            body = l4[8:]
            assert kind == FrameKind.UDP
        else:
            c = pkt[ICMP]
            assert (f["icmp_type"], f["icmp_code"]) == (c.type, c.code)
            body = l4
            assert kind == FrameKind.ICMP
        if TCP not in pkt:
            assert not malformed
        assert payload == body and f["payload_len"] == len(body)
        # scapy's checksum of the bytes as received decides accept
        if ICMP in pkt:
            ok = checksum(l4) == 0
        else:
            ok = (UDP in pkt and pkt[UDP].chksum == 0) or in4_chksum(i.proto, i, l4) == 0
        assert bool(accept) == ok, (pkt.summary(), DROP_REASONS[reason])
        if not ok:
            assert DROP_REASONS[reason] == "l4_checksum"
    assert malformed_seen == 5


@pytest.mark.parametrize("lanes", [1, 2])
def test_frame_builder_of_some_kinds_matches_scapy(lanes):
    """A builder made for ARP and UDP only (``kinds``): its UDP frames (random payloads of
    odd and even length) and ARP replies equal scapy's, checksums included, under random
    backpressure; a TCP or ICMP request is taken and ended (``ready``, ``done``) without a
    frame, and the next request is built as if it had not come."""
    from scapy.layers.inet import IP, UDP
    from scapy.layers.l2 import ARP, Ether

    from hdl.net.rx import FrameKind

    rng = random.Random(lanes)
    dut = FrameBuilder(2, lanes=lanes, ttl=1, kinds=(FrameKind.ARP, FrameKind.UDP))
    mac, ip = "02:00:00:00:46:01", "10.0.0.7"
    # per requester: (kind, fields, payload) in order; port 1 mixes in the unsupported kinds
    plan = {0: [], 1: []}
    for k in range(12):
        payload = rng.randbytes(rng.choice([1, 2, 17, 18, rng.randrange(1, 60)]))
        plan[0].append((FrameKind.UDP, payload))
        plan[1].append((rng.choice([FrameKind.ARP, FrameKind.TCP, FrameKind.ICMP]), payload))
    peer_mac = [rng.randrange(1 << 48) & ~(1 << 40) for _ in range(24)]
    peer_ip = [rng.randrange(1 << 32) for _ in range(24)]
    ended = {0: 0, 1: 0}
    frames = []

    def want(port, k, ip_id):
        kind, payload = plan[port][k]
        dst_mac = ":".join(f"{b:02x}" for b in peer_mac[2 * k + port].to_bytes(6, "big"))
        dst_ip = ".".join(map(str, peer_ip[2 * k + port].to_bytes(4, "big")))
        if kind == FrameKind.ARP:
            return bytes(Ether(src=mac, dst=dst_mac) / ARP(op=2, hwsrc=mac, psrc=ip,
                                                           hwdst=dst_mac, pdst=dst_ip))
        return bytes(Ether(src=mac, dst=dst_mac) /
                     IP(src=ip, dst=dst_ip, ttl=1, id=ip_id, flags="DF") /
                     UDP(sport=4000 + k, dport=5000 + port) / payload)

    def requester(port):
        req = getattr(dut, f"req_{port}")

        async def run(ctx):
            for k, (kind, payload) in enumerate(plan[port]):
                await ctx.tick().repeat(rng.randrange(1, 20))
                r = req.request
                ctx.set(r.kind, kind)
                ctx.set(r.eth_dst, peer_mac[2 * k + port])
                ctx.set(r.ip_dst, peer_ip[2 * k + port])
                ctx.set(r.arp_oper, 2)
                ctx.set(r.src_port, 4000 + k)
                ctx.set(r.dst_port, 5000 + port)
                ctx.set(r.length, len(payload))
                ctx.set(r.payload_sum, ones_sum(payload))
                ctx.set(r.payload_addr, 0)
                ctx.set(req.valid, 1)
                await ctx.tick().until(req.ready)
                ctx.set(req.valid, 0)
                while True:       # a synchronous read port: the bytes a cycle after the address
                    *_, addr, done = await ctx.tick().sample(req.rd_addr, req.done)
                    ctx.set(req.rd_data, int.from_bytes(payload[addr:addr + lanes].ljust(
                        lanes, b"\0"), "little"))
                    if done:
                        break
                ended[port] += 1
        return run

    async def sink(ctx):
        o = dut.m_axis
        current = bytearray()
        while True:
            ready = rng.random() < 0.6
            ctx.set(o.tready, ready)
            *_, valid, data, last, keep, grant = await ctx.tick().sample(
                o.tvalid, o.tdata, o.tlast, o.tkeep if lanes > 1 else o.tvalid, dut.grant)
            if valid and ready:
                current += data.to_bytes(lanes, "little")[:bin(keep).count("1")]
                if last:
                    frames.append((grant, bytes(current)))
                    current = bytearray()

    async def addresses(ctx):
        ctx.set(dut.local_mac, mac_to_int(mac))
        ctx.set(dut.local_ip, ip_to_int(ip))
        await ctx.tick()

    async def finish(ctx):
        await ctx.tick().repeat(30)
        while min(ended.values()) < 12:
            await ctx.tick()
        await ctx.tick().repeat(10)

    simulate(dut, addresses, requester(0), requester(1), finish, background=[sink])
    built = {0: [], 1: []}
    for port, frame in frames:
        built[port].append(frame)
    supported = [k for k, (kind, _) in enumerate(plan[1]) if kind == FrameKind.ARP]
    assert 0 < len(supported) < 12
    assert len(built[0]) == 12 and len(built[1]) == len(supported), \
        (len(built[0]), len(built[1]), len(supported))
    # IPv4 ids count the IP frames in the order they left
    ids = {}
    for port, frame in frames:
        if frame[12:14] == b"\x08\x00":
            ids[frame] = int.from_bytes(frame[18:20], "big")
    assert sorted(ids.values()) == list(range(len(ids)))
    for k, frame in enumerate(built[0]):
        assert frame == want(0, k, ids[frame]), (k, frame.hex())
    for k, frame in zip(supported, built[1]):
        assert frame == want(1, k, None), (k, frame.hex())


def test_frame_builder_refuses_bad_kinds():
    with pytest.raises(ParameterError, match=re.escape("kinds must be one or more FrameKind "
                                                       "members, not ()")):
        FrameBuilder(2, kinds=())
    with pytest.raises(ParameterError, match=re.escape("kinds must be one or more FrameKind "
                                                       "members, not ('udp',)")):
        FrameBuilder(2, kinds=("udp",))
