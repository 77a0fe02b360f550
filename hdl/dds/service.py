"""Services over hardware-mapped topics (docs/services.md).

A service is two hardware topics: clients publish requests on ``<service>_request``, the
server publishes replies on ``<service>_reply``, which every client subscribes. Each message on
them is a *frame*: one 64-bit header beat (:data:`FRAME_HEADER`) and, after it, the body: the
request or reply message in the ``cdr`` framing, as a DDS participant carries it. The header's
``client`` and ``sequence`` are the request id (ROS 2's writer GUID and sequence number): a
client numbers its requests, the server copies the id into the reply, and a client takes only
replies with its own id to a request it has outstanding, so concurrent clients share the topics
without seeing each other's replies.
"""

import enum

from amaranth.hdl import Const, Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.fifo import SyncFIFOBuffered
from amaranth.lib.wiring import In, Out

from ..params import check_int, check_power_of_two
from ..stream import AXIStreamSignature
from .topic import HW_TOPIC_STREAM

__all__ = ["FRAME_HEADER", "FRAME_INFO", "REQUEST_ID", "REPLY_INFO", "BODY_STREAM", "FrameKind",
           "ReplyStatus", "FrameSender", "FrameReceiver", "ServiceServer", "ServiceClient"]

#: the first beat of every frame on a service's or an action's topics
FRAME_HEADER = data.StructLayout({"sequence": 32, "client": 16, "kind": 8, "status": 8})
#: a frame to send or just received: its header and whether a body follows
FRAME_INFO = data.StructLayout({"header": FRAME_HEADER, "body": 1})
#: who asked: the client's id and the number it gave the request (or goal)
REQUEST_ID = data.StructLayout({"sequence": 32, "client": 16})
#: what a client learns of each reply before its body
REPLY_INFO = data.StructLayout({"sequence": 32, "status": 8})
#: a frame's body: a message in the ``cdr`` framing, 64-bit beats, ``tkeep`` on the last
BODY_STREAM = AXIStreamSignature(64)


class FrameKind(enum.IntEnum):
    """``kind`` of a frame header (docs/services.md)."""
    REQUEST = 1          #: client -> server, body: the request
    REPLY = 2            #: server -> clients, body: the reply (none when ``status`` is not OK)
    GOAL = 3             #: action client -> server, body: the goal
    GOAL_RESPONSE = 4    #: no body; ``status`` 1 accepted, 0 rejected
    CANCEL = 5           #: no body; ``sequence`` names the goal to cancel
    CANCEL_RESPONSE = 6  #: no body; ``status`` a :class:`CancelStatus`
    FEEDBACK = 7         #: body: the feedback of the goal ``sequence``
    RESULT = 8           #: body: the result; ``status`` a :class:`GoalStatus`


class ReplyStatus(enum.IntEnum):
    """``status`` of a REPLY frame."""
    OK = 0
    #: the server could not read the request (a bad body); the reply has no body
    BAD_REQUEST = 1


def header_beat(m, *, kind, client, sequence, status=0):
    """A :data:`FRAME_HEADER` value (a ``data.View``) driven combinationally in ``m``."""
    value = Signal(FRAME_HEADER)
    m.d.comb += [value.kind.eq(kind), value.client.eq(client), value.sequence.eq(sequence),
                 value.status.eq(status)]
    return value


