"""Message serializer generated from a stream plan (``gen.msg.plan``)."""

import enum

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int
from ..stream import AXIStreamSignature, keep_count
from .bytes import BytePacker, ChunkRegisterSlice, byte_mask, byte_unpacker_class
from .steps import (RuntimeStep, StepRemainder, count_chunks, count_step, next_element,
                    pad_bytes, payload_bytes, registered_facts, send_count_chunk)

__all__ = ["Serializer", "SerializerError", "ErrorSignature", "payload_port"]


class SerializerError(enum.IntEnum):
    """Reason codes of :class:`Serializer` ``error.code``."""
    #: a payload stream ended (``tlast``) before its count of bytes: the rest is sent as zeros
    PAYLOAD_SHORT = 1
    #: a payload stream went on after its count of bytes: the excess is dropped up to ``tlast``
    PAYLOAD_LONG = 2
    #: a count inside packed elements above its bound or ``max_count``: written as 0 (one
    #: report per stream and message: what follows in that stream is not reported again)
    LENGTH = 3


class ErrorSignature(wiring.Signature):
    """Error report of a (de)serializer, seen from the reporter (``Out``).

    Members
    -------
    valid : Out(1)
        One-cycle pulse: a message had an error.
    code : Out(3)
        Reason code (:class:`SerializerError`, :class:`~hdl.msg.DeserializerError`) while
        ``valid``; it keeps the last code afterwards.
    count : Out(32)
        Messages with an error since reset (wraps), counted the cycle after ``valid``.
    """

    def __init__(self):
        super().__init__({"valid": Out(1), "code": Out(3), "count": Out(32)})

    def __eq__(self, other):
        return type(other) is type(self)

    def __hash__(self):
        return hash(type(self))


def count_errors(m, error):
    """Count ``error``'s pulses into ``error.count``, the cycle after each: the counter's
    enable comes from a register, not from the logic that decides an error."""
    pulse = Signal()
    m.d.sync += pulse.eq(error.valid)
    with m.If(pulse):
        m.d.sync += error.count.eq(error.count + 1)


def payload_port(variable, direction):
    """Member name of a variable-length field's stream: ``s_<field>_axis`` (in) or
    ``m_<field>_axis`` (out)."""
    return f"{direction}_{variable.port_name}_axis"


def check_plan_width(plan, data_width):
    check_int("data_width", data_width, 8, 512, multiple_of=8)
    if plan.data_width is not None and data_width != plan.data_width:
        raise ParameterError("data_width", data_width,
                             f"{plan.data_width} for framing {plan.framing!r}")


