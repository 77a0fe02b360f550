"""Formal checks of the network engine's header path (docs/network.md "Unit": "yowasp-sby:
no read past frame end, no dead FSM state").

* :class:`FrameParser`, fed any byte stream shaped like :class:`GmiiRx`'s output: payload
  bytes lie inside the IPv4 datagram, are numbered 0, 1, 2, ... without a gap, never come
  from an ARP frame, and an accepted frame has delivered exactly its ``payload_len`` bytes,
  none of them FCS (bounded, ``abc bmc3``); the TCP option walker is back in its waiting
  state at every frame's first byte, whatever came before (unbounded, ``abc pdr``).
* :class:`RbcpServer` with the stack's two windows, any request in its buffer and a bus that
  acknowledges late or never: strobes only for a well-formed request inside a window, one
  per byte at the request's addresses in order; buffer writes only to the flag byte and the
  request's data bytes (bounded, ``abc bmc3``).
* :class:`FrameBuilder`, serving two requesters that change their requests freely between
  frames: every frame is ``header + length`` bytes with ``tlast`` on the last, payload byte
  ``k`` is the requester's buffer byte ``payload_addr + k`` (so nothing before or after the
  payload is read), each request is taken once and its frame ends with one ``done`` to the
  same requester, and an offered byte stays until taken (bounded, ``abc bmc3``).

* :class:`TcpRequestScheduler` with any due requests and a free builder: a request reaches
  the builder only while pending and not held, the one chosen is the highest-priority due
  one and stays what was chosen until it is sent or dropped, and ``sent`` pulses only for a
  transfer (unbounded, ``abc pdr``).
* :class:`GlobalRegisters` on a free bus: no strobe inside the global block reaches the
  user's bus, every one inside is acknowledged the next cycle, and a register changes only
  by a write strobe to one of its bytes (unbounded, ``abc pdr``).

The environment models (:class:`GmiiRxEnvironment`, the requesters) are written from the
interfaces' docstrings (RxBeatSignature, TxRequestSignature), not from the RTL.
"""

import pytest
from amaranth.asserts import AnyConst, AnySeq, Initial
from amaranth.hdl import (Assert, Assume, Cat, Const, Elaboratable, Module, Mux, ResetSignal,
                          Signal)

from hdl.net.frames import (
    ARP_LENGTH,
    ETH_HEADER,
    L4_OFFSET,
    RBCP_HEADER,
    RBCP_READ,
    RBCP_VERSION,
    RBCP_WRITE,
)
from hdl.net.rbcp import RbcpServer
from hdl.net.registers import GLOBAL_BASE, GLOBAL_REGS, GlobalRegisters
from hdl.net.rx import OPTIONS_WAIT, FrameKind, FrameParser
from hdl.net.tcp import TcpRequest, TcpRequestScheduler
from hdl.net.tx import FrameBuilder
from tb.formal import held_until_taken, run_sby

pytestmark = pytest.mark.formal

#: bounded depths in cycles (abc bmc3 on this machine, make test / test-full): the parser sees
#: frames up to 51 bytes at 56 cycles (every ARP, ICMP and UDP header with payload), 61 at 66
#: (a TCP header, its options and payload; 18 s / 65 s, 60 cycles took 30-38 s); the solver's
#: time grows about 1.25 times per cycle beyond 55
PARSER_DEPTHS = [pytest.param(56, id="bmc56"), pytest.param(66, id="bmc66",
                                                          marks=pytest.mark.full)]
#: the same at two bytes per cycle: the same frames in about half the cycles
PARSER_DEPTHS_2 = [pytest.param(32, id="bmc32"), pytest.param(38, id="bmc38",
                                                            marks=pytest.mark.full)]
#: the same at two bytes per cycle: a grant, the pre-sums, an ICMP header and its first
#: payload beats at 24 (about 25 s), about ten payload bytes at 28 (3 min; 32 took over 10)
BUILDER_DEPTHS_2 = [pytest.param(24, id="bmc24"), pytest.param(28, id="bmc28",
                                                             marks=pytest.mark.full)]
#: the RBCP server: the header, its checks and about six bus accesses at 30, ten at 40 (7 s / 65 s)
RBCP_DEPTHS = [pytest.param(30, id="bmc30"), pytest.param(40, id="bmc40",
                                                        marks=pytest.mark.full)]
#: the builder: a grant, the checksum pre-sums, an ICMP header and its first 2 payload bytes at
#: 38, 8 payload bytes at 44 (17 s / 274 s; 40 cycles took 42 s)
BUILDER_DEPTHS = [pytest.param(38, id="bmc38"), pytest.param(44, id="bmc44",
                                                          marks=pytest.mark.full)]


