"""Hardware threads on services and actions over hardware topics (docs/services.md): a node
that only talks on hardware topics, and hardware clients that software drives through
mailboxes."""

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..dds import HW_TOPIC_STREAM
from ..dds.action import ActionClient
from ..dds.service import FrameKind, ReplyStatus, ServiceClient
from ..msg import Deserializer, Serializer
from ..msg.serializer import payload_port
from ..params import ParameterError, check_power_of_two
from ..stream import AXIStreamSignature, StreamFIFO
from .hwt import HardwareThread

__all__ = ["TopicNodeThread", "SortClientThread", "FibonacciClientThread", "CallStatus"]


class CallStatus:
    """First word a client thread reports per call (low byte)."""
    OK = 0
    #: the server answered BAD_REQUEST (a service) or rejected the goal (an action)
    REFUSED = 1
    #: the request was larger than the thread's buffer: not sent
    TOO_LARGE = 2
    #: the reply could not be read (a bad body)
    BAD_REPLY = 3


class TopicNodeThread(HardwareThread):
    """A node that only talks on hardware topics, in a slot: the slot's OSIF and MEMIF stay
    idle.

    Parameters
    ----------
    arch : str
    node : wiring.Component
        With stream members for the topics.
    ports : dict
        Thread port (the hardware-topic endpoint's name) -> the node's member.
    """

    def __init__(self, arch, node, ports):
        self.node = node
        self.ports = dict(ports)
        members = {}
        for port, member in self.ports.items():
            flow = node.signature.members[member].flow
            members[port] = flow(HW_TOPIC_STREAM)
        super().__init__(arch, members)

    def elaborate(self, platform):
        m = Module()
        m.submodules.node = self.node
        for port, member in self.ports.items():
            inner, outer = getattr(self.node, member), getattr(self, port)
            if self.node.signature.members[member].flow == In:
                wiring.connect(m, wiring.flipped(outer), inner)
            else:
                wiring.connect(m, inner, wiring.flipped(outer))
        return m


def _single_sequence(plan, what, element_bytes=4):
    streams = plan.streams
    if (len(streams) != 1 or len(plan.layout.members) != 1 or
            streams[0].element_bytes != element_bytes or streams[0].elements):
        raise ParameterError(what, plan.typename, "a type whose only field is a sequence of "
                                                  f"{8 * element_bytes}-bit values")
    return streams[0]


def put_words(m, os, fifo, h_mbox, left, high, state, *, then):
    """States ``state`` and ``state + "_NEXT"``: put ``left`` words of ``fifo`` (64-bit beats,
    two words each, ``tkeep`` on the last; a ``tkeep``-0 beat is an empty packet) into
    mailbox ``h_mbox``, then drop the rest of the packet up to its ``tlast``. ``left`` and
    ``high`` (0) are set before."""
    beat = fifo.m_axis
    with m.State(state):
        with m.If(beat.tvalid & ((left == 0) | (beat.tkeep == 0))):
            m.d.comb += beat.tready.eq(1)
            with m.If(beat.tlast):
                m.next = then
        with m.Elif(beat.tvalid):
            os.mbox_put(h_mbox, Mux(high, beat.tdata[32:], beat.tdata[:32]),
                        then=state + "_NEXT")
    with m.State(state + "_NEXT"):
        m.d.sync += [left.eq(left - 1), high.eq(~high)]
        with m.If(high | (left == 1) | ~beat.tkeep[4]):
            m.d.comb += beat.tready.eq(1)
            m.d.sync += high.eq(0)
            with m.If(beat.tlast):
                m.next = then
            with m.Else():
                m.next = state
        with m.Else():
            m.next = state


def report_states(m, os, h_done, status_word, status, cycles, count, fifo, *, then):
    """The states that report a call into mailbox ``h_done``: ``STATUS`` (``status_word``),
    ``CYCLES``, ``RESULT_COUNT``, then the ``count`` result words of ``fifo`` when ``status``
    is OK, else whatever ``fifo`` holds is dropped (a refused call left nothing, a bad reply
    perhaps a cut packet); then ``then``."""
    left, high = Signal(32, name="report_left"), Signal(name="report_high")
    with m.State("STATUS"):
        os.mbox_put(h_done, status_word, then="CYCLES")
    with m.State("CYCLES"):
        os.mbox_put(h_done, cycles, then="RESULT_COUNT")
    with m.State("RESULT_COUNT"):
        m.d.sync += [left.eq(count), high.eq(0)]
        with m.If(status == CallStatus.OK):
            os.mbox_put(h_done, count, then="RESULT_VALUES")
        with m.Else():
            os.mbox_put(h_done, count, then="DRAIN")
    put_words(m, os, fifo, h_done, left, high, "RESULT_VALUES", then=then)
    drain(m, fifo, "DRAIN", then=then)


