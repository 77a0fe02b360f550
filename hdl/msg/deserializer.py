"""Message deserializer generated from a stream plan (``gen.msg.plan``)."""

import enum
from contextlib import ExitStack

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..logic import kept
from ..params import check_int
from ..stream import AXIStreamSignature
from .bytes import (BytePacker, ChunkRegisterSlice, SettlingByteUnpacker, byte_mask,
                    byte_unpacker_class)
from .serializer import ErrorSignature, check_plan_width, count_errors, payload_port
from .steps import (RuntimeStep, StepRemainder, chunk_facts, count_chunk_bytes, count_chunks,
                    count_step, next_element, pad_bytes, payload_bytes, registered_facts,
                    run_chunk_bytes, send_count_chunk)

__all__ = ["Deserializer", "DeserializerError"]


class DeserializerError(enum.IntEnum):
    """Reason codes of :class:`Deserializer` ``error.code``."""
    #: an element count above the field's bound or the configured ``max_count``
    LENGTH = 1
    #: the input message ended (``tlast``) before the plan did
    EARLY_END = 2
    #: the plan ended but the input message did not: the rest is dropped up to ``tlast``
    LATE_END = 3
    #: non-zero CDR alignment padding
    PADDING = 4
    #: malformed framing: CDR encapsulation not little-endian CDR, a CDR string count of 0 or a
    #: missing NUL, a ROS 1 length prefix that disagrees with the body
    FORMAT = 5


class _Offer:
    """The bytes the deserializer takes when it takes at its position in the plan (``op``,
    ``step``), chosen by flip-flops that every move writes with the new position's facts.

    The byte window's shift and room test start from these flip-flops instead of the decode
    of the position (a choice among every step's chunk sizes). A chunk of a run or of a count
    offers a constant; a runtime step (``pad``, payload) offers its chunk size, from the
    registers it keeps (its first chunk's facts, then the shared remainder's)."""

    def __init__(self, steps, bytes_per_beat):
        B = bytes_per_beat
        self._const, self._runtime = {}, {}
        for i, s in enumerate(steps):
            if s.kind == "run":
                sizes = run_chunk_bytes(s.nbytes, B)
            elif s.kind == "count":
                sizes = count_chunk_bytes(B)
            elif s.kind in ("loop", "next"):
                sizes = []
            else:
                sizes = []
                self._runtime[i] = len(self._runtime)
            self._const.update({(i, j): k for j, k in enumerate(sizes)})
        const, runtime = self._facts(0, 0)
        self.const = Signal(range(B + 1), name="offer_const", init=const)
        self.runtime = Signal(max(1, len(self._runtime)), name="offer_runtime", init=runtime)
        self.in_runtime = Signal(name="offer_in_runtime", init=runtime != 0)

    @property
    def runtime_steps(self):
        """Indices of the runtime steps (pad, payload), in plan order."""
        return list(self._runtime)

    def _facts(self, op, step):
        r = self._runtime.get(op)
        return self._const.get((op, step), 0), 0 if r is None else 1 << r

    def at(self, op):
        """The flip-flop that is set while the position is in runtime step ``op``."""
        return self.runtime[self._runtime[op]]

    def move(self, op, step=0):
        """The writes (sync domain) of a move to chunk ``step`` of step ``op``."""
        const, runtime = self._facts(op, step)
        return [self.const.eq(const), self.runtime.eq(runtime), self.in_runtime.eq(runtime != 0)]

    def amount(self, first_k, later, remainder_k):
        """The offered bytes: ``first_k[i]`` is runtime step ``i``'s first chunk size,
        ``later`` says a runtime step is past its first chunk (``remainder_k`` then)."""
        first = Const(0, len(self.const))
        for i, r in self._runtime.items():
            first = first | Mux(self.runtime[r], first_k[i], 0)
        return self.const | Mux(later & self.in_runtime, remainder_k, first)


