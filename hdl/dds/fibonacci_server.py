"""The Fibonacci action as a node on hardware topics (docs/services.md)."""

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..msg import Deserializer, Serializer
from ..msg.serializer import payload_port
from ..params import ParameterError, check_int
from ..stream import RegisterSlice, StreamRepacker
from .action import ActionServer, GoalStatus
from .topic import HW_TOPIC_STREAM

__all__ = ["FibonacciServer", "MAX_ORDER"]

#: the largest order whose sequence fits int32: F(46) = 1,836,311,903
MAX_ORDER = 46


class FibonacciServer(wiring.Component):
    """An action server on hardware topics with ROS 2's ``Fibonacci`` action (``int32 order
    --- int32[] sequence --- int32[] sequence``).

    A goal of order ``n`` (0 <= n <= :data:`MAX_ORDER`) is accepted; any other (or a goal the
    deserializer rejects) is rejected. The sequence F(0), F(1), ... is computed one value per
    step, ``step_cycles`` apart (the work a real node would do between feedbacks). After F(k)
    (k = 1..n) the feedback carries F(0..k); the result carries F(0..n) with status SUCCEEDED.
    A cancel of the goal is honoured before the next step: the result then carries the values
    so far with status CANCELED.

    Parameters
    ----------
    goal_plan, result_plan : gen.msg.plan.StreamPlan
        ``cdr`` plans of the goal (one ``int32``) and of the result (one ``int32[]``); the
        feedback has the result's form.
    step_cycles : int
        Cycles before each value, 0..2**24.

    Members
    -------
    request_in : In(HW_TOPIC_STREAM)
    reply_out : Out(HW_TOPIC_STREAM)
        The action's topics (:class:`~hdl.dds.action.ActionServer`).
    server : the ActionServer's counters
        ``busy_rejects``, ``unknown_cancels``, ``bad_frames``: Out(32) each.
    """

    def __init__(self, goal_plan, result_plan, *, step_cycles=1000):
        for name, plan in (("goal_plan", goal_plan), ("result_plan", result_plan)):
            if plan.framing != "cdr":
                raise ParameterError(name, plan.framing, "the 'cdr' framing")
        leaves = [leaf for leaf in goal_plan.leaves if leaf.type == "int32"]
        if goal_plan.streams or len(leaves) != 1:
            raise ParameterError("goal_plan", goal_plan.typename, "a type with one int32")
        streams = result_plan.streams
        if len(streams) != 1 or streams[0].element_bytes != 4 or len(result_plan.layout.members) != 1:
            raise ParameterError("result_plan", result_plan.typename,
                                 "a type whose only field is an int32[]")
        self._order = leaves[0].path
        self._sequence = streams[0]
        self.goal_plan, self.result_plan = goal_plan, result_plan
        self._step_cycles = check_int("step_cycles", step_cycles, 0, 1 << 24)
        super().__init__({"request_in": In(HW_TOPIC_STREAM),
                          "reply_out": Out(HW_TOPIC_STREAM),
                          "busy_rejects": Out(32),
                          "unknown_cancels": Out(32),
                          "bad_frames": Out(32)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.server = server = ActionServer()
        m.submodules.deserializer = des = Deserializer(self.goal_plan, 64)
        m.submodules.serializer = ser = Serializer(self.result_plan, 64)
        m.submodules.packer = packer = StreamRepacker(4, 8)
        wiring.connect(m, wiring.flipped(self.request_in), server.request_in)
        wiring.connect(m, server.reply_out, wiring.flipped(self.reply_out))
        wiring.connect(m, server.goal, des.s_axis)
        for name in ("busy_rejects", "unknown_cancels", "bad_frames"):
            m.d.comb += getattr(self, name).eq(getattr(server, name))
        wiring.connect(m, packer.m_axis, getattr(ser, payload_port(self._sequence, "s")))
        to_result = Signal()
        # the serializer's messages leave through a register slice: the action server's port
        # choice and ready do not reach back into the serializer's byte packer
        m.submodules.out_slice = out = RegisterSlice(ser.signature.members["m_axis"].signature)
        wiring.connect(m, ser.m_axis, out.s_axis)

        order = Signal(32)
        computed = Signal(range(64))      # index of the last value computed
        wait = Signal(range(self._step_cycles + 2))
        a, b = Signal(32), Signal(32, init=1)     # the generator: F(i), F(i + 1)
        tail_seen = Signal()
        tail_out = out.m_axis.tvalid & out.m_axis.tready & out.m_axis.tlast
        emitted = Signal(range(64))
        status = Signal(8)
        good_order = (~order[31]) & (order <= MAX_ORDER)

        # the serializer's messages go to FEEDBACK or RESULT
        for port, chosen in ((server.feedback, ~to_result), (server.result, to_result)):
            m.d.comb += [port.tvalid.eq(out.m_axis.tvalid & chosen),
                         port.tdata.eq(out.m_axis.tdata), port.tkeep.eq(out.m_axis.tkeep),
                         port.tlast.eq(out.m_axis.tlast)]
        m.d.comb += [out.m_axis.tready.eq(Mux(to_result, server.result.tready,
                                              server.feedback.tready)),
                     server.result_status.eq(status),
                     ser.fields.payload[self._sequence.path].eq(computed + 1),
                     packer.s_axis.tdata.eq(a), packer.s_axis.tkeep.eq(0xF),
                     packer.s_axis.tlast.eq(emitted == computed)]

        with m.FSM():
            with m.State("IDLE"):
                m.d.comb += des.fields.ready.eq(1)
                with m.If(des.fields.valid):
                    m.d.sync += order.eq(des.fields.payload[self._order])
                    with m.If(des.done):
                        m.next = "DECIDE"
                    with m.Else():
                        m.next = "VERDICT"
                with m.Elif(des.error.valid):
                    m.d.sync += order.eq(-1)
                    m.next = "DECIDE"
            with m.State("VERDICT"):
                with m.If(des.error.valid):
                    m.d.sync += order.eq(-1)
                with m.If(des.done | des.error.valid):
                    m.next = "DECIDE"
            with m.State("DECIDE"):
                m.d.comb += [server.decision.valid.eq(1), server.decision.payload.eq(good_order)]
                with m.If(server.decision.ready):
                    m.d.sync += [computed.eq(0), wait.eq(self._step_cycles)]
                    with m.If(good_order):
                        m.next = "STEP"
                    with m.Else():
                        m.next = "IDLE"
            with m.State("STEP"):
                with m.If(computed == order[:6]):
                    m.d.sync += [to_result.eq(1), status.eq(GoalStatus.SUCCEEDED),
                                 tail_seen.eq(0)]
                    m.next = "SEND"
                with m.Elif(server.cancel_requested):
                    m.d.sync += [to_result.eq(1), status.eq(GoalStatus.CANCELED),
                                 tail_seen.eq(0)]
                    m.next = "SEND"
                with m.Elif(wait != 0):
                    m.d.sync += wait.eq(wait - 1)
                with m.Else():
                    m.d.sync += [computed.eq(computed + 1), wait.eq(self._step_cycles),
                                 to_result.eq(0), tail_seen.eq(0)]
                    m.next = "SEND"
            with m.State("SEND"):
                with m.If(tail_out):
                    m.d.sync += tail_seen.eq(1)
                m.d.comb += [ser.fields.valid.eq(1), packer.s_axis.tvalid.eq(emitted <= computed)]
                with m.If(packer.s_axis.tvalid & packer.s_axis.tready):
                    m.d.sync += [a.eq(b), b.eq(a + b), emitted.eq(emitted + 1)]
                with m.If(ser.fields.ready):
                    m.d.sync += [a.eq(0), b.eq(1), emitted.eq(0)]
                    m.next = "SENT"
            with m.State("SENT"):
                # the message's last beat may still be in the serializer or the slice: it
                # must reach the port it was meant for before ``to_result`` changes (the
                # action server must see the same order of events as without the slice)
                with m.If((tail_seen | tail_out) & to_result):
                    m.next = "IDLE"
                with m.Elif(tail_seen | tail_out):
                    m.next = "STEP"
        return m
