"""Bench-only hardware around the network engine: a GMII peer port that moves whole frames
as wide words (so the Python peer wakes once per word, not once per byte), a byte-pattern
generator and a checking sink for session streams, and a message generator and CRC sink for
TCPROS endpoints. Not part of rosgate's hardware; the benches measure the engine inside."""

from amaranth.hdl import Cat, ClockDomain, DomainRenamer, Module, Mux, ResetSignal, Signal
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from hdl.net import NetStack
from hdl.net.crc import Crc32
from hdl.net.frames import IFG, PREAMBLE, SFD
from hdl.net.stack import STACK_COUNTERS
from hdl.net.tcp import TCP_COUNTERS
from hdl.ros1 import TcprosNode
from hdl.ros1.registers import PHASES
from hdl.stream import AXIStreamSignature, StreamFIFO, keep_count

__all__ = ["GmiiWordPeer", "NetBenchTop", "Ros1BenchTop", "WORD_BYTES", "pattern_bytes",
           "NET_BENCH_CONFIGS", "ROS1_BENCH_CONFIG", "build_net_bench_top",
           "build_ros1_bench_top"]

WORD_BYTES = 64

#: the throughput bench tops ``make bench`` builds: case -> :class:`NetBenchTop` parameters
NET_BENCH_CONFIGS = {"linux_64k": dict(tx_depth=65536, rx_depth=65536),
                     "seed_16k": dict(tx_depth=16384, rx_depth=65536)}
#: the TCPROS node bench top (64 KiB buffers each way)
ROS1_BENCH_CONFIG = dict(tx_depth=65536, rx_depth=65536)


def build_net_bench_top(**params):
    """The engine throughput bench top (``net_bench``), for :func:`tb.harness.run_bench`."""
    return NetBenchTop(**params)


def build_ros1_bench_top(**params):
    """The TCPROS node bench top (``ros1_bench``), for :func:`tb.harness.run_bench`."""
    return Ros1BenchTop(**params)


def pattern_bytes(start, count):
    """Bytes ``start .. start + count - 1`` of the bench's data pattern, byte ``i`` being
    ``(i[7:0] * 131 + i[15:8]) mod 256``; the hardware generator and sink compute it with
    :func:`_pattern`."""
    import numpy as np
    i = np.arange(start, start + count, dtype=np.int64)
    return (((i & 0xFF) * 131 + ((i >> 8) & 0xFF)) & 0xFF).astype(np.uint8).tobytes()


def _pattern(i):
    return (i[0:8] * 131 + i[8:16])[0:8]