class Deserializer(wiring.Component):
    """Deserializes AXI4-Stream messages of one type in one framing.

    Nothing is buffered beyond two beats (four above 64 bits): each variable-length field
    streams out as it arrives. Above 64 bits (at a power of two) the byte window is a
    :class:`~hdl.msg.bytes.SettlingByteUnpacker`: a payload's full chunks move a beat per
    cycle but its last, every other take costs two cycles more.

    Parameters
    ----------
    plan : gen.msg.plan.StreamPlan
        The type and framing (see :class:`~hdl.msg.Serializer`).
    data_width : int
        Width of every stream in bits: a multiple of 8 in 8..512 (``reconros``: 64).
    max_count : int
        Largest accepted element count of an unbounded variable-length field (a bounded one
        uses its bound). Default 2**24.

    Members
    -------
    s_axis : In(AXIStreamSignature(data_width))
        Messages, one packet each; ``tkeep`` contiguous from byte 0 (all ones but on the last
        beat).
    fields : Out(amaranth.lib.stream.Signature(plan.layout))
        The fixed part of the current message, offered as soon as its last member has been
        read (a message that fails before that offers nothing) and held until ``ready``; the
        next message is not read before. Counts are element counts (strings without NUL).
    m_<field>_axis : Out(AXIStreamSignature(data_width, user_width=1))
        One per variable-length field with a stream (``plan.streams``), in stream order:
        exactly one packet per message with the field's bytes, never more than its count, full
        beats but the last, ``tuser`` set on the first beat; an empty field is one beat with
        ``tkeep`` 0 and ``tlast``. A sequence of messages or strings carries its elements
        packed (``gen.msg.plan``), each inner count as an element count (no NUL). If the
        message ends early or fails inside the field, the packet ends there; fields after an
        error get no packet.
    error : Out(ErrorSignature())
        A pulse with a :class:`DeserializerError` code per bad message; the rest of the message
        is dropped up to ``tlast`` and the next one is read normally.
    done : Out(1)
        A pulse when a message has been read to its ``tlast`` without error: with ``error``,
        exactly one verdict per message, in order.
    """

    def __init__(self, plan, data_width=64, *, max_count=1 << 24):
        check_plan_width(plan, data_width)
        check_int("max_count", max_count, 1, (1 << 32) - 2)
        self.plan = plan
        self._width = data_width
        self._max_count = max_count
        members = {"s_axis": In(AXIStreamSignature(data_width)),
                   "fields": Out(stream.Signature(plan.layout))}
        for v in plan.streams:
            members[payload_port(v, "m")] = Out(AXIStreamSignature(data_width, user_width=1))
        members["error"] = Out(ErrorSignature())
        members["done"] = Out(1)
        super().__init__(members)

    @property
    def parameters(self):
        return {"type": self.plan.typename, "framing": self.plan.framing,
                "data_width": self._width, "max_count": self._max_count}

    def elaborate(self, platform):
        m = Module()
        plan, W, B = self.plan, self._width, self._width // 8
        steps = plan.steps
        reconros = plan.framing == "reconros"
        # Wide, the decisions that read the window's bytes would reach every bit of a window
        # chosen by the take before: the settling unpacker's window is a register, and a
        # payload's full chunks, decided from registers, still move a beat per cycle
        m.submodules.unpacker = unpacker = byte_unpacker_class(W, settling=True)(W)
        settling = isinstance(unpacker, SettlingByteUnpacker)
        wiring.connect(m, wiring.flipped(self.s_axis), unpacker.s_axis)
        window, avail, ended = unpacker.window, unpacker.avail, unpacker.ended
        # the steps that decide from the window's bytes begin after a take of ``amount``
        # bytes (a payload's last chunk is never a ``take_full``): wide, they read the window
        # as built at the read position, which no ``take_full`` chooses
        decided = unpacker.settled_window if settling else window

        # Registers hold the wire values; the output shows element counts (a CDR string count
        # includes the NUL) and the ReconROS publisher id (beat 0 is id + 1000).
        fields = Signal(plan.layout.size)
        shown = Signal(plan.layout.size)
        m.d.comb += shown.eq(fields)
        for v in plan.streams:
            if v.nul:
                leaf = v.count
                m.d.comb += shown[leaf.offset:leaf.offset + 32].eq(
                    fields[leaf.offset:leaf.offset + 32] - 1)
        if reconros:
            m.d.comb += shown[:32].eq(fields[:32] - plan.publisher_offset)
        m.d.comb += self.fields.payload.eq(shown)
        count_width = 64 if reconros else 32
        counts = [Signal(count_width, name=f"count{v.index}") for v in plan.variables]
        # A count is written through its next value, and what the steps derive from it (its
        # checks, its field's length) is registered from that next value: equal to a function
        # of the count in every cycle, from flip-flops rather than the count's arithmetic. A
        # count is always read at least one step before it is used.
        count_next = [Signal(count_width, name=f"count_next{v.index}") for v in plan.variables]
        empty, count_bad, count_bad_code, lengths, firsts = self._count_facts(
            m, counts, count_next, lagged=settling)
        ports = {v.index: getattr(self, payload_port(v, "m")) for v in plan.streams}
        length_prefix = Signal(32)

        # a sequence of messages or strings: its packed elements go through a packer
        chunks, opened = {}, {}
        for v in plan.streams:
            if not v.elements:
                continue
            packer = m.submodules[f"packer{v.index}"] = BytePacker(W)
            cut = m.submodules[f"chunk_slice{v.index}"] = ChunkRegisterSlice(W)
            wiring.connect(m, cut.o, packer.chunk)
            port = ports[v.index]
            m.d.comb += [port.tdata.eq(packer.m_axis.tdata), port.tkeep.eq(packer.m_axis.tkeep),
                         port.tlast.eq(packer.m_axis.tlast), port.tvalid.eq(packer.m_axis.tvalid),
                         port.tuser.eq(packer.first), packer.m_axis.tready.eq(port.tready)]
            chunks[v.index] = cut.i
            opened[v.index] = Signal(name=f"opened{v.index}")
        elements_left = {v.index: Signal(count_width, name=f"elements_left{v.index}")
                         for v in plan.variables if v.elements}

        op = Signal(range(len(steps) + 2))
        END, WAIT = len(steps), len(steps) + 1
        # an inner count is read, then written packed
        max_steps = max([-(-s.nbytes // B) for s in steps if s.kind == "run"]
                        + [2 * count_chunks(B), 1])
        step = Signal(range(max_steps + 1))
        remainder = StepRemainder(m, count_width + 3, B)
        pos = Signal(32)
        offered = Signal()     # fields offered for this message (until accepted)
        with m.If(self.fields.valid & self.fields.ready):
            m.d.sync += offered.eq(0)
        # Wide, a run or padding step takes its bytes whatever their checks say and a bad
        # verdict fails the message in the next cycle, before anything else (the window is
        # settling then): the checks of the window's bytes reach two flip-flops, not the
        # take. Nothing leaves meanwhile: the fields are held back, and a step that emits
        # elements keeps its checks before its take.
        late_bad = Signal()
        late_code = Signal(3)
        m.d.comb += self.fields.valid.eq(offered & ~late_bad if settling else offered)

        last_writer = max([i for i, s in enumerate(steps)
                           if any(p.kind in ("field", "extend", "publisher", "count")
                                  for p in s.parts)]
                          + [-1])

        error_code = Signal(3)     # the last reported code
        code_now = Signal(3)
        m.d.comb += self.error.code.eq(Mux(self.error.valid, code_now, error_code))

        count_errors(m, self.error)

        offer = _Offer(steps, B)
        # each runtime step's first chunk facts, once: the offer and the step both read them
        first_facts = {}
        for i in offer.runtime_steps:
            if steps[i].kind == "pad":
                pad = Signal(len(remainder.value), name=f"pad_bytes{i}")
                m.d.comb += pad.eq(pad_bytes(plan, steps[i], pos, empty))
                first_facts[i] = chunk_facts(pad, B)
            else:
                first_facts[i] = firsts[steps[i].var]
        m.d.comb += unpacker.amount.eq(offer.amount(
            {i: f.k for i, f in first_facts.items()}, step != 0, remainder.k))

        def go(i, j=0):
            """Move to chunk ``j`` of step ``i``."""
            m.d.sync += [op.eq(i), step.eq(j), *offer.move(i, j)]

        def fail(code):
            m.d.comb += [self.error.valid.eq(1), code_now.eq(code), unpacker.flush.eq(1)]
            m.d.sync += error_code.eq(code)
            go(WAIT)

        def fail_next_cycle(bad, code):
            """Fail with ``code`` in the next cycle if ``bad`` (wide only)."""
            m.d.sync += [late_bad.eq(bad), late_code.eq(code)]

        def take(n):
            """Take ``n`` bytes, the amount this position offers (``_Offer``), in the cycle
            its condition holds."""
            m.d.comb += unpacker.take.eq(1)
            m.d.sync += pos.eq(pos + n)

        def next_op(i):
            go(i + 1)
            if i == last_writer:
                m.d.sync += offered.eq(1)

        def count_error(var):
            """(bad, code) of the element count of variable ``var``: above its bound or
            ``max_count`` (LENGTH), or a CDR string count of 0 (FORMAT)."""
            return count_bad[var], count_bad_code[var]

        def close(var, then):
            """End the packet of elements stream ``var`` (an empty last chunk), then
            ``then()``."""
            chunk = chunks[var]
            m.d.comb += [chunk.valid.eq(1), chunk.len.eq(0), chunk.last.eq(1)]
            with m.If(chunk.ready):
                m.d.sync += opened[var].eq(0)
                then()

        stream_at = plan.step_streams()
        full_bit = B.bit_length() - 1
        full_chunks, loads = [], []

        late = ExitStack()
        if settling:
            m.d.sync += late_bad.eq(0)
            with m.If(late_bad):
                fail(late_code)
                m.d.sync += offered.eq(0)
            late.enter_context(m.Else())
        with m.Switch(op):
            for i, s in enumerate(steps):
                with m.Case(i):
                    chunk = chunks.get(stream_at[i])
                    if s.kind == "run":
                        self._run(m, s, i, decided, avail, ended, fields, count_next,
                                  length_prefix, step, take, go, fail, next_op, chunk,
                                  unchecked_writes=settling,
                                  fail_next_cycle=fail_next_cycle if settling else None)
                        continue
                    if s.kind == "count":
                        self._count(m, s, i, decided, avail, ended, counts, count_next, step,
                                    take, go, fail, next_op, chunk, count_error,
                                    unchecked_writes=settling)
                        continue
                    if s.kind == "loop":
                        top = plan.variables[s.var].into is None
                        bad_count, bad_code = count_error(s.var)
                        with m.If(bad_count):
                            fail(bad_code)
                        with m.Elif(empty[s.var]):
                            if top:
                                close(s.var, lambda s=s: next_op(s.target))
                            else:
                                next_op(s.target)
                        with m.Else():
                            m.d.sync += elements_left[s.var].eq(counts[s.var])
                            if top:
                                m.d.sync += opened[s.var].eq(1)
                            next_op(i)
                        continue
                    if s.kind == "next":
                        if plan.variables[s.var].into is None:
                            def done(s=s, i=i):
                                close(s.var, lambda: next_op(i))
                        else:
                            def done(i=i):
                                next_op(i)
                        next_element(m, s, elements_left[s.var], op, step, done=done,
                                     to_op=go)
                        continue
                    first = first_facts[i]
                    length = pad_bytes(plan, s, pos, empty) if s.kind == "pad" else lengths[s.var]
                    # Wide, the remainder loads on every chunk, both chunk sizes are compared
                    # before the step's choice and a padding that fits a chunk goes on from
                    # its first (at 64 bits the netlist the cores that embed it were timed
                    # with stays)
                    walk = RuntimeStep(m, i, B, step=step, remainder=remainder, length=length,
                                       next_step=next_op, first=first, load_always=settling)
                    k, final, advance = walk.k, walk.final, walk.advance
                    have = walk.covered(avail) if settling else avail >= k
                    if settling and s.kind == "pad" and s.align - 1 <= B:
                        k, have = first.k, kept(m, avail >= first.k, f"covered_pad{i}")

                        def advance(i=i):
                            next_op(i)
                    short = ~have & ended
                    # a payload that ends early ends the message: what it takes then does not
                    # matter (the window is flushed), so the offer stays k

                    if s.kind == "pad":
                        # a bad count of the sequence this padding aligns is reported as
                        # such, not as the padding it implies (the count came first)
                        bad_pad = Signal(name=f"bad_pad_{i}")
                        nonzero = (byte_mask(decided, B, k) != 0) if s.check else Const(0)
                        if s.var is not None:
                            bad_count, bad_code = count_error(s.var)
                            bad_pad_code = Mux(bad_count, bad_code, DeserializerError.PADDING)
                            m.d.comb += bad_pad.eq(nonzero | bad_count)
                        else:
                            bad_pad_code = DeserializerError.PADDING
                            m.d.comb += bad_pad.eq(nonzero)
                        with m.If(have):
                            if settling:
                                take(k)
                                advance()
                                fail_next_cycle(bad_pad, bad_pad_code)
                            else:
                                with m.If(bad_pad):
                                    fail(bad_pad_code)
                                with m.Else():
                                    take(k)
                                    advance()
                        with m.Elif(short):
                            fail(Mux(bad_count, bad_code, DeserializerError.EARLY_END)
                                 if s.var is not None else DeserializerError.EARLY_END)
                        continue
                    bad_count, bad_code = count_error(s.var)
                    # wide, the chunk facts of a count follow it a cycle later: the step
                    # waits out the first cycle of the window's settling (a count is read by
                    # a take, which settles)
                    movable = ((have | ended) & ~unpacker.settling if settling
                               else have | ended)
                    with m.If((step == 0) & bad_count):
                        fail(bad_code)
                    with m.Else():
                        n = Mux(short, avail, k)
                        # the window's bytes past ``avail`` are zero: a short chunk is the
                        # window as it is, and the late ``short`` only chooses between
                        # masks built from registers
                        data = Mux(short, window, byte_mask(window, B, k))
                        if chunk is not None:      # inside the elements of a stream
                            valid, ready = chunk.valid, chunk.ready
                            m.d.comb += [chunk.data.eq(data), chunk.len.eq(n),
                                         chunk.last.eq(0)]
                        else:
                            port = ports[s.var]
                            valid, ready = port.tvalid, port.tready
                            m.d.comb += [
                                port.tdata.eq(data),
                                port.tkeep.eq(Mux(short, Cat(*(avail > j for j in range(B))),
                                                  Cat(*(k > j for j in range(B))))),
                                port.tlast.eq(final | short),
                                port.tuser.eq(step == 0),
                            ]
                        m.d.comb += valid.eq(movable)
                        with m.If(valid & ready):
                            take(n)
                            with m.If(short):
                                fail(DeserializerError.EARLY_END)
                            with m.Else():
                                advance(load=not settling)
                    if settling:
                        # the remainder loads whenever the step could move a chunk, told by
                        # its offer flip-flop: a bad count or an early end fails the message,
                        # and the next one's first chunk loads it again (no decode of the step
                        # and no verdict before the remainder's enable)
                        # (spelled out: ``offer.at(i) & movable`` groups the same terms
                        # differently, and this grouping is the netlist that was timed)
                        loads.append(offer.at(i) & (have | ended) & ~unpacker.settling
                                     & ready)
                        # a full chunk and a full window: k and avail are at most B, so their
                        # top bits say it; the step is told by its offer flip-flop and k's top
                        # bit is chosen from flip-flops, so no decode of the step and no
                        # comparison comes before the window's multiplexers. A bad count
                        # flushes, and a flush comes first
                        full_chunks.append(offer.at(i) & ready & Mux(
                            step != 0, remainder.k[full_bit] & ~remainder.final,
                            first.k[full_bit] & ~first.final))
            with m.Case(END):
                ok = ended & (avail == 0)
                if plan.framing == "ros1":
                    ok = ok & (pos - 4 == length_prefix)
                with m.If(ok):
                    m.d.comb += [unpacker.flush.eq(1), self.done.eq(1)]
                    go(WAIT)
                    if last_writer < 0:
                        m.d.sync += offered.eq(1)
                with m.Elif(ended & (avail == 0)):
                    fail(DeserializerError.FORMAT)
                with m.Else():
                    fail(DeserializerError.LATE_END)
            with m.Case(WAIT):
                for var in chunks:      # a packet cut by an error ends here
                    with m.If(opened[var]):
                        close(var, lambda: None)
                with m.If(~unpacker.dropping & (~offered | self.fields.ready)
                          & ~Cat(Const(0, 1), *opened.values()).any()):
                    m.d.sync += pos.eq(0)
                    go(0)
        late.close()
        if settling:
            with m.If(Cat(Const(0, 1), *loads).any()):
                remainder.load_proposed()
            m.d.comb += unpacker.take_full.eq(avail[full_bit]
                                              & Cat(Const(0, 1), *full_chunks).any())
        return m

    def _count_facts(self, m, counts, count_next, *, lagged=False):
        """Registers beside each count, from its next value: (empty, bad, bad_code, lengths,
        firsts), per variable: no elements; a bad count (above its bound or ``max_count``:
        LENGTH, or a CDR string count of 0: FORMAT) and its code; the bytes of its field and
        their :class:`ChunkFacts` (``RuntimeStep``'s ``first``; ``None`` for packed
        elements, which have no payload step). ``lagged``: the chunk facts follow the field's
        length a cycle later, and a bad count is a comparison with a constant."""
        width = len(counts[0]) if counts else 32
        B = self._width // 8
        empty, bad, bad_code, lengths, firsts = [], [], [], [], []
        for v, count, nxt in zip(self.plan.variables, counts, count_next):
            m.d.comb += nxt.eq(count)
            m.d.sync += count.eq(nxt)
            bound = v.bound or self._max_count
            nul = int(v.nul)
            # their values for a count of 0, the count's reset value
            is_empty = Signal(name=f"empty{v.index}", init=1)
            is_bad = Signal(name=f"bad_count{v.index}", init=v.nul)
            code = Signal(3, name=f"bad_code{v.index}",
                          init=DeserializerError.FORMAT if v.nul else DeserializerError.LENGTH)
            # (lagged, a string's count of 0 is bad anyway: no subtraction of its NUL)
            too_many = nxt > bound + nul if lagged else nxt - nul > bound
            m.d.sync += is_empty.eq(nxt == 0)
            if v.nul:
                m.d.sync += [is_bad.eq((nxt == 0) | too_many),
                             code.eq(Mux(nxt == 0, DeserializerError.FORMAT,
                                         DeserializerError.LENGTH))]
            else:
                m.d.sync += is_bad.eq(too_many)
            empty.append(is_empty)
            bad.append(is_bad)
            bad_code.append(code)
            if v.elements:
                lengths.append(None)
                firsts.append(None)
                continue
            length_width = width + 3
            init = payload_bytes(v, -nul) & ((1 << length_width) - 1)
            length = Signal(length_width, name=f"length{v.index}", init=init)
            length_next = Signal(length_width, name=f"length_next{v.index}")
            m.d.comb += length_next.eq(payload_bytes(v, nxt - nul)[:length_width])
            m.d.sync += length.eq(length_next)
            lengths.append(length)
            firsts.append(registered_facts(m, length if lagged else length_next, B,
                                           name=f"length{v.index}", init=init))
        return empty, bad, bad_code, lengths, firsts

    def _count(self, m, s, i, window, avail, ended, counts, count_next, step, take, go, fail,
               next_op, chunk, count_error, *, unchecked_writes=False):
        """The count of an inner variable: read into its register, checked, then written to
        the stream as an element count. ``unchecked_writes``: as in :meth:`_run`."""
        B = self._width // 8
        v = self.plan.variables[s.var]
        count = counts[s.var]
        value = (count[:32] - int(v.nul))[:32]
        bad_count, bad_code = count_error(s.var)

        def read(j, offset, k, moved):
            writes = [count_next[s.var].word_select(offset + x, 8).eq(window.word_select(x, 8))
                      for x in range(k)]
            if unchecked_writes:
                m.d.comb += writes
            with m.If(avail >= k):
                if not unchecked_writes:
                    m.d.comb += writes
                take(k)
                moved()
            with m.Elif(ended):
                fail(DeserializerError.EARLY_END)

        def write(j, offset, k, moved):
            with m.If(bad_count if j == 0 else Const(0)):
                fail(bad_code)
            with m.Else():
                send_count_chunk(m, chunk, value, offset, k, moved)

        count_step(m, step, B, read, write, then=lambda: next_op(i), to_step=lambda j: go(i, j))

    def _run(self, m, s, i, window, avail, ended, fields, count_next, length_prefix, step,
             take, go, fail, next_op, chunk=None, *, unchecked_writes=False,
             fail_next_cycle=None):
        """One ``run`` step: static byte ranges land in fixed registers, checks per byte;
        inside a loop, element bytes go to the stream's ``chunk``. ``unchecked_writes``: the
        registers are written in every cycle of the step from whatever the window shows,
        whatever its checks and its take decide; the write of the cycle that takes the bytes
        is the one that stays (a message that fails is not offered, and a count is read again
        before it is used).
        ``fail_next_cycle(bad, code)``: a chunk that emits no elements is taken whatever its
        checks say, which report it a cycle later."""
        B = self._width // 8
        sizes = run_chunk_bytes(s.nbytes, B)
        nsteps = len(sizes)

        def move(j, k):
            take(k)
            if j == nsteps - 1:
                next_op(i)
            else:
                go(i, j + 1)
        with m.Switch(step):
            for j, k in enumerate(sizes):
                with m.Case(j):
                    bad_padding, bad_format = [], []
                    writes, count_writes, emitted = [], [], []
                    start = 0
                    for part in s.parts:
                        lo, hi = max(start, j * B), min(start + part.nbytes, j * B + k)
                        for x in range(lo, hi):
                            byte = window.word_select(x - j * B, 8)
                            index = x - start
                            if part.kind == "element":
                                emitted.append(byte)
                            elif part.kind in ("field", "extend", "publisher"):
                                if index < part.leaf.width // 8:
                                    writes.append(fields.word_select(
                                        part.leaf.offset // 8 + index, 8).eq(byte))
                            elif part.kind == "count":
                                count_writes.append(
                                    count_next[part.var].word_select(index, 8).eq(byte))
                                if index < 4:
                                    offset = self.plan.variables[part.var].count.offset
                                    writes.append(fields.word_select(offset // 8 + index, 8)
                                                  .eq(byte))
                            elif part.kind == "length":
                                writes.append(length_prefix.word_select(index, 8).eq(byte))
                            elif part.kind == "zero":
                                bad_padding.append(byte != 0)
                            elif part.kind == "nul":
                                bad_format.append(byte != 0)
                            elif part.kind == "const" and part.mask[index]:
                                bad_format.append(
                                    (byte & part.mask[index]) != part.value[index])
                        start += part.nbytes
                    format_bad = Cat(*bad_format, Const(0, 1)).any()
                    padding_bad = Cat(*bad_padding, Const(0, 1)).any()
                    if unchecked_writes:
                        m.d.sync += writes
                        m.d.comb += count_writes
                    with m.If(avail >= k):
                        if fail_next_cycle is not None and not emitted:
                            move(j, k)
                            fail_next_cycle(format_bad | padding_bad,
                                            Mux(format_bad, DeserializerError.FORMAT,
                                                DeserializerError.PADDING))
                        else:
                            with m.If(format_bad):
                                fail(DeserializerError.FORMAT)
                            with m.Elif(padding_bad):
                                fail(DeserializerError.PADDING)
                            with m.Else():
                                if emitted:
                                    m.d.comb += [chunk.valid.eq(1), chunk.data.eq(Cat(*emitted)),
                                                 chunk.len.eq(len(emitted)), chunk.last.eq(0)]
                                with m.If(chunk.ready if emitted else Const(1)):
                                    if not unchecked_writes:
                                        m.d.sync += writes
                                        m.d.comb += count_writes
                                    move(j, k)
                    with m.Elif(ended):
                        fail(DeserializerError.EARLY_END)
