"""Traffic counters for one AXI4-Stream port."""

from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int

__all__ = ["StreamMonitorSignature", "StreamMonitor"]


class StreamMonitorSignature(wiring.Signature):
    """Counters of one stream port, seen from the counting side (``Out``).

    Members
    -------
    messages : Out(counter_width)
        Beats transferred with ``tlast`` set.
    beats : Out(counter_width)
        Beats transferred (``tvalid & tready``).
    stalls : Out(counter_width)
        Cycles with ``tvalid & ~tready``: the transmitter waited on the receiver.
    """

    def __init__(self, counter_width=32):
        check_int("counter_width", counter_width, 1, 64)
        self._counter_width = counter_width
        super().__init__({name: Out(counter_width) for name in ("messages", "beats", "stalls")})

    counter_width = property(lambda self: self._counter_width)

    def __eq__(self, other):
        return type(other) is type(self) and other._counter_width == self._counter_width

    def __hash__(self):
        return hash((type(self), self._counter_width))

    def __repr__(self):
        return f"StreamMonitorSignature({self._counter_width})"


class StreamMonitor(wiring.Component):
    """Counts messages, beats and stall cycles on a stream port it only observes.

    Counters reset with the domain and wrap.

    Members
    -------
    tvalid, tready, tlast : In(1)
        The observed handshake and ``tlast``.
    counters : Out(StreamMonitorSignature(counter_width))
        The counts.
    """

    def __init__(self, counter_width=32):
        super().__init__({
            "tvalid": In(1), "tready": In(1), "tlast": In(1),
            "counters": Out(StreamMonitorSignature(counter_width)),
        })

    def elaborate(self, platform):
        m = Module()
        c = self.counters
        with m.If(self.tvalid & self.tready):
            m.d.sync += c.beats.eq(c.beats + 1)
            with m.If(self.tlast):
                m.d.sync += c.messages.eq(c.messages + 1)
        with m.If(self.tvalid & ~self.tready):
            m.d.sync += c.stalls.eq(c.stalls + 1)
        return m
