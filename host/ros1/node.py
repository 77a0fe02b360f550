"""The node-side Slave API of a ROS 1 hardware node (docs/messages.md; seed paper
Figs. 6-7): XML-RPC stays in software, each topic's TCPROS connection is a hardware endpoint.
"""

import os
import threading
import xmlrpc.client

from hdl.net.stack import global_register
from hdl.params import check_int

from .endpoint import EndpointClient
from .master import XmlRpcServer

__all__ = ["HardwareNode"]

SUCCESS, FAILURE, ERROR = 1, 0, -1


class HardwareNode:
    """Registers hardware endpoints with a ROS master and serves their Slave API.

    Parameters
    ----------
    name : str
        Caller id (``/fpga``).
    master_uri : str
    host : str
        Address of this node's XML-RPC server.
    engine_ip : str
        The hardware's IP address (what ``requestTopic`` answers).
    rbcp : RbcpClient
    endpoints : list of dict
        Per endpoint, in the hardware's order: ``topic``, ``type`` (ROS 1 name), ``md5sum``,
        ``definition`` and, for a publisher, ``port``: the TCP port it listens on, 1..65535,
        or 0 (the default) for the engine's TCP port (its ``tcp_port`` register, SiTCP's 24
        unless changed), which :meth:`start` reads back so that ``requestTopic`` names the
        port the hardware really listens on.

    A hardware publisher has one TCP session, so ``requestTopic`` answers a second subscriber
    with code 0 while the first is connected (docs/network.md). A hardware subscriber connects to
    the first publisher it learns of, from ``registerSubscriber`` or ``publisherUpdate``.
    """

    def __init__(self, name, master_uri, host, engine_ip, rbcp, endpoints):
        self.name = name
        self.master = xmlrpc.client.ServerProxy(master_uri)
        self.master_uri = master_uri
        self.engine_ip = engine_ip
        self.rbcp = rbcp
        self.specs = list(endpoints)
        for k, spec in enumerate(self.specs):
            check_int(f"endpoint {k} ({spec.get('topic')!r}) port", spec.get("port", 0), 0, 65535)
        self.clients = [EndpointClient(rbcp, k) for k in range(len(self.specs))]
        self.listen_ports = {}            # publisher endpoint -> the port it listens on
        self.server = XmlRpcServer(host)
        for fn in ("requestTopic", "publisherUpdate", "getBusInfo", "getBusStats",
                   "getMasterUri", "getPid", "getSubscriptions", "getPublications",
                   "paramUpdate", "shutdown"):
            self.server.register_function(getattr(self, fn), fn)
        self.connected_publisher = {}     # subscriber endpoint -> publisher api
        self._lock = threading.Lock()
        self.errors = []

    @property
    def uri(self):
        return self.server.uri

    def _role(self, k):
        return self.clients[k].role

    def start(self):
        """Configure every endpoint, serve the Slave API, register with the master."""
        self.server.start()
        for k, (spec, client) in enumerate(zip(self.specs, self.clients)):
            client.configure(callerid=self.name, topic=spec["topic"], typename=spec["type"],
                             md5sum=spec["md5sum"], definition=spec["definition"])
            spec["role"] = client.role
            if spec["role"] == "publisher":
                port = spec.get("port", 0)
                client.listen(port)
                self.listen_ports[k] = port or self.engine_tcp_port()
        for k, spec in enumerate(self.specs):
            if spec["role"] == "publisher":
                self.master.registerPublisher(self.name, spec["topic"], spec["type"], self.uri)
            else:
                code, _, pubs = self.master.registerSubscriber(self.name, spec["topic"],
                                                               spec["type"], self.uri)
                if code == SUCCESS and pubs:
                    self._connect(k, pubs)
        return self

    def engine_tcp_port(self):
        """The engine's TCP port (its global ``tcp_port`` register): where an endpoint with
        ``LOCAL_PORT`` 0 listens."""
        return self.rbcp.read_int(*global_register("tcp_port"))

    def stop(self):
        for spec in self.specs:
            try:
                if spec.get("role") == "publisher":
                    self.master.unregisterPublisher(self.name, spec["topic"], self.uri)
                else:
                    self.master.unregisterSubscriber(self.name, spec["topic"], self.uri)
            except (OSError, xmlrpc.client.Error):
                pass
        self.server.stop()

    def _connect(self, k, publisher_apis):
        with self._lock:
            if self.connected_publisher.get(k) in publisher_apis:
                return
            for api in publisher_apis:
                try:
                    code, msg, params = xmlrpc.client.ServerProxy(api).requestTopic(
                        self.name, self.specs[k]["topic"], [["TCPROS"]])
                except (OSError, xmlrpc.client.Error) as exc:
                    self.errors.append(f"requestTopic to {api}: {exc}")
                    continue
                if code != SUCCESS or not params or params[0] != "TCPROS":
                    self.errors.append(f"requestTopic to {api}: {code} {msg}")
                    continue
                _, host, port = params[:3]
                self.clients[k].connect(host, int(port))
                self.connected_publisher[k] = api
                return

    # ---- Slave API
    def requestTopic(self, caller_id, topic, protocols):
        for k, (spec, client) in enumerate(zip(self.specs, self.clients)):
            if spec.get("role") == "publisher" and spec["topic"] == topic:
                if not any(p and p[0] == "TCPROS" for p in protocols):
                    return [FAILURE, "no supported protocol implementations", []]
                if client.phase not in ("idle", "connecting"):
                    return [FAILURE, f"hardware publisher of [{topic}] already has a "
                                     f"subscriber (one TCP session)", []]
                port = self.listen_ports.get(k)
                if port is None:
                    return [FAILURE, f"hardware publisher of [{topic}] is not listening yet", []]
                return [SUCCESS, f"ready on {self.engine_ip}:{port}",
                        ["TCPROS", self.engine_ip, port]]
        return [ERROR, f"Not a publisher of [{topic}]", []]

    def publisherUpdate(self, caller_id, topic, publishers):
        for k, spec in enumerate(self.specs):
            if spec.get("role") == "subscriber" and spec["topic"] == topic and publishers:
                threading.Thread(target=self._connect, args=(k, list(publishers)),
                                 daemon=True).start()
        return [SUCCESS, "", 0]

    def getBusInfo(self, caller_id):
        info = []
        for k, spec in enumerate(self.specs):
            direction = "o" if spec.get("role") == "publisher" else "i"
            info.append([k, self.connected_publisher.get(k, ""), direction, "TCPROS",
                         spec["topic"], True])
        return [SUCCESS, "bus info", info]

    def getBusStats(self, caller_id):
        return [SUCCESS, "bus stats", [[], [], []]]

    def getMasterUri(self, caller_id):
        return [SUCCESS, "", self.master_uri]

    def getPid(self, caller_id):
        return [SUCCESS, "", os.getpid()]

    def getSubscriptions(self, caller_id):
        return [SUCCESS, "", [[s["topic"], s["type"]] for s in self.specs
                              if s.get("role") == "subscriber"]]

    def getPublications(self, caller_id):
        return [SUCCESS, "", [[s["topic"], s["type"]] for s in self.specs
                              if s.get("role") == "publisher"]]

    def paramUpdate(self, caller_id, key, value):
        return [SUCCESS, "", 0]

    def shutdown(self, caller_id, msg=""):
        return [SUCCESS, "", 0]
