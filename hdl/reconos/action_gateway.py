"""A hardware thread that serves a software action by sending its goals to the same action
over hardware topics (docs/services.md): the gateway that makes an action between hardware
threads reachable from software and, with ``rosgate sim --ros2``, from DDS."""

from amaranth import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..dds.action import ActionClient
from ..dds.service import FrameKind
from ..dds.topic import HW_TOPIC_STREAM
from ..msg import Deserializer, Serializer
from .gateway import _OsifLock, _Receiver, _Transmitter, check_gateway_side, gateway_side
from .hwt import HardwareThread

__all__ = ["ActionGatewayThread"]


class ActionGatewayThread(HardwareThread):
    """Serves a software action (ReconOS ``rosactions``) by sending each goal to the action
    over hardware topics as one more client (r64).

    One goal at a time: ``ROS_ACTIONS_GOAL_TAKE``; the goal read over MEMIF and sent,
    serialized in CDR, as a GOAL frame (an :class:`~hdl.dds.action.ActionClient`); the
    hardware server's GOAL_RESPONSE becomes ``ROS_ACTIONS_GOAL_DECIDE``. An accepted goal:
    ``ROS_ACTIONS_RESULT_TAKE`` (the software client asks for the result), then each
    FEEDBACK body is written into the feedback message and sent with
    ``ROS_ACTIONS_FEEDBACK``, and the RESULT body into the result response, with the
    RESULT's status (SUCCEEDED, CANCELED or ABORTED) in its ``status`` field, sent with
    ``ROS_ACTIONS_RESULT_SEND``. Every ``poll_cycles`` while the goal runs
    ``ROS_ACTIONS_CANCEL_TRYTAKE`` asks whether software wants it canceled; if so a CANCEL
    frame goes to the server, whose RESULT then says CANCELED. A result body that does not
    read as the result type is answered with the empty result and the RESULT's status.

    Parameters
    ----------
    arch : str
        ``"r64"``.
    goal_plan, feedback_plan, result_plan : gen.msg.plan.StreamPlan
        ``cdr`` plans of ``<Action>_Goal``, ``_Feedback`` and ``_Result``.
    goal_layout, feedback_layout, result_layout : MemoryLayout
        Where their parts are in the messages the runtime hands over: the goal in the
        ``_SendGoal_Request``, the feedback in the ``_FeedbackMessage``, the result in the
        ``_GetResult_Response`` (offsets from the start of those structs).
    status_offset : int
        Byte offset of ``status`` (int8) in the ``_GetResult_Response``.
    client_id : int
        This gateway's id among the action's clients (its thread id + 1).
    h_as, h_goal, h_res, h_fb : int
        Handles of the action server, its goal request, result response and feedback
        message.
    request_port, reply_port : str
        Ports on the ``<action>_request`` and ``<action>_reply`` topics.
    max_count : int
        Largest element count of a string or sequence taken from feedback or a result.
    poll_cycles : int
        Cycles between two cancel checks while a goal runs.

    Members
    -------
    <request_port> : Out(HW_TOPIC_STREAM)
    <reply_port> : In(HW_TOPIC_STREAM)
    """

    def __init__(self, arch, *, goal_plan, feedback_plan, result_plan, goal_layout,
                 feedback_layout, result_layout, status_offset, client_id, h_as, h_goal,
                 h_res, h_fb, request_port="request_out", reply_port="reply_in",
                 max_count=1 << 20, poll_cycles=256):
        for name, plan, layout in (("goal_plan", goal_plan, goal_layout),
                                   ("feedback_plan", feedback_plan, feedback_layout),
                                   ("result_plan", result_plan, result_layout)):
            check_gateway_side(name, plan, layout, "actions")
        super().__init__(arch, {request_port: Out(HW_TOPIC_STREAM),
                                reply_port: In(HW_TOPIC_STREAM)})
        if self.arch.word_bits != 64:
            raise ValueError(f"arch {arch!r}: the gateway runs on r64 (64-bit memory words)")
        if not 1 <= poll_cycles <= 1 << 16:
            raise ValueError(f"poll_cycles {poll_cycles}: expected 1..65536")
        self.client = ActionClient(client_id)
        self.handles = (h_as, h_goal, h_res, h_fb)
        self.request_port, self.reply_port = request_port, reply_port
        self.max_count, self.poll_cycles = max_count, poll_cycles
        self.status_offset = status_offset
        self.goal = gateway_side(goal_plan, goal_layout)
        self.feedback = gateway_side(feedback_plan, feedback_layout)
        self.result = gateway_side(result_plan, result_layout)

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        h_as, h_goal, h_res, h_fb = self.handles
        m.submodules.client = client = self.client
        wiring.connect(m, client.request_out, wiring.flipped(getattr(self, self.request_port)))
        wiring.connect(m, wiring.flipped(getattr(self, self.reply_port)), client.reply_in)
        m.submodules.serializer = ser = Serializer(self.goal.plan, 64)
        wiring.connect(m, ser.m_axis, client.goal)
        m.submodules.feedback_deserializer = fb_des = Deserializer(
            self.feedback.plan, 64, max_count=self.max_count)
        wiring.connect(m, client.feedback, fb_des.s_axis)
        m.submodules.result_deserializer = res_des = Deserializer(
            self.result.plan, 64, max_count=self.max_count)

        started = Signal()
        lock = _OsifLock(m, second_receiver=True)
        status = Signal(8)              # the RESULT's status, written into the response
        fb_rx = _Receiver(self.feedback, m, os, mem, lock, started, fb_des, h_fb,
                          prefix="feedback", who=_OsifLock.RX)
        res_rx = _Receiver(self.result, m, os, mem, lock, started, res_des, h_res,
                           prefix="result", who=_OsifLock.RX2,
                           fixed={self.status_offset: status})
        tx = _Transmitter(self.goal, m, os, mem, lock, started, ser, early_ready=True)

        # the result's body goes to its receiver once every feedback before it is sent: the
        # two receivers never write memory at the same time
        result_seen = Signal()
        feedback_fsm = fb_rx.build(lambda then: os.ros_actions_feedback(h_as, h_fb, then=then))
        feedback_idle = feedback_fsm.ongoing("RX_IDLE") & ~fb_rx.arriving
        gate = result_seen & feedback_idle
        m.d.comb += [res_des.s_axis.tdata.eq(client.result.tdata),
                     res_des.s_axis.tkeep.eq(client.result.tkeep),
                     res_des.s_axis.tlast.eq(client.result.tlast),
                     res_des.s_axis.tvalid.eq(client.result.tvalid & gate),
                     client.result.tready.eq(res_des.s_axis.tready & gate)]
        result_fsm = res_rx.build(
            lambda then: os.ros_actions_result_send(h_as, h_res, then=then),
            failed="RX_EMPTY")
        result_sent = Signal()
        with m.If(result_fsm.ongoing("RX_PUBLISH_FREE")):
            m.d.sync += result_sent.eq(1)

        with m.FSM(name="start"):
            with m.State("INIT"):
                os.thread_init(then="FEEDBACK_ADDR")
            with m.State("FEEDBACK_ADDR"):
                os.memory_getobjaddr(h_fb, ptr=fb_rx.msg, then="RESULT_ADDR")
            with m.State("RESULT_ADDR"):
                os.memory_getobjaddr(h_res, ptr=res_rx.msg, then="RUN")
            with m.State("RUN"):
                m.d.comb += started.eq(1)

        response = client.response
        header = response.payload
        accepted = Signal()
        canceled = Signal()             # the reply's low bit: 0, a cancel was asked for
        cancel_sent = Signal()
        wait = Signal(range(self.poll_cycles + 1))
        with m.If(wait != 0):
            m.d.sync += wait.eq(wait - 1)

        def take_states():
            lock.call(_OsifLock.TX, "TX_TAKE", lambda then: os.ros_actions_goal_take(
                h_as, h_goal, ptr=tx.ptr, then=then), "TX_READ")

        def goal_states():
            with m.State("GOAL_RESPONSE"):
                m.d.comb += response.ready.eq(1)
                with m.If(response.valid & (header.kind == FrameKind.GOAL_RESPONSE)):
                    m.d.sync += accepted.eq(header.status == 1)
                    m.next = "DECIDE"
            lock.call(_OsifLock.TX, "DECIDE", lambda then: os.ros_actions_goal_decide(
                h_as, accepted, then=then), "DECIDED")
            with m.State("DECIDED"):
                m.d.sync += [result_seen.eq(0), result_sent.eq(0), cancel_sent.eq(0),
                             wait.eq(self.poll_cycles)]
                m.next = "RESULT_TAKE"
                with m.If(~accepted):
                    m.next = "TX_IDLE"
            lock.call(_OsifLock.TX, "RESULT_TAKE", lambda then: os.ros_actions_result_take(
                h_as, then=then), "RUNNING")
            with m.State("RUNNING"):
                m.d.comb += response.ready.eq(1)
                with m.If(response.valid & (header.kind == FrameKind.RESULT)):
                    m.d.sync += [status.eq(header.status), result_seen.eq(1)]
                    m.next = "FINISH"
                with m.Elif(~response.valid & (wait == 0) & ~cancel_sent):
                    m.next = "CANCEL_CHECK"
            lock.call(_OsifLock.TX, "CANCEL_CHECK", lambda then: os.ros_actions_cancel_trytake(
                h_as, ret=canceled, then=then), "CANCEL_DECIDE")
            with m.State("CANCEL_DECIDE"):
                m.d.sync += wait.eq(self.poll_cycles)
                with m.If(canceled == 0):
                    m.next = "CANCEL_SEND"
                with m.Else():
                    m.next = "RUNNING"
            with m.State("CANCEL_SEND"):
                m.d.comb += [client.cancel.valid.eq(1),
                             client.cancel.payload.eq(client.goal_sequence)]
                with m.If(client.cancel.ready):
                    m.d.sync += cancel_sent.eq(1)
                    m.next = "RUNNING"
            with m.State("FINISH"):
                m.d.comb += response.ready.eq(1)        # a late CANCEL_RESPONSE
                with m.If(result_sent):
                    m.d.sync += [result_seen.eq(0), result_sent.eq(0)]
                    m.next = "TX_IDLE"
        tx.build(take_states, sent="GOAL_RESPONSE", extra_states=goal_states)
        return m
