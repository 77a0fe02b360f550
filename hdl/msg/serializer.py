"""Message serializer generated from a stream plan (``gen.msg.plan``)."""

import enum

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int
from ..stream import AXIStreamSignature, keep_count
from .bytes import BytePacker, ChunkRegisterSlice, byte_mask
from .steps import RuntimeStep, pad_bytes, payload_bytes

__all__ = ["Serializer", "SerializerError", "ErrorSignature", "payload_port"]


class SerializerError(enum.IntEnum):
    """Reason codes of :class:`Serializer` ``error.code``."""
    #: a payload stream ended (``tlast``) before its count of bytes: the rest is sent as zeros
    PAYLOAD_SHORT = 1
    #: a payload stream went on after its count of bytes: the excess is dropped up to ``tlast``
    PAYLOAD_LONG = 2


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
        Messages with an error since reset (wraps).
    """

    def __init__(self):
        super().__init__({"valid": Out(1), "code": Out(3), "count": Out(32)})

    def __eq__(self, other):
        return type(other) is type(self)

    def __hash__(self):
        return hash(type(self))


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

    Members
    -------
    fields : In(amaranth.lib.stream.Signature(plan.layout))
        The fixed part of a message (primitives, fixed arrays and the element count of every
        variable-length field; ReconROS: also ``publisher``). It must stay valid and unchanged
        until ``ready``, which is asserted in the cycle the message's last byte is handed to the
        output stage.
    s_<field>_axis : In(AXIStreamSignature(data_width))
        One per variable-length field (``plan.variables``), read when the message reaches the
        field: exactly one packet per message with the field's bytes (count times element size,
        little endian; strings without NUL) in full beats, ``tlast`` on the last. An empty field
        is one beat with ``tlast`` (its data is ignored). ``tkeep`` counts on the last beat
        only. A packet that ends early is completed with zero bytes, one that goes on is cut
        and drained up to its ``tlast``; both are reported on ``error``.
    m_axis : Out(AXIStreamSignature(data_width[, user_width=1]))
        The messages, one packet each, ``tkeep`` all ones but on the last beat. ReconROS
        framing: ``tuser`` is 0 on the first and the last beat and 1 between (docs/topics.md).
    error : Out(ErrorSignature())
    """

    def __init__(self, plan, data_width=64):
        check_plan_width(plan, data_width)
        self.plan = plan
        self._width = data_width
        self._reconros = plan.framing == "reconros"
        members = {"fields": In(stream.Signature(plan.layout))}
        for v in plan.variables:
            members[payload_port(v, "s")] = In(AXIStreamSignature(data_width))
        members["m_axis"] = Out(AXIStreamSignature(data_width,
                                                   user_width=1 if self._reconros else 0))
        members["error"] = Out(ErrorSignature())
        super().__init__(members)

    @property
    def parameters(self):
        return {"type": self.plan.typename, "framing": self.plan.framing,
                "data_width": self._width}

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
        ports = [getattr(self, payload_port(v, "s")) for v in plan.variables]
        counts = [fv[v.count.offset:v.count.offset + 32] for v in plan.variables]
        lengths = [payload_bytes(v, c) for c, v in zip(counts, plan.variables)]

        op = Signal(range(max(len(steps), 2)))
        max_steps = max([-(-s.nbytes // B) for s in steps if s.kind == "run"] + [1])
        step = Signal(range(max_steps + 1))
        remaining = Signal(32)
        pos = Signal(32)
        fill = Signal()
        drain = Signal()
        recent = Signal(64)

        error_code = Signal(3)     # the last reported code
        code_now = Signal(3)
        m.d.comb += self.error.code.eq(Mux(self.error.valid, code_now, error_code))

        def report(code):
            m.d.comb += [self.error.valid.eq(1), code_now.eq(code)]
            m.d.sync += [error_code.eq(code), self.error.count.eq(self.error.count + 1)]

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
        for length in lengths:
            body = body + length
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

        # The fields stay valid until the cycle the message's last chunk is taken.
        with m.If(self.fields.valid):
            with m.Switch(op):
                for i, s in enumerate(steps):
                    last_op = i == len(steps) - 1
                    with m.Case(i):
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
                        length = pad_bytes(plan, s, pos, counts) if s.kind == "pad" \
                            else lengths[s.var]
                        walk = RuntimeStep(m, i, B, step=step, remaining=remaining,
                                           length=length, next_step=next_op)
                        left, k, final, advance = walk.left, walk.k, walk.final, walk.advance
                        m.d.comb += chunk.len.eq(k)

                        if s.kind == "pad":
                            m.d.comb += [chunk.valid.eq(1), chunk.last.eq(last_op & final)]
                            with m.If(chunk.ready):
                                advance()
                            continue
                        port = ports[s.var]
                        with m.If(drain):
                            m.d.comb += port.tready.eq(1)
                            with m.If(port.tvalid & port.tlast):
                                m.d.sync += drain.eq(0)
                                next_op(i)
                        with m.Elif(fill):
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
                                    m.d.sync += [fill.eq(1), step.eq(1),
                                                 remaining.eq(left - Mux(supplied < k, supplied,
                                                                         k))]
                                with m.Else():
                                    advance()
        return m


def _extend(value, width):
    """``value`` sign- or zero-extended (by its signedness) to ``width`` bits, as unsigned."""
    if value.shape().signed:
        return Cat(value, *([value[-1]] * (width - len(value))))
    return Cat(value, Const(0, width - len(value)))
