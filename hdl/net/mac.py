"""GMII 8-bit Ethernet MAC, receive and transmit halves (docs/network.md)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import data, wiring
from amaranth.lib.fifo import AsyncFIFO
from amaranth.lib.wiring import In, Out

from ..params import check_int
from ..stream import AXIStreamSignature, RegisterSlice
from .crc import Crc32
from .frames import IFG, MAX_FRAME, MIN_FRAME, PREAMBLE, PREAMBLE_BYTE, SFD

__all__ = ["GmiiSignature", "GmiiRx", "GmiiTx", "RxBeatSignature", "FrameStreamSignature",
           "FrameStatus", "RxBeatBridge", "TxBeatBridge", "GMII_HZ", "DEFAULT_CLOCK_HZ"]

#: the GMII byte clock
GMII_HZ = 125_000_000
#: the core clock by lanes: GMII's own with one byte per cycle, half of it with two (the
#: slowest that carries the line rate through an :class:`RxBeatBridge`)
DEFAULT_CLOCK_HZ = {1: GMII_HZ, 2: GMII_HZ // 2}



class GmiiSignature(wiring.Signature):
    """GMII as the MAC sees it (``Out`` = towards the PHY).

    Parameters
    ----------
    clocks : bool
        The port brings its own clocks (a MAC whose core runs on another clock); without
        them it runs on the core clock.

    Members
    -------
    txd, tx_en, tx_er : Out
        Transmit byte, enable and error, one byte per 8 ns cycle, ``txd[0]`` first on the wire.
    rxd, rx_dv, rx_er : In
        Receive byte, data valid and error from the PHY. Nothing can hold the PHY back.
    rx_clk, tx_clk : In(1), with ``clocks``
        The PHY's receive clock (RX_CLK) and the 125 MHz transmit clock (forwarded to the PHY
        as GTX_CLK).
    """

    def __init__(self, *, clocks=False):
        self._clocks = bool(clocks)
        super().__init__({
            "txd": Out(8), "tx_en": Out(1), "tx_er": Out(1),
            "rxd": In(8), "rx_dv": In(1), "rx_er": In(1),
            **({"rx_clk": In(1), "tx_clk": In(1)} if clocks else {}),
        })

    clocks = property(lambda self: self._clocks)

    def __eq__(self, other):
        return type(other) is type(self) and other._clocks == self._clocks

    def __hash__(self):
        return hash((type(self), self._clocks))


class RxBeatSignature(wiring.Signature):
    """A received frame as the MAC hands it on: ``lanes`` bytes per cycle, no backpressure.

    Parameters
    ----------
    lanes : int
        Bytes per beat, 1 (GMII's byte per cycle) or 2 (two bytes per cycle of a core clock
        at half the GMII clock, from an :class:`RxBeatBridge`).

    Members
    -------
    data : Out(8 * lanes)
        Bytes ``index`` .. ``index + lanes - 1`` of the frame, byte ``index`` in bits 0..7
        (destination MAC first; the FCS bytes come last). The frame's last beat may hold
        fewer: its bytes beyond the frame's length (``index`` at ``end``) mean nothing.
    valid : Out(1)
        ``data`` is the beat at ``index``.
    index : Out(11)
        Position of the beat's first byte in the frame, a multiple of ``lanes``, saturating
        at ``2048 - lanes``; with ``end``, the frame's length in bytes.
    end : Out(1)
        One-cycle pulse after the frame's last beat; ``ok`` and the ``err_*`` flags are valid.
    ok : Out(1)
        The frame is 64..1518 bytes, had no RX_ER and its FCS is correct.
    err_fcs, err_rx_er, err_size : Out(1)
        Why it is not ``ok`` (``err_size`` wins over ``err_rx_er`` wins over ``err_fcs``).
    """

    def __init__(self, lanes=1):
        self._lanes = check_int("lanes", lanes, 1, 2)
        super().__init__({
            "data": Out(8 * lanes), "valid": Out(1), "index": Out(11), "end": Out(1),
            "ok": Out(1), "err_fcs": Out(1), "err_rx_er": Out(1), "err_size": Out(1),
        })

    lanes = property(lambda self: self._lanes)

    def __eq__(self, other):
        return type(other) is type(self) and other._lanes == self._lanes

    def __hash__(self):
        return hash((type(self), self._lanes))


#: ``tuser`` of a frame stream's last byte: ``bad`` (the frame is not ``ok``) and why
#: (``err_fcs``, ``err_rx_er``, ``err_size``), as :class:`RxBeatSignature` reports them
FrameStatus = data.StructLayout({"bad": 1, "err_fcs": 1, "err_rx_er": 1, "err_size": 1})


def FrameStreamSignature(lanes=1):
    """Whole frames as beats of ``lanes`` bytes, destination MAC to FCS, ``tlast`` on the
    last beat (with 2 lanes ``tkeep`` 0b01 when it holds one byte), whose ``tuser`` carries
    the frame's status (:data:`FrameStatus`)."""
    return AXIStreamSignature(8 * lanes, keep=lanes > 1, user_width=FrameStatus.size)


