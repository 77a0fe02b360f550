"""Step arithmetic shared by the serializer and the deserializer: how many bytes a runtime
step (``pad``, ``payload``) moves, and how a step is cut into chunks of at most W/8 bytes."""

from typing import NamedTuple

from amaranth.hdl import Const, Mux, Signal, Value

from ..logic import kept

__all__ = ["payload_bytes", "pad_bytes", "chunk_bytes", "last_chunk", "ChunkFacts",
           "chunk_facts", "chunk_facts_value", "StepRemainder",
           "RuntimeStep", "COUNT_BYTES", "count_chunks", "run_chunk_bytes",
           "count_chunk_bytes", "count_chunk_cases", "count_step", "send_count_chunk", "next_element"]

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


def chunk_bytes(left, bytes_per_beat):
    """Bytes of the next chunk of a step with ``left`` bytes to go: ``min(left, B)``."""
    # B is a power of two: "at least B" and "at most B" are tests of the high bits, not
    # word-wide comparisons (a carry chain each, in front of the next step's subtraction)
    low = bytes_per_beat.bit_length() - 1
    return Mux(left[low:].any(), bytes_per_beat, left[:low])


def last_chunk(left, bytes_per_beat):
    """The next chunk of a step with ``left`` bytes to go is its last: ``left <= B``."""
    low = bytes_per_beat.bit_length() - 1
    return ~left[low + 1:].any() & (~left[low] | ~left[:low].any())


class ChunkFacts(NamedTuple):
    """What the chunk logic reads of a step's bytes to go, ``left``."""
    #: bytes of the next chunk, ``min(left, B)``
    k: Value
    #: the next chunk is the last, ``left <= B``
    final: Value
    #: the same two of the chunk after it (``left - B``, when ``left > B``)
    k_after: Value
    final_after: Value


def chunk_facts(left, bytes_per_beat):
    """:class:`ChunkFacts` of ``left``, tests of its bits (no comparison, no subtraction:
    B is a power of two, so ``left - B`` has the low bits of ``left``)."""
    B, low = bytes_per_beat, bytes_per_beat.bit_length() - 1
    return ChunkFacts(chunk_bytes(left, B), last_chunk(left, B),
                      Mux(left[low + 1:].any(), B, left[:low]), last_chunk(left, 2 * B))


def chunk_facts_value(left, bytes_per_beat):
    """:func:`chunk_facts` of the integer ``left`` (a register's reset value)."""
    B = bytes_per_beat
    return ChunkFacts(min(left, B), int(left <= B), B if left >= 2 * B else left % B,
                      int(left <= 2 * B))


def registered_facts(m, value, bytes_per_beat, *, name, init=0):
    """:class:`ChunkFacts` of ``value`` in flip-flops loaded every cycle (they follow it one
    cycle later), with the reset values of ``init``; named ``<name>_k`` and so on."""
    facts = []
    for field, fact, reset in zip(ChunkFacts._fields, chunk_facts(value, bytes_per_beat),
                                  chunk_facts_value(init, bytes_per_beat)):
        held = Signal(len(fact), name=f"{name}_{field}", init=reset)
        m.d.sync += held.eq(fact)
        facts.append(held)
    return ChunkFacts(*facts)