class GmiiRxEnvironment(Elaboratable):
    """Drives a ``RxBeatSignature`` port as :class:`GmiiRx` (one lane) or an
    :class:`RxBeatBridge` (two) may: a frame is a run of beats on consecutive cycles
    (``index`` counting from 0 by the lanes) closed by one ``end`` pulse with any status; at
    least 4 idle cycles separate ``end`` from the next frame (preamble and inter-frame gap).
    Byte values and the status flags are free; with two lanes the frame's length at ``end``
    is its beats' bytes or one less (a last beat with one byte).

    ``count`` is the index the next beat will have.
    """

    def __init__(self, rx):
        self.rx = rx
        self.lanes = len(rx.data) // 8
        self.count = Signal(11)
        self.in_frame = Signal()

    def elaborate(self, platform):
        m = Module()
        rx = self.rx
        valid, end = AnySeq(1), AnySeq(1)
        quiet = Signal(range(5), init=4)
        L = self.lanes
        odd = AnySeq(1) if L == 2 else Const(0)
        m.d.comb += [rx.valid.eq(valid), rx.end.eq(end),
                     rx.index.eq(Mux(end & odd & (self.count != 0), self.count - 1,
                                     self.count)),
                     rx.data.eq(AnySeq(8 * L)), rx.ok.eq(AnySeq(1)), rx.err_fcs.eq(AnySeq(1)),
                     rx.err_rx_er.eq(AnySeq(1)), rx.err_size.eq(AnySeq(1))]
        m.d.comb += Assume(~(valid & end))
        with m.If(self.in_frame):
            m.d.comb += Assume(valid | end)
        with m.Else():
            m.d.comb += Assume(~end)
            with m.If(quiet != 4):
                m.d.comb += Assume(~valid)
        with m.If(valid):
            m.d.sync += [self.count.eq(Mux(self.count == 2048 - L, 2048 - L,
                                           self.count + L)),
                         self.in_frame.eq(1)]
        with m.If(end):
            m.d.sync += [self.count.eq(0), self.in_frame.eq(0), quiet.eq(0)]
        with m.Elif(~self.in_frame & (quiet != 4)):
            m.d.sync += quiet.eq(quiet + 1)
        return m


class FrameParserPayloadProperty(Elaboratable):
    """No payload byte outside the IPv4 datagram; payload offsets 0, 1, 2, ... without a
    gap, a beat's payload bytes from lane 0; an accepted frame delivered ``payload_len``
    bytes, all before its FCS."""

    def __init__(self, lanes=1):
        self.lanes = lanes

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = dut = FrameParser(lanes=self.lanes)
        m.submodules.env = env = GmiiRxEnvironment(dut.rx)
        f = dut.fields
        m.d.comb += Assume(ResetSignal() == Initial())
        m.d.comb += [dut.local_mac.eq(AnyConst(48)), dut.local_ip.eq(AnyConst(32))]

        keep = dut.payload_keep
        count = Signal(range(self.lanes + 1))   # payload bytes in this beat
        m.d.comb += count.eq(sum(keep[k] for k in range(self.lanes)))
        delivered = Signal(12)          # payload bytes of the current frame so far
        last_byte = Signal(12)          # the frame index of the last of them
        with m.If(dut.payload_valid):
            m.d.sync += [delivered.eq(delivered + count),
                         last_byte.eq(env.count + count - 1)]
        frame_delivered = Signal(12)
        before_fcs = Signal()
        with m.If(dut.rx.end):
            m.d.sync += [delivered.eq(0), frame_delivered.eq(delivered),
                         before_fcs.eq((delivered == 0) | (last_byte + 4 < dut.rx.index))]

        with m.If(~Initial() & ~ResetSignal()):
            with m.If(dut.payload_valid):
                m.d.comb += [Assert(dut.rx.valid), Assert(keep[0]),
                             Assert(env.count + count - 1 < ETH_HEADER + f.ip_len),
                             Assert(dut.payload_offset == delivered),
                             Assert(dut.kind != FrameKind.ARP)]
            with m.If(dut.done & dut.accept & (dut.kind != FrameKind.ARP)):
                m.d.comb += [Assert(frame_delivered == f.payload_len), Assert(before_fcs)]
        return m


