"""Logic idioms the packages share, for the way synthesis maps them."""

from amaranth.hdl import Signal

__all__ = ["kept"]


def kept(m, value, name):
    """``value`` on a wire synthesis keeps (Yosys and Vivado ``keep``): the logic in front of
    it is mapped on its own, so a late signal that chooses between such wires meets them in
    the last LUT before the flip-flops instead of at the start of one merged cone."""
    wire = Signal(len(value), name=name, attrs={"keep": 1})
    m.d.comb += wire.eq(value)
    return wire
