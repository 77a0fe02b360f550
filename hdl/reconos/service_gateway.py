"""A hardware thread that serves a software service by calling the same service over hardware
topics (docs/services.md): the gateway that makes a service between hardware threads reachable
from software and, with ``rosgate sim --ros2``, from DDS."""

from amaranth import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..dds.service import ReplyStatus, ServiceClient
from ..dds.topic import HW_TOPIC_STREAM
from ..msg import Deserializer, Serializer
from .gateway import _OsifLock, _Receiver, _Transmitter, check_gateway_side, gateway_side
from .hwt import HardwareThread

__all__ = ["ServiceGatewayThread"]


class ServiceGatewayThread(HardwareThread):
    """Serves software calls of a service (ReconOS ``rossrvs``) by calling it over hardware
    topics as one more client (r64).

    One call at a time: ``ROS_SERVICES_TAKE`` the request; read its struct and every string
    and sequence over MEMIF and stream it, serialized in CDR, as a REQUEST frame with this
    client's id (a :class:`~hdl.dds.service.ServiceClient`); deserialize the REPLY's body
    into the response message (``ROS_MESSAGE_SET_SIZE`` per string or sequence, MEMIF
    writes, then the struct) and answer with ``ROS_SERVICES_RESPONSE``; then take the next
    request. A REPLY with status BAD_REQUEST, and a reply body that does not read as the
    response type (counted in ``rx_errors``), are answered with the empty response (every
    field zero, every string and sequence empty), so no software call is left waiting.

    Parameters
    ----------
    arch : str
        ``"r64"``.
    request_plan, reply_plan : gen.msg.plan.StreamPlan
        ``cdr`` plans of the request and the response.
    request_layout, reply_layout : MemoryLayout
        Where their parts are in the rosidl C structs.
    client_id : int
        This gateway's id among the service's clients (its thread id + 1, as every client of
        a project).
    h_srvs, h_req, h_res : int
        Handles of the service server and of its request and response messages.
    request_port, reply_port : str
        Names of the ports on the ``<service>_request`` and ``<service>_reply`` topics.
    max_count : int
        Largest element count of a string or sequence taken from a reply.

    Members
    -------
    <request_port> : Out(HW_TOPIC_STREAM)
    <reply_port> : In(HW_TOPIC_STREAM)
    """

    def __init__(self, arch, *, request_plan, reply_plan, request_layout, reply_layout,
                 client_id, h_srvs, h_req, h_res, request_port="request_out",
                 reply_port="reply_in", max_count=1 << 20):
        for name, plan, layout in (("request_plan", request_plan, request_layout),
                                   ("reply_plan", reply_plan, reply_layout)):
            check_gateway_side(name, plan, layout, "services")
        super().__init__(arch, {request_port: Out(HW_TOPIC_STREAM),
                                reply_port: In(HW_TOPIC_STREAM)})
        if self.arch.word_bits != 64:
            raise ValueError(f"arch {arch!r}: the gateway runs on r64 (64-bit memory words)")
        self.client = ServiceClient(client_id, pending=1)
        self.handles = (h_srvs, h_req, h_res)
        self.request_port, self.reply_port = request_port, reply_port
        self.max_count = max_count
        self.request = gateway_side(request_plan, request_layout)
        self.reply = gateway_side(reply_plan, reply_layout)

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        h_srvs, h_req, h_res = self.handles
        m.submodules.client = client = self.client
        wiring.connect(m, client.request_out, wiring.flipped(getattr(self, self.request_port)))
        wiring.connect(m, wiring.flipped(getattr(self, self.reply_port)), client.reply_in)
        m.submodules.serializer = ser = Serializer(self.request.plan, 64)
        wiring.connect(m, ser.m_axis, client.request)
        m.submodules.deserializer = des = Deserializer(self.reply.plan, 64,
                                                       max_count=self.max_count)
        wiring.connect(m, client.reply, des.s_axis)

        started = Signal()
        lock = _OsifLock(m)
        rx = _Receiver(self.reply, m, os, mem, lock, started, des, h_res)
        tx = _Transmitter(self.request, m, os, mem, lock, started, ser, early_ready=True)
        # the reply's status comes first; a refused call has no body
        refused = Signal()
        m.d.comb += client.reply_info.ready.eq(1)
        with m.If(client.reply_info.valid & (client.reply_info.payload.status != ReplyStatus.OK)):
            m.d.sync += refused.eq(1)
        responded = Signal()
        with m.FSM(name="start"):
            with m.State("INIT"):
                os.thread_init(then="ADDR")
            with m.State("ADDR"):
                os.memory_getobjaddr(h_res, ptr=rx.msg, then="RUN")
            with m.State("RUN"):
                m.d.comb += started.eq(1)

        def respond(then):
            os.ros_services_response(h_srvs, h_res, then=then)
        rx_fsm = rx.build(respond, empty=refused, failed="RX_EMPTY")
        # the call is answered once the response has gone (the lock's release follows it);
        # a refusal can be answered before the request has even left
        with m.If(rx_fsm.ongoing("RX_PUBLISH_FREE")):
            m.d.sync += responded.eq(1)

        def take_states():
            lock.call(_OsifLock.TX, "TX_TAKE", lambda then: os.ros_services_take(
                h_srvs, h_req, ptr=tx.ptr, then=then), "TX_READ")

        def wait_states():
            with m.State("TX_WAIT"):
                with m.If(responded):
                    m.d.sync += responded.eq(0)
                    m.next = "TX_IDLE"
        tx.build(take_states, sent="TX_WAIT", extra_states=wait_states)
        return m
