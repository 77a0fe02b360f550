"""Logic idioms the packages share, for the way synthesis maps them."""

from amaranth.hdl import Signal

__all__ = ["Countdown", "adder_tree", "kept"]


def adder_tree(values):
    """The sum of ``values`` (a non-empty list) as a balanced tree of additions, depth log2 of
    their number: Python's ``sum`` would chain them one after the other."""
    values = list(values)
    while len(values) > 1:
        values = [values[k] + values[k + 1] if k + 1 < len(values) else values[k]
                  for k in range(0, len(values), 2)]
    return values[0]


def kept(m, value, name):
    """``value`` on a wire synthesis keeps (Yosys and Vivado ``keep``): the logic in front of
    it is mapped on its own, so a late signal that chooses between such wires meets them in
    the last LUT before the flip-flops instead of at the start of one merged cone."""
    wire = Signal(len(value), name=name, attrs={"keep": 1})
    m.d.comb += wire.eq(value)
    return wire


class Countdown:
    """A down counter of elements still to move, with "none left" and "one left" in
    flip-flops beside it.

    A handshake that tests ``value == 0`` or ``value == 1`` waits for a comparison as wide as
    the counter (a carry chain when the loaded value is arithmetic on other registers); the
    flags answer from a flip-flop. Use the statements in ``m.d.sync``; flags nobody reads are
    removed by synthesis.

    Parameters
    ----------
    width : int
        Width of the counter.
    name : str
        Prefix of the signals' names.

    Attributes
    ----------
    value : Signal(width)
        Elements left.
    none : Signal
        ``value == 0`` (high after reset).
    last : Signal
        ``value == 1``.
    """

    def __init__(self, width, name):
        self.value = Signal(width, name=f"{name}_left")
        self.none = Signal(init=1, name=f"{name}_none")
        self.last = Signal(name=f"{name}_last")

    def load(self, value):
        """Statements that start a count of ``value`` (``value`` itself is only assigned)."""
        return [self.value.eq(value), self.none.eq(value == 0), self.last.eq(value == 1)]

    def step(self):
        """Statements that count one element (never while :attr:`none`)."""
        return [self.value.eq(self.value - 1), self.none.eq(self.last),
                self.last.eq(self.value == 2)]
