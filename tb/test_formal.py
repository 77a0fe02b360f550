"""Formal checks (SymbiYosys via yowasp, z3): stream stages never lose, duplicate, corrupt or
reorder a beat, and keep their output stable while it waits (AXI4-Stream rule).

Technique: the environment picks an arbitrary beat number ``n`` and value ``v`` (``AnyConst``);
whenever the ``n``-th beat written carries ``v``, the ``n``-th beat read must carry ``v``. As
``n`` and ``v`` are free, this covers every beat within the bound.
"""

import pytest
from amaranth.asserts import AnyConst, AnySeq, Initial
from amaranth.hdl import Assert, Assume, Cat, Elaboratable, Module, ResetSignal, Signal

from hdl.stream import AXIStreamSignature, RegisterSlice, StreamFIFO
from tb.formal import held_until_taken, run_sby

pytestmark = pytest.mark.formal

#: cycles of bounded model checking: at 12 a 2-entry FIFO's pointers wrap 4 times, at 10
#: three times; make test checks the FIFOs to 10 cycles and test-full to 12 (z3 takes about
#: 5 times as long for the last two cycles: 82 s against 19 s for both FIFOs on this machine)
DEPTH = 12
FIFO_DEPTHS = [pytest.param(10, id="bmc10"), pytest.param(DEPTH, id=f"bmc{DEPTH}",
                                                         marks=pytest.mark.full)]


class LosslessProperty(Elaboratable):
    """Wraps a stage with ``s_axis`` / ``m_axis`` (8-bit, no tkeep) in the proof obligations."""

    def __init__(self, dut, capacity):
        self.dut = dut
        self.capacity = capacity

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = dut = self.dut
        s, o = dut.s_axis, dut.m_axis
        m.d.comb += Assume(ResetSignal() == Initial())
        m.d.comb += [s.tdata.eq(AnySeq(8)), s.tlast.eq(AnySeq(1)), s.tvalid.eq(AnySeq(1)),
                     o.tready.eq(AnySeq(1))]

        # The source obeys AXI: an offered beat stays, unchanged, until it transfers.
        held_until_taken(m, s.tvalid, s.tready, Cat(s.tdata, s.tlast), Assume)

        written = Signal(5)
        read = Signal(5)
        with m.If(s.tvalid & s.tready):
            m.d.sync += written.eq(written + 1)
        with m.If(o.tvalid & o.tready):
            m.d.sync += read.eq(read + 1)

        nth = AnyConst(5)
        value = AnyConst(9)
        with m.If(s.tvalid & s.tready & (written == nth)):
            m.d.comb += Assume(value == Cat(s.tlast, s.tdata))
        with m.If(~Initial() & ~ResetSignal()):
            with m.If(o.tvalid & o.tready & (read == nth)):
                m.d.comb += Assert(value == Cat(o.tlast, o.tdata))
            m.d.comb += [Assert(read <= written), Assert(written - read <= self.capacity)]

        # The stage obeys AXI on its output too.
        held_until_taken(m, o.tvalid, o.tready, Cat(o.tdata, o.tlast), Assert,
                         when=~ResetSignal())
        return m


SIG = AXIStreamSignature(8, keep=False)


@pytest.mark.parametrize("ready_only,capacity", [(False, 2), (True, 1)],
                         ids=["full", "ready_only"])
def test_register_slice_is_lossless(ready_only, capacity):
    run_sby(f"register_slice{'_ready_only' * ready_only}",
            LosslessProperty(RegisterSlice(SIG, ready_only=ready_only), capacity=capacity), DEPTH)


@pytest.mark.parametrize("depth", FIFO_DEPTHS)
@pytest.mark.parametrize("packet", [False, True], ids=["cut_through", "packet"])
def test_stream_fifo_is_lossless(packet, depth):
    run_sby(f"stream_fifo_{'packet' if packet else 'plain'}_{depth}",
            LosslessProperty(StreamFIFO(SIG, 2, packet=packet), capacity=3), depth)
