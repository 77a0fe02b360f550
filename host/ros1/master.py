"""A ROS 1 master: the Master API over XML-RPC (docs/messages.md; wiki ROS/Master_API;
ros_comm rosmaster/master_api.py)."""

import os
import threading
import xmlrpc.client
from socketserver import ThreadingMixIn
from xmlrpc.server import SimpleXMLRPCRequestHandler, SimpleXMLRPCServer

__all__ = ["RosMaster", "XmlRpcServer"]

SUCCESS, FAILURE, ERROR = 1, 0, -1


class _QuietHandler(SimpleXMLRPCRequestHandler):
    def log_message(self, *args):
        pass


class XmlRpcServer(ThreadingMixIn, SimpleXMLRPCServer):
    """Threaded XML-RPC server on ``(host, port)`` (port 0: any); :meth:`start` serves in a
    daemon thread, :meth:`stop` ends it."""

    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, host, port=0):
        super().__init__((host, port), requestHandler=_QuietHandler, allow_none=True,
                         logRequests=False)
        self._thread = None

    @property
    def uri(self):
        host, port = self.server_address[:2]
        return f"http://{host}:{port}/"

    def start(self):
        self._thread = threading.Thread(target=self.serve_forever, daemon=True)
        self._thread.start()
        return self

    def stop(self):
        self.shutdown()
        self.server_close()


class RosMaster:
    """Registration and lookup for topics, services and nodes; tells subscribers about new
    publishers with ``publisherUpdate`` (from a background thread, as rosmaster does)."""

    def __init__(self, host="127.0.0.1", port=11311):
        self.server = XmlRpcServer(host, port)
        self.publishers = {}      # topic -> {caller_id: api}
        self.subscribers = {}
        self.services = {}        # service -> (caller_id, service_api, caller_api)
        self.topic_types = {}
        self.nodes = {}           # caller_id -> api
        self.params = {}
        self._lock = threading.Lock()
        for name in ("registerPublisher", "unregisterPublisher", "registerSubscriber",
                     "unregisterSubscriber", "registerService", "unregisterService",
                     "lookupService", "lookupNode", "getPublishedTopics", "getTopicTypes",
                     "getSystemState", "getUri", "getPid"):
            self.server.register_function(getattr(self, name), name)
        self.updates = []         # (subscriber api, topic, publisher apis) sent

    @property
    def uri(self):
        return self.server.uri

    def start(self):
        self.server.start()
        return self

    def stop(self):
        self.server.stop()

    def _notify(self, topic):
        pubs = list(self.publishers.get(topic, {}).values())
        for api in list(self.subscribers.get(topic, {}).values()):
            self.updates.append((api, topic, pubs))

            def call(api=api):
                try:
                    xmlrpc.client.ServerProxy(api).publisherUpdate("/master", topic, pubs)
                except (OSError, xmlrpc.client.Error):
                    pass
            threading.Thread(target=call, daemon=True).start()

    def _node(self, caller_id, caller_api):
        self.nodes[caller_id] = caller_api

    def registerPublisher(self, caller_id, topic, topic_type, caller_api):
        with self._lock:
            self._node(caller_id, caller_api)
            self.publishers.setdefault(topic, {})[caller_id] = caller_api
            self.topic_types.setdefault(topic, topic_type)
            subs = list(self.subscribers.get(topic, {}).values())
            self._notify(topic)
        return [SUCCESS, f"Registered [{caller_id}] as publisher of [{topic}]", subs]

    def unregisterPublisher(self, caller_id, topic, caller_api):
        with self._lock:
            n = int(self.publishers.get(topic, {}).pop(caller_id, None) is not None)
            if n:
                self._notify(topic)
        return [SUCCESS, f"Unregistered [{caller_id}] as publisher of [{topic}]", n]

    def registerSubscriber(self, caller_id, topic, topic_type, caller_api):
        with self._lock:
            self._node(caller_id, caller_api)
            self.subscribers.setdefault(topic, {})[caller_id] = caller_api
            self.topic_types.setdefault(topic, topic_type)
            pubs = list(self.publishers.get(topic, {}).values())
        return [SUCCESS, f"Subscribed to [{topic}]", pubs]

    def unregisterSubscriber(self, caller_id, topic, caller_api):
        with self._lock:
            n = int(self.subscribers.get(topic, {}).pop(caller_id, None) is not None)
        return [SUCCESS, f"Unregistered [{caller_id}] as subscriber of [{topic}]", n]

    def registerService(self, caller_id, service, service_api, caller_api):
        with self._lock:
            self._node(caller_id, caller_api)
            self.services[service] = (caller_id, service_api, caller_api)
        return [SUCCESS, f"Registered [{caller_id}] as provider of [{service}]", 1]

    def unregisterService(self, caller_id, service, service_api):
        with self._lock:
            n = int(self.services.pop(service, None) is not None)
        return [SUCCESS, f"Unregistered [{caller_id}] as provider of [{service}]", n]

    def lookupService(self, caller_id, service):
        entry = self.services.get(service)
        if entry is None:
            return [ERROR, f"no provider for service [{service}]", ""]
        return [SUCCESS, f"rosrpc URI: [{entry[1]}]", entry[1]]

    def lookupNode(self, caller_id, node_name):
        api = self.nodes.get(node_name)
        if api is None:
            return [ERROR, f"unknown node [{node_name}]", ""]
        return [SUCCESS, f"node api: [{api}]", api]

    def getPublishedTopics(self, caller_id, subgraph):
        topics = [[t, self.topic_types[t]] for t, pubs in self.publishers.items()
                  if pubs and t.startswith(subgraph or "")]
        return [SUCCESS, "current topics", topics]

    def getTopicTypes(self, caller_id):
        return [SUCCESS, "current system topic types", [[t, ty] for t, ty in
                                                        self.topic_types.items()]]

    def getSystemState(self, caller_id):
        pubs = [[t, sorted(n)] for t, n in self.publishers.items() if n]
        subs = [[t, sorted(n)] for t, n in self.subscribers.items() if n]
        srvs = [[s, [entry[0]]] for s, entry in self.services.items()]
        return [SUCCESS, "current system state", [pubs, subs, srvs]]

    def getUri(self, caller_id):
        return [SUCCESS, "", self.uri]

    def getPid(self, caller_id):
        return [SUCCESS, "", os.getpid()]
