"""Lock-step broadcast of one stream to M subscribers (docs/topics.md)."""

from amaranth.hdl import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int
from ..stream import check_stream_signature

__all__ = ["TopicBroadcast"]


class TopicBroadcast(wiring.Component):
    """Copies every beat of ``s_axis`` to every ``m_axis[j]`` (QoS Keep All + Reliable).

    All outputs share the input's payload; a per-output flag remembers which subscribers have
    taken the current beat, so subscribers may accept it in different cycles. The input beat is
    consumed once every subscriber has it; the slowest subscriber back-pressures the topic.
    No storage, no latency. ``s_axis.tready`` depends combinationally on every
    ``m_axis[j].tready``, so feed it from a :class:`~hdl.stream.RegisterSlice`.

    Parameters
    ----------
    signature : AXIStreamSignature
        Stream format of all ports.
    subs : int
        Number of outputs, 2..16.

    Members
    -------
    s_axis : In(signature)
        Input stream.
    m_axis : Out(signature).array(subs)
        Subscriber streams, each carrying every input beat once, in order.
    """

    def __init__(self, signature, subs):
        check_stream_signature(signature)
        check_int("subs", subs, 2, 16)
        self._stream = signature
        self._subs = subs
        super().__init__({"s_axis": In(signature), "m_axis": Out(signature).array(subs)})

    def elaborate(self, platform):
        m = Module()
        sig = self._stream
        taken = Signal(self._subs)
        accept = Signal(self._subs)
        for j, out in enumerate(self.m_axis):
            m.d.comb += sig.copy_payload(out, self.s_axis)
            m.d.comb += [
                out.tvalid.eq(self.s_axis.tvalid & ~taken[j]),
                accept[j].eq(taken[j] | out.tready),
            ]
        m.d.comb += self.s_axis.tready.eq(accept.all())
        with m.If(self.s_axis.tvalid):
            with m.If(accept.all()):
                m.d.sync += taken.eq(0)
            with m.Else():
                m.d.sync += taken.eq(accept)
        return m
