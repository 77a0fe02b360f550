"""Message-granular round-robin arbiter (docs/topics.md, defect D1 fixed)."""

from amaranth.hdl import Array, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int
from ..stream import check_stream_signature

__all__ = ["TopicArbiter"]


class TopicArbiter(wiring.Component):
    """Merges N publisher streams into one, a whole message at a time.

    Once a publisher's first beat is offered on ``m_axis``, that publisher keeps the grant until
    its ``tlast`` beat transfers: messages never interleave, whatever the publishers do with
    ``tvalid`` in the middle of a message (ReconROS's ``ARB_ON_TLAST = 0`` interconnect could
    switch mid-message, docs/topics.md D1). The grant is chosen combinationally, so the message
    after
    a ``tlast`` can start in the very next cycle. Round robin: the search for the next message
    starts after the publisher served last, so a publisher with a message waiting is served
    within N messages. Purely combinational datapath (zero latency); follow it with a
    :class:`~hdl.stream.RegisterSlice` to break the ``tready`` path.

    Parameters
    ----------
    signature : AXIStreamSignature
        Stream format of all ports.
    pubs : int
        Number of input streams, 2..16.

    Members
    -------
    s_axis : In(signature).array(pubs)
        Publisher streams.
    m_axis : Out(signature)
        Merged stream.
    grant : Out(range(pubs))
        The publisher currently selected.
    locked : Out(1)
        A message is in progress (the grant is held).
    """

    def __init__(self, signature, pubs):
        check_stream_signature(signature)
        check_int("pubs", pubs, 2, 16)
        self._stream = signature
        self._pubs = pubs
        super().__init__({
            "s_axis": In(signature).array(pubs),
            "m_axis": Out(signature),
            "grant": Out(range(pubs)),
            "locked": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        n = self._pubs
        sig = self._stream

        valid = Signal(n)
        for i, s in enumerate(self.s_axis):
            m.d.comb += valid[i].eq(s.tvalid)

        last = Signal(range(n), init=n - 1)  # publisher whose message ended last
        held = Signal(range(n))
        after_last = Signal(n)
        for i in range(n):
            m.d.comb += after_last[i].eq(valid[i] & (last < i) if i else 0)

        def lowest_set(bits, index):
            for i in reversed(range(n)):
                with m.If(bits[i]):
                    m.d.comb += index.eq(i)

        first_after, first_any = Signal(range(n)), Signal(range(n))
        lowest_set(after_last, first_after)
        lowest_set(valid, first_any)
        sel = Signal(range(n))
        m.d.comb += [
            sel.eq(Mux(self.locked, held,
                       Mux(after_last.any(), first_after, first_any))),
            self.grant.eq(sel),
        ]

        for name in sig.payload_members + ("tvalid",):
            m.d.comb += getattr(self.m_axis, name).eq(
                Array(getattr(s, name) for s in self.s_axis)[sel])
        for i, s in enumerate(self.s_axis):
            m.d.comb += s.tready.eq((sel == i) & self.m_axis.tready)

        with m.If(self.m_axis.tvalid):
            with m.If(self.m_axis.tready & self.m_axis.tlast):
                m.d.sync += [self.locked.eq(0), last.eq(sel)]
            with m.Else():
                m.d.sync += [self.locked.eq(1), held.eq(sel)]
        return m