class FrameParserOptionsResyncProperty(Elaboratable):
    """The TCP option walker waits again from every frame's first byte (no state in which a
    frame's end leaves it, that the next frame cannot leave)."""

    def elaborate(self, platform):
        m = Module()
        dut = FrameParser()
        # the walker's state is not a port: elaborate the parser here to reach it
        dut._MustUse__silence = True
        m.submodules.dut = dut.elaborate(platform)
        waiting = dut._options_state == OPTIONS_WAIT
        m.submodules.env = env = GmiiRxEnvironment(dut.rx)
        m.d.comb += Assume(ResetSignal() == Initial())
        m.d.comb += [dut.local_mac.eq(AnyConst(48)), dut.local_ip.eq(AnyConst(32))]
        first_byte = Signal()
        m.d.sync += first_byte.eq(dut.rx.valid & (env.count == 0))
        with m.If(~Initial() & ~ResetSignal() & first_byte):
            m.d.comb += Assert(waiting)
        return m


class FrameBuilderProperty(Elaboratable):
    """Frame length, payload addressing, one ``ready`` per request and one ``done`` per frame,
    and a stable output while it waits, for two requesters."""

    def __init__(self, lanes=1):
        self.lanes = lanes

    def elaborate(self, platform):
        m = Module()
        L = self.lanes
        m.submodules.dut = dut = FrameBuilder(2, lanes=L)
        reqs = [dut.req_0, dut.req_1]
        o = dut.m_axis
        m.d.comb += Assume(ResetSignal() == Initial())
        m.d.comb += [dut.local_mac.eq(AnyConst(48)), dut.local_ip.eq(AnyConst(32)),
                     o.tready.eq(AnySeq(1))]

        # Requesters: any request, held unchanged from valid until ready; the buffer returns
        # a byte one cycle after its address, a function of the address alone (each lane's
        # of its own address).
        for q in reqs:
            m.d.comb += [q.valid.eq(AnySeq(1)), q.request.eq(AnySeq(len(q.request.as_value())))]
            held_until_taken(m, q.valid, q.ready, q.request.as_value(), Assume)
            m.d.comb += Assume(q.request.length <= 1460)
            m.d.comb += Assume(q.request.kind.as_value() <= FrameKind.TCP.value)
            rd_addr = Signal(16)
            m.d.sync += rd_addr.eq(q.rd_addr)
            m.d.comb += q.rd_data.eq(Cat(*(_buffer_byte(rd_addr + k) for k in range(L))))

        # the frame being sent, from the request the builder took
        busy = Signal()
        owner = Signal()
        request = Signal.like(reqs[0].request)
        sent = Signal(11)
        header = Signal(11)
        kind = request.kind
        l4 = Mux(kind == FrameKind.TCP, Mux(request.mss, 24, 20),
                 Mux(kind == FrameKind.UDP, 8, 0))
        m.d.comb += header.eq(Mux(kind == FrameKind.ARP, ETH_HEADER + ARP_LENGTH, L4_OFFSET + l4))
        length = Mux(kind == FrameKind.ARP, 0, request.length)
        beat = o.tvalid & o.tready

        with m.If(~Initial() & ~ResetSignal()):
            # at most one requester is taken, only when no frame is under way
            m.d.comb += Assert(~(reqs[0].ready & reqs[1].ready))
            for k, q in enumerate(reqs):
                with m.If(q.ready):
                    m.d.comb += [Assert(q.valid), Assert(~busy)]
                    m.d.sync += [busy.eq(1), owner.eq(k), request.eq(q.request), sent.eq(0)]
                with m.If(q.done):
                    m.d.comb += [Assert(busy), Assert(owner == k), Assert(beat & o.tlast)]
            with m.If(o.tvalid):
                m.d.comb += Assert(busy)
            with m.If(beat):
                m.d.sync += sent.eq(sent + L)
                m.d.comb += Assert(o.tlast == (sent + L >= header + length))
                if L == 2:
                    # a frame of odd length ends with one byte; header lengths are even
                    m.d.comb += Assert(o.tkeep == Mux(sent + 1 == header + length, 0b01, 0b11))
                for k in range(L):
                    with m.If((sent + k >= header) & (sent + k < header + length)):
                        address = (request.payload_addr + (sent + k - header))[:16]
                        m.d.comb += Assert(o.tdata.word_select(k, 8) == _buffer_byte(address))
                with m.If(o.tlast):
                    m.d.comb += Assert(reqs[0].done | reqs[1].done)
                    m.d.sync += busy.eq(0)
        # AXI4-Stream: an offered byte stays until taken
        held_until_taken(m, o.tvalid, o.tready,
                         Cat(o.tdata, o.tlast, o.tkeep if L == 2 else Const(0, 0)), Assert,
                         when=~ResetSignal())
        return m