class GmiiRx(wiring.Component):
    """GMII receiver: finds the SFD after 0..7 preamble bytes, counts bytes, checks the FCS.

    It runs on the GMII clock (an :class:`RxBeatBridge` takes its bytes to a core clock).
    Noise before the SFD is ignored; a byte other than 0x55 before the SFD discards the
    burst.

    Members
    -------
    gmii_rxd, gmii_rx_dv, gmii_rx_er : In
        From the PHY; registered once inside.
    rx : Out(RxBeatSignature(1))
        The frame's bytes and its end status.
    """

    def __init__(self):
        super().__init__({
            "gmii_rxd": In(8), "gmii_rx_dv": In(1), "gmii_rx_er": In(1),
            "rx": Out(RxBeatSignature(1)),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.fcs = crc = Crc32(1)
        rxd = Signal(8)
        dv = Signal()
        er = Signal()
        m.d.sync += [rxd.eq(self.gmii_rxd), dv.eq(self.gmii_rx_dv), er.eq(self.gmii_rx_er)]

        count = Signal(range(2048))
        er_seen = Signal()
        m.d.comb += [crc.data.eq(rxd), self.rx.data.eq(rxd), self.rx.index.eq(count)]
        m.d.sync += self.rx.end.eq(0)

        size_bad = (count < MIN_FRAME) | (count > MAX_FRAME)
        with m.FSM():
            with m.State("IDLE"):
                with m.If(dv & (rxd == SFD)):
                    m.d.comb += crc.clear.eq(1)
                    m.d.sync += [count.eq(0), er_seen.eq(er)]
                    m.next = "DATA"
                with m.Elif(dv & (rxd == PREAMBLE_BYTE)):
                    m.next = "PREAMBLE"
                with m.Elif(dv):
                    m.next = "DISCARD"
            with m.State("PREAMBLE"):
                with m.If(~dv):
                    m.next = "IDLE"
                with m.Elif(rxd == SFD):
                    m.d.comb += crc.clear.eq(1)
                    m.d.sync += [count.eq(0), er_seen.eq(er)]
                    m.next = "DATA"
                with m.Elif(rxd != PREAMBLE_BYTE):
                    m.next = "DISCARD"
            with m.State("DATA"):
                with m.If(dv):
                    m.d.comb += [self.rx.valid.eq(1), crc.valid.eq(1)]
                    m.d.sync += [count.eq(Mux(count == 2047, count, count + 1)),
                                 er_seen.eq(er_seen | er)]
                with m.Else():
                    m.d.sync += [
                        self.rx.end.eq(1),
                        self.rx.ok.eq(~size_bad & ~er_seen & crc.residue_ok),
                        self.rx.err_size.eq(size_bad),
                        self.rx.err_rx_er.eq(~size_bad & er_seen),
                        self.rx.err_fcs.eq(~size_bad & ~er_seen & ~crc.residue_ok),
                    ]
                    m.next = "IDLE"
            with m.State("DISCARD"):
                with m.If(~dv):
                    m.next = "IDLE"
        return m


class GmiiTx(wiring.Component):
    """GMII transmitter: preamble and SFD, the frame, zero padding to 60 bytes, the FCS and
    at least 12 idle byte times.

    Members
    -------
    s_axis : In(AXIStreamSignature(8, keep=False))
        One frame per message, from the destination MAC to the end of the payload, through a
        register slice (``tready`` comes from a flip-flop; the slice takes a frame's first
        two bytes while the preamble goes out). Once the frame's bytes leave the slice,
        from the end of the preamble, the source must offer a byte every cycle. A missing
        byte (underrun) is sent with ``gmii_tx_er`` set, which makes the PHY corrupt the
        frame, and counts in ``underruns``.
    gmii_txd, gmii_tx_en, gmii_tx_er : Out
        To the PHY, registered.
    r_axis : In(FrameStreamSignature()), with ``raw``
        Whole frames to repeat as they are, destination MAC to FCS (no padding, no FCS
        added), from a :class:`~hdl.net.queue.FrameQueue`; a last byte whose status
        (:data:`FrameStatus`) is ``bad`` is sent with ``gmii_tx_er``, so the next receiver drops the
        frame. Served before ``s_axis`` when both wait. The same no-gap rule applies.
    frames : Out(32)
        Frames sent.
    underruns : Out(16)
        Frames sent with ``gmii_tx_er``.

    Parameters
    ----------
    raw : bool
        Add the ``r_axis`` input (a node that forwards frames between two ports).
    """

    def __init__(self, *, raw=False):
        self._raw = bool(raw)
        members = {
            "s_axis": In(AXIStreamSignature(8, keep=False)),
            "gmii_txd": Out(8), "gmii_tx_en": Out(1), "gmii_tx_er": Out(1),
            "frames": Out(32), "underruns": Out(16),
        }
        if raw:
            members["r_axis"] = In(FrameStreamSignature())
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        m.submodules.fcs = crc = Crc32(1)
        # the slice keeps the source's byte selection out of the FCS and the source's
        # progress out of this state machine
        m.submodules.slice = slice_ = RegisterSlice(AXIStreamSignature(8, keep=False))
        wiring.connect(m, wiring.flipped(self.s_axis), slice_.s_axis)
        s_axis = slice_.m_axis
        count = Signal(range(2048))
        underrun = Signal()
        byte = Signal(8)
        en = Signal()
        err = Signal()
        m.d.sync += [self.gmii_txd.eq(byte), self.gmii_tx_en.eq(en), self.gmii_tx_er.eq(err)]
        m.d.comb += crc.data.eq(byte)
        fcs_byte = Signal(2)

        raw = Signal()              # the frame being sent comes from r_axis
        with m.FSM():
            with m.State("IDLE"):
                if self._raw:
                    with m.If(self.r_axis.tvalid):
                        m.d.sync += [count.eq(0), raw.eq(1)]
                        m.next = "PREAMBLE"
                    with m.Elif(s_axis.tvalid):
                        m.d.sync += [count.eq(0), raw.eq(0)]
                        m.next = "PREAMBLE"
                else:
                    with m.If(s_axis.tvalid):
                        m.d.sync += count.eq(0)
                        m.next = "PREAMBLE"
            with m.State("PREAMBLE"):
                m.d.comb += [en.eq(1), byte.eq(Mux(count == PREAMBLE, SFD, PREAMBLE_BYTE)),
                             crc.clear.eq(1)]
                m.d.sync += count.eq(count + 1)
                with m.If(count == PREAMBLE):
                    m.d.sync += [count.eq(0), underrun.eq(0), fcs_byte.eq(0)]
                    m.next = "RAW" if self._raw else "DATA"
                    if self._raw:
                        with m.If(~raw):
                            m.next = "DATA"
            if self._raw:
                with m.State("RAW"):
                    r = self.r_axis
                    m.d.comb += [en.eq(1), r.tready.eq(1), byte.eq(r.tdata),
                                 err.eq(~r.tvalid | (r.tlast & FrameStatus(r.tuser).bad))]
                    with m.If(~r.tvalid):
                        m.d.sync += underrun.eq(1)
                    with m.Elif(r.tlast):
                        m.d.sync += [count.eq(0), self.frames.eq(self.frames + 1)]
                        with m.If(underrun):
                            m.d.sync += self.underruns.eq(self.underruns + 1)
                        m.next = "GAP"
            with m.State("DATA"):
                m.d.comb += [en.eq(1), s_axis.tready.eq(1), byte.eq(s_axis.tdata),
                             crc.valid.eq(1), err.eq(~s_axis.tvalid)]
                m.d.sync += count.eq(count + 1)
                with m.If(~s_axis.tvalid):
                    m.d.sync += underrun.eq(1)
                with m.Elif(s_axis.tlast):
                    with m.If(count + 1 < MIN_FRAME - 4):
                        m.next = "PAD"
                    with m.Else():
                        m.next = "FCS"
            with m.State("PAD"):
                m.d.comb += [en.eq(1), byte.eq(0), crc.valid.eq(1)]
                m.d.sync += count.eq(count + 1)
                with m.If(count + 1 == MIN_FRAME - 4):
                    m.next = "FCS"
            with m.State("FCS"):
                m.d.comb += [en.eq(1), err.eq(underrun), byte.eq(crc.crc.word_select(fcs_byte, 8))]
                m.d.sync += fcs_byte.eq(fcs_byte + 1)
                with m.If(fcs_byte == 3):
                    m.d.sync += [count.eq(0), self.frames.eq(self.frames + 1)]
                    with m.If(underrun):
                        m.d.sync += self.underruns.eq(self.underruns + 1)
                    m.next = "GAP"
            with m.State("GAP"):
                m.d.sync += count.eq(count + 1)
                with m.If(count == IFG - 1):
                    m.next = "IDLE"
        return m


#: entries a bridge's asynchronous FIFO holds
BRIDGE_DEPTH = 16


class RxBeatBridge(wiring.Component):
    """Received frames from the GMII clock to the core clock, two bytes per beat.

    A :class:`GmiiRx`'s bytes (domain ``gmii_domain``) are paired into beats and cross an
    asynchronous FIFO (Gray-coded pointers, :class:`amaranth.lib.fifo.AsyncFIFO`); on the
    core clock (``sync``) they come out as an :class:`RxBeatSignature` of 2 lanes, every
    member from a flip-flop. The core clock must be at least half the GMII clock: a frame
    of N bytes arrives in N + 20 GMII cycles (with preamble and gap) and leaves in N / 2 + 2
    core cycles. Should the FIFO still fill (a slower core clock), the frame loses its
    remaining bytes and ends as an RX error (``ok`` low, ``err_rx_er``), so it is dropped
    and counted; a frame that starts while the lost frame's end waits is dropped whole.

    Parameters
    ----------
    gmii_domain : str
        The GMII receive clock's domain.

    Members
    -------
    gmii : In(RxBeatSignature(1))
        From the :class:`GmiiRx`, in ``gmii_domain``.
    rx : Out(RxBeatSignature(2))
        On the core clock.
    """

    def __init__(self, *, gmii_domain="gmii"):
        self._domain = gmii_domain
        super().__init__({"gmii": In(RxBeatSignature(1)), "rx": Out(RxBeatSignature(2))})

    def elaborate(self, platform):
        m = Module()
        g = m.d[self._domain]
        entry = data.StructLayout({"data": 16, "beat": 1, "end": 1, "length": 11,
                                   "ok": 1, "err_fcs": 1, "err_rx_er": 1, "err_size": 1})
        m.submodules.fifo = fifo = AsyncFIFO(width=entry.size, depth=BRIDGE_DEPTH,
                                             w_domain=self._domain, r_domain="sync")
        i = self.gmii
        # write side: a beat is written when its second byte arrives, the last beat with
        # the end (the partial beat of an odd length, or none)
        low = Signal(8)
        odd = Signal()                  # ``low`` holds a byte waiting for its pair
        lost = Signal()                 # this frame has lost bytes: drop the rest
        end_waits = Signal()            # the lost frame's end waits for room
        skip = Signal()                 # a frame that started while an end waited
        # the frame's first byte (index 0) from a flag rather than the 11-bit index: the
        # receive clock's longest path runs from here into the FIFO's write pointer
        in_frame = Signal()
        first = ~in_frame
        with m.If(i.end):
            g += in_frame.eq(0)
        with m.Elif(i.valid):
            g += in_frame.eq(1)
        w = Signal(entry)
        held = Signal(entry)
        m.d.comb += fifo.w_data.eq(Mux(end_waits, held, w))
        with m.If(end_waits):
            m.d.comb += fifo.w_en.eq(1)
            with m.If(fifo.w_rdy):
                g += end_waits.eq(0)
            with m.If(i.valid & first):
                g += skip.eq(1)
        with m.Elif(i.valid & (first | (~skip & ~lost))):
            g += skip.eq(0)
            with m.If(i.index[0]):
                m.d.comb += [w.data.eq(Cat(low, i.data)), w.beat.eq(1), fifo.w_en.eq(1)]
                g += odd.eq(0)
                with m.If(~fifo.w_rdy):
                    g += lost.eq(1)
            with m.Else():
                g += [low.eq(i.data), odd.eq(1)]
                with m.If(first):
                    g += lost.eq(0)
        with m.Elif(i.end & ~skip):
            m.d.comb += [w.data.eq(Cat(low, Const(0, 8))), w.beat.eq(odd & ~lost), w.end.eq(1),
                         w.length.eq(i.index), w.ok.eq(i.ok & ~lost),
                         w.err_fcs.eq(i.err_fcs & ~lost), w.err_size.eq(i.err_size),
                         w.err_rx_er.eq((i.err_rx_er | lost) & ~i.err_size),
                         fifo.w_en.eq(1)]
            g += [odd.eq(0), lost.eq(0)]
            with m.If(~fifo.w_rdy):
                g += [held.eq(w), end_waits.eq(1)]
        with m.Elif(i.end):
            g += skip.eq(0)

        # read side: one entry a cycle; an entry with a beat and the end gives the beat,
        # then the end
        o = self.rx
        r = Signal(entry)
        m.d.comb += r.eq(fifo.r_data)
        count = Signal(11)
        end_next = Signal()
        last = Signal(entry)
        m.d.sync += [o.valid.eq(0), o.end.eq(0)]

        def finish(e):
            return [o.end.eq(1), o.index.eq(e.length), o.ok.eq(e.ok), o.err_fcs.eq(e.err_fcs),
                    o.err_rx_er.eq(e.err_rx_er), o.err_size.eq(e.err_size), count.eq(0)]

        with m.If(end_next):
            m.d.sync += finish(last) + [end_next.eq(0)]
        with m.Elif(fifo.r_rdy):
            m.d.comb += fifo.r_en.eq(1)
            with m.If(r.beat):
                m.d.sync += [o.valid.eq(1), o.data.eq(r.data), o.index.eq(count),
                             count.eq(Mux(count == 2046, count, count + 2))]
                with m.If(r.end):
                    m.d.sync += [end_next.eq(1), last.eq(r)]
            with m.Elif(r.end):
                m.d.sync += finish(r)
        return m


class TxBeatBridge(wiring.Component):
    """Frames to send, from the core clock to the GMII clock: two-byte beats in, bytes out.

    Beats (``sync``) cross an asynchronous FIFO and leave byte by byte, lane 0 first, in
    ``gmii_domain`` for a :class:`GmiiTx`. Once a frame's first beat has been taken its
    beats must follow one per core cycle, with a core clock at least half the GMII clock:
    the transmitter sends the preamble while the FIFO fills, and then never waits (a
    :class:`FrameBuilder` keeps this rule).

    Parameters
    ----------
    gmii_domain : str
        The GMII transmit clock's domain.

    Members
    -------
    s_axis : In(AXIStreamSignature(16))
        Frames, ``tkeep`` 0b01 only on a last beat (frames of odd length).
    gmii : Out(AXIStreamSignature(8, keep=False))
        The frames' bytes, in ``gmii_domain``.
    """

    def __init__(self, *, gmii_domain="gmii"):
        self._domain = gmii_domain
        super().__init__({"s_axis": In(AXIStreamSignature(16)),
                          "gmii": Out(AXIStreamSignature(8, keep=False))})

    def elaborate(self, platform):
        m = Module()
        g = m.d[self._domain]
        sig = AXIStreamSignature(16)
        m.submodules.fifo = fifo = AsyncFIFO(width=sig.payload_width, depth=BRIDGE_DEPTH,
                                             w_domain="sync", r_domain=self._domain)
        s = self.s_axis
        m.d.comb += [fifo.w_data.eq(sig.pack(s)), fifo.w_en.eq(s.tvalid),
                     s.tready.eq(fifo.w_rdy)]
        beat = Signal(16)
        second = Signal()               # lane 1 of the beat in ``beat`` is still to leave
        last = Signal()
        r = sig.flip().create()
        m.d.comb += sig.unpack(r, fifo.r_data)
        o = self.gmii
        m.d.comb += [o.tvalid.eq(second | fifo.r_rdy),
                     o.tdata.eq(Mux(second, beat[8:], r.tdata[:8])),
                     o.tlast.eq(Mux(second, last, r.tlast & ~r.tkeep[1]))]
        with m.If(second):
            with m.If(o.tready):
                g += second.eq(0)
        with m.Elif(fifo.r_rdy & o.tready):
            m.d.comb += fifo.r_en.eq(1)
            g += [beat.eq(r.tdata), second.eq(r.tkeep[1]), last.eq(r.tlast)]
        return m