def drain(m, fifo, state, *, then):
    """State ``state``: drop whatever ``fifo`` holds, then go to ``then``."""
    with m.State(state):
        m.d.comb += fifo.m_axis.tready.eq(1)
        with m.If(~fifo.m_axis.tvalid):
            m.next = then


class SortClientThread(HardwareThread):
    """A hardware client of a sort-like service over hardware topics (request and reply a
    ``uint32[]`` each), driven by software through two mailboxes.

    Per call: from ``h_cmd`` the value count ``n``, then the ``n`` values (kept in a FIFO
    until all are there, so the request crosses the topic at full rate); the request is sent;
    the reply's values are kept likewise. Into ``h_done``: the status (:class:`CallStatus`),
    the cycles, the reply's count and its values. The cycles count from the request's creation (its serializer starting) to the
    reply's last byte read.

    Parameters
    ----------
    arch : str
    client_id : int
        The client's id on the service (the thread id).
    request_plan, reply_plan : gen.msg.plan.StreamPlan
        ``cdr`` plans of the request and reply.
    h_cmd, h_done : int
        Mailbox handles.
    request_port, reply_port : str
        Names of the thread's hardware-topic ports.
    max_count : int
        Most values per request and per reply, a power of two in 4..65536 (default 2048).
    """

    def __init__(self, arch, client_id, request_plan, reply_plan, *, h_cmd, h_done,
                 request_port, reply_port, max_count=2048):
        self._in = _single_sequence(request_plan, "request_plan")
        self._out = _single_sequence(reply_plan, "reply_plan")
        self._max = check_power_of_two("max_count", max_count, 4, 1 << 16)
        self.client = ServiceClient(client_id, pending=1)
        self.request_plan, self.reply_plan = request_plan, reply_plan
        self.handles = (h_cmd, h_done)
        self.request_port, self.reply_port = request_port, reply_port
        super().__init__(arch, {request_port: Out(HW_TOPIC_STREAM),
                                reply_port: In(HW_TOPIC_STREAM)})

    def elaborate(self, platform):
        m = Module()
        os, _ = self.os_and_memory(m)
        h_cmd, h_done = self.handles
        m.submodules.client = client = self.client
        m.submodules.serializer = ser = Serializer(self.request_plan, 64)
        m.submodules.deserializer = des = Deserializer(self.reply_plan, 64,
                                                       max_count=self._max)
        beats = AXIStreamSignature(64)
        m.submodules.values_out = out_fifo = StreamFIFO(beats, self._max // 2)
        m.submodules.values_in = in_fifo = StreamFIFO(AXIStreamSignature(64, user_width=1),
                                                      self._max // 2)
        wiring.connect(m, client.request_out, wiring.flipped(getattr(self, self.request_port)))
        wiring.connect(m, wiring.flipped(getattr(self, self.reply_port)), client.reply_in)
        wiring.connect(m, ser.m_axis, client.request)
        wiring.connect(m, client.reply, des.s_axis)
        wiring.connect(m, getattr(des, payload_port(self._out, "m")), in_fifo.s_axis)
        values = getattr(ser, payload_port(self._in, "s"))

        n, got, low = Signal(32), Signal(32), Signal(32)
        word = Signal(self.arch.word_bits)
        status, cycles, count = Signal(8), Signal(32), Signal(32)
        timing = Signal()
        with m.If(timing):
            m.d.sync += cycles.eq(cycles + 1)
        m.d.comb += ser.fields.payload[self._in.path].eq(n)
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="COUNT")
            with m.State("COUNT"):
                os.mbox_get(h_cmd, data=word, then="CHECK")
            with m.State("CHECK"):
                m.d.sync += [n.eq(word), got.eq(0), cycles.eq(0), count.eq(0)]
                with m.If(word[:32] > self._max):
                    m.next = "DISCARD"
                with m.Elif(word[:32] == 0):
                    m.next = "SEND"
                with m.Else():
                    m.next = "VALUE"
            with m.State("VALUE"):
                os.mbox_get(h_cmd, data=word, then="STORE")
            with m.State("STORE"):
                last = got + 1 == n
                m.d.comb += [out_fifo.s_axis.tdata.eq(Cat(Mux(got[0], low, word[:32]),
                                                          Mux(got[0], word[:32], 0))),
                             out_fifo.s_axis.tkeep.eq(Mux(got[0], 0xFF, 0x0F)),
                             out_fifo.s_axis.tlast.eq(last),
                             out_fifo.s_axis.tvalid.eq(got[0] | last)]
                m.d.sync += [low.eq(word[:32]), got.eq(got + 1)]
                m.next = "VALUE"
                with m.If(last):
                    m.next = "SEND"
            with m.State("DISCARD"):
                os.mbox_get(h_cmd, data=word, then="DISCARDED")
            with m.State("DISCARDED"):
                m.d.sync += got.eq(got + 1)
                with m.If(got + 1 >= n):
                    m.d.sync += status.eq(CallStatus.TOO_LARGE)
                    m.next = "STATUS"
                with m.Else():
                    m.next = "DISCARD"
            with m.State("SEND"):
                m.d.comb += ser.fields.valid.eq(1)
                with m.If(n == 0):   # an empty field is one beat with tlast
                    m.d.comb += [values.tvalid.eq(1), values.tlast.eq(1), values.tkeep.eq(0)]
                with m.Else():
                    wiring.connect(m, out_fifo.m_axis, values)
                m.d.sync += timing.eq(1)
                with m.If(ser.fields.ready):
                    m.next = "REPLY"
            with m.State("REPLY"):
                m.d.comb += client.reply_info.ready.eq(1)
                with m.If(client.reply_info.valid):
                    with m.If(client.reply_info.payload.status == ReplyStatus.OK):
                        m.next = "RECEIVE"
                    with m.Else():
                        m.d.sync += [timing.eq(0), status.eq(CallStatus.REFUSED)]
                        m.next = "STATUS"
            with m.State("RECEIVE"):
                m.d.comb += des.fields.ready.eq(1)
                with m.If(des.fields.valid):
                    m.d.sync += count.eq(des.fields.payload[self._out.path])
                with m.If(des.done):
                    m.d.sync += [timing.eq(0), status.eq(CallStatus.OK)]
                    m.next = "STATUS"
                with m.If(des.error.valid):
                    m.d.sync += [timing.eq(0), status.eq(CallStatus.BAD_REPLY), count.eq(0)]
                    m.next = "STATUS"
            report_states(m, os, h_done, status, status, cycles, count, in_fifo, then="COUNT")
        return m


class FibonacciClientThread(HardwareThread):
    """A hardware client of a Fibonacci-like action over hardware topics (goal: one
    ``int32``; result and feedback: an ``int32[]``), driven by software through two
    mailboxes.

    Per goal, one word from ``h_cmd``: bits 0-7 the order (signed), bits 8-15 ``cancel_after``
    (cancel the goal once that many feedbacks have arrived; 0: never), bit 16: also cancel a
    goal this client never sent (its next number plus 100) right after the goal. Into
    ``h_done``: a status word (bits 0-7 :class:`CallStatus`, 8-15 the result's
    ``GoalStatus``, 16-23 the last CANCEL_RESPONSE's code (255: none), 24-31 the feedbacks
    received), the cycles from the goal's creation to the result's last byte read, the
    result's count and its values. Feedback bodies are counted and dropped.

    Parameters
    ----------
    arch : str
    client_id : int
    goal_plan, result_plan : gen.msg.plan.StreamPlan
    h_cmd, h_done : int
    request_port, reply_port : str
    max_count : int
        Most values in a result, a power of two in 4..65536 (default 64).
    """

    def __init__(self, arch, client_id, goal_plan, result_plan, *, h_cmd, h_done,
                 request_port, reply_port, max_count=64):
        leaves = [leaf for leaf in goal_plan.leaves if leaf.type == "int32"]
        if goal_plan.streams or len(leaves) != 1:
            raise ParameterError("goal_plan", goal_plan.typename, "a type with one int32")
        self._order = leaves[0].path
        self._seq = _single_sequence(result_plan, "result_plan")
        self._max = check_power_of_two("max_count", max_count, 4, 1 << 16)
        self.client = ActionClient(client_id)
        self.goal_plan, self.result_plan = goal_plan, result_plan
        self.handles = (h_cmd, h_done)
        self.request_port, self.reply_port = request_port, reply_port
        super().__init__(arch, {request_port: Out(HW_TOPIC_STREAM),
                                reply_port: In(HW_TOPIC_STREAM)})

    def elaborate(self, platform):
        m = Module()
        os, _ = self.os_and_memory(m)
        h_cmd, h_done = self.handles
        m.submodules.client = client = self.client
        m.submodules.serializer = ser = Serializer(self.goal_plan, 64)
        m.submodules.deserializer = des = Deserializer(self.result_plan, 64,
                                                       max_count=self._max)
        m.submodules.values_in = in_fifo = StreamFIFO(AXIStreamSignature(64, user_width=1),
                                                      self._max // 2)
        wiring.connect(m, client.request_out, wiring.flipped(getattr(self, self.request_port)))
        wiring.connect(m, wiring.flipped(getattr(self, self.reply_port)), client.reply_in)
        wiring.connect(m, ser.m_axis, client.goal)
        wiring.connect(m, client.result, des.s_axis)
        wiring.connect(m, getattr(des, payload_port(self._seq, "m")), in_fifo.s_axis)
        m.d.comb += client.feedback.tready.eq(1)

        command = Signal(self.arch.word_bits)
        order = command[:8].as_signed()
        cancel_after, stranger = command[8:16], command[16]
        m.d.comb += ser.fields.payload[self._order].eq(order)
        feedbacks, cancel_code = Signal(8), Signal(8)
        result_status, status = Signal(8), Signal(8)
        cancel_sent, cancels_open, result_done = Signal(), Signal(2), Signal()
        cycles, count = Signal(32), Signal(32)
        timing = Signal()
        goal = client.goal_sequence
        with m.If(timing):
            m.d.sync += cycles.eq(cycles + 1)
        with m.If(client.feedback.tvalid & client.feedback.tlast):
            m.d.sync += feedbacks.eq(feedbacks + 1)

        # responses of the goal in flight
        resp = client.response
        m.d.comb += resp.ready.eq(1)
        with m.If(resp.valid):
            with m.Switch(resp.payload.kind):
                with m.Case(FrameKind.RESULT):
                    m.d.sync += result_status.eq(resp.payload.status)
                with m.Case(FrameKind.CANCEL_RESPONSE):
                    m.d.sync += cancel_code.eq(resp.payload.status)
        cancel_in = client.cancel.valid & client.cancel.ready
        cancel_back = resp.valid & (resp.payload.kind == FrameKind.CANCEL_RESPONSE)
        m.d.sync += cancels_open.eq(cancels_open + cancel_in - cancel_back)

        cancel_now = Signal(32)
        m.d.comb += client.cancel.payload.eq(cancel_now)
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="COMMAND")
            with m.State("COMMAND"):
                os.mbox_get(h_cmd, data=command, then="GOAL")
                m.d.sync += [feedbacks.eq(0), cancel_code.eq(0xFF), result_status.eq(0),
                             cancel_sent.eq(0), result_done.eq(0),
                             cycles.eq(0), count.eq(0)]
            with m.State("GOAL"):
                m.d.comb += ser.fields.valid.eq(1)
                m.d.sync += timing.eq(1)
                with m.If(ser.fields.ready):
                    m.next = "RESPONSE"
            with m.State("RESPONSE"):
                with m.If(resp.valid & (resp.payload.kind == FrameKind.GOAL_RESPONSE)):
                    with m.If(resp.payload.status == 0):
                        m.d.sync += [timing.eq(0), status.eq(CallStatus.REFUSED)]
                        m.next = "STATUS"
                    with m.Elif(stranger):
                        m.d.sync += cancel_now.eq(goal + 100)
                        m.next = "CANCEL_STRANGER"
                    with m.Else():
                        m.next = "RUNNING"
            with m.State("CANCEL_STRANGER"):
                m.d.comb += client.cancel.valid.eq(1)
                with m.If(client.cancel.ready):
                    m.next = "RUNNING"
            with m.State("RUNNING"):
                with m.If(~cancel_sent & ~result_done & (cancel_after != 0) &
                          (feedbacks >= cancel_after) & (cancels_open == 0)):
                    m.d.sync += cancel_now.eq(goal)
                    m.next = "CANCEL"
                m.d.comb += des.fields.ready.eq(1)
                with m.If(des.fields.valid):
                    m.d.sync += count.eq(des.fields.payload[self._seq.path])
                with m.If(des.done | des.error.valid):
                    m.d.sync += [timing.eq(0), result_done.eq(1),
                                 status.eq(Mux(des.done, CallStatus.OK, CallStatus.BAD_REPLY))]
                with m.If(result_done & (cancels_open == 0)):
                    m.next = "STATUS"
            with m.State("CANCEL"):
                m.d.comb += [client.cancel.valid.eq(1), des.fields.ready.eq(1)]
                with m.If(des.fields.valid):
                    m.d.sync += count.eq(des.fields.payload[self._seq.path])
                with m.If(des.done | des.error.valid):
                    m.d.sync += [timing.eq(0), result_done.eq(1),
                                 status.eq(Mux(des.done, CallStatus.OK, CallStatus.BAD_REPLY))]
                with m.If(client.cancel.ready):
                    m.d.sync += cancel_sent.eq(1)
                    m.next = "RUNNING"
            report_states(m, os, h_done, Cat(status, result_status, cancel_code, feedbacks),
                          status, cycles, count, in_fifo, then="COMMAND")
        return m
