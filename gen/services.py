"""A service or an action on its two hardware topics, with a server node and its clients
(docs/services.md): the graph a project builds for ``rossrvs``/``rossrvc`` or
``rosactions``/``rosactionc`` marked ``hw``, and the ``services`` top of the benches."""

from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from hdl.dds import HW_TOPIC_STREAM, Topic
from hdl.dds.action import ActionClient
from hdl.dds.fibonacci_server import FibonacciServer
from hdl.dds.service import ServiceClient
from hdl.dds.sort_server import SortServer
from hdl.params import check_choice, check_int

__all__ = ["ServiceGraph", "SERVERS", "interface_plans"]

#: server node kinds -> the interface they serve, its form and what the bench calls it
SERVERS = {"sort": "service", "fibonacci": "action"}

_TOPIC_PORTS = ("request_out", "reply_in", "request_in", "reply_out")


def interface_plans(library, interface):
    """The ``cdr`` stream plans of ``interface`` (``pkg/srv/Name`` or ``pkg/action/Name`` of
    ``library``) as its server nodes and clients take them: ``request_plan`` and
    ``reply_plan`` of a service, ``goal_plan`` and ``result_plan`` of an action (the feedback
    has the result's form in the Fibonacci action)."""
    from gen.msg.plan import stream_plan
    if "/srv/" in interface:
        return {"request_plan": stream_plan(library, f"{interface}_Request"),
                "reply_plan": stream_plan(library, f"{interface}_Response")}
    return {"goal_plan": stream_plan(library, f"{interface}_Goal"),
            "result_plan": stream_plan(library, f"{interface}_Result")}


class ServiceGraph(wiring.Component):
    """A server node and ``clients`` client ends on the interface's request and reply
    topics, plus one more publisher on each topic and one more subscriber of the replies (a
    test bench's way in and out; tie them off otherwise).

    Parameters
    ----------
    server : str
        ``"sort"`` (:class:`~hdl.dds.sort_server.SortServer`, a service) or ``"fibonacci"``
        (:class:`~hdl.dds.fibonacci_server.FibonacciServer`, an action).
    plans : dict
        The interface's plans (:func:`interface_plans`).
    clients : int
        Client ends, 1..8, with ids 1..clients.
    server_params : dict
        More parameters of the server node.

    Members
    -------
    c<i>_<member> :
        Every member of client ``i`` but its topic ports (:class:`~hdl.dds.service.ServiceClient`
        or :class:`~hdl.dds.action.ActionClient`).
    raw_request, raw_reply : In(HW_TOPIC_STREAM)
        Extra publishers on the request and the reply topic.
    tap_reply : Out(HW_TOPIC_STREAM)
        Extra subscriber of the reply topic.
    server_<counter> : Out(32)
        The server node's counters.
    """

    def __init__(self, server, plans, *, clients=2, **server_params):
        check_choice("server", server, tuple(SERVERS))
        check_int("clients", clients, 1, 8)
        self.kind = SERVERS[server]
        self.server = (SortServer if server == "sort" else FibonacciServer)(**plans,
                                                                            **server_params)
        client_class = ServiceClient if self.kind == "service" else ActionClient
        self.clients = [client_class(i + 1) for i in range(clients)]
        members = {}
        for i, client in enumerate(self.clients):
            for name, member in client.signature.members.items():
                if name not in _TOPIC_PORTS:
                    members[f"c{i}_{name}"] = member
        members.update({"raw_request": In(HW_TOPIC_STREAM), "raw_reply": In(HW_TOPIC_STREAM),
                        "tap_reply": Out(HW_TOPIC_STREAM)})
        for name, member in self.server.signature.members.items():
            if name not in _TOPIC_PORTS:
                members[f"server_{name}"] = member
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        n = len(self.clients)
        m.submodules.server = server = self.server
        m.submodules.request_topic = requests = Topic(n + 1, 1, 64, user_width=1, monitor=False)
        m.submodules.reply_topic = replies = Topic(2, n + 1, 64, user_width=1, monitor=False)
        wiring.connect(m, requests.m_axis[0], server.request_in)
        wiring.connect(m, server.reply_out, replies.s_axis[0])
        wiring.connect(m, wiring.flipped(self.raw_request), requests.s_axis[n])
        wiring.connect(m, wiring.flipped(self.raw_reply), replies.s_axis[1])
        wiring.connect(m, replies.m_axis[n], wiring.flipped(self.tap_reply))
        for i, client in enumerate(self.clients):
            m.submodules[f"client{i}"] = client
            wiring.connect(m, client.request_out, requests.s_axis[i])
            wiring.connect(m, replies.m_axis[i], client.reply_in)
            self._expose(m, client, f"c{i}_")
        self._expose(m, server, "server_")
        return m

    def _expose(self, m, inner, prefix):
        for name, member in inner.signature.members.items():
            if name in _TOPIC_PORTS:
                continue
            outer, port = getattr(self, prefix + name), getattr(inner, name)
            if member.is_signature:
                wiring.connect(m, wiring.flipped(outer), port)
            elif member.flow == In:
                m.d.comb += port.eq(outer)
            else:
                m.d.comb += outer.eq(port)
