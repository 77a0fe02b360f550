"""Register slice: breaks every combinational path of an AXI4-Stream link."""

from amaranth.hdl import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from .signature import check_stream_signature

__all__ = ["RegisterSlice"]


class RegisterSlice(wiring.Component):
    """Full-throughput AXI4-Stream register slice (skid buffer).

    ``m_axis`` payload and ``tvalid`` come from flip-flops, and so does ``s_axis.tready``;
    no combinational path crosses the slice. It moves one beat per cycle in steady state, adds
    one cycle of latency, and holds at most two beats.

    Parameters
    ----------
    signature : AXIStreamSignature
        Stream format of both ports.

    Members
    -------
    s_axis : In(signature)
        Input stream.
    m_axis : Out(signature)
        Output stream, the same beats in the same order.
    """

    def __init__(self, signature):
        check_stream_signature(signature)
        self._stream = signature
        super().__init__({"s_axis": In(signature), "m_axis": Out(signature)})

    def elaborate(self, platform):
        m = Module()
        sig = self._stream
        # Payload registers need no reset: nothing reads them while tvalid is low.
        skid = Signal(sig.payload_width, reset_less=True)
        out = Signal(sig.payload_width, reset_less=True)
        skid_valid = Signal()

        m.d.comb += self.s_axis.tready.eq(~skid_valid)
        m.d.comb += sig.unpack(self.m_axis, out)
        with m.If(~self.m_axis.tvalid | self.m_axis.tready):
            with m.If(skid_valid):
                m.d.sync += [out.eq(skid), self.m_axis.tvalid.eq(1), skid_valid.eq(0)]
            with m.Else():
                m.d.sync += [out.eq(sig.pack(self.s_axis)),
                             self.m_axis.tvalid.eq(self.s_axis.tvalid)]
        with m.Elif(self.s_axis.tvalid & ~skid_valid):
            m.d.sync += [skid.eq(sig.pack(self.s_axis)), skid_valid.eq(1)]
        return m
