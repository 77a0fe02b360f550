"""The test bench of the FinEmbP node and line tops: GMII models on each port, a master that
builds and reads FinEmbP frames (tb/models/finemb.py), and the node's counters."""

import logging
import struct

import cocotb
from cocotb.triggers import ClockCycles, RisingEdge
from cocotbext.eth import GmiiFrame, GmiiSink, GmiiSource
from scapy.layers.inet import IP
from scapy.layers.l2 import Ether

from gen.finemb import load_io_description
from hdl.finemb import NODE_COUNTERS
from hdl.finemb.protocol import (
    BROADCAST_IP, BROADCAST_MAC, FINEMB_PORT, NODE_ALL, Direction, Flag, MsgType, NodeState,
    ReinitReason,
)
from hdl.net.frames import int_to_mac, mac_to_int
from host.simulator import GMII_NS, clock_cycles, start_gmii_clocks

from .harness import ROOT, bench_params
from .models.finemb import body_of, finemb_frame, parse_finemb
from .net_tb import read_counter_bank
from .streams import reset_aresetn

__all__ = ["CLOCK_NS", "PID_IO", "NodeTB", "LineMaster", "Port", "node_ip"]

#: the benches' time base: the GMII clock (a byte on the wire; the nodes' core runs at half)
CLOCK_NS = GMII_NS
PID_IO = str(ROOT / "examples" / "finemb" / "pid_node.toml")


def node_ip(k):
    """The address the benches give node ``k`` (RFC 2544 block)."""
    return f"198.18.0.{16 + k}"


