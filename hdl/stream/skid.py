"""Register slices: break every combinational path of an AXI4-Stream or an
``amaranth.lib.stream`` link, or (:class:`ReadyRegisterSlice`) only the ready path."""

from amaranth.hdl import Module, Mux, Shape, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from .signature import check_stream_signature

__all__ = ["PayloadRegisterSlice", "ReadyRegisterSlice", "RegisterSlice", "skid_buffer",
           "ready_skid"]


def skid_buffer(m, width, i_valid, i_ready, i_payload, o_valid, o_ready, o_payload):
    """Add to ``m`` a full-throughput skid buffer between a valid/ready input and output of
    ``width`` payload bits: ``o_valid``, ``o_payload`` and ``i_ready`` come from flip-flops
    (``o_valid`` must be a plain signal the function may drive in ``m.d.sync``)."""
    # Payload registers need no reset: nothing reads them while the output valid is low.
    skid = Signal(width, reset_less=True)
    out = Signal(width, reset_less=True)
    skid_valid = Signal()
    m.d.comb += [i_ready.eq(~skid_valid), o_payload.eq(out)]
    with m.If(~o_valid | o_ready):
        with m.If(skid_valid):
            m.d.sync += [out.eq(skid), o_valid.eq(1), skid_valid.eq(0)]
        with m.Else():
            m.d.sync += [out.eq(i_payload), o_valid.eq(i_valid)]
    with m.Elif(i_valid & ~skid_valid):
        m.d.sync += [skid.eq(i_payload), skid_valid.eq(1)]


def ready_skid(m, width, i_valid, i_ready, i_payload, o_valid, o_ready, o_payload):
    """Add to ``m`` half a skid buffer: ``i_ready`` comes from a flip-flop, ``o_valid`` and
    ``o_payload`` pass through while it is empty (no cycle of latency). A payload offered
    while the output is not ready is held and offered from there until taken; meanwhile
    ``i_ready`` is low."""
    held = Signal(width, reset_less=True)
    held_valid = Signal()
    m.d.comb += [i_ready.eq(~held_valid), o_valid.eq(held_valid | i_valid),
                 o_payload.eq(Mux(held_valid, held, i_payload))]
    with m.If(held_valid):
        with m.If(o_ready):
            m.d.sync += held_valid.eq(0)
    with m.Elif(i_valid & ~o_ready):
        m.d.sync += [held.eq(i_payload), held_valid.eq(1)]


class RegisterSlice(wiring.Component):
    """Full-throughput AXI4-Stream register slice (skid buffer).

    ``m_axis`` payload and ``tvalid`` come from flip-flops, and so does ``s_axis.tready``;
    no combinational path crosses the slice. It moves one beat per cycle in steady state, adds
    one cycle of latency, and holds at most two beats.

    With ``ready_only``, only ``s_axis.tready`` comes from a flip-flop (as
    :class:`ReadyRegisterSlice`): beats pass straight through while the slice is empty, no
    cycle of latency; the consumer's ready reaches only the slice.

    Parameters
    ----------
    signature : AXIStreamSignature
        Stream format of both ports.
    ready_only : bool
        Break only the ready path.

    Members
    -------
    s_axis : In(signature)
        Input stream.
    m_axis : Out(signature)
        Output stream, the same beats in the same order.
    """

    def __init__(self, signature, *, ready_only=False):
        check_stream_signature(signature)
        self._stream = signature
        self._ready_only = bool(ready_only)
        super().__init__({"s_axis": In(signature), "m_axis": Out(signature)})

    def elaborate(self, platform):
        m = Module()
        sig = self._stream
        out = Signal(sig.payload_width)
        m.d.comb += sig.unpack(self.m_axis, out)
        (ready_skid if self._ready_only else skid_buffer)(
            m, sig.payload_width, self.s_axis.tvalid, self.s_axis.tready,
            sig.pack(self.s_axis), self.m_axis.tvalid, self.m_axis.tready, out)
        return m


class PayloadRegisterSlice(wiring.Component):
    """:class:`RegisterSlice` for an ``amaranth.lib.stream`` link (``valid``, ``ready``,
    ``payload``): every output and ``i.ready`` from flip-flops, one transfer per cycle, one
    cycle of latency.

    Parameters
    ----------
    payload_shape : ShapeLike
        Shape of the payload.

    Members
    -------
    i : In(stream.Signature(payload_shape))
    o : Out(stream.Signature(payload_shape))
        The same payloads in the same order.
    """

    def __init__(self, payload_shape):
        self._shape = payload_shape
        super().__init__({"i": In(stream.Signature(payload_shape)),
                          "o": Out(stream.Signature(payload_shape))})

    def elaborate(self, platform):
        m = Module()
        width = Shape.cast(self._shape).width
        skid_buffer(m, width, self.i.valid, self.i.ready, self.i.payload.as_value(),
                     self.o.valid, self.o.ready, self.o.payload.as_value())
        return m


class ReadyRegisterSlice(PayloadRegisterSlice):
    """Half a :class:`PayloadRegisterSlice`: ``i.ready`` comes from a flip-flop, ``o.valid``
    and ``o.payload`` pass through while the slice is empty. No cycle of latency; one transfer
    per cycle. Parameters and members as :class:`PayloadRegisterSlice`.

    A payload offered while the consumer is not ready is taken into the slice (so the
    producer's pop does not wait for the consumer's ready) and is offered from there until
    taken; meanwhile ``i.ready`` is low.
    """

    def elaborate(self, platform):
        m = Module()
        ready_skid(m, Shape.cast(self._shape).width, self.i.valid, self.i.ready,
                   self.i.payload.as_value(), self.o.valid, self.o.ready,
                   self.o.payload.as_value())
        return m
