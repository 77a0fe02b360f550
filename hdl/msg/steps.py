"""Step arithmetic shared by the serializer and the deserializer: how many bytes a runtime
step (``pad``, ``payload``) moves, and how a step is cut into chunks of at most W/8 bytes."""

from amaranth.hdl import Const, Mux, Signal

__all__ = ["payload_bytes", "pad_bytes", "RuntimeStep", "COUNT_BYTES", "count_chunks",
           "count_chunk_cases", "count_step", "send_count_chunk", "next_element"]

#: bytes of an element count on the wire and in a packed element (``uint32``)
COUNT_BYTES = 4


def payload_bytes(variable, element_count):
    """Bytes of a variable-length field of ``element_count`` elements (NUL not included)."""
    return element_count << (variable.element_bytes.bit_length() - 1)


def pad_bytes(plan, step, pos, empty):
    """Zero bytes of a ``pad`` step at byte position ``pos`` of the message: up to the step's
    alignment counted from ``plan.origin``; none before the elements of an empty sequence
    (``empty[var]``: variable ``var`` has no elements)."""
    # the alignment is a power of two: only the low bits of the position take part (a
    # word-wide subtraction would put a carry chain in front of the position's adder)
    bits = (step.align - 1).bit_length()
    if bits == 0:
        return Const(0, 1)
    length = (Const(plan.origin % step.align, bits) - pos[:bits])[:bits]
    if step.var is not None:
        length = Mux(empty[step.var], 0, length)
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
        # word-wide comparisons (a carry chain each, in front of the next step's subtraction).
        # Both sources are tested, the choice comes after the tests.
        low = B.bit_length() - 1

        def k_of(left):
            return Mux(left[low:].any(), B, left[:low])

        def final_of(left):
            return ~left[low + 1:].any() & (~left[low] | ~left[:low].any())

        later = step != 0
        first = Signal(len(remaining), name=f"length{index}")
        m.d.comb += first.eq(length)
        m.d.comb += self.k.eq(Mux(later, k_of(remaining), k_of(first)))
        self.final = Signal(name=f"final{index}")
        m.d.comb += self.final.eq(Mux(later, final_of(remaining), final_of(first)))

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


def count_chunks(bytes_per_beat):
    """Chunks (cycles) that move one element count at ``bytes_per_beat`` bytes a cycle."""
    return -(-COUNT_BYTES // bytes_per_beat)


def count_chunk_cases(m, step, bytes_per_beat, first, chunk_case, *, then):
    """Cases ``first`` .. ``first + count_chunks() - 1`` of ``step``, one per chunk of an
    element count: ``chunk_case(j, offset, k, moved)`` writes the logic of chunk ``j``
    (``k`` bytes from byte ``offset``) and calls ``moved()`` in the cycle the chunk moves,
    which goes to the next case and after the last one to ``then()``."""
    B = bytes_per_beat
    n = count_chunks(B)
    for j in range(n):
        with m.Case(first + j):
            def moved(j=j):
                if j == n - 1:
                    then()
                else:
                    m.d.sync += step.eq(first + j + 1)
            chunk_case(j, j * B, min(B, COUNT_BYTES - j * B), moved)


def count_step(m, step, bytes_per_beat, read, write, *, then):
    """The cases of a ``count`` step on ``step``: the count is read in chunks (``read``), then
    written in chunks (``write``; both as ``chunk_case`` of :func:`count_chunk_cases`), then
    ``then()``."""
    n = count_chunks(bytes_per_beat)

    def to_write():
        m.d.sync += step.eq(n)

    with m.Switch(step):
        count_chunk_cases(m, step, bytes_per_beat, 0, read, then=to_write)
        count_chunk_cases(m, step, bytes_per_beat, n, write, then=then)


def send_count_chunk(m, chunk, value, offset, k, moved):
    """Offer bytes ``offset .. offset + k`` of the 32-bit ``value`` as one chunk (not the
    last of a message); ``moved()`` when it is taken."""
    m.d.comb += [chunk.valid.eq(1), chunk.len.eq(k), chunk.last.eq(0),
                 chunk.data.eq(value[8 * offset:8 * (offset + k)])]
    with m.If(chunk.ready):
        moved()


def next_element(m, step_desc, elements_left, op, step, *, done):
    """A ``next`` step: back to the first step of the loop body while elements are left,
    ``done()`` after the last one."""
    with m.If(elements_left == 1):
        done()
    with m.Else():
        m.d.sync += [elements_left.eq(elements_left - 1), op.eq(step_desc.target + 1),
                     step.eq(0)]