class FrameSender(wiring.Component):
    """Puts frames on a service or action topic: a header beat, then the body.

    Members
    -------
    header : In(stream.Signature(FRAME_INFO))
        The next frame's header; with ``body`` set, the body is taken from ``s_axis`` after it.
    s_axis : In(BODY_STREAM)
        Bodies, one packet each, read only while a frame with a body is being sent.
    m_axis : Out(HW_TOPIC_STREAM)
        Frames: the header beat (``tuser`` 1, ``tlast`` when there is no body), then the body's
        beats unchanged (``tuser`` 0). Purely combinational; zero latency.
    """

    def __init__(self):
        super().__init__({"header": In(stream.Signature(FRAME_INFO)),
                          "s_axis": In(BODY_STREAM),
                          "m_axis": Out(HW_TOPIC_STREAM)})

    def elaborate(self, platform):
        m = Module()
        hdr, body, out = self.header, self.s_axis, self.m_axis
        in_body = Signal()
        with m.If(in_body):
            m.d.comb += [out.tvalid.eq(body.tvalid), out.tdata.eq(body.tdata),
                         out.tkeep.eq(body.tkeep), out.tlast.eq(body.tlast),
                         body.tready.eq(out.tready)]
            with m.If(body.tvalid & body.tready & body.tlast):
                m.d.sync += in_body.eq(0)
        with m.Else():
            m.d.comb += [out.tvalid.eq(hdr.valid), out.tdata.eq(hdr.payload.header),
                         out.tkeep.eq(0xFF), out.tlast.eq(~hdr.payload.body), out.tuser.eq(1),
                         hdr.ready.eq(out.tready)]
            with m.If(hdr.valid & hdr.ready & hdr.payload.body):
                m.d.sync += in_body.eq(1)
        return m


class FrameReceiver(wiring.Component):
    """Takes frames off a service or action topic: offers each header, then passes or drops
    the body as the header's taker decides.

    Members
    -------
    s_axis : In(HW_TOPIC_STREAM)
        Frames. A frame whose first beat is not a full 8-byte header is dropped up to its
        ``tlast`` and counted in ``bad_frames``.
    header : Out(stream.Signature(FRAME_INFO))
        The header of the frame, ``body`` set when beats follow it.
    forward : In(1)
        Sampled with each ``header`` transfer: pass the frame's body on ``m_axis`` (1) or drop
        it up to its ``tlast`` (0).
    m_axis : Out(BODY_STREAM)
        Bodies of the frames forwarded, unchanged, ``tlast`` on the frame's last beat.
    bad_frames : Out(32)
        Frames dropped because their header beat was short.
    """

    def __init__(self):
        super().__init__({"s_axis": In(HW_TOPIC_STREAM),
                          "header": Out(stream.Signature(FRAME_INFO)),
                          "forward": In(1),
                          "m_axis": Out(BODY_STREAM),
                          "bad_frames": Out(32)})

    def elaborate(self, platform):
        m = Module()
        s, hdr, out = self.s_axis, self.header, self.m_axis
        take = s.tvalid & s.tready
        with m.FSM():
            with m.State("HEADER"):
                short = s.tkeep != 0xFF
                m.d.comb += [hdr.valid.eq(s.tvalid & ~short),
                             hdr.payload.header.eq(s.tdata), hdr.payload.body.eq(~s.tlast),
                             s.tready.eq(hdr.ready | short)]
                with m.If(take & short):
                    m.d.sync += self.bad_frames.eq(self.bad_frames + 1)
                    with m.If(~s.tlast):
                        m.next = "DROP"
                with m.Elif(take & ~s.tlast):
                    with m.If(self.forward):
                        m.next = "FORWARD"
                    with m.Else():
                        m.next = "DROP"
            with m.State("FORWARD"):
                m.d.comb += [out.tvalid.eq(s.tvalid), out.tdata.eq(s.tdata),
                             out.tkeep.eq(s.tkeep), out.tlast.eq(s.tlast),
                             s.tready.eq(out.tready)]
                with m.If(take & s.tlast):
                    m.next = "HEADER"
            with m.State("DROP"):
                m.d.comb += s.tready.eq(1)
                with m.If(take & s.tlast):
                    m.next = "HEADER"
        return m


def _counter(m, counter, event):
    with m.If(event & (counter != Const(-1, len(counter)))):
        m.d.sync += counter.eq(counter + 1)


