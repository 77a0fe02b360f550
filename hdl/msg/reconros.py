"""Serializer and deserializer of the ReconROS framing that move whole 64-bit beats.

In ReconROS' framing (docs/topics.md) every part starts on a beat: each primitive is one beat,
each array is a size beat, a capacity beat and its bytes from the start of the next beat, and
the message ends with a trailer beat. No byte ever has to move inside a beat, so these
components need neither :class:`~hdl.msg.BytePacker` nor :class:`~hdl.msg.ByteUnpacker`: a
payload beat goes straight through, its last one masked to the field's length, and each
fixed beat is a constant set of byte lanes. Their ports and rules are those of
:class:`~hdl.msg.Serializer` and :class:`~hdl.msg.Deserializer` for a ``reconros`` plan.
"""

from dataclasses import dataclass

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int
from ..stream import AXIStreamSignature
from .deserializer import DeserializerError
from .serializer import (ErrorSignature, SerializerError, _extend, check_plan_width,
                         count_errors, payload_port)

__all__ = ["ReconrosSerializer", "ReconrosDeserializer", "beat_program"]

#: bytes per beat of the framing (its plan's ``data_width``, checked by :func:`beat_program`)
BEAT = 8


@dataclass(frozen=True)
class Lane:
    """Bytes ``first .. first + nbytes - 1`` of ``part``, in a beat from byte ``at``."""
    part: object
    first: int
    nbytes: int
    at: int


@dataclass(frozen=True)
class Beat:
    """One beat of the program: a fixed beat (``lanes``) or the payload of variable ``var``
    (as many beats as its bytes need)."""
    lanes: tuple = ()
    var: int = None

    @property
    def payload(self):
        return self.var is not None

    def parts(self, kind):
        return [lane.part for lane in self.lanes if lane.part.kind == kind]


def beat_program(plan):
    """The :class:`Beat` list of a ``reconros`` plan, in stream order.

    Raises :class:`~hdl.params.ParameterError` for another framing or for a plan whose parts
    are not beat-aligned."""
    if plan.framing != "reconros":
        raise ParameterError("plan", plan.typename,
                             f"in the 'reconros' framing (this one is in {plan.framing!r})")
    check_plan_width(plan, 8 * BEAT)
    beats = []
    for s in plan.steps:
        if s.kind == "payload":
            beats.append(Beat(var=s.var))
        elif s.kind == "pad":
            if s.align != BEAT or s.check:
                raise ParameterError("plan", plan.typename,
                                     "padded to whole beats, unchecked (a step "
                                     f"pads to {s.align}{', checked' if s.check else ''})")
        elif s.kind == "run":
            if s.nbytes % BEAT:
                raise ParameterError("plan", plan.typename,
                                     f"made of whole beats (a run has {s.nbytes} bytes)")
            # (part, byte of the part) for every byte of the run, grouped per beat and part
            owners = [(part, x) for part in s.parts for x in range(part.nbytes)]
            for j in range(0, s.nbytes, BEAT):
                lanes = []
                for at, (part, x) in enumerate(owners[j:j + BEAT]):
                    if lanes and lanes[-1].part is part:
                        lanes[-1] = Lane(part, lanes[-1].first, lanes[-1].nbytes + 1,
                                         lanes[-1].at)
                    else:
                        lanes.append(Lane(part, x, 1, at))
                beats.append(Beat(lanes=tuple(lanes)))
        else:
            raise ParameterError("plan", plan.typename,
                                 f"free of {s.kind!r} steps (sequences of messages "
                                 "or strings)")
    counts = [i for i, b in enumerate(beats) if b.parts("count")]
    for i in counts:
        # the payload's facts are registered from the count beat and read two beats later
        if not (beats[i + 1].parts("capacity") and beats[i + 2].payload):
            raise ParameterError("plan", plan.typename,
                                 "laid out as count, capacity, payload for each "
                                 "field")
    return beats


def _keep(nbytes):
    """``tkeep`` of the last beat of ``nbytes`` bytes (``nbytes`` mod 8 from 3 bits; a
    partial beat never keeps byte 7)."""
    return Mux(nbytes == 0, 0xFF, Cat(*(nbytes > j for j in range(BEAT - 1)), 0))


def _bytes_enabled(keep):
    """A 64-bit mask with the bytes ``keep`` selects."""
    return Cat(*(Mux(keep[j], 0xFF, 0x00) for j in range(BEAT)))


