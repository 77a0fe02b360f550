"""Step arithmetic shared by the serializer and the deserializer: how many bytes a runtime
step (``pad``, ``payload``) moves, and how a step is cut into chunks of at most W/8 bytes."""

from amaranth.hdl import Const, Mux, Signal

__all__ = ["payload_bytes", "pad_bytes", "RuntimeStep"]


def payload_bytes(variable, element_count):
    """Bytes of a variable-length field of ``element_count`` elements (NUL not included)."""
    return element_count << (variable.element_bytes.bit_length() - 1)


def pad_bytes(plan, step, pos, counts):
    """Zero bytes of a ``pad`` step at byte position ``pos`` of the message: up to the step's
    alignment counted from ``plan.origin``; none before the elements of an empty sequence."""
    # the alignment is a power of two: only the low bits of the position take part (a
    # word-wide subtraction would put a carry chain in front of the position's adder)
    bits = (step.align - 1).bit_length()
    if bits == 0:
        return Const(0, 1)
    length = (Const(plan.origin % step.align, bits) - pos[:bits])[:bits]
    if step.var is not None:
        length = Mux(counts[step.var] == 0, 0, length)
    return length


class RuntimeStep:
    """One runtime step cut into chunks: ``left`` bytes to go (``length`` in its first cycle,
    then the ``remaining`` register), ``k`` bytes this cycle, ``final`` on the last chunk.

    ``advance()`` (inside the condition that the chunk moved) goes to the next step through
    ``next_step`` or keeps counting.
    """

    def __init__(self, m, index, bytes_per_beat, *, step, remaining, length, next_step):
        B = bytes_per_beat
        assert B & (B - 1) == 0, "bytes per beat is a power of two"
        self._m, self._B = m, B
        self._step, self._remaining, self._next = step, remaining, next_step
        self._length = length
        self.index = index
        self.left = Signal(len(remaining), name=f"left{index}")
        self.k = Signal(range(B + 1), name=f"k{index}")
        m.d.comb += self.left.eq(Mux(step != 0, remaining, length))
        # B is a power of two: "at least B" and "at most B" are tests of the high bits, not
        # word-wide comparisons (a carry chain each, in front of the next step's subtraction)
        low = B.bit_length() - 1
        at_least_b = self.left[low:].any()
        m.d.comb += self.k.eq(Mux(at_least_b, B, self.left[:low]))
        self.final = ~self.left[low + 1:].any() & (~self.left[low] | ~self.left[:low].any())

    def advance(self):
        m = self._m
        with m.If(self.final):
            self._next(self.index)
        with m.Else():
            # both differences straight from their sources, the choice after them: the
            # subtraction is not behind the step decode
            m.d.sync += [self._remaining.eq(Mux(self._step != 0, self._remaining - self._B,
                                                self._length - self._B)),
                         self._step.eq(1)]
