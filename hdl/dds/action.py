"""Actions over hardware-mapped topics (docs/services.md).

An action uses the framing of :mod:`hdl.dds.service` on two topics: clients publish GOAL and
CANCEL frames on ``<action>_request``; the server publishes GOAL_RESPONSE, FEEDBACK, RESULT and
CANCEL_RESPONSE frames on ``<action>_reply``. A goal's id is the client's id and the sequence
number of its GOAL frame. The server executes one goal at a time: a goal that arrives while
another is being decided or executed is rejected at once.
"""

import enum

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int
from .arbiter import TopicArbiter
from .service import (BODY_STREAM, FRAME_HEADER, REQUEST_ID, FrameKind, FrameReceiver,
                      FrameSender, _counter, header_beat)
from .topic import HW_TOPIC_STREAM

__all__ = ["GoalStatus", "CancelStatus", "ActionServer", "ActionClient"]


class GoalStatus(enum.IntEnum):
    """``action_msgs/msg/GoalStatus`` codes; a RESULT frame's ``status`` is one of the last
    three."""
    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6


class CancelStatus(enum.IntEnum):
    """``status`` of a CANCEL_RESPONSE frame (``action_msgs/srv/CancelGoal`` return codes)."""
    ERROR_NONE = 0
    ERROR_REJECTED = 1
    ERROR_UNKNOWN_GOAL_ID = 2
    ERROR_GOAL_TERMINATED = 3


