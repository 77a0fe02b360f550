"""A FinEmbP master over ordinary UDP sockets (docs/finemb.md): finds the nodes of a network,
gives them addresses, reads their IO descriptors, runs cycles (SoC to the multicast group,
ISEND_REQ to every node, their ISEND_RES back), re-initialises nodes that fall out and
counts what happened."""

import dataclasses
import ipaddress
import select
import socket
import struct
import time

from hdl.finemb import IoDescriptor
from hdl.finemb.protocol import (
    BROADCAST_IP, FINEMB_PORT, GROUP_IP, HEADER, IP_TTL_FINEMB, NODE_ALL, PAYLOAD_FORMATS,
    STATE_SHIFT, Direction, Flag, MsgType, NodeState, ReinitReason, decode_header,
    encode_header,
)
from hdl.net.frames import int_to_mac

__all__ = ["FinembMaster", "NodeRecord", "FinembError"]

#: SO_BINDTODEVICE (Linux)
_SO_BINDTODEVICE = getattr(socket, "SO_BINDTODEVICE", 25)
#: cycles a node may miss in a row before the master takes it out and initialises it again
MISSES_TO_REINIT = 3


class FinembError(RuntimeError):
    """A node did not answer an initialisation request, or answered wrongly."""


@dataclasses.dataclass
class NodeRecord:
    """What the master knows of one node."""

    node_id: int
    mac: bytes
    ip: str
    serial: int
    page_in_bytes: int
    page_out_bytes: int
    descriptor: IoDescriptor = None
    state: NodeState = NodeState.INIT     # as the node reported it last
    answered: int = 0                     # ISEND_RES in time
    late: int = 0                         # cycles without one
    reinit_answers: int = 0               # answers reporting REINIT (watchdog or REINIT)
    missed_in_row: int = 0
    reinits: int = 0
    inputs: dict = None                   # the last input page, decoded

    @property
    def mac_text(self):
        return int_to_mac(int.from_bytes(self.mac, "big"))


