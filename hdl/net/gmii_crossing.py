"""GMII receive bytes from a PHY's recovered clock onto a local clock of the same nominal
rate (docs/boards.md "Clocks")."""

from amaranth.hdl import Module, Signal
from amaranth.lib import data, wiring
from amaranth.lib.fifo import AsyncFIFO
from amaranth.lib.wiring import In, Out

from ..params import check_int

__all__ = ["GmiiRxCrossing"]


class _Entry(data.Struct):
    rxd: 8
    er: 1
    #: end of a frame (no byte); with ``er``: the frame lost bytes on the way in
    end: 1


class GmiiRxCrossing(wiring.Component):
    """Received GMII frames, moved from the PHY's receive clock (``i_domain``) to a local
    clock (``o_domain``) of the same nominal frequency, each within ±100 ppm (IEEE 802.3).

    A node whose ports all transmit on one local 125 MHz clock takes every port's receive
    side onto that clock with one of these. Only the bytes of a frame (``rx_dv`` high,
    with their ``rx_er``) and one end mark per frame cross; the idle gap between frames absorbs
    the clocks' difference. The local side starts a frame once ``prefill`` entries wait
    (with ±100 ppm each, a 1,522-byte frame drifts by less than half a byte) and then passes
    one entry per cycle, so a frame leaves as it came: contiguous, byte for byte.

    Nothing is silently lost: a frame that finds the crossing full (the local clock stopped
    or far too slow) is cut and its end leaves with ``rx_er``; a frame whose bytes do not
    arrive in time (the local clock far too fast) gets ``rx_er`` where a byte was missing.
    Either way the MAC drops that frame and the next one starts clean; ``overruns`` and
    ``underruns`` pulse once per such frame.

    Parameters
    ----------
    i_domain, o_domain : str
        The PHY's receive clock domain and the local one.
    depth : int
        Entries of the crossing, 8..64 (a power of two).
    prefill : int
        Entries that wait before a frame starts on the local side, 1..depth/2.

    Members
    -------
    rxd, rx_dv, rx_er : In
        From the PHY, on ``i_domain``.
    out_rxd, out_rx_dv, out_rx_er : Out
        To the MAC, on ``o_domain`` (registered).
    overruns : Out(1)
        Pulse on ``i_domain``: a frame was cut because the crossing was full.
    underruns : Out(1)
        Pulse on ``o_domain``: a frame's byte was not there in time.
    """

    def __init__(self, *, i_domain="gmii_rx", o_domain="sync", depth=16, prefill=4):
        self._i, self._o = i_domain, o_domain
        self._depth = check_int("depth", depth, 8, 64)
        if depth & (depth - 1):
            raise ValueError(f"depth={depth!r}: expected a power of two in 8..64")
        self._prefill = check_int("prefill", prefill, 1, depth // 2)
        super().__init__({"rxd": In(8), "rx_dv": In(1), "rx_er": In(1),
                          "out_rxd": Out(8), "out_rx_dv": Out(1), "out_rx_er": Out(1),
                          "overruns": Out(1), "underruns": Out(1)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.fifo = fifo = AsyncFIFO(width=_Entry.as_shape().size, depth=self._depth,
                                             r_domain=self._o, w_domain=self._i)
        wd = m.d[self._i]
        rd = m.d[self._o]

        # the PHY's side: a frame's bytes, then its end mark; a frame that finds the crossing
        # full is dropped from there on and its end mark says so
        w_entry = _Entry(fifo.w_data)
        in_frame = Signal()
        dropping = Signal()
        pending_end = Signal()
        pending_er = Signal()
        cut = Signal()
        end_now = in_frame & ~self.rx_dv                    # the gap after a frame
        mark_er = (pending_end & pending_er) | (end_now & dropping)
        wd += in_frame.eq(self.rx_dv)
        with m.If(pending_end | end_now):
            # a frame's end mark, in the gap after it; one that found no room waits, and a
            # byte arriving meanwhile cannot be written (a mark waiting when the next frame
            # ends ends both, with ``er`` if either lost bytes)
            m.d.comb += [w_entry.end.eq(1), w_entry.er.eq(mark_er), fifo.w_en.eq(1),
                         cut.eq(self.rx_dv)]
            wd += [pending_end.eq(~fifo.w_rdy), pending_er.eq(mark_er)]
        with m.Elif(self.rx_dv & ~dropping):
            m.d.comb += [w_entry.rxd.eq(self.rxd), w_entry.er.eq(self.rx_er),
                         fifo.w_en.eq(1), cut.eq(~fifo.w_rdy)]
        with m.If(end_now):
            wd += dropping.eq(0)
        with m.Elif(cut & ~dropping):
            wd += dropping.eq(1)
            m.d.comb += self.overruns.eq(1)

        # the local side: a frame starts once ``prefill`` entries wait, then one per cycle
        r_entry = _Entry(fifo.r_data)
        active = Signal()
        missing = Signal()
        rd += [self.out_rx_dv.eq(0), self.out_rx_er.eq(0)]
        with m.If(~active):
            with m.If(fifo.r_rdy & r_entry.end):
                m.d.comb += fifo.r_en.eq(1)                 # the mark of a frame already cut
            with m.Elif(fifo.r_level >= self._prefill):
                rd += active.eq(1)
        with m.Else():
            m.d.comb += fifo.r_en.eq(1)
            with m.If(~fifo.r_rdy):
                rd += [self.out_rx_dv.eq(1), self.out_rx_er.eq(1), missing.eq(1)]
                m.d.comb += self.underruns.eq(~missing)
            with m.Elif(r_entry.end):
                rd += [active.eq(0), missing.eq(0), self.out_rx_dv.eq(r_entry.er),
                       self.out_rx_er.eq(r_entry.er)]
            with m.Else():
                rd += [self.out_rxd.eq(r_entry.rxd), self.out_rx_dv.eq(1),
                       self.out_rx_er.eq(r_entry.er)]
        return m