class _PayloadFacts:
    """The facts a payload runs on, written from its element count at its count beat (the
    count is two beats before the payload, see :func:`beat_program`) and kept while the
    payload runs: its beats left, whether the next is its last, the last beat's ``tkeep``,
    whether it is empty, whether the count is above ``bound``."""

    def __init__(self):
        self.left = Signal(34, name="payload_beats_left")
        self.one = Signal(name="payload_one_left")
        self.keep = Signal(BEAT, name="payload_last_keep")
        self.empty = Signal(name="payload_empty")
        self.bad = Signal(name="payload_count_bad")

    def load(self, m, count, element_bytes, bound=None):
        """Writes (in the cycle the count beat is taken) from ``count`` (a 64-bit value)."""
        nbytes = count[:33] * element_bytes
        per_beat = BEAT // element_bytes
        m.d.sync += [self.left.eq((nbytes + BEAT - 1) >> 3),
                     self.one.eq((count != 0) & (count <= per_beat)),
                     self.keep.eq(_keep(nbytes[:3])),
                     self.empty.eq(count == 0)]
        if bound is not None:
            m.d.sync += self.bad.eq(count > bound)

    def step(self, m):
        """Writes of a payload beat taken."""
        m.d.sync += [self.left.eq(self.left - 1), self.one.eq(self.left == 2)]