class StepRemainder:
    """The bytes a runtime step has still to move after its first chunk, shared by the
    steps, with its chunk size and last-chunk test kept in flip-flops beside it: the chunk
    logic reads them without a word-wide test in front of its decision.

    The steps :meth:`propose` their next remainder with its size and test where these do
    not depend on a decision, and :meth:`load_proposed` it in the cycle the chunk moves;
    :meth:`set` writes any other value.

    ``registered=False`` computes ``k`` and ``final`` from ``value`` instead: for a user
    whose decision does not wait for them (the serializer's waits for its payload ports).

    Members
    -------
    value, k, final
        The bytes to go, and :class:`ChunkFacts` ``k`` and ``final`` of them (flip-flops
        unless ``registered=False``).
    after : ChunkFacts
        Of ``value`` (from flip-flops); its ``k_after`` and ``final_after`` are what one
        more chunk leaves.
    """

    def __init__(self, m, width, bytes_per_beat, *, registered=True):
        self._m, self._B = m, bytes_per_beat
        self._registered = registered
        self.value = Signal(width, name="remaining")
        self.k = Signal(range(bytes_per_beat + 1), name="remaining_k")
        self.final = Signal(name="remaining_final", init=1)
        self.after = chunk_facts(self.value, bytes_per_beat)
        self._proposed = (Signal(width, name="proposed"), Signal.like(self.k, name="proposed_k"),
                          Signal(name="proposed_final"))
        self._load = Signal(name="remaining_load")
        if registered:
            with m.If(self._load):
                m.d.sync += [self.value.eq(self._proposed[0]), self.k.eq(self._proposed[1]),
                             self.final.eq(self._proposed[2])]
        else:
            m.d.comb += [self.k.eq(self.after.k), self.final.eq(self.after.final)]
            with m.If(self._load):
                m.d.sync += self.value.eq(self._proposed[0])

    def propose(self, value, k, final):
        """The next remainder ``value`` and its facts (one proposal per cycle)."""
        self._m.d.comb += [p.eq(x) for p, x in zip(self._proposed, (value, k, final))]

    def load_proposed(self):
        """Load this cycle's proposal at the next clock edge."""
        self._m.d.comb += self._load.eq(1)

    def set(self, value):
        """``remaining = value`` at the next clock edge (registered ``k`` and ``final`` are
        computed from ``value``: a test behind whatever computes it)."""
        left = Signal(len(self.value), name="remaining_set")
        self._m.d.comb += left.eq(value)
        self._m.d.sync += self.value.eq(left)
        if self._registered:
            facts = chunk_facts(left, self._B)
            self._m.d.sync += [self.k.eq(facts.k), self.final.eq(facts.final)]


class RuntimeStep:
    """One runtime step cut into chunks: ``left`` bytes to go (``length`` in its first cycle,
    then the shared :class:`StepRemainder`), ``k`` bytes this cycle, ``final`` on the last
    chunk.

    ``first`` gives :func:`chunk_facts` of ``length`` when the caller keeps them in
    flip-flops beside it; otherwise they are computed from ``length``. ``advance()``
    (inside the condition that the chunk moved) goes to the next step through ``next_step``
    or keeps counting; with ``load_always`` it loads the remainder on the last chunk as well.
    """

    def __init__(self, m, index, bytes_per_beat, *, step, remainder, length, next_step,
                 first=None, load_always=False):
        B = bytes_per_beat
        assert B & (B - 1) == 0, "bytes per beat is a power of two"
        self._m, self._step, self._remainder, self._next = m, step, remainder, next_step
        self._load_always = load_always
        self.index = index
        remaining = remainder.value
        self.left = Signal(len(remaining), name=f"left{index}")
        self.k = Signal(range(B + 1), name=f"k{index}")
        self.final = Signal(name=f"final{index}")
        later = step != 0
        m.d.comb += self.left.eq(Mux(later, remaining, length))
        if first is None:
            length_now = Signal(len(remaining), name=f"length{index}")
            m.d.comb += length_now.eq(length)
            first = chunk_facts(length_now, B)
        # each source's facts and difference first, the choice after them: no test or
        # subtraction behind the step decode
        m.d.comb += [self.k.eq(Mux(later, remainder.k, first.k)),
                     self.final.eq(Mux(later, remainder.final, first.final))]
        self._later, self._first = later, first
        remainder.propose(Mux(later, remaining - B, length - B),
                          Mux(later, remainder.after.k_after, first.k_after),
                          Mux(later, remainder.after.final_after, first.final_after))

    def covered(self, avail):
        """``avail >= k``, each source of ``k`` compared on a kept wire before the choice
        between them (merged, the choice would come first and the comparison after it)."""
        m, i = self._m, self.index
        return Mux(self._later, kept(m, avail >= self._remainder.k, f"covered_rest{i}"),
                   kept(m, avail >= self._first.k, f"covered_first{i}"))

    def advance(self, *, load=True):
        """Next chunk or next step; ``load=False`` (with ``load_always``): the caller loads
        the remainder itself, under a condition of its own."""
        m = self._m
        # ``load_always``: the last chunk loads the remainder too (no step reads it before
        # its own first chunk loads it), which keeps ``final`` out of the load's logic
        if self._load_always and load:
            self._remainder.load_proposed()
        with m.If(self.final):
            self._next(self.index)
        with m.Else():
            if not self._load_always:
                self._remainder.load_proposed()
            m.d.sync += self._step.eq(1)


