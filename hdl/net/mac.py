"""GMII 8-bit Ethernet MAC, receive and transmit halves (docs/network.md)."""

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from ..stream import AXIStreamSignature, RegisterSlice
from .crc import Crc32
from .frames import IFG, MAX_FRAME, MIN_FRAME, PREAMBLE, SFD

__all__ = ["GmiiSignature", "GmiiRx", "GmiiTx", "RxByteSignature", "FrameStreamSignature",
           "FrameStatus"]

_PREAMBLE_BYTE = 0x55


class GmiiSignature(wiring.Signature):
    """GMII as the MAC sees it (``Out`` = towards the PHY).

    Members
    -------
    txd, tx_en, tx_er : Out
        Transmit byte, enable and error, one byte per 8 ns cycle, ``txd[0]`` first on the wire.
    rxd, rx_dv, rx_er : In
        Receive byte, data valid and error from the PHY. Nothing can hold the PHY back.
    """

    def __init__(self):
        super().__init__({
            "txd": Out(8), "tx_en": Out(1), "tx_er": Out(1),
            "rxd": In(8), "rx_dv": In(1), "rx_er": In(1),
        })


class RxByteSignature(wiring.Signature):
    """A received frame as the MAC hands it on: one byte per cycle, no backpressure.

    Members
    -------
    data : Out(8)
        The byte (destination MAC first; the FCS bytes come last).
    valid : Out(1)
        ``data`` is byte ``index`` of the current frame.
    index : Out(11)
        Position in the frame, saturating at 2047.
    end : Out(1)
        One-cycle pulse after the frame's last byte; ``ok`` and the ``err_*`` flags are valid.
    ok : Out(1)
        The frame is 64..1518 bytes, had no RX_ER and its FCS is correct.
    err_fcs, err_rx_er, err_size : Out(1)
        Why it is not ``ok`` (``err_size`` wins over ``err_rx_er`` wins over ``err_fcs``).
    """

    def __init__(self):
        super().__init__({
            "data": Out(8), "valid": Out(1), "index": Out(11), "end": Out(1), "ok": Out(1),
            "err_fcs": Out(1), "err_rx_er": Out(1), "err_size": Out(1),
        })


#: ``tuser`` of a frame stream's last byte: ``bad`` (the frame is not ``ok``) and why
#: (``err_fcs``, ``err_rx_er``, ``err_size``), as :class:`RxByteSignature` reports them
FrameStatus = data.StructLayout({"bad": 1, "err_fcs": 1, "err_rx_er": 1, "err_size": 1})


def FrameStreamSignature():
    """Whole frames as bytes, destination MAC to FCS, ``tlast`` on the last byte, whose
    ``tuser`` carries the frame's status (:data:`FrameStatus`)."""
    return AXIStreamSignature(8, keep=False, user_width=FrameStatus.size)


class GmiiRx(wiring.Component):
    """GMII receiver: finds the SFD after 0..7 preamble bytes, counts bytes, checks the FCS.

    GMII runs on the core clock here (a board with a separate RX clock puts an asynchronous
    FIFO in front). Noise before the SFD is ignored; a byte other than 0x55 before the SFD
    discards the burst.

    Members
    -------
    gmii_rxd, gmii_rx_dv, gmii_rx_er : In
        From the PHY; registered once inside.
    rx : Out(RxByteSignature())
        The frame's bytes and its end status.
    """

    def __init__(self):
        super().__init__({
            "gmii_rxd": In(8), "gmii_rx_dv": In(1), "gmii_rx_er": In(1),
            "rx": Out(RxByteSignature()),
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
                with m.Elif(dv & (rxd == _PREAMBLE_BYTE)):
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
                with m.Elif(rxd != _PREAMBLE_BYTE):
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
                m.d.comb += [en.eq(1), byte.eq(Mux(count == PREAMBLE, SFD, _PREAMBLE_BYTE)),
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
