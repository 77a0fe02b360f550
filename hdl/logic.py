"""Logic idioms the packages share, for the way synthesis maps them."""

from amaranth.hdl import Cat, Const, Signal, Value, signed

__all__ = ["Countdown", "adder_tree", "kept", "shifted_sum", "split_product",
           "split_square"]


def adder_tree(values):
    """The sum of ``values`` (a non-empty list) as a balanced tree of additions, depth log2 of
    their number: Python's ``sum`` would chain them one after the other."""
    values = list(values)
    while len(values) > 1:
        values = [values[k] + values[k + 1] if k + 1 < len(values) else values[k]
                  for k in range(0, len(values), 2)]
    return values[0]


def shifted_sum(terms):
    """``sum(weight * value)`` for ``(weight, value)`` pairs with constant non-negative integer
    weights, exact: one shifted copy of a value per set bit of its weight, added in a
    balanced tree. (A product with a constant would otherwise take a multiplier block, and
    Python's ``sum`` chains its additions one after the other.)"""
    return adder_tree([Value.cast(value) << bit for weight, value in terms
                       for bit in range(weight.bit_length()) if weight >> bit & 1])


def _chunks(value):
    """``value`` (signed) as ``[(chunk, shift)]``: 17-bit unsigned chunks from bit 0 (as
    18-bit signed values) and a signed top chunk of at most 18 bits."""
    value = value.as_signed()
    if len(value) <= 18:
        return [(value, 0)]
    chunks, low = [], 0
    while len(value) - low > 18:
        chunks.append((Cat(value[low:low + 17], Const(0, 1)).as_signed(), low))
        low += 17
    return chunks + [(value[low:].as_signed(), low)]


def split_product(m, a, b, name):
    """``a * b`` (signed values) two cycles later: partial products of at most 18x18 bits
    (one ECP5 or 7-series multiplier each) registered, then their sum registered."""
    terms = []
    for x, sx in _chunks(a):
        for y, sy in _chunks(b):
            partial = Signal(signed(len(x) + len(y)), name=f"{name}_p{sx}_{sy}")
            m.d.sync += partial.eq(x * y)
            terms.append(partial << (sx + sy))
    result = Signal(signed(len(a) + len(b)), name=name)
    m.d.sync += result.eq(adder_tree(terms))
    return result


def split_square(m, a, name):
    """``a * a`` (a signed value of 19 to 35 bits) two cycles later from three registered
    partial products: ``a = h * 2**17 + l`` gives ``h*h * 2**34 + h*l * 2**18 + l*l``, and
    ``l*l < 2**34`` is placed beside ``h*h`` without an addition."""
    if not 19 <= len(a) <= 35:
        raise ValueError(f"square of a {len(a)}-bit value: expected 19 to 35 bits")
    (low, _), (high, _) = _chunks(a)
    hh = Signal(2 * len(high), name=f"{name}_hh")
    hl = Signal(signed(len(high) + 18), name=f"{name}_hl")
    ll = Signal(34, name=f"{name}_ll")
    m.d.sync += [hh.eq(high * high), hl.eq(high * low), ll.eq(low * low)]
    result = Signal(2 * len(a), name=name)
    m.d.sync += result.eq(Cat(ll, hh) + (hl << 18))
    return result


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