class GmiiWordPeer(wiring.Component):
    """Frames to and from a GMII port as ``WORD_BYTES``-byte words.

    ``peer_in``: frames for the device (destination MAC .. FCS), ``tkeep`` marks the bytes
    of the last word; a frame starts on GMII only once all its words are stored, so the
    Python side can never underrun it. ``peer_out``: the device's frames after the SFD, FCS
    included, one message per frame. ``out_overflow`` counts words lost to a full FIFO.
    """

    def __init__(self):
        sig = AXIStreamSignature(8 * WORD_BYTES, keep=True)
        super().__init__({
            "peer_in": In(sig), "peer_out": Out(sig),
            "txd": Out(8), "tx_en": Out(1),              # towards the device's GMII RX
            "rxd": In(8), "rx_en": In(1), "rx_er": In(1),  # from the device's GMII TX
            "out_overflow": Out(16), "out_errors": Out(16),
        })

    def elaborate(self, platform):
        m = Module()
        sig = AXIStreamSignature(8 * WORD_BYTES, keep=True)
        m.submodules.in_fifo = in_fifo = StreamFIFO(sig, 64, packet=True)
        m.submodules.out_fifo = out_fifo = StreamFIFO(sig, 256)
        wiring.connect(m, wiring.flipped(self.peer_in), in_fifo.s_axis)
        wiring.connect(m, out_fifo.m_axis, wiring.flipped(self.peer_out))

        # words -> GMII
        w = in_fifo.m_axis
        k = Signal(range(WORD_BYTES))
        count = Signal(range(16))
        byte = Signal(8)
        en = Signal()
        m.d.sync += [self.txd.eq(byte), self.tx_en.eq(en)]
        last_byte = (k == WORD_BYTES - 1) | ~w.tkeep.bit_select(k + 1, 1)
        with m.FSM(name="tx"):
            with m.State("IDLE"):
                with m.If(w.tvalid):
                    m.d.sync += count.eq(0)
                    m.next = "PREAMBLE"
            with m.State("PREAMBLE"):
                m.d.comb += [en.eq(1), byte.eq(Mux(count == PREAMBLE, SFD, 0x55))]
                m.d.sync += count.eq(count + 1)
                with m.If(count == PREAMBLE):
                    m.d.sync += k.eq(0)
                    m.next = "DATA"
            with m.State("DATA"):
                m.d.comb += [en.eq(1), byte.eq(w.tdata.word_select(k, 8))]
                m.d.sync += k.eq(k + 1)
                with m.If(last_byte):
                    m.d.comb += w.tready.eq(1)
                    m.d.sync += k.eq(0)
                    with m.If(w.tlast):
                        m.d.sync += count.eq(0)
                        m.next = "GAP"
            with m.State("GAP"):
                m.d.sync += count.eq(count + 1)
                with m.If(count == IFG - 1):
                    m.next = "IDLE"

        # GMII -> words; a full word waits until the next byte shows whether it is the last
        o = out_fifo.s_axis
        word = Signal(8 * WORD_BYTES)
        keep = Signal(WORD_BYTES)
        j = Signal(range(WORD_BYTES + 1))
        in_frame = Signal()
        rxd = Signal(8)
        rx_en = Signal()
        m.d.sync += [rxd.eq(self.rxd), rx_en.eq(self.rx_en)]
        with m.If(self.rx_er):
            m.d.sync += self.out_errors.eq(self.out_errors + 1)
        m.d.comb += [o.tdata.eq(word), o.tkeep.eq(keep)]
        with m.If(~in_frame):
            with m.If(rx_en & (rxd == SFD)):
                m.d.sync += [in_frame.eq(1), j.eq(0), keep.eq(0)]
        with m.Elif(rx_en):
            with m.If(j == WORD_BYTES):
                m.d.comb += o.tvalid.eq(1)
                m.d.sync += [word.word_select(0, 8).eq(rxd), keep.eq(1), j.eq(1)]
            with m.Else():
                m.d.sync += [word.word_select(j[:6], 8).eq(rxd),
                             keep.bit_select(j[:6], 1).eq(1), j.eq(j + 1)]
        with m.Else():
            m.d.sync += in_frame.eq(0)
            m.d.comb += [o.tvalid.eq(j != 0), o.tlast.eq(1)]
        with m.If(o.tvalid & ~o.tready):
            m.d.sync += self.out_overflow.eq(self.out_overflow + 1)
        return m


#: bytes per beat of the throughput bench's session streams: the engine's line rate at its
#: core clock
USER_BYTES = 2


class _PatternSource(wiring.Component):
    """``count`` bytes of :func:`pattern_bytes` on ``m_axis``, ``USER_BYTES`` a beat (the
    last beat partial), after each ``start`` pulse."""

    def __init__(self):
        super().__init__({"start": In(1), "count": In(32), "m_axis":
                          Out(AXIStreamSignature(8 * USER_BYTES)), "sent": Out(32)})

    def elaborate(self, platform):
        m = Module()
        left = Signal(32)
        with m.If(self.start):
            m.d.sync += left.eq(self.count)
        short = left < USER_BYTES
        n = Mux(short, left, USER_BYTES)
        s = self.m_axis
        m.d.comb += [s.tvalid.eq(left != 0),
                     s.tdata.eq(Cat(*(_pattern(self.sent + k) for k in range(USER_BYTES)))),
                     s.tkeep.eq(Cat(*((left > k) for k in range(USER_BYTES)))),
                     s.tlast.eq(left <= USER_BYTES)]
        with m.If(s.tvalid & s.tready):
            m.d.sync += [left.eq(left - n), self.sent.eq(self.sent + n)]
        return m


class _PatternSink(wiring.Component):
    """Always ready; counts bytes and those that differ from :func:`pattern_bytes`."""

    def __init__(self):
        super().__init__({"s_axis": In(AXIStreamSignature(8 * USER_BYTES)),
                          "received": Out(32), "mismatches": Out(32)})

    def elaborate(self, platform):
        m = Module()
        s = self.s_axis
        m.d.comb += s.tready.eq(1)
        with m.If(s.tvalid):
            m.d.sync += self.received.eq(self.received + keep_count(s.tkeep))
            wrong = Cat(*(s.tkeep[k] & (s.tdata.word_select(k, 8) !=
                                        _pattern(self.received + k))
                          for k in range(USER_BYTES)))
            m.d.sync += self.mismatches.eq(self.mismatches + wrong.any())
        return m