def _buffer_byte(address):
    """The byte the formal checks' buffers hold at a 16-bit ``address``."""
    address = address[:16]
    return address[:8] ^ address[8:]


@pytest.mark.parametrize("depth", PARSER_DEPTHS)
def test_frame_parser_payload_inside_frame(depth):
    run_sby(f"frame_parser_payload_{depth}", FrameParserPayloadProperty(), depth,
            engine="abc bmc3")


@pytest.mark.parametrize("depth", PARSER_DEPTHS_2)
def test_frame_parser_two_lanes_payload_inside_frame(depth):
    run_sby(f"frame_parser_payload_2l_{depth}", FrameParserPayloadProperty(lanes=2), depth,
            engine="abc bmc3")


def test_frame_parser_options_resync():
    run_sby("frame_parser_options_resync", FrameParserOptionsResyncProperty(), 20,
            mode="prove", engine="abc pdr")


class RbcpServerProperty(Elaboratable):
    """Strobes only for a well-formed request inside a window, at its addresses in order;
    buffer writes only to the reply's flag byte and data bytes."""

    #: the stack's windows with the default user window (docs/network.md)
    WINDOWS = ((0, 0x10000), (GLOBAL_BASE, 0x10000))

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = dut = RbcpServer(self.WINDOWS)
        bus = dut.bus
        m.d.comb += Assume(ResetSignal() == Initial())

        # the request: any header and length, fixed for the run; the data bytes are free
        header = AnyConst(64)           # byte 0 in the top bits, as on the wire
        length = AnyConst(11)
        version, command, ident, count = (header.word_select(7 - q, 8) for q in range(4))
        base = header[:32]
        read_addr = Signal(11)
        m.d.sync += read_addr.eq(dut.buf_addr)
        header_byte = header.word_select((7 - read_addr[:3]).as_unsigned()[:3], 8)
        m.d.comb += [dut.length.eq(length),
                     dut.buf_rdata.eq(Mux(read_addr < RBCP_HEADER, header_byte, AnySeq(8)))]

        # one request at a time; an acknowledge answers one strobe
        running = Signal()
        outstanding = Signal()
        m.d.comb += dut.start.eq(AnySeq(1))
        with m.If(dut.start):
            m.d.comb += Assume(~running)
            m.d.sync += running.eq(1)
        with m.If(dut.done):
            m.d.sync += running.eq(0)
        m.d.comb += [bus.ack.eq(AnySeq(1)), bus.rd.eq(AnySeq(8))]
        with m.If(bus.ack):
            m.d.comb += Assume(outstanding)
        with m.If(bus.we | bus.re):
            m.d.sync += outstanding.eq(1)
        with m.Elif(bus.ack):
            m.d.sync += outstanding.eq(0)

        # the request as docs/network.md defines a good one
        end = base + count
        inside = 0
        for wbase, wsize in self.WINDOWS:
            inside = inside | ((base >= wbase) & (end <= wbase + wsize))
        well_formed = ((length >= RBCP_HEADER) & (version == RBCP_VERSION) &
                       ((command == RBCP_WRITE) | (command == RBCP_READ)) & (count != 0) &
                       inside & ((command == RBCP_READ) | (length >= RBCP_HEADER + count)))
        strobes = Signal(9)
        with m.If(dut.start):
            m.d.sync += strobes.eq(0)
        with m.Elif(bus.we | bus.re):
            m.d.sync += strobes.eq(strobes + 1)

        with m.If(~Initial() & ~ResetSignal()):
            with m.If(bus.we | bus.re):
                m.d.comb += [Assert(running), Assert(well_formed), Assert(bus.act),
                             Assert(~(bus.we & bus.re)),
                             Assert(bus.we == (command == RBCP_WRITE)),
                             Assert(strobes < count), Assert(bus.addr == base + strobes)]
            with m.If(dut.buf_we):
                m.d.comb += [Assert(running),
                             Assert((dut.buf_addr == 1) |
                                    ((dut.buf_addr >= RBCP_HEADER) &
                                     (dut.buf_addr < RBCP_HEADER + count)))]
            with m.If(dut.done & dut.reply):
                m.d.comb += Assert(dut.reply_len == RBCP_HEADER + count)
        return m


@pytest.mark.parametrize("depth", RBCP_DEPTHS)
def test_rbcp_server_accesses(depth):
    run_sby(f"rbcp_server_{depth}", RbcpServerProperty(), depth, engine="abc bmc3")


@pytest.mark.parametrize("depth", BUILDER_DEPTHS)
def test_frame_builder_frames(depth):
    run_sby(f"frame_builder_{depth}", FrameBuilderProperty(), depth, engine="abc bmc3")