class Serializer(wiring.Component):
    """Serializes one message type in one framing into AXI4-Stream messages.

    Parameters
    ----------
    plan : gen.msg.plan.StreamPlan
        What goes on the stream, in order (type, framing, fixed-part layout, variable fields).
    data_width : int
        Width of every stream in bits: a multiple of 8 in 8..512 (``reconros``: 64).
    max_count : int
        Largest accepted count inside packed elements of an unbounded string or sequence (a
        bounded one uses its bound). Default 2**24.

    Raises :class:`~hdl.params.ParameterError` for the ``ros1`` framing of a type with a
    sequence of elements whose size varies (messages holding strings or sequences, strings):
    ROS 1 writes the message length first, before those elements have been read.

    Members
    -------
    fields : In(amaranth.lib.stream.Signature(plan.layout))
        The fixed part of a message (primitives, fixed arrays and the element count of every
        variable-length field; ReconROS: also ``publisher``). It must stay valid and unchanged
        until ``ready``, which is asserted in the cycle the message's last byte is handed to the
        output stage.
    s_<field>_axis : In(AXIStreamSignature(data_width))
        One per variable-length field with a stream (``plan.streams``), read when the message
        reaches the field: exactly one packet per message with the field's bytes (count times
        element size, little endian; strings without NUL; a sequence of messages or strings:
        the elements packed, see ``gen.msg.plan``) in full beats, ``tlast`` on the last. An
        empty field is one beat with ``tlast`` (its data is ignored). ``tkeep`` counts on the
        last beat only. A packet that ends early is completed with zero bytes, one that goes on
        is cut and drained up to its ``tlast``; both are reported on ``error``.
    m_axis : Out(AXIStreamSignature(data_width[, user_width=1]))
        The messages, one packet each, ``tkeep`` all ones but on the last beat. ReconROS
        framing: ``tuser`` is 0 on the first and the last beat and 1 between (docs/topics.md).
    error : Out(ErrorSignature())
    """

    def __init__(self, plan, data_width=64, *, max_count=1 << 24):
        check_plan_width(plan, data_width)
        check_int("max_count", max_count, 1, (1 << 32) - 2)
        if plan.framing == "ros1":
            varying = [v.path for v in plan.variables if v.elements and v.element_bytes is None]
            if varying:
                raise ParameterError(
                    "plan", plan.typename,
                    "a type whose sequences of elements have a fixed size for the ros1 "
                    f"serializer ({varying[0]}: the message length comes first)")
        self.plan = plan
        self._width = data_width
        self._max_count = max_count
        self._reconros = plan.framing == "reconros"
        members = {"fields": In(stream.Signature(plan.layout))}
        for v in plan.streams:
            members[payload_port(v, "s")] = In(AXIStreamSignature(data_width))
        members["m_axis"] = Out(AXIStreamSignature(data_width,
                                                   user_width=1 if self._reconros else 0))
        members["error"] = Out(ErrorSignature())
        super().__init__(members)

    @property
    def parameters(self):
        return {"type": self.plan.typename, "framing": self.plan.framing,
                "data_width": self._width, "max_count": self._max_count}

    def elaborate(self, platform):
        m = Module()
        plan, W, B = self.plan, self._width, self._width // 8
        steps = plan.steps
        m.submodules.packer = packer = BytePacker(W)
        m.d.comb += [
            self.m_axis.tdata.eq(packer.m_axis.tdata),
            self.m_axis.tkeep.eq(packer.m_axis.tkeep),
            self.m_axis.tlast.eq(packer.m_axis.tlast),
            self.m_axis.tvalid.eq(packer.m_axis.tvalid),
            packer.m_axis.tready.eq(self.m_axis.tready),
        ]
        if self._reconros:
            m.d.comb += self.m_axis.tuser.eq(~packer.first & ~packer.m_axis.tlast)

        # the step engine and the packer's shifter in separate clock periods
        m.submodules.chunk_slice = chunk_slice = ChunkRegisterSlice(W)
        wiring.connect(m, chunk_slice.o, packer.chunk)
        fv = self.fields.payload.as_value()
        chunk = chunk_slice.i
        ports = {v.index: getattr(self, payload_port(v, "s")) for v in plan.streams}
        counts = {v.index: (fv[v.count.offset:v.count.offset + 32] if v.into is None
                            else Signal(32, name=f"count{v.index}")) for v in plan.variables}
        lengths = {v.index: payload_bytes(v, counts[v.index]) for v in plan.variables
                   if not v.elements}
        empty = {var: count == 0 for var, count in counts.items()}
        # the fields are held while valid (the stream rule) and step 0 is never a runtime
        # step, so what the later steps derive from a field's count is kept in flip-flops:
        # its bytes, their chunk facts, whether it is empty (not a word-wide test behind the
        # fields' source)
        held_lengths, held_firsts, held_empty = {}, {}, {}
        for v in plan.variables:
            if v.into is not None:
                continue
            held_empty[v.index] = Signal(name=f"field_empty{v.index}", init=1)
            m.d.sync += held_empty[v.index].eq(empty[v.index])
            if v.elements:
                continue
            now = Signal(32, name=f"field_bytes_now{v.index}")
            held_lengths[v.index] = Signal(32, name=f"field_bytes{v.index}")
            m.d.comb += now.eq(lengths[v.index])
            m.d.sync += held_lengths[v.index].eq(now)
            held_firsts[v.index] = registered_facts(m, now, B, name=f"field_bytes{v.index}")

        def derived(i):
            """(lengths, firsts, empty) as step ``i`` reads them: from flip-flops after
            step 0."""
            if i == 0:
                return lengths, {}, empty
            return {**lengths, **held_lengths}, held_firsts, {**empty, **held_empty}
        # a sequence of messages or strings: its packed elements are read through a window
        unpackers, reported = {}, {}
        for v in plan.streams:
            if v.elements:
                unpacker = m.submodules[f"unpacker{v.index}"] = byte_unpacker_class(W)(W)
                wiring.connect(m, wiring.flipped(ports[v.index]), unpacker.s_axis)
                unpackers[v.index] = unpacker
                reported[v.index] = Signal(name=f"reported{v.index}")
        elements_left = {v.index: Signal(32, name=f"elements_left{v.index}")
                         for v in plan.variables if v.elements}
        stream_at = plan.step_streams()

        op = Signal(range(max(len(steps), 2)))
        # an inner count is read from the packed stream, then written
        max_steps = max([-(-s.nbytes // B) for s in steps if s.kind == "run"]
                        + [2 * count_chunks(B), 1])
        step = Signal(range(max_steps + 1))
        remainder = StepRemainder(m, 32, B, registered=False)
        pos = Signal(32)
        fill = Signal()
        drain = Signal()
        shortfall = Signal(range(B + 1))        # bytes a short payload beat supplied
        shortfall_pending = Signal()
        recent = Signal(64)

        error_code = Signal(3)     # the last reported code
        code_now = Signal(3)
        m.d.comb += self.error.code.eq(Mux(self.error.valid, code_now, error_code))

        count_errors(m, self.error)

        def report(code):
            m.d.comb += [self.error.valid.eq(1), code_now.eq(code)]
            m.d.sync += error_code.eq(code)

        def next_op(i):
            if i == len(steps) - 1:
                m.d.comb += self.fields.ready.eq(1)
                m.d.sync += [op.eq(0), pos.eq(0)]
            else:
                m.d.sync += op.eq(i + 1)
            m.d.sync += [step.eq(0), fill.eq(0)]

        with m.If(chunk.valid & chunk.ready):
            m.d.sync += pos.eq(pos + chunk.len)
            if self._reconros:
                m.d.sync += recent.eq(
                    (Cat(recent, byte_mask(chunk.data, B, chunk.len)) >> (chunk.len * 8))[:64])

        body = Const(plan.static_bytes() - 4, 32)
        for v in plan.streams if plan.framing == "ros1" else ():
            body = body + (counts[v.index] * v.element_bytes if v.elements
                           else lengths[v.index])
        body = body[:32]

        def part_value(part, run_bits):
            if part.kind == "const":
                return Const(int.from_bytes(part.value, "little"), 8 * part.nbytes)
            if part.kind in ("zero", "nul", "reserved"):
                return Const(0, 8 * part.nbytes)
            if part.kind == "field":
                return fv[part.leaf.offset:part.leaf.offset + part.leaf.width]
            if part.kind == "extend":
                value = fv[part.leaf.offset:part.leaf.offset + part.leaf.width]
                return _extend(value.as_signed() if part.leaf.signed else value, 64)
            if part.kind in ("count", "capacity"):
                count = counts[part.var] + int(part.kind == "count" and
                                               plan.variables[part.var].nul)
                return _extend(count[:32], 8 * part.nbytes)
            if part.kind == "length":
                return body
            if part.kind == "publisher":
                return Cat((fv[:32] + plan.publisher_offset)[:32], Const(0, 32))
            if part.kind == "trailer":
                if run_bits:
                    return Cat(*run_bits)[-64:]
                return recent
            raise AssertionError(part.kind)

        def read(unpacker, need, stream):
            """``need`` bytes of a packed elements stream, zeros past its end (reported once):
            (ok to go on, data, ``take()`` to call in the cycle they are used). Called where
            the step is decoded, outside the conditions of ``take()``: the amount goes to the
            unpacker from there."""
            have = unpacker.avail >= need
            data = byte_mask(unpacker.window, B, unpacker.avail)
            m.d.comb += unpacker.amount.eq(Mux(have, need, unpacker.avail))

            def take():
                m.d.comb += unpacker.take.eq(1)
                with m.If(~have):
                    with m.If(~reported[stream]):
                        report(SerializerError.PAYLOAD_SHORT)
                    m.d.sync += reported[stream].eq(1)
            return have | unpacker.ended, data, take

        def end_of_stream(stream, empty, last, then):
            """The packet of elements stream ``stream`` must end here (``empty``: the field is
            empty, its one beat is ignored); ``last``: the message ends too."""
            unpacker = unpackers[stream]
            extra = unpacker.avail != 0
            done = Signal(name=f"stream_done{stream}_{len(steps)}")
            m.d.comb += done.eq(unpacker.ended | extra)
            if last:
                m.d.comb += [chunk.valid.eq(done), chunk.len.eq(0), chunk.last.eq(1)]
                done = done & chunk.ready
            with m.If(done):
                if not empty:
                    with m.If(extra & ~reported[stream]):
                        report(SerializerError.PAYLOAD_LONG)
                m.d.comb += unpacker.flush.eq(1)
                m.d.sync += reported[stream].eq(0)
                then()

        # The fields stay valid until the cycle the message's last chunk is taken.
        with m.If(self.fields.valid):
            with m.Switch(op):
                for i, s in enumerate(steps):
                    last_op = i == len(steps) - 1
                    stream = stream_at[i]
                    step_lengths, step_firsts, step_empty = derived(i)
                    with m.Case(i):
                        if s.kind == "run" and stream is not None:
                            self._element_run(m, s, i, chunk, step, read, unpackers[stream],
                                              stream, next_op)
                            continue
                        if s.kind == "count":
                            self._count(m, s, i, chunk, step, counts[s.var],
                                        read, unpackers[stream], stream, reported[stream],
                                        report, next_op)
                            continue
                        if s.kind == "loop":
                            top = plan.variables[s.var].into is None
                            exit_last = s.target == len(steps) - 1
                            with m.If(step_empty[s.var]):
                                if top:
                                    end_of_stream(s.var, True, exit_last,
                                                  lambda s=s: next_op(s.target))
                                else:
                                    next_op(s.target)
                            with m.Else():
                                m.d.sync += elements_left[s.var].eq(counts[s.var])
                                next_op(i)
                            continue
                        if s.kind == "next":
                            if plan.variables[s.var].into is None:
                                def done(s=s, i=i, last_op=last_op):
                                    end_of_stream(s.var, False, last_op, lambda: next_op(i))
                            else:
                                def done(i=i):
                                    next_op(i)
                            next_element(m, s, elements_left[s.var], op, step, done=done)
                            continue
                        if s.kind == "run":
                            bits = []
                            for part in s.parts:
                                bits.append(part_value(part, bits))
                            vector = Cat(*bits)
                            nsteps = -(-s.nbytes // B)
                            with m.Switch(step):
                                for j in range(nsteps):
                                    k = min(B, s.nbytes - j * B)
                                    with m.Case(j):
                                        m.d.comb += [chunk.valid.eq(1), chunk.len.eq(k),
                                                     chunk.data.eq(vector[j * W:j * W + 8 * k]),
                                                     chunk.last.eq(last_op and j == nsteps - 1)]
                                        with m.If(chunk.ready):
                                            if j == nsteps - 1:
                                                next_op(i)
                                            else:
                                                m.d.sync += step.eq(j + 1)
                            continue
                        length = pad_bytes(plan, s, pos, step_empty) if s.kind == "pad" \
                            else step_lengths[s.var]
                        first = None if s.kind == "pad" else step_firsts.get(s.var)
                        walk = RuntimeStep(m, i, B, step=step, remainder=remainder,
                                           length=length, next_step=next_op, first=first)
                        left, k, final, advance = walk.left, walk.k, walk.final, walk.advance
                        m.d.comb += chunk.len.eq(k)

                        if s.kind == "pad":
                            m.d.comb += [chunk.valid.eq(1), chunk.last.eq(last_op & final)]
                            with m.If(chunk.ready):
                                advance()
                            continue
                        if stream is not None:     # a string or sequence inside elements
                            ok, data, take = read(unpackers[stream], k, stream)
                            m.d.comb += [chunk.valid.eq(ok), chunk.data.eq(data)]
                            with m.If(ok & chunk.ready):
                                take()
                                advance()
                            continue
                        port = ports[s.var]
                        with m.If(drain):
                            m.d.comb += port.tready.eq(1)
                            with m.If(port.tvalid & port.tlast):
                                m.d.sync += drain.eq(0)
                                next_op(i)
                        with m.Elif(fill):
                            with m.If(shortfall_pending):
                                remainder.set(remainder.value - shortfall)
                                m.d.sync += shortfall_pending.eq(0)
                            with m.Else():
                                m.d.comb += [chunk.valid.eq(1), chunk.last.eq(last_op & final)]
                                with m.If(chunk.ready):
                                    advance()
                        with m.Else():
                            supplied = Signal(range(B + 1), name=f"supplied{i}")
                            m.d.comb += supplied.eq(Mux(port.tlast, keep_count(port.tkeep), B))
                            short = port.tlast & ((supplied < k) | ~final)
                            m.d.comb += [chunk.valid.eq(port.tvalid), chunk.data.eq(port.tdata),
                                         chunk.len.eq(Mux(supplied < k, supplied, k)),
                                         chunk.last.eq(last_op & final & ~short),
                                         port.tready.eq(chunk.ready)]
                            with m.If(port.tvalid & chunk.ready):
                                with m.If(final & ~port.tlast):
                                    report(SerializerError.PAYLOAD_LONG)
                                    m.d.sync += drain.eq(1)
                                with m.Elif(short):
                                    report(SerializerError.PAYLOAD_SHORT)
                                    # what is left is counted in the next cycle (an
                                    # error path: no subtraction behind the port's tkeep)
                                    remainder.set(left)
                                    m.d.sync += [fill.eq(1), step.eq(1),
                                                 shortfall.eq(Mux(supplied < k, supplied, k)),
                                                 shortfall_pending.eq(1)]
                                with m.Else():
                                    advance()
        return m


    def _count(self, m, s, i, chunk, step, count, read, unpacker, stream, reported, report,
               next_op):
        """The count of an inner variable: read from the packed stream into its register,
        checked against its bound (above it: reported, written as 0), then written in the
        framing's form (CDR strings: plus the NUL)."""
        B = self._width // 8
        v = self.plan.variables[s.var]
        wire = (count + int(v.nul))[:32]

        def load(j, offset, k, moved):
            ok, data, take = read(unpacker, k, stream)
            with m.If(ok):
                take()
                m.d.sync += [count.word_select(offset + x, 8).eq(data.word_select(x, 8))
                             for x in range(k)]
                moved()

        def write(j, offset, k, moved):
            with m.If(count > (v.bound or self._max_count) if j == 0 else Const(0)):
                with m.If(~reported):
                    report(SerializerError.LENGTH)
                m.d.sync += [count.eq(0), reported.eq(1)]
            with m.Else():
                send_count_chunk(m, chunk, wire, offset, k, moved)

        count_step(m, step, B, load, write, then=lambda: next_op(i))

    def _element_run(self, m, s, i, chunk, step, read, unpacker, stream, next_op):
        """A ``run`` inside elements: element bytes come from the packed stream, padding and
        NULs are zeros."""
        B = self._width // 8
        nsteps = -(-s.nbytes // B)
        kinds = [p.kind == "element" for p in s.parts for _ in range(p.nbytes)]
        with m.Switch(step):
            for j in range(nsteps):
                k = min(B, s.nbytes - j * B)
                need = sum(kinds[j * B:j * B + k])
                with m.Case(j):
                    ok, data, take = read(unpacker, need, stream)
                    out, used = [], 0
                    for element in kinds[j * B:j * B + k]:
                        out.append(data.word_select(used, 8) if element else Const(0, 8))
                        used += element
                    m.d.comb += [chunk.valid.eq(ok), chunk.len.eq(k), chunk.data.eq(Cat(*out))]
                    with m.If(ok & chunk.ready):
                        take()
                        if j == nsteps - 1:
                            next_op(i)
                        else:
                            m.d.sync += step.eq(j + 1)


def _extend(value, width):
    """``value`` sign- or zero-extended (by its signedness) to ``width`` bits, as unsigned."""
    if value.shape().signed:
        return Cat(value, *([value[-1]] * (width - len(value))))
    return Cat(value, Const(0, width - len(value)))