def _bridge(m, peer, device, clock):
    """``peer``'s GMII to ``device``'s, both on the bench's GMII clock ``clock``."""
    m.d.comb += [device.gmii_rxd.eq(peer.txd), device.gmii_rx_dv.eq(peer.tx_en),
                 device.gmii_rx_er.eq(0), peer.rxd.eq(device.gmii_txd),
                 peer.rx_en.eq(device.gmii_tx_en), peer.rx_er.eq(device.gmii_tx_er),
                 device.gmii_rx_clk.eq(clock), device.gmii_tx_clk.eq(clock)]


def _gmii_peer(m, clock):
    """A :class:`GmiiWordPeer` in domain ``gmii``, on ``clock``."""
    m.domains += (cd := ClockDomain("gmii", local=True))
    m.d.comb += cd.clk.eq(clock)
    m.submodules.gmii_reset = FFSynchronizer(ResetSignal("sync"), cd.rst, o_domain="gmii",
                                             init=1)
    m.submodules.peer = peer = DomainRenamer("gmii")(GmiiWordPeer())
    return peer


class NetBenchTop(wiring.Component):
    """A :class:`NetStack` with one session, its GMII on a :class:`GmiiWordPeer` on the GMII
    clock ``gmii_clk`` (``peer_in``/``peer_out`` too), a pattern generator on its transmit
    stream and a checking sink on its receive stream."""

    def __init__(self, **stack):
        self._stack = NetStack(sessions=1, user_width=8 * USER_BYTES, **stack)
        sig = AXIStreamSignature(8 * WORD_BYTES, keep=True)
        super().__init__({
            "gmii_clk": In(1), "peer_in": In(sig), "peer_out": Out(sig),
            "out_overflow": Out(16), "out_errors": Out(16),
            "gen_start": In(1), "gen_count": In(32), "gen_sent": Out(32),
            "sink_received": Out(32), "sink_mismatches": Out(32),
            "open_req": In(1), "active": In(1), "local_port": In(16), "remote_ip": In(32),
            "remote_port": In(16), "state": Out(4),
            "tcp_counter_index": In(range(len(TCP_COUNTERS))), "tcp_counter_value": Out(32),
            "counter_index": In(range(len(STACK_COUNTERS))), "counter_value": Out(32),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.stack = stack = self._stack
        peer = _gmii_peer(m, self.gmii_clk)
        m.submodules.gen = gen = _PatternSource()
        m.submodules.sink = sink = _PatternSink()
        _bridge(m, peer, stack, self.gmii_clk)
        wiring.connect(m, wiring.flipped(self.peer_in), peer.peer_in)
        wiring.connect(m, peer.peer_out, wiring.flipped(self.peer_out))
        s = stack.tcp0
        wiring.connect(m, gen.m_axis, s.tx)
        wiring.connect(m, s.rx, sink.s_axis)
        m.d.comb += [gen.start.eq(self.gen_start), gen.count.eq(self.gen_count),
                     self.gen_sent.eq(gen.sent), self.sink_received.eq(sink.received),
                     self.sink_mismatches.eq(sink.mismatches),
                     self.out_overflow.eq(peer.out_overflow), self.out_errors.eq(peer.out_errors),
                     s.open_req.eq(self.open_req), s.active.eq(self.active),
                     s.local_port.eq(self.local_port), s.remote_ip.eq(self.remote_ip),
                     s.remote_port.eq(self.remote_port), s.close_ack.eq(s.close_req),
                     self.state.eq(s.state), s.counter_index.eq(self.tcp_counter_index),
                     self.tcp_counter_value.eq(s.counter_value),
                     stack.counter_index.eq(self.counter_index),
                     self.counter_value.eq(stack.counter_value)]
        return m


class _MessageSource(wiring.Component):
    """One message of ``length`` bytes per ``start``, ``USER_BYTES`` a beat: ``prefix``
    (``prefix_len`` bytes) then :func:`pattern_bytes` bytes; ``tuser`` = ``length``."""

    def __init__(self):
        from hdl.ros1 import message_stream_signature
        super().__init__({"start": In(1), "length": In(32), "prefix": In(8 * 64),
                          "prefix_len": In(7),
                          "m_axis": Out(message_stream_signature(USER_BYTES))})

    def elaborate(self, platform):
        m = Module()
        left = Signal(32)
        i = Signal(32)
        with m.If(self.start):
            m.d.sync += [left.eq(self.length), i.eq(0)]

        def byte(k):
            at = i + k
            return Mux(at < self.prefix_len, self.prefix.word_select(at[:6], 8), _pattern(at))
        n = Mux(left < USER_BYTES, left, USER_BYTES)
        s = self.m_axis
        m.d.comb += [s.tvalid.eq(left != 0), s.tdata.eq(Cat(*(byte(k) for k in range(USER_BYTES)))),
                     s.tkeep.eq(Cat(*((left > k) for k in range(USER_BYTES)))),
                     s.tlast.eq(left <= USER_BYTES), s.tuser.eq(self.length)]
        with m.If(s.tvalid & s.tready):
            m.d.sync += [left.eq(left - n), i.eq(i + n)]
        return m


class _MessageSink(wiring.Component):
    """Always ready; counts bytes and messages and keeps the CRC-32 (``zlib.crc32``) of the
    last complete message."""

    def __init__(self):
        from hdl.ros1 import message_stream_signature
        super().__init__({"s_axis": In(message_stream_signature(USER_BYTES)),
                          "received": Out(32), "messages": Out(32), "crc": Out(32)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.fcs = crc = Crc32(USER_BYTES)
        s = self.s_axis
        done = Signal()
        m.d.comb += [s.tready.eq(1), crc.data.eq(s.tdata), crc.count.eq(keep_count(s.tkeep)),
                     crc.valid.eq(s.tvalid), crc.clear.eq(done)]
        m.d.sync += done.eq(s.tvalid & s.tlast)
        with m.If(s.tvalid):
            m.d.sync += self.received.eq(self.received + keep_count(s.tkeep))
            with m.If(s.tlast):
                m.d.sync += self.messages.eq(self.messages + 1)
        with m.If(done):
            m.d.sync += self.crc.eq(crc.crc)
        return m


class Ros1BenchTop(wiring.Component):
    """The seed paper's measurement rig: a :class:`TcprosNode` with endpoints 0 subscriber
    (into a CRC sink: receive-only), 1 publisher (from a message generator: send-only),
    2 subscriber looped to 3 publisher (round trip), on a :class:`GmiiWordPeer` on the GMII
    clock ``gmii_clk``."""

    ENDPOINTS = ["subscriber", "publisher", "subscriber", "publisher"]

    def __init__(self, **stack):
        self._node = TcprosNode(self.ENDPOINTS, loopback=[(2, 3)], **stack)
        sig = AXIStreamSignature(8 * WORD_BYTES, keep=True)
        super().__init__({
            "gmii_clk": In(1), "peer_in": In(sig), "peer_out": Out(sig),
            "out_overflow": Out(16),
            "gen_start": In(1), "gen_length": In(32), "gen_prefix": In(8 * 64),
            "gen_prefix_len": In(7),
            "sink_received": Out(32), "sink_messages": Out(32), "sink_crc": Out(32),
            **{f"phase{k}": Out(range(len(PHASES))) for k in range(4)},
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.node = node = self._node
        peer = _gmii_peer(m, self.gmii_clk)
        m.submodules.gen = gen = _MessageSource()
        m.submodules.sink = sink = _MessageSink()
        _bridge(m, peer, node, self.gmii_clk)
        wiring.connect(m, wiring.flipped(self.peer_in), peer.peer_in)
        wiring.connect(m, peer.peer_out, wiring.flipped(self.peer_out))
        wiring.connect(m, node.sub0, sink.s_axis)
        wiring.connect(m, gen.m_axis, node.pub1)
        m.d.comb += [gen.start.eq(self.gen_start), gen.length.eq(self.gen_length),
                     gen.prefix.eq(self.gen_prefix), gen.prefix_len.eq(self.gen_prefix_len),
                     self.sink_received.eq(sink.received), self.sink_messages.eq(sink.messages),
                     self.sink_crc.eq(sink.crc), self.out_overflow.eq(peer.out_overflow)]
        for k in range(4):
            m.d.comb += getattr(self, f"phase{k}").eq(getattr(node, f"phase{k}"))
        return m