@pytest.mark.parametrize("depth", BUILDER_DEPTHS_2)
def test_frame_builder_two_lanes_frames(depth):
    run_sby(f"frame_builder_2l_{depth}", FrameBuilderProperty(lanes=2), depth,
            engine="abc bmc3")


class TcpRequestSchedulerProperty(Elaboratable):
    """Requests offered only while pending and not held, chosen by priority, unchanged until
    sent or dropped."""

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = dut = TcpRequestScheduler()
        m.d.comb += Assume(ResetSignal() == Initial())
        names = [f"{kind.name.lower()}_due" for kind in TcpRequest]
        for name in names + ["hold", "withdraw", "unsent", "ready", "syn_only"]:
            m.d.comb += getattr(dut, name).eq(AnySeq(1))
        m.d.comb += dut.choose.eq(AnySeq(1))
        # the sequence engine chooses only when nothing is pending (its docstring)
        with m.If(dut.choose):
            m.d.comb += Assume(~dut.pending & dut.next_due)
        chosen = Signal(TcpRequest)
        with m.If(dut.choose):
            m.d.sync += chosen.eq(dut.next_kind)
        dues = Cat(*(getattr(dut, name) for name in names))
        highest = Signal(TcpRequest)
        for k in reversed(range(len(names))):
            with m.If(dues[k]):
                m.d.comb += highest.eq(k)
        with m.If(~Initial() & ~ResetSignal()):
            m.d.comb += [Assert(dut.next_due == dues.any()),
                         Assert(~dut.valid | (dut.pending & ~dut.hold)),
                         Assert(dut.sent == (dut.valid & dut.ready))]
            with m.If(dut.next_due):
                m.d.comb += Assert(dut.next_kind == highest)
            with m.If(dut.pending):
                m.d.comb += Assert(dut.kind == chosen)
        return m


class GlobalRegistersProperty(Elaboratable):
    """No user strobe inside the block, an acknowledge the cycle after each strobe inside,
    registers changed only by a write to one of their bytes."""

    INIT = {"mac": 1, "ip": 2, "rto_cycles": 3, "msl_cycles": 4, "rbcp_port": 5,
            "arp_retry_cycles": 6, "tcp_port": 7}

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = dut = GlobalRegisters(self.INIT)
        bus = dut.bus
        m.d.comb += Assume(ResetSignal() == Initial())
        m.d.comb += [bus.act.eq(AnySeq(1)), bus.addr.eq(AnySeq(32)), bus.wd.eq(AnySeq(8)),
                     bus.we.eq(AnySeq(1)), bus.re.eq(AnySeq(1)), dut.user.ack.eq(AnySeq(1)),
                     dut.user.rd.eq(AnySeq(8)), dut.counter_value.eq(AnySeq(32))]
        m.d.comb += Assume(~(bus.we & bus.re))
        # the server holds the address until the acknowledge (RbcpBusSignature)
        last_addr = Signal(32)
        strobed = Signal()
        m.d.sync += [last_addr.eq(bus.addr), strobed.eq(bus.we | bus.re)]
        with m.If(strobed):
            m.d.comb += Assume(bus.addr == last_addr)
        inside = bus.addr[16:] == (GLOBAL_BASE >> 16)
        was_inside_write = Signal()
        written = Signal(16)
        past_valid = Signal()
        m.d.sync += [was_inside_write.eq(bus.we & inside), written.eq(bus.addr[:16]),
                     past_valid.eq(~ResetSignal())]
        registers = {offset: (getattr(dut, name), size)
                     for offset, (name, size, writable) in GLOBAL_REGS.items() if writable}
        past = {offset: Signal.like(value) for offset, (value, _) in registers.items()}
        m.d.sync += [past[offset].eq(value) for offset, (value, _) in registers.items()]
        with m.If(~Initial() & ~ResetSignal() & past_valid):
            with m.If(dut.user.we | dut.user.re):
                m.d.comb += Assert(~inside)
            with m.If(strobed & inside):
                m.d.comb += Assert(bus.ack)
            for offset, (value, size) in registers.items():
                hit = was_inside_write & (written >= offset) & (written < offset + size)
                with m.If(~hit):
                    m.d.comb += Assert(value == past[offset])
        return m


def test_tcp_request_scheduler_offers_what_it_chose():
    run_sby("tcp_request_scheduler", TcpRequestSchedulerProperty(), 20, mode="prove",
            engine="abc pdr")


def test_global_registers_decode():
    run_sby("global_registers", GlobalRegistersProperty(), 20, mode="prove", engine="abc pdr")