class ServiceServer(wiring.Component):
    """The server's end of a service over hardware topics.

    Requests are served in the order they arrive; each gets exactly one reply, with the
    request's id.

    Parameters
    ----------
    pending : int
        Requests taken whose reply has not started, a power of two in 1..16 (default 1: the
        next request is read once the reply to the last one has begun, so a node that serves
        one request at a time needs nothing more).

    Members
    -------
    request_in : In(HW_TOPIC_STREAM)
        The ``<service>_request`` topic. Frames other than a REQUEST with a body are dropped
        and counted in ``bad_frames``.
    request : Out(BODY_STREAM)
        The body of each request, in order.
    request_id : Out(REQUEST_ID)
        The id of the request whose body is on ``request`` (valid from its first beat).
    reply : In(BODY_STREAM)
        One reply body per request, in request order.
    reply_error : In(stream.Signature(8))
        Instead of a body: a reply without body whose status is the payload (a
        :class:`ReplyStatus` other than OK), for the oldest request without reply.
    reply_out : Out(HW_TOPIC_STREAM)
        The ``<service>_reply`` topic.
    bad_frames : Out(32)
        Frames dropped from ``request_in`` (short headers included).
    """

    def __init__(self, *, pending=1):
        self._pending = check_power_of_two("pending", pending, 1, 16)
        super().__init__({"request_in": In(HW_TOPIC_STREAM),
                          "request": Out(BODY_STREAM),
                          "request_id": Out(REQUEST_ID),
                          "reply": In(BODY_STREAM),
                          "reply_error": In(stream.Signature(8)),
                          "reply_out": Out(HW_TOPIC_STREAM),
                          "bad_frames": Out(32)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.receiver = rx = FrameReceiver()
        m.submodules.sender = tx = FrameSender()
        m.submodules.ids = ids = SyncFIFOBuffered(width=REQUEST_ID.size, depth=self._pending)
        wiring.connect(m, wiring.flipped(self.request_in), rx.s_axis)
        wiring.connect(m, rx.m_axis, wiring.flipped(self.request))
        wiring.connect(m, tx.m_axis, wiring.flipped(self.reply_out))

        h = rx.header.payload.header
        good = (h.kind == FrameKind.REQUEST) & rx.header.payload.body
        incoming = Signal(REQUEST_ID)
        m.d.comb += [incoming.client.eq(h.client), incoming.sequence.eq(h.sequence),
                     rx.header.ready.eq(~good | ids.w_rdy), rx.forward.eq(good),
                     ids.w_data.eq(incoming), ids.w_en.eq(rx.header.valid & good)]
        with m.If(rx.header.valid & rx.header.ready & good):
            m.d.sync += self.request_id.eq(incoming)
        bad = Signal()
        m.d.comb += bad.eq(rx.header.valid & ~good)
        bad_frames = Signal(32)
        _counter(m, bad_frames, bad)
        m.d.comb += self.bad_frames.eq(bad_frames + rx.bad_frames)

        oldest = Signal(REQUEST_ID)
        error = self.reply_error
        m.d.comb += [
            oldest.eq(ids.r_data),
            tx.header.valid.eq(ids.r_rdy & (error.valid | self.reply.tvalid)),
            tx.header.payload.header.eq(header_beat(
                m, kind=FrameKind.REPLY, client=oldest.client, sequence=oldest.sequence,
                status=Mux(error.valid, error.payload, ReplyStatus.OK))),
            tx.header.payload.body.eq(~error.valid),
            ids.r_en.eq(tx.header.valid & tx.header.ready),
            error.ready.eq(tx.header.valid & tx.header.ready & error.valid),
        ]
        wiring.connect(m, wiring.flipped(self.reply), tx.s_axis)
        return m


class ServiceClient(wiring.Component):
    """A client's end of a service over hardware topics.

    Parameters
    ----------
    client_id : int
        This client's id on the service, 0..65535, unique among its clients (a project gives
        each client thread its thread id).
    pending : int
        Requests that may be outstanding at once, a power of two in 1..16 (default 4). Request
        ``s`` uses slot ``s mod pending``; a request waits while its slot still waits for a
        reply.

    Members
    -------
    request : In(BODY_STREAM)
        Request bodies; each becomes a REQUEST frame numbered ``sequence``.
    sequence : Out(32)
        The number the next request gets (0, 1, 2, ...).
    request_out : Out(HW_TOPIC_STREAM)
        The ``<service>_request`` topic.
    reply_in : In(HW_TOPIC_STREAM)
        The ``<service>_reply`` topic: every client's replies.
    reply_info : Out(stream.Signature(REPLY_INFO))
        One per reply to one of this client's outstanding requests, before its body.
    reply : Out(BODY_STREAM)
        The body of each reply whose status is OK, after its ``reply_info``.
    unmatched : Out(32)
        Frames with this client's id that answer no outstanding request (a reply to a request
        nobody made, a second reply, another kind of frame): dropped. Frames for other clients
        are dropped without counting.
    bad_frames : Out(32)
        Frames with a short header.
    """

    def __init__(self, client_id, *, pending=4):
        self._client_id = check_int("client_id", client_id, 0, 0xFFFF)
        self._pending = check_power_of_two("pending", pending, 1, 16)
        super().__init__({"request": In(BODY_STREAM),
                          "sequence": Out(32),
                          "request_out": Out(HW_TOPIC_STREAM),
                          "reply_in": In(HW_TOPIC_STREAM),
                          "reply_info": Out(stream.Signature(REPLY_INFO)),
                          "reply": Out(BODY_STREAM),
                          "unmatched": Out(32),
                          "bad_frames": Out(32)})

    client_id = property(lambda self: self._client_id)

    def elaborate(self, platform):
        m = Module()
        P = self._pending
        m.submodules.sender = tx = FrameSender()
        m.submodules.receiver = rx = FrameReceiver()
        wiring.connect(m, tx.m_axis, wiring.flipped(self.request_out))
        wiring.connect(m, wiring.flipped(self.reply_in), rx.s_axis)
        wiring.connect(m, rx.m_axis, wiring.flipped(self.reply))
        m.d.comb += self.bad_frames.eq(rx.bad_frames)

        waiting = Signal(P)
        slot_bits = (P - 1).bit_length()
        seq = self.sequence

        def slot(sequence):
            return sequence[:slot_bits] if slot_bits else Const(0, 1)
        free = ~waiting.bit_select(slot(seq), 1)
        m.d.comb += [
            tx.header.valid.eq(self.request.tvalid & free),
            tx.header.payload.header.eq(header_beat(m, kind=FrameKind.REQUEST,
                                                    client=self._client_id, sequence=seq)),
            tx.header.payload.body.eq(1),
        ]
        wiring.connect(m, wiring.flipped(self.request), tx.s_axis)
        sent = tx.header.valid & tx.header.ready

        h = rx.header.payload.header
        mine = h.client == self._client_id
        behind = Signal(32)
        m.d.comb += behind.eq(seq - h.sequence - 1)
        matched = ((h.kind == FrameKind.REPLY) & waiting.bit_select(slot(h.sequence), 1) &
                   (behind < P) & ((h.status == ReplyStatus.OK) == rx.header.payload.body))
        info = self.reply_info
        m.d.comb += [info.valid.eq(rx.header.valid & mine & matched),
                     info.payload.sequence.eq(h.sequence), info.payload.status.eq(h.status),
                     rx.header.ready.eq(~(mine & matched) | info.ready),
                     rx.forward.eq(mine & matched)]
        answered = info.valid & info.ready
        _counter(m, self.unmatched, rx.header.valid & mine & ~matched)

        for i in range(P):
            with m.If(sent & (slot(seq) == i)):
                m.d.sync += waiting[i].eq(1)
            with m.Elif(answered & (slot(h.sequence) == i)):
                m.d.sync += waiting[i].eq(0)
        with m.If(sent):
            m.d.sync += seq.eq(seq + 1)
        return m