class ReconrosDeserializer(wiring.Component):
    """Deserializes messages of one type in ReconROS' framing, a beat at a time.

    Same ports, rules and error codes as :class:`~hdl.msg.Deserializer` with a ``reconros``
    plan at 64 bits (see there), with these differences, all about when things happen:
    ``error`` and ``done`` pulse in the cycle after the beat that decides them; a message is
    read at one beat per cycle, a payload beat goes to its port in the cycle it arrives
    (``s_axis.tready`` follows the port's ``tready``), and an empty field's beat takes one
    cycle of its own. Padding bytes after a payload and the capacity and trailer beats are
    not checked (ReconROS does not check them either).

    Parameters
    ----------
    plan : gen.msg.plan.StreamPlan
        The type in the ``reconros`` framing.
    data_width : int
        64.
    max_count : int
        Largest accepted element count of an unbounded string or sequence. Default 2**24.

    Members
    -------
    s_axis : In(AXIStreamSignature(64))
    fields : Out(amaranth.lib.stream.Signature(plan.layout))
    m_<field>_axis : Out(AXIStreamSignature(64, user_width=1))
    error : Out(ErrorSignature())
    done : Out(1)
    """

    def __init__(self, plan, data_width=64, *, max_count=1 << 24):
        self.program = beat_program(plan)
        check_plan_width(plan, data_width)
        check_int("max_count", max_count, 1, (1 << 32) - 2)
        self.plan = plan
        self._max_count = max_count
        members = {"s_axis": In(AXIStreamSignature(64)),
                   "fields": Out(stream.Signature(plan.layout))}
        for v in plan.streams:
            members[payload_port(v, "m")] = Out(AXIStreamSignature(64, user_width=1))
        members["error"] = Out(ErrorSignature())
        members["done"] = Out(1)
        super().__init__(members)

    @property
    def parameters(self):
        return {"type": self.plan.typename, "framing": self.plan.framing, "data_width": 64,
                "max_count": self._max_count, "beats": True}

    def elaborate(self, platform):
        m = Module()
        plan, program = self.plan, self.program
        inp = self.s_axis
        taken = inp.tvalid & inp.tready

        fields = Signal(plan.layout.size)
        shown = Signal(plan.layout.size)
        m.d.comb += [shown.eq(fields),
                     shown[:32].eq(fields[:32] - plan.publisher_offset),
                     self.fields.payload.eq(shown)]
        offered = Signal()
        m.d.comb += self.fields.valid.eq(offered)
        with m.If(self.fields.valid & self.fields.ready):
            m.d.sync += offered.eq(0)
        last_writer = max([i for i, b in enumerate(program)
                           if any(lane.part.kind in ("field", "extend", "count", "publisher")
                                  for lane in b.lanes)])

        op = Signal(range(len(program)))
        first = Signal(name="payload_first")
        facts = _PayloadFacts()
        dropping = Signal()
        code = Signal(3, name="error_code")
        done = Signal(name="done_pulse")
        m.d.comb += [self.error.code.eq(code), self.done.eq(done)]
        m.d.sync += [self.error.valid.eq(0), done.eq(0)]
        count_errors(m, self.error)

        def fail(reason, ended):
            m.d.sync += [self.error.valid.eq(1), code.eq(reason), op.eq(0),
                         dropping.eq(~ended)]

        def goto(i):
            m.d.sync += op.eq(i)
            if i < len(program) and program[i].payload:
                m.d.sync += first.eq(1)

        with m.If(dropping):
            m.d.comb += inp.tready.eq(1)
            with m.If(inp.tvalid & inp.tlast):
                m.d.sync += dropping.eq(0)
        with m.Else():
            with m.Switch(op):
                for i, beat in enumerate(program):
                    with m.Case(i):
                        if beat.payload:
                            self._payload(m, beat, i, facts, first, taken, fail, goto)
                        else:
                            self._fixed(m, beat, i, fields, facts, offered, taken, fail, goto,
                                        last=i == len(program) - 1,
                                        offers=i == last_writer, done=done)
        return m

    def _fixed(self, m, beat, i, fields, facts, offered, taken, fail, goto, *, last, offers,
               done):
        """One fixed beat: its lanes land in ``fields`` (and a count in ``facts``), its
        constants are checked; the first beat waits until the last message's fields are
        taken."""
        inp, data = self.s_axis, self.s_axis.tdata
        writes, bad_format = [], []
        for lane in beat.lanes:
            part = lane.part
            for x in range(lane.nbytes):
                byte = data.word_select(lane.at + x, 8)
                index = lane.first + x
                if part.kind in ("field", "extend", "publisher"):
                    if index < part.leaf.width // 8:
                        writes.append(fields.word_select(part.leaf.offset // 8 + index, 8)
                                      .eq(byte))
                elif part.kind == "count" and index < 4:
                    offset = self.plan.variables[part.var].count.offset
                    writes.append(fields.word_select(offset // 8 + index, 8).eq(byte))
                elif part.kind == "const" and part.mask[index]:
                    bad_format.append((byte & part.mask[index]) != part.value[index])
        # a message's first beat waits until the last message's fields are taken
        m.d.comb += inp.tready.eq(~offered if i == 0 else 1)
        with m.If(taken):
            m.d.sync += writes
            for part in beat.parts("count"):
                v = self.plan.variables[part.var]
                facts.load(m, data, v.element_bytes,
                           v.bound or self._max_count)
            with m.If(Cat(*bad_format, Const(0, 1)).any()):
                fail(DeserializerError.FORMAT, inp.tlast)
            with m.Elif(~inp.tlast if last else inp.tlast):
                fail(*((DeserializerError.LATE_END, False) if last
                       else (DeserializerError.EARLY_END, True)))
            with m.Else():
                if offers:
                    m.d.sync += offered.eq(1)
                if last:
                    m.d.sync += done.eq(1)
                goto(0 if last else i + 1)

    def _payload(self, m, beat, i, facts, first, taken, fail, goto):
        """The beats of one string or sequence, straight through to its port."""
        inp = self.s_axis
        v = self.plan.variables[beat.var]
        port = getattr(self, payload_port(v, "m"))
        with m.If(first & facts.bad):
            fail(DeserializerError.LENGTH, False)
        with m.Elif(facts.empty):
            m.d.comb += [port.tvalid.eq(1), port.tkeep.eq(0), port.tlast.eq(1),
                         port.tuser.eq(1)]
            with m.If(port.tready):
                goto(i + 1)
        with m.Else():
            keep = Mux(facts.one, facts.keep, 0xFF) & Mux(inp.tlast, inp.tkeep, 0xFF)
            m.d.comb += [port.tvalid.eq(inp.tvalid), inp.tready.eq(port.tready),
                         port.tdata.eq(inp.tdata & _bytes_enabled(keep)), port.tkeep.eq(keep),
                         port.tlast.eq(facts.one | inp.tlast), port.tuser.eq(first)]
            with m.If(taken):
                m.d.sync += first.eq(0)
                facts.step(m)
                with m.If(inp.tlast):
                    fail(DeserializerError.EARLY_END, True)
                with m.Elif(facts.one):
                    goto(i + 1)


class ReconrosSerializer(wiring.Component):
    """Serializes messages of one type into ReconROS' framing, a beat at a time.

    Same ports, rules and error codes as :class:`~hdl.msg.Serializer` with a ``reconros``
    plan at 64 bits (see there). ``m_axis`` comes from flip-flops (one output register that
    moves a beat per cycle; its ``tready`` reaches the payload ports' ``tready``); an empty
    field's one input beat takes a cycle of its own, and an error is reported in the cycle
    after the beat that shows it.

    Parameters
    ----------
    plan : gen.msg.plan.StreamPlan
        The type in the ``reconros`` framing.
    data_width : int
        64.

    Members
    -------
    fields : In(amaranth.lib.stream.Signature(plan.layout))
    s_<field>_axis : In(AXIStreamSignature(64))
    m_axis : Out(AXIStreamSignature(64, user_width=1))
    error : Out(ErrorSignature())
    """

    def __init__(self, plan, data_width=64):
        self.program = beat_program(plan)
        check_plan_width(plan, data_width)
        self.plan = plan
        members = {"fields": In(stream.Signature(plan.layout))}
        for v in plan.streams:
            members[payload_port(v, "s")] = In(AXIStreamSignature(64))
        members["m_axis"] = Out(AXIStreamSignature(64, user_width=1))
        members["error"] = Out(ErrorSignature())
        super().__init__(members)

    @property
    def parameters(self):
        return {"type": self.plan.typename, "framing": self.plan.framing, "data_width": 64,
                "beats": True}

    def elaborate(self, platform):
        m = Module()
        plan, program = self.plan, self.program
        fv = self.fields.payload.as_value()
        out = self.m_axis
        # the output register: loads when empty or when its beat is taken
        load = Signal()
        m.d.comb += load.eq(~out.tvalid | out.tready)
        with m.If(out.tvalid & out.tready):
            m.d.sync += out.tvalid.eq(0)

        op = Signal(range(len(program)))
        facts = _PayloadFacts()
        filling = Signal()
        draining = Signal()
        code = Signal(3, name="error_code")
        m.d.comb += self.error.code.eq(code)
        m.d.sync += self.error.valid.eq(0)
        count_errors(m, self.error)

        def report(reason):
            m.d.sync += [self.error.valid.eq(1), code.eq(reason)]

        def emit(i, data):
            last = i == len(program) - 1
            m.d.sync += [out.tvalid.eq(1), out.tdata.eq(data), out.tkeep.eq(0xFF),
                         out.tlast.eq(last), out.tuser.eq(i != 0 and not last)]

        def finish(i):
            """Beat (or payload) ``i`` is out: on to the next, or to the next message."""
            if i == len(program) - 1:
                m.d.comb += self.fields.ready.eq(1)
                m.d.sync += op.eq(0)
            else:
                m.d.sync += op.eq(i + 1)

        with m.If(self.fields.valid):
            with m.Switch(op):
                for i, beat in enumerate(program):
                    with m.Case(i):
                        if not beat.payload:
                            data = Cat(*(self._lane_value(lane, fv, out.tdata)
                                         for lane in beat.lanes))
                            with m.If(load):
                                emit(i, data)
                                for part in beat.parts("count"):
                                    v = plan.variables[part.var]
                                    count = fv[v.count.offset:v.count.offset + 32]
                                    facts.load(m, count, v.element_bytes)
                                finish(i)
                            continue
                        port = getattr(self, payload_port(plan.variables[beat.var], "s"))
                        with m.If(draining):
                            m.d.comb += port.tready.eq(1)
                            with m.If(port.tvalid & port.tlast):
                                m.d.sync += draining.eq(0)
                                finish(i)
                        with m.Elif(filling):
                            with m.If(load):
                                emit(i, 0)
                                facts.step(m)
                                with m.If(facts.one):
                                    m.d.sync += filling.eq(0)
                                    finish(i)
                        with m.Elif(facts.empty):
                            # the field's one beat, data ignored
                            m.d.comb += port.tready.eq(1)
                            with m.If(port.tvalid):
                                with m.If(port.tlast):
                                    finish(i)
                                with m.Else():
                                    report(SerializerError.PAYLOAD_LONG)
                                    m.d.sync += draining.eq(1)
                        with m.Else():
                            keep = (Mux(facts.one, facts.keep, 0xFF)
                                    & Mux(port.tlast, port.tkeep, 0xFF))
                            m.d.comb += port.tready.eq(load)
                            with m.If(port.tvalid & load):
                                emit(i, port.tdata & _bytes_enabled(keep))
                                facts.step(m)
                                with m.If(facts.one):
                                    with m.If(~port.tlast):
                                        report(SerializerError.PAYLOAD_LONG)
                                        m.d.sync += draining.eq(1)
                                    with m.Else():
                                        with m.If(keep != facts.keep):
                                            report(SerializerError.PAYLOAD_SHORT)
                                        finish(i)
                                with m.Elif(port.tlast):
                                    report(SerializerError.PAYLOAD_SHORT)
                                    m.d.sync += filling.eq(1)
        return m

    def _lane_value(self, lane, fv, previous):
        """The bytes of ``lane`` from the fields (``previous``: the beat before, for the
        trailer)."""
        part, plan = lane.part, self.plan
        if part.kind == "const":
            value = Const(int.from_bytes(part.value, "little"), 8 * part.nbytes)
        elif part.kind in ("zero", "nul", "reserved"):
            value = Const(0, 8 * part.nbytes)
        elif part.kind == "field":
            value = fv[part.leaf.offset:part.leaf.offset + part.leaf.width]
        elif part.kind == "extend":
            leaf = fv[part.leaf.offset:part.leaf.offset + part.leaf.width]
            value = _extend(leaf.as_signed() if part.leaf.signed else leaf, 64)
        elif part.kind in ("count", "capacity"):
            v = plan.variables[part.var]
            value = Cat(fv[v.count.offset:v.count.offset + 32], Const(0, 32))
        elif part.kind == "publisher":
            value = Cat((fv[:32] + plan.publisher_offset)[:32], Const(0, 32))
        elif part.kind == "trailer":
            value = previous
        else:
            raise AssertionError(part.kind)
        return Value.cast(value)[8 * lane.first:8 * (lane.first + lane.nbytes)]