class ActionServer(wiring.Component):
    """The server's end of an action over hardware topics.

    Members
    -------
    request_in : In(HW_TOPIC_STREAM)
        The ``<action>_request`` topic. Frames other than a GOAL with a body or a CANCEL
        without one are dropped and counted in ``bad_frames``.
    goal : Out(BODY_STREAM)
        The body of a goal that arrived while no goal was being decided or executed.
    goal_id : Out(REQUEST_ID)
        Its id, valid from the goal's first beat until the goal ends.
    decision : In(stream.Signature(1))
        After a goal's body: 1 accepts it, 0 rejects it. The server answers GOAL_RESPONSE.
    active : Out(1)
        An accepted goal is being executed (from its GOAL_RESPONSE until its RESULT ends).
    feedback : In(BODY_STREAM)
        Feedback bodies of the active goal: each becomes a FEEDBACK frame.
    result : In(BODY_STREAM)
        The result body of the active goal; its last beat ends the goal.
    result_status : In(8)
        A :class:`GoalStatus`, sampled with the result's first beat.
    cancel_requested : Out(1)
        A CANCEL named the active goal; cleared when the goal ends. The node decides when to
        stop (and sends its result with status CANCELED).
    reply_out : Out(HW_TOPIC_STREAM)
        The ``<action>_reply`` topic.
    busy_rejects : Out(32)
        Goals rejected because another one was being decided or executed.
    unknown_cancels : Out(32)
        CANCEL frames naming no active goal: answered with ERROR_UNKNOWN_GOAL_ID.
    bad_frames : Out(32)
    """

    def __init__(self):
        super().__init__({"request_in": In(HW_TOPIC_STREAM),
                          "goal": Out(BODY_STREAM),
                          "goal_id": Out(REQUEST_ID),
                          "decision": In(stream.Signature(1)),
                          "active": Out(1),
                          "feedback": In(BODY_STREAM),
                          "result": In(BODY_STREAM),
                          "result_status": In(8),
                          "cancel_requested": Out(1),
                          "reply_out": Out(HW_TOPIC_STREAM),
                          "busy_rejects": Out(32),
                          "unknown_cancels": Out(32),
                          "bad_frames": Out(32)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.receiver = rx = FrameReceiver()
        m.submodules.control = control = FrameSender()
        m.submodules.feedback = feedback = FrameSender()
        m.submodules.result = result = FrameSender()
        m.submodules.arbiter = arbiter = TopicArbiter(HW_TOPIC_STREAM, 3)
        for i, sender in enumerate((control, feedback, result)):
            wiring.connect(m, sender.m_axis, arbiter.s_axis[i])
        wiring.connect(m, arbiter.m_axis, wiring.flipped(self.reply_out))
        wiring.connect(m, wiring.flipped(self.request_in), rx.s_axis)
        wiring.connect(m, rx.m_axis, wiring.flipped(self.goal))

        idle, deciding = Signal(init=1), Signal()
        gid = self.goal_id

        # GOAL_RESPONSE and CANCEL_RESPONSE wait in one register. An accepted goal becomes
        # active once its GOAL_RESPONSE has left it, so that response is the goal's first frame.
        held = Signal(FRAME_HEADER)
        held_valid = Signal()
        starting = Signal()
        m.d.comb += [control.header.valid.eq(held_valid), control.header.payload.header.eq(held),
                     control.header.payload.body.eq(0)]
        with m.If(control.header.valid & control.header.ready):
            m.d.sync += held_valid.eq(0)
            with m.If(starting):
                m.d.sync += [starting.eq(0), self.active.eq(1)]

        h = rx.header.payload.header
        body = rx.header.payload.body
        is_goal = (h.kind == FrameKind.GOAL) & body
        is_cancel = (h.kind == FrameKind.CANCEL) & ~body
        take_goal = is_goal & idle
        answers = (is_goal & ~idle) | is_cancel
        names_active = ((self.active | starting) & (h.client == gid.client) &
                        (h.sequence == gid.sequence))
        m.d.comb += [rx.header.ready.eq(~answers | ~held_valid), rx.forward.eq(take_goal)]
        taken = rx.header.valid & rx.header.ready
        with m.If(taken & take_goal):
            m.d.sync += [idle.eq(0), deciding.eq(1), gid.client.eq(h.client),
                         gid.sequence.eq(h.sequence)]
        with m.If(taken & answers):
            m.d.sync += [held_valid.eq(1), held.client.eq(h.client),
                         held.sequence.eq(h.sequence)]
            with m.If(is_goal):
                m.d.sync += [held.kind.eq(FrameKind.GOAL_RESPONSE), held.status.eq(0)]
            with m.Else():
                m.d.sync += [held.kind.eq(FrameKind.CANCEL_RESPONSE),
                             held.status.eq(Mux(names_active, CancelStatus.ERROR_NONE,
                                                CancelStatus.ERROR_UNKNOWN_GOAL_ID))]
                with m.If(names_active):
                    m.d.sync += self.cancel_requested.eq(1)
        _counter(m, self.busy_rejects, taken & is_goal & ~idle)
        _counter(m, self.unknown_cancels, taken & is_cancel & ~names_active)
        bad = Signal(32)
        _counter(m, bad, taken & ~is_goal & ~is_cancel)
        m.d.comb += self.bad_frames.eq(bad + rx.bad_frames)

        decision = self.decision
        m.d.comb += decision.ready.eq(deciding & ~held_valid &
                                      ~(rx.header.valid & answers))
        with m.If(decision.valid & decision.ready):
            m.d.sync += [held_valid.eq(1), held.kind.eq(FrameKind.GOAL_RESPONSE),
                         held.client.eq(gid.client), held.sequence.eq(gid.sequence),
                         held.status.eq(decision.payload), deciding.eq(0),
                         starting.eq(decision.payload), idle.eq(~decision.payload)]

        for sender, port, kind, status in ((feedback, self.feedback, FrameKind.FEEDBACK, 0),
                                           (result, self.result, FrameKind.RESULT,
                                            self.result_status)):
            m.d.comb += [sender.header.valid.eq(self.active & port.tvalid),
                         sender.header.payload.header.eq(header_beat(
                             m, kind=kind, client=gid.client, sequence=gid.sequence,
                             status=status)),
                         sender.header.payload.body.eq(1)]
            wiring.connect(m, wiring.flipped(port), sender.s_axis)
        with m.If(self.result.tvalid & self.result.tready & self.result.tlast):
            m.d.sync += [self.active.eq(0), idle.eq(1), self.cancel_requested.eq(0)]
        return m


class ActionClient(wiring.Component):
    """A client's end of an action over hardware topics: one goal at a time.

    Parameters
    ----------
    client_id : int
        This client's id on the action, 0..65535, unique among its clients.

    Members
    -------
    goal : In(BODY_STREAM)
        Goal bodies, taken when this client has no goal waiting for its response or its
        result; each becomes a GOAL frame numbered ``goal_sequence``.
    goal_sequence : Out(32)
        The number of the goal last sent (the next one gets the one after).
    cancel : In(stream.Signature(32))
        Sends a CANCEL naming the goal ``payload`` of this client; one at a time (the next is
        taken after the CANCEL_RESPONSE).
    request_out : Out(HW_TOPIC_STREAM)
        The ``<action>_request`` topic.
    reply_in : In(HW_TOPIC_STREAM)
        The ``<action>_reply`` topic.
    response : Out(stream.Signature(FRAME_HEADER))
        The header of each GOAL_RESPONSE, CANCEL_RESPONSE and RESULT for this client (a
        RESULT's before its body).
    feedback : Out(BODY_STREAM)
        FEEDBACK bodies of the goal in progress.
    result : Out(BODY_STREAM)
        The RESULT body of the goal.
    unmatched : Out(32)
        Frames with this client's id that answer nothing it asked (a response to a goal or
        cancel it did not send, feedback or a result of a goal not in progress): dropped.
    bad_frames : Out(32)
    """

    def __init__(self, client_id):
        self._client_id = check_int("client_id", client_id, 0, 0xFFFF)
        super().__init__({"goal": In(BODY_STREAM),
                          "goal_sequence": Out(32),
                          "cancel": In(stream.Signature(32)),
                          "request_out": Out(HW_TOPIC_STREAM),
                          "reply_in": In(HW_TOPIC_STREAM),
                          "response": Out(stream.Signature(FRAME_HEADER)),
                          "feedback": Out(BODY_STREAM),
                          "result": Out(BODY_STREAM),
                          "unmatched": Out(32),
                          "bad_frames": Out(32)})

    client_id = property(lambda self: self._client_id)

    def elaborate(self, platform):
        m = Module()
        me = self._client_id
        m.submodules.sender = tx = FrameSender()
        m.submodules.receiver = rx = FrameReceiver()
        wiring.connect(m, tx.m_axis, wiring.flipped(self.request_out))
        wiring.connect(m, wiring.flipped(self.reply_in), rx.s_axis)
        m.d.comb += self.bad_frames.eq(rx.bad_frames)

        waiting_response, in_progress = Signal(), Signal()
        cancelling, cancelled = Signal(), Signal(32)
        seq = self.goal_sequence
        next_seq = Signal(32)
        cancel = self.cancel
        send_cancel = cancel.valid & ~cancelling
        send_goal = self.goal.tvalid & ~waiting_response & ~in_progress & ~send_cancel
        m.d.comb += [
            tx.header.valid.eq(send_cancel | send_goal),
            tx.header.payload.header.eq(header_beat(
                m, kind=Mux(send_cancel, FrameKind.CANCEL, FrameKind.GOAL), client=me,
                sequence=Mux(send_cancel, cancel.payload, next_seq))),
            tx.header.payload.body.eq(~send_cancel),
            cancel.ready.eq(tx.header.ready & send_cancel),
        ]
        wiring.connect(m, wiring.flipped(self.goal), tx.s_axis)
        with m.If(tx.header.valid & tx.header.ready):
            with m.If(send_cancel):
                m.d.sync += [cancelling.eq(1), cancelled.eq(cancel.payload)]
            with m.Else():
                m.d.sync += [waiting_response.eq(1), seq.eq(next_seq), next_seq.eq(next_seq + 1)]

        h = rx.header.payload.header
        body = rx.header.payload.body
        mine = h.client == me
        of_goal = h.sequence == seq
        is_response = (h.kind == FrameKind.GOAL_RESPONSE) & ~body & waiting_response & of_goal
        is_feedback = (h.kind == FrameKind.FEEDBACK) & body & in_progress & of_goal
        is_result = (h.kind == FrameKind.RESULT) & body & in_progress & of_goal
        is_cancel = ((h.kind == FrameKind.CANCEL_RESPONSE) & ~body & cancelling &
                     (h.sequence == cancelled))
        reported = is_response | is_result | is_cancel
        matched = mine & (reported | is_feedback)
        resp = self.response
        m.d.comb += [resp.valid.eq(rx.header.valid & mine & reported), resp.payload.eq(h),
                     rx.header.ready.eq(~(mine & reported) | resp.ready),
                     rx.forward.eq(matched)]
        taken = rx.header.valid & rx.header.ready
        _counter(m, self.unmatched, taken & mine & ~matched)
        with m.If(taken & mine):
            with m.If(is_response):
                m.d.sync += [waiting_response.eq(0), in_progress.eq(h.status != 0)]
            with m.If(is_result):
                m.d.sync += in_progress.eq(0)
            with m.If(is_cancel):
                m.d.sync += cancelling.eq(0)

        to_result = Signal()
        with m.If(taken & matched):
            m.d.sync += to_result.eq(is_result)
        for port, chosen in ((self.feedback, ~to_result), (self.result, to_result)):
            m.d.comb += [port.tvalid.eq(rx.m_axis.tvalid & chosen), port.tdata.eq(rx.m_axis.tdata),
                         port.tkeep.eq(rx.m_axis.tkeep), port.tlast.eq(rx.m_axis.tlast)]
        m.d.comb += rx.m_axis.tready.eq(Mux(to_result, self.result.tready,
                                            self.feedback.tready))
        return m
