"""Software ROS 1 nodes that speak TCPROS over ordinary sockets, written from docs/messages.md
(the behaviour of rospy's publisher and subscriber): the peers of the hardware node."""

import socket
import threading
import xmlrpc.client

from gen.msg.ros1 import decode_connection_header, encode_connection_header, frame_message
from host.ros1.master import XmlRpcServer

__all__ = ["SoftwarePublisher", "SoftwareSubscriber", "read_exact"]

SUCCESS, FAILURE, ERROR = 1, 0, -1


def read_exact(sock, n):
    out = bytearray()
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        if not chunk:
            raise ConnectionError(f"connection closed after {len(out)} of {n} bytes")
        out += chunk
    return bytes(out)


def read_header(sock):
    n = int.from_bytes(read_exact(sock, 4), "little")
    raw = read_exact(sock, n)
    try:
        return decode_connection_header(raw)
    except ValueError as exc:
        raise ConnectionError(f"bad connection header {raw[:80]!r}: {exc}") from None


class _Node:
    def __init__(self, name, master_uri, host):
        self.name = name
        self.master = xmlrpc.client.ServerProxy(master_uri)
        self.host = host
        self.server = XmlRpcServer(host).start()
        self.errors = []

    @property
    def uri(self):
        return self.server.uri


class SoftwarePublisher(_Node):
    """Publishes ``typename`` on ``topic``: answers ``requestTopic`` with its TCP server,
    checks each subscriber's header (topic and md5sum, ``*`` accepted), replies with its own
    header or ``error=`` and a close, then sends every :meth:`publish`\\ ed message."""

    def __init__(self, name, master_uri, host, topic, typename, md5sum, definition):
        super().__init__(name, master_uri, host)
        self.topic, self.typename, self.md5sum, self.definition = topic, typename, md5sum, \
            definition
        self.listener = socket.create_server((host, 0))
        self.port = self.listener.getsockname()[1]
        self.connections = []
        self.rejected = []
        self.server.register_function(self.requestTopic, "requestTopic")
        self.server.register_function(lambda *a: [SUCCESS, "", 0], "publisherUpdate")
        threading.Thread(target=self._accept, daemon=True).start()

    def register(self):
        return self.master.registerPublisher(self.name, self.topic, self.typename, self.uri)

    def requestTopic(self, caller_id, topic, protocols):
        if topic != self.topic:
            return [ERROR, f"Not a publisher of [{topic}]", []]
        return [SUCCESS, "ready", ["TCPROS", self.host, self.port]]

    def _accept(self):
        while True:
            try:
                conn, _ = self.listener.accept()
            except OSError:
                return
            try:
                conn.settimeout(60)
                fields = read_header(conn)
                ok = (fields.get("topic") == self.topic and
                      fields.get("md5sum") in (self.md5sum, "*") and "callerid" in fields)
                if not ok:
                    conn.sendall(encode_connection_header(
                        [("error", f"topic or md5sum mismatch: {fields.get('md5sum')}")]))
                    self.rejected.append(fields)
                    conn.close()
                    continue
                conn.sendall(encode_connection_header([
                    ("callerid", self.name), ("md5sum", self.md5sum), ("type", self.typename),
                    ("topic", self.topic), ("latching", "0"),
                    ("message_definition", self.definition)]))
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self.connections.append((conn, fields))
            except (OSError, ConnectionError) as exc:
                self.errors.append(str(exc))
                conn.close()

    def publish(self, body):
        frame = frame_message(body)
        for conn, _ in list(self.connections):
            conn.sendall(frame)

    def close(self):
        self.listener.close()
        for conn, _ in self.connections:
            conn.close()
        self.server.stop()


class SoftwareSubscriber(_Node):
    """Subscribes to ``topic``: connects to each publisher it learns of (``registerSubscriber``
    or ``publisherUpdate``), sends its header, checks the reply (an ``error=`` field or a wrong
    md5sum is recorded in :attr:`errors`), then collects messages in :attr:`messages`."""

    def __init__(self, name, master_uri, host, topic, typename, md5sum, definition):
        super().__init__(name, master_uri, host)
        self.topic, self.typename, self.md5sum, self.definition = topic, typename, md5sum, \
            definition
        self.messages = []
        self.headers = []
        self.closed = threading.Event()
        self._connected = set()
        self.server.register_function(self.publisherUpdate, "publisherUpdate")

    def register(self):
        code, msg, pubs = self.master.registerSubscriber(self.name, self.topic, self.typename,
                                                         self.uri)
        self.publisherUpdate("/master", self.topic, pubs)
        return code

    def publisherUpdate(self, caller_id, topic, publishers):
        for api in publishers:
            if api not in self._connected:
                self._connected.add(api)
                threading.Thread(target=self._subscribe, args=(api,), daemon=True).start()
        return [SUCCESS, "", 0]

    def _subscribe(self, api):
        try:
            code, msg, params = xmlrpc.client.ServerProxy(api).requestTopic(
                self.name, self.topic, [["TCPROS"]])
            if code != SUCCESS:
                self.errors.append(f"requestTopic: {code} {msg}")
                self._connected.discard(api)
                return
            _, host, port = params[:3]
            sock = socket.create_connection((host, int(port)), timeout=120)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.sendall(encode_connection_header([
                ("callerid", self.name), ("topic", self.topic), ("md5sum", self.md5sum),
                ("type", self.typename), ("tcp_nodelay", "1"),
                ("message_definition", self.definition)]))
            fields = read_header(sock)
            self.headers.append(fields)
            if "error" in fields or fields.get("md5sum") not in (self.md5sum, "*"):
                self.errors.append(f"publisher refused: {fields}")
                sock.close()
                return
            while True:
                n = int.from_bytes(read_exact(sock, 4), "little")
                self.messages.append(read_exact(sock, n))
        except (OSError, ConnectionError, xmlrpc.client.Error) as exc:
            self.errors.append(str(exc))
        finally:
            self.closed.set()

    def close(self):
        self.server.stop()