def count_chunks(bytes_per_beat):
    """Chunks (cycles) that move one element count at ``bytes_per_beat`` bytes a cycle."""
    return -(-COUNT_BYTES // bytes_per_beat)


def count_chunk_bytes(bytes_per_beat):
    """Bytes of each chunk of an element count, in order."""
    return run_chunk_bytes(COUNT_BYTES, bytes_per_beat)


def run_chunk_bytes(nbytes, bytes_per_beat):
    """Bytes of each chunk of a static run of ``nbytes`` bytes: full chunks, then the rest."""
    B = bytes_per_beat
    return [min(B, nbytes - j * B) for j in range(-(-nbytes // B))]


def _step_writer(m, step, to_step):
    if to_step is not None:
        return to_step

    def write(j):
        m.d.sync += step.eq(j)
    return write


def count_chunk_cases(m, step, bytes_per_beat, first, chunk_case, *, then, to_step=None):
    """Cases ``first`` .. ``first + count_chunks() - 1`` of ``step``, one per chunk of an
    element count: ``chunk_case(j, offset, k, moved)`` writes the logic of chunk ``j``
    (``k`` bytes from byte ``offset``) and calls ``moved()`` in the cycle the chunk moves,
    which goes to the next case (``to_step(case)``, default: write ``step``) and after the
    last one to ``then()``."""
    B = bytes_per_beat
    to_step = _step_writer(m, step, to_step)
    sizes = count_chunk_bytes(B)
    for j, k in enumerate(sizes):
        with m.Case(first + j):
            def moved(j=j):
                if j == len(sizes) - 1:
                    then()
                else:
                    to_step(first + j + 1)
            chunk_case(j, j * B, k, moved)


def count_step(m, step, bytes_per_beat, read, write, *, then, to_step=None):
    """The cases of a ``count`` step on ``step``: the count is read in chunks (``read``), then
    written in chunks (``write``; both as ``chunk_case`` of :func:`count_chunk_cases`), then
    ``then()``. ``to_step(case)`` moves to another case of ``step`` (default: writes
    ``step``)."""
    n = count_chunks(bytes_per_beat)
    to_step = _step_writer(m, step, to_step)

    with m.Switch(step):
        count_chunk_cases(m, step, bytes_per_beat, 0, read, then=lambda: to_step(n),
                          to_step=to_step)
        count_chunk_cases(m, step, bytes_per_beat, n, write, then=then, to_step=to_step)


def send_count_chunk(m, chunk, value, offset, k, moved):
    """Offer bytes ``offset .. offset + k`` of the 32-bit ``value`` as one chunk (not the
    last of a message); ``moved()`` when it is taken."""
    m.d.comb += [chunk.valid.eq(1), chunk.len.eq(k), chunk.last.eq(0),
                 chunk.data.eq(value[8 * offset:8 * (offset + k)])]
    with m.If(chunk.ready):
        moved()


def next_element(m, step_desc, elements_left, op, step, *, done, to_op=None):
    """A ``next`` step: back to the first step of the loop body while elements are left,
    ``done()`` after the last one. ``to_op(index)`` moves to the body's first step (default:
    writes ``op`` and ``step``)."""
    with m.If(elements_left == 1):
        done()
    with m.Else():
        m.d.sync += elements_left.eq(elements_left - 1)
        if to_op is None:
            m.d.sync += [op.eq(step_desc.target + 1), step.eq(0)]
        else:
            to_op(step_desc.target + 1)
