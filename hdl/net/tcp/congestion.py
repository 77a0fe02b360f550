"""Congestion control of a TCP session, counted in segments (docs/network.md "TCP
session"; RFC 5681)."""

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ...params import check_power_of_two
from .codes import INITIAL_WINDOW

__all__ = ["TcpCongestionControl"]


class TcpCongestionControl(wiring.Component):
    """RFC 5681 in segments, as Linux counts it.

    The transmit ring already knows how many segments are in flight, so the window needs no
    byte arithmetic. The initial window is ``INITIAL_WINDOW`` segments; slow start adds one
    per new ACK, congestion avoidance one per window; the third duplicate ACK halves the
    segments in flight (at least 2) into ``ssthresh``, asks for a fast retransmit and sets
    the window to ``ssthresh + 3``; every further duplicate ACK inflates it by one. A
    retransmission timeout halves likewise and restarts from one segment. The window never
    exceeds the ring (``descriptors - 1`` segments).

    Parameters
    ----------
    descriptors : int
        Segments of the transmit ring, a power of two in 4..256.

    Members
    -------
    in_flight : In(range(descriptors))
        Segments sent and not yet acknowledged.
    reset : In(1)
        A new connection (wins over the events below).
    new_ack : In(1)
        An ACK acknowledged new data.
    dup_ack : In(1)
        A duplicate ACK (RFC 5681 §2: no data, no window change, data outstanding).
    timeout : In(1)
        The retransmission timer expired.
    cwnd : Out(range(descriptors))
        Segments that may be in flight.
    fast_retransmit : Out(1)
        This ``dup_ack`` is the third: resend from SND.UNA.
    """

    def __init__(self, *, descriptors=64):
        self._descriptors = check_power_of_two("descriptors", descriptors, 4, 256)
        super().__init__({
            "in_flight": In(range(descriptors)),
            "reset": In(1), "new_ack": In(1), "dup_ack": In(1), "timeout": In(1),
            "cwnd": Out(range(descriptors), init=INITIAL_WINDOW), "fast_retransmit": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        nd = self._descriptors
        cwnd = self.cwnd
        ssthresh = Signal(range(nd), init=nd - 1)
        grown_in_window = Signal(range(nd))
        dupacks = Signal(2)

        half_flight = self.in_flight[1:]
        reduced = Mux(half_flight < 2, 2, half_flight)
        grown = Mux(cwnd == nd - 1, cwnd, cwnd + 1)
        inflated = Signal(range(nd + 3))
        m.d.comb += inflated.eq(reduced + 3)
        # with 8 or more descriptors ssthresh + 3 always fits, and the comparison would be
        # constant
        most_inflated = max(2, (nd - 1) // 2) + 3
        inflated_cwnd = (Mux(inflated > nd - 1, nd - 1, inflated) if most_inflated > nd - 1
                         else inflated)
        m.d.comb += self.fast_retransmit.eq(self.dup_ack & (dupacks == 2))

        with m.If(self.reset):
            m.d.sync += [cwnd.eq(INITIAL_WINDOW), ssthresh.eq(nd - 1),
                         grown_in_window.eq(0), dupacks.eq(0)]
        with m.Elif(self.new_ack):
            m.d.sync += dupacks.eq(0)
            with m.If(cwnd < ssthresh):
                m.d.sync += cwnd.eq(grown)
            with m.Elif(grown_in_window + 1 >= cwnd):
                m.d.sync += [grown_in_window.eq(0), cwnd.eq(grown)]
            with m.Else():
                m.d.sync += grown_in_window.eq(grown_in_window + 1)
        with m.Elif(self.dup_ack):
            m.d.sync += dupacks.eq(Mux(dupacks == 3, 3, dupacks + 1))
            with m.If(dupacks == 2):
                m.d.sync += [ssthresh.eq(reduced), cwnd.eq(inflated_cwnd)]
            with m.If(dupacks == 3):
                m.d.sync += cwnd.eq(grown)
        with m.Elif(self.timeout):
            m.d.sync += [cwnd.eq(1), grown_in_window.eq(0), dupacks.eq(0),
                         ssthresh.eq(reduced)]
        return m