class FinembMaster:
    """A FinEmbP master on the host's network stack.

    Parameters
    ----------
    local_ip : str
        The host's address on the fieldbus network (nodes answer to it).
    interface : str or None
        The network interface of the fieldbus (``SO_BINDTODEVICE``: broadcasts and the
        multicast SoC leave there); needs ``CAP_NET_RAW``.
    first_node_ip : str or None
        The address given to node 1 (node k gets this + k - 1); default: ``local_ip``'s
        network + 17 (node k at host number 16 + k).
    netmask : str
    port : int
        FinEmbP's UDP port on both sides.
    timeout_s : float
        How long an initialisation request waits for its answer.
    """

    def __init__(self, local_ip, *, interface=None, first_node_ip=None, netmask="255.255.255.0",
                 port=FINEMB_PORT, timeout_s=2.0):
        self.local_ip = str(ipaddress.IPv4Address(local_ip))
        network = ipaddress.IPv4Network(f"{local_ip}/{netmask}", strict=False)
        self.first_node_ip = ipaddress.IPv4Address(first_node_ip or network.network_address + 17)
        self.netmask = netmask
        self.port = port
        self.timeout_s = timeout_s
        self.nodes = {}            # node id -> NodeRecord
        self.cycle_no = 0
        self.seq = 0
        self.cycles_run = 0
        self.started = None
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
            if interface:
                self.sock.setsockopt(socket.SOL_SOCKET, _SO_BINDTODEVICE, interface.encode())
            self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_TTL, IP_TTL_FINEMB)
            self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, IP_TTL_FINEMB)
            self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 0)
            self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF,
                                 socket.inet_aton(self.local_ip))
            # broadcasts (ID_RES of nodes without an address) and unicast answers
            self.sock.bind(("", port))
        except OSError:
            self.sock.close()
            raise
        self.sock.setblocking(False)

    def close(self):
        self.sock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ---- frames
    def _send(self, type_, node_id, body=b"", *, to, flags=0, cycle=0):
        self.seq = (self.seq + 1) & 0xFFFF
        payload = encode_header(type_, node_id, flags=flags, cycle=cycle, length=len(body),
                                seq=self.seq) + bytes(body)
        self.sock.sendto(payload, (to, self.port))
        return self.seq

    def _receive(self, deadline):
        """The next FinEmbP message before ``deadline`` (monotonic seconds) as
        ``(type, node_id, flags, cycle, seq, body, sender)``, or ``None``; datagrams that are
        not FinEmbP are skipped."""
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            readable, _, _ = select.select([self.sock], [], [], left)
            if not readable:
                return None
            try:
                data, sender = self.sock.recvfrom(2048)
            except BlockingIOError:
                continue
            try:
                type_, node_id, flags, cycle, _, seq = decode_header(data)
            except ValueError:
                continue
            if sender[0] == self.local_ip:
                continue                   # our own broadcast, looped back
            yield_type = MsgType(type_) if type_ in MsgType._value2member_map_ else None
            if yield_type is None:
                continue
            return yield_type, node_id, flags, cycle, seq, data[HEADER:], sender

    def _ask(self, type_, node_id, body, answer, *, to, match=lambda m: True):
        """Send a request and wait for an ``answer`` type message that ``match`` accepts;
        two more tries after a time-out."""
        for _ in range(3):
            self._send(type_, node_id, body, to=to)
            deadline = time.monotonic() + self.timeout_s
            while (msg := self._receive(deadline)) is not None:
                if msg[0] == answer and match(msg):
                    return msg
        raise FinembError(f"no {answer.name} to {type_.name} (node {node_id}, {to}) after "
                          f"3 tries of {self.timeout_s} s")

    # ---- initialisation
    def discover(self, wait_s=None):
        """ID_REQ to the network: ``{mac: (serial, page_in, page_out)}`` of every node still
        without an address (answers collected for ``wait_s``)."""
        self._send(MsgType.ID_REQ, NODE_ALL, struct.pack(PAYLOAD_FORMATS[MsgType.ID_REQ], 1),
                   to=BROADCAST_IP)
        found = {}
        deadline = time.monotonic() + (self.timeout_s if wait_s is None else wait_s)
        while (msg := self._receive(deadline)) is not None:
            if msg[0] == MsgType.ID_RES:
                mac, _vendor, serial, _ports, _caps, page_in, page_out = struct.unpack(
                    PAYLOAD_FORMATS[MsgType.ID_RES], msg[5][:18])
                found[mac] = (serial, page_in, page_out)
        return found

    def node_ip(self, node_id):
        return str(self.first_node_ip + node_id - 1)

    def assign(self, mac, node_id, serial=0, page_in=0, page_out=0):
        """Give the node with ``mac`` its id and address, read its IO descriptor; return its
        :class:`NodeRecord` (also in :attr:`nodes`)."""
        ip = self.node_ip(node_id)
        body = struct.pack(PAYLOAD_FORMATS[MsgType.ADDR_REQ], mac, socket.inet_aton(ip),
                           socket.inet_aton(self.netmask), node_id)
        msg = self._ask(MsgType.ADDR_REQ, NODE_ALL, body, MsgType.ADDR_RES, to=BROADCAST_IP,
                        match=lambda m: m[1] == node_id and m[5][:6] == mac)
        node = NodeRecord(node_id, mac, ip, serial, page_in, page_out,
                          state=NodeState(msg[2] >> STATE_SHIFT & 3))
        node.descriptor = self.read_descriptor(node)
        if (node.descriptor.page_in_bytes, node.descriptor.page_out_bytes) != \
                (page_in or node.descriptor.page_in_bytes,
                 page_out or node.descriptor.page_out_bytes):
            raise FinembError(f"node {node_id}: its IO descriptor's pages disagree with ID_RES")
        old = self.nodes.get(node_id)
        if old is not None:
            node.reinits, node.answered, node.late = old.reinits + 1, old.answered, old.late
            node.reinit_answers = old.reinit_answers
        self.nodes[node_id] = node
        return node

    def read_descriptor(self, node):
        data, total = b"", None
        while total is None or len(data) < total:
            body = struct.pack(PAYLOAD_FORMATS[MsgType.IODESC_REQ], len(data), 1024)
            msg = self._ask(MsgType.IODESC_REQ, node.node_id, body, MsgType.IODESC_RES,
                            to=node.ip, match=lambda m: m[1] == node.node_id)
            offset, total = struct.unpack_from("<HH", msg[5])
            if offset != len(data):
                raise FinembError(f"node {node.node_id}: IO descriptor chunk at {offset}, "
                                  f"asked for {len(data)}")
            data += msg[5][4:]
        try:
            return IoDescriptor.decode(data)
        except ValueError as exc:
            raise FinembError(f"node {node.node_id}: {exc}") from None

    def init(self, expected=None, wait_s=None):
        """Find the nodes without address and initialise them, ids in the order of their
        serial numbers after the ids in use. With ``expected``, raise unless that many nodes
        are then known."""
        found = self.discover(wait_s)
        next_id = max(self.nodes, default=0) + 1
        known = {n.mac: n.node_id for n in self.nodes.values()}
        for mac, (serial, page_in, page_out) in sorted(found.items(), key=lambda kv: kv[1][0]):
            node_id = known.get(mac)
            if node_id is None:
                node_id, next_id = next_id, next_id + 1
            self.assign(mac, node_id, serial, page_in, page_out)
        if expected is not None and len(self.nodes) != expected:
            raise FinembError(f"found {len(self.nodes)} node(s), expected {expected}")
        return self.nodes

    def restart(self, *, forget=True):
        """A master that starts over: every node forgets its address (REINIT, master
        restart) and the cycle counter starts again at 0. With ``forget`` the master forgets
        its nodes too (call :meth:`init` next); without, it keeps them, and the cycles that
        follow find them silent and initialise them again one by one."""
        self._send(MsgType.REINIT, NODE_ALL,
                   struct.pack(PAYLOAD_FORMATS[MsgType.REINIT], ReinitReason.MASTER_RESTART),
                   to=GROUP_IP)
        if forget:
            self.nodes.clear()
        self.cycle_no = 0

    # ---- cycles
    def cycle(self, outputs, deadline_s, period_ns=40_000):
        """One cycle: SoC, an ISEND_REQ with ``outputs[node_id]`` (port name -> value) to every
        node, their answers until ``deadline_s`` (monotonic). Returns ``{node_id: inputs}``
        of the nodes that answered in time; the others count as late, and a node late
        :data:`MISSES_TO_REINIT` times in a row is initialised again."""
        if self.started is None:
            self.started = time.monotonic()
        soc = struct.pack(PAYLOAD_FORMATS[MsgType.SOC], period_ns, time.monotonic_ns(),
                          len(self.nodes), 0)
        self._send(MsgType.SOC, NODE_ALL, soc, to=GROUP_IP, cycle=self.cycle_no)
        for node_id, node in self.nodes.items():
            page = node.descriptor.pack(Direction.OUT, outputs.get(node_id, {}))
            self._send(MsgType.ISEND_REQ, node_id, page, to=node.ip, cycle=self.cycle_no)
        got = {}
        while len(got) < len(self.nodes):
            msg = self._receive(deadline_s)
            if msg is None:
                break
            type_, node_id, flags, cycle, _, body, _ = msg
            node = self.nodes.get(node_id)
            if type_ != MsgType.ISEND_RES or node is None or cycle != self.cycle_no:
                continue
            node.state = NodeState(flags >> STATE_SHIFT & 3)
            if node.state == NodeState.REINIT:
                node.reinit_answers += 1
            if flags & Flag.ERROR or len(body) != node.descriptor.page_in_bytes:
                continue
            node.inputs = got[node_id] = node.descriptor.unpack(Direction.IN, body)
        for node_id, node in list(self.nodes.items()):
            if node_id in got:
                node.answered += 1
                node.missed_in_row = 0
            else:
                node.late += 1
                node.missed_in_row += 1
                if node.missed_in_row >= MISSES_TO_REINIT:
                    self._reinit(node)
        self.cycle_no = (self.cycle_no + 1) & 0xFFFFFFFF
        self.cycles_run += 1
        return got

    def _reinit(self, node):
        """A node that fell out: address and IO descriptor again (it may have restarted);
        when it does not answer, it stays in the table and is tried again later."""
        node.missed_in_row = 0
        try:
            self.assign(node.mac, node.node_id, node.serial, node.page_in_bytes,
                        node.page_out_bytes)
        except FinembError:
            node.state = NodeState.REINIT

    def cycle_rate_hz(self):
        """Cycles per second since the first cycle."""
        if not self.started or not self.cycles_run:
            return 0.0
        return self.cycles_run / (time.monotonic() - self.started)