class Port:
    """GMII source and sink on one port of a node or line top (``<prefix>_rxd`` ...)."""

    def __init__(self, dut, prefix):
        self.dut = dut
        self.source = GmiiSource(getattr(dut, f"{prefix}_rxd"), getattr(dut, f"{prefix}_rx_er"),
                                 getattr(dut, f"{prefix}_rx_dv"), dut.gmii_clk, dut.aresetn,
                                 reset_active_level=False)
        self.sink = GmiiSink(getattr(dut, f"{prefix}_txd"), getattr(dut, f"{prefix}_tx_er"),
                             getattr(dut, f"{prefix}_tx_en"), dut.gmii_clk, dut.aresetn,
                             reset_active_level=False)
        for model in (self.source, self.sink):
            model.log.setLevel(logging.WARNING)

    async def send(self, frame, *, fcs=True, error=False, raw=None):
        """Send a scapy frame (FCS added), or ``raw`` bytes as they are."""
        gf = GmiiFrame.from_raw_payload(raw) if raw is not None else \
            GmiiFrame.from_payload(bytes(frame)) if fcs else \
            GmiiFrame.from_raw_payload(bytes(frame))
        if error:
            gf.error = [0] * len(gf.data)
            gf.error[len(gf.data) // 2] = 1
        await self.source.send(gf)

    def take(self):
        """The next frame sent on this port, as ``(GmiiFrame, scapy Ether or None)``, or
        ``None``."""
        if self.sink.empty():
            return None
        gf = self.sink.recv_nowait()
        ok = gf.check_fcs() and not any(gf.error or [])
        payload = bytes(gf.get_payload())
        return gf, (Ether(payload) if ok else None)


class NodeTB:
    """One FinEmbP node (``finemb_node`` top) with its two ports and a master on port 0."""

    def __init__(self, dut):
        self.dut = dut
        self.params = bench_params()
        self.io = load_io_description(self.params["io"])
        start_gmii_clocks(dut)
        self.ports = [Port(dut, "port0"), Port(dut, "port1")]
        dut.counter_index.value = 0
        self.cycle = 0
        self.seq = 0
        cocotb.start_soon(self._count())

    async def _count(self):
        while True:
            await RisingEdge(self.dut.gmii_clk)
            self.cycle += 1

    async def reset(self):
        await reset_aresetn(self.dut)

    async def counters(self):
        return await read_counter_bank(self.dut.aclk, self.dut.counter_index,
                                       self.dut.counter_value, NODE_COUNTERS,
                                       registered=True)

    @property
    def state(self):
        return NodeState(int(self.dut.state.value))

    async def send(self, frame, port=0, **kw):
        await self.ports[port].send(frame, **kw)

    async def recv(self, port=0, timeout_cycles=5000, *, finemb=True):
        """The next frame on ``port`` (a FinEmbP message dict when ``finemb``, else the
        scapy frame), or ``None``."""
        for _ in range(timeout_cycles // 8):
            got = self.ports[port].take()
            if got is not None:
                gf, frame = got
                assert frame is not None, "a frame from the node with a bad FCS or TX_ER"
                if IP in frame:
                    frame = Ether(bytes(frame)[:14 + frame[IP].len])
                return parse_finemb(frame) if finemb else frame
            await ClockCycles(self.dut.gmii_clk, 8)
        return None

    async def expect_silence(self, port=0, cycles=2000):
        got = await self.recv(port, cycles, finemb=False)
        assert got is None, f"unexpected frame on port {port}: {got!r}"

    async def drain(self, port, cycles=200):
        """Frames sent on ``port`` within ``cycles`` (scapy)."""
        out = []
        await clock_cycles(self.dut.gmii_clk, cycles)
        while (got := self.ports[port].take()) is not None:
            out.append(got[1])
        return out

    # ---- a master's requests
    def request(self, type_, node_id, body=b"", **kw):
        self.seq = (self.seq + 1) & 0xFFFF
        return finemb_frame(type_, node_id, body, seq=self.seq, **kw)

    async def exchange(self, frame, *, port=0, timeout_cycles=5000):
        await self.send(frame, port)
        return await self.recv(port, timeout_cycles)

    async def init(self, node_id=1, ip=None, port=0):
        """ID, address and IO descriptor exchange; return the descriptor bytes read."""
        ip = ip or node_ip(node_id)
        res = await self.exchange(self.request(MsgType.ID_REQ, NODE_ALL, body_of(MsgType.ID_REQ, 1),
                                               dst_mac=BROADCAST_MAC, dst_ip=BROADCAST_IP),
                                  port=port)
        assert res and res["type"] == MsgType.ID_RES, res
        mac = res["body"][:6]
        res = await self.exchange(self.request(
            MsgType.ADDR_REQ, NODE_ALL,
            body_of(MsgType.ADDR_REQ, mac, _ip_bytes(ip),
                    _ip_bytes("255.255.255.0"), node_id),
            dst_mac=BROADCAST_MAC, dst_ip=BROADCAST_IP), port=port)
        assert res and res["type"] == MsgType.ADDR_RES and res["node_id"] == node_id, res
        desc = b""
        total = None
        while total is None or len(desc) < total:
            res = await self.exchange(self.request(
                MsgType.IODESC_REQ, node_id, body_of(MsgType.IODESC_REQ, len(desc), 40),
                dst_mac=self.node_mac, dst_ip=ip), port=port)
            assert res and res["type"] == MsgType.IODESC_RES, res
            offset, total = struct.unpack_from("<HH", res["body"])
            assert offset == len(desc), (offset, len(desc))
            desc += res["body"][4:]
        return desc

    @property
    def node_mac(self):
        return int_to_mac(mac_to_int(self.params.get("mac", "02:00:00:00:46:01")))

    async def isend(self, node_id, values, *, cycle=0, port=0, ip=None, **kw):
        """One ISEND_REQ with the output page of ``values``; the ISEND_RES message."""
        page = self.io.pack(Direction.OUT, values)
        return await self.exchange(self.request(
            MsgType.ISEND_REQ, node_id, page, cycle=cycle, dst_mac=self.node_mac,
            dst_ip=ip or node_ip(node_id), **kw), port=port)

    def soc(self, period_ns=40_000, cycle=0, nodes=1):
        return self.request(MsgType.SOC, NODE_ALL, body_of(MsgType.SOC, period_ns, 0, nodes, 0),
                            cycle=cycle)

    def reinit_all(self):
        return self.request(MsgType.REINIT, NODE_ALL,
                            body_of(MsgType.REINIT, ReinitReason.MASTER_RESTART))


def _ip_bytes(ip):
    return bytes(int(x) for x in ip.split("."))



class LineMaster:
    """A cycle-accurate FinEmbP master on the master link of a line bench top
    (``finemb_line``): frames leave at exact clock cycles and every answer is timed at its
    last byte. It initialises nodes (all, or the ones it is given), runs cycles at the
    fastest pace or a fixed period, sequentially (one node after the other) or pipelined (all
    requests back to back), and checks every answer against the AVR221 model of its node.

    Times are clock cycles (8 ns) since the simulation started.
    """

    def __init__(self, dut, nodes, *, io=PID_IO):
        from cocotb.queue import Queue
        self.dut = dut
        self.n = nodes
        self.io = load_io_description(io)
        start_gmii_clocks(dut)
        self.port = Port(dut, "port0")
        self.seq = 0
        self.nodes = {}           # node id -> {"mac", "ip", "model", "serial"}
        self.rx = Queue()
        self.late = {}            # node id -> cycles without an answer in time
        self.answered = {}        # node id -> answers
        self.cycle_no = 0
        self.last_sent = []
        dut.loss_threshold.value = 0
        cocotb.start_soon(self._receive())

    @staticmethod
    def now():
        from cocotb.utils import get_sim_time
        return int(get_sim_time("ns")) // CLOCK_NS

    async def _receive(self):
        while True:
            gf = await self.port.sink.recv()
            at = self.now()
            ok = gf.check_fcs() and not any(gf.error or [])
            if not ok:
                continue
            frame = Ether(bytes(gf.get_payload()))
            if IP in frame:
                frame = Ether(bytes(frame)[:14 + frame[IP].len])
            msg = parse_finemb(frame)
            if msg is not None and msg["sport"] == FINEMB_PORT:
                self.rx.put_nowait((at, msg))

    async def reset(self):
        await reset_aresetn(self.dut)

    def request(self, type_, node_id, body=b"", **kw):
        self.seq = (self.seq + 1) & 0xFFFF
        return finemb_frame(type_, node_id, body, seq=self.seq, **kw)

    def send(self, frame):
        self.port.source.send_nowait(GmiiFrame.from_payload(bytes(frame)))

    async def answers(self, until, want, count=None):
        """Messages up to cycle ``until`` (or the first ``count``) for which ``want(msg)``
        holds, as ``(cycle, msg)`` (others are dropped)."""
        from cocotb.triggers import with_timeout
        got = []
        while self.now() < until and (count is None or len(got) < count):
            try:
                at, msg = await with_timeout(self.rx.get(), (until - self.now()) * CLOCK_NS,
                                             "ns")
            except TimeoutError:
                break
            if want(msg):
                got.append((at, msg))
        return got

    async def ask(self, frame, type_, node_id=None, timeout=20_000):
        """Send ``frame`` and return the first answer of ``type_`` (from ``node_id``)."""
        self.send(frame)
        deadline = self.now() + timeout
        while self.now() < deadline:
            got = await self.answers(deadline, lambda m: m["type"] == type_ and (
                node_id is None or m["node_id"] == node_id), count=1)
            if got:
                return got[0][1]
        raise AssertionError(f"no {type_.name} from node {node_id} within {timeout} cycles")

    async def discover(self, quiet=3_000):
        """ID_REQ to all: the MACs of the nodes still without address, by serial (collected
        until ``quiet`` cycles pass without another ID_RES)."""
        self.send(self.request(MsgType.ID_REQ, NODE_ALL, body_of(MsgType.ID_REQ, 1),
                               dst_mac=BROADCAST_MAC, dst_ip=BROADCAST_IP))
        got = []
        while True:
            more = await self.answers(self.now() + quiet, lambda m: m["type"] == MsgType.ID_RES,
                                      count=1)
            if not more:
                break
            got += more
        found = {}
        for _, msg in got:
            mac, _vendor, serial, *_ = struct.unpack("<6sHIBBHH", msg["body"])
            found[serial] = mac
        return found

    async def join(self, serial, mac):
        """Address the node with ``mac`` as node ``serial`` and read its IO descriptor."""
        node_id, ip = serial, node_ip(serial)
        msg = await self.ask(self.request(
            MsgType.ADDR_REQ, NODE_ALL, body_of(MsgType.ADDR_REQ, mac, _ip_bytes(ip),
                                                _ip_bytes("255.255.255.0"), node_id),
            dst_mac=BROADCAST_MAC, dst_ip=BROADCAST_IP), MsgType.ADDR_RES, node_id)
        assert msg["state"] == NodeState.PREOP, msg
        mac_text = int_to_mac(int.from_bytes(mac, "big"))
        desc = b""
        total = None
        while total is None or len(desc) < total:
            msg = await self.ask(self.request(
                MsgType.IODESC_REQ, node_id, body_of(MsgType.IODESC_REQ, len(desc), 256),
                dst_mac=mac_text, dst_ip=ip), MsgType.IODESC_RES, node_id)
            offset, total = struct.unpack_from("<HH", msg["body"])
            assert offset == len(desc)
            desc += msg["body"][4:]
        assert desc == self.io.encode(), f"node {node_id}: a different IO descriptor"
        self.nodes[node_id] = {"mac": mac_text, "ip": ip, "serial": serial,
                               "model": None, "values": None, "updates": None,
                               "unanswered": []}
        self.late.setdefault(node_id, 0)
        self.answered.setdefault(node_id, 0)

    async def init(self, serials=None):
        """Discover the line and join the nodes of ``serials`` (default: all)."""
        found = await self.discover()
        for serial in sorted(found):
            if serials is None or serial in serials:
                await self.join(serial, found[serial])
        return found

    def isend(self, node_id, values):
        node = self.nodes[node_id]
        frame = self.request(MsgType.ISEND_REQ, node_id, self.io.pack(Direction.OUT, values),
                             cycle=self.cycle_no, dst_mac=node["mac"], dst_ip=node["ip"])
        self.last_sent.append(frame)
        return frame

    def values(self, rng, node_id):
        """The next output page of a node: new set point and measurement, fixed gains."""
        node = self.nodes[node_id]
        if node["model"] is None:
            from .models.pid import AvrPid
            node["gains"] = dict(p_gain=rng.randrange(64, 512), i_gain=rng.randrange(0, 128),
                                 d_gain=rng.randrange(0, 64))
            node["model"] = AvrPid(node["gains"]["p_gain"], node["gains"]["i_gain"],
                                   node["gains"]["d_gain"])
        return dict(set_point=rng.randrange(-3000, 3000),
                    measurement=rng.randrange(-3000, 3000), **node["gains"])

    async def cycle(self, rng, *, polling, deadline, check=True):
        """One cycle: SoC, then every node's ISEND_REQ (sequential: each after the previous
        answer); answers are taken until cycle ``deadline``. Return ``(start, last answer
        cycle or None, {node: answer})``; a node that did not answer counts as late."""
        start = self.now()
        ids = sorted(self.nodes)
        soc = self.request(MsgType.SOC, NODE_ALL, body_of(
            MsgType.SOC, 40_000, start * CLOCK_NS, len(ids), 0), cycle=self.cycle_no)
        self.send(soc)
        self.last_sent = [soc]         # the frames of this cycle, for wire-time sums
        sent = {k: self.values(rng, k) for k in ids}
        got = {}
        last = None

        def want(node_ids):
            return lambda m: (m["type"] == MsgType.ISEND_RES and m["node_id"] in node_ids and
                              m["cycle"] == self.cycle_no)
        if polling == "pipelined":
            for k in ids:
                self.send(self.isend(k, sent[k]))
            while len(got) < len(ids) and self.now() < deadline:
                for at, msg in await self.answers(deadline, want(set(ids) - set(got)),
                                                  count=len(ids) - len(got)):
                    got[msg["node_id"]] = msg
                    last = at
                    if len(got) == len(ids):
                        break
        else:
            for k in ids:
                self.send(self.isend(k, sent[k]))
                for at, msg in await self.answers(deadline, want({k}), count=1):
                    got[k] = msg
                    last = at
                    break
                if k not in got:
                    break
        for k in ids:
            node = self.nodes[k]
            if k in got:
                self.answered[k] += 1
                msg = got[k]
                assert not msg["flags"] & Flag.ERROR, msg
                values = self.io.unpack(Direction.IN, msg["body"])
                model = node["model"]
                # a request whose answer came too late (or never) may still have run the
                # node's PID: the count of updates in the answer says how many of them did,
                # the latest ones (a lost request is older than a late one)
                ran = 0 if node["updates"] is None else values["updates"] - node["updates"] - 1
                if check:
                    assert 0 <= ran <= len(node["unanswered"]), \
                        (self.cycle_no, k, values["updates"], node["updates"],
                         len(node["unanswered"]))
                unanswered = node["unanswered"]
                for earlier in unanswered[len(unanswered) - max(ran, 0):]:
                    model.update(earlier["set_point"], earlier["measurement"])
                node["unanswered"] = []
                node["updates"] = values["updates"]
                expected = model.update(sent[k]["set_point"], sent[k]["measurement"])
                if check:
                    assert values["output"] == expected, (self.cycle_no, k, values, expected)
            else:
                self.late[k] += 1
                node["unanswered"].append(sent[k])
        self.cycle_no += 1
        return start, last, got

