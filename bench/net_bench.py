"""cocotb side of ``make bench`` for the network engine: a Python peer on the wide-word GMII
port of tb/net_bench_tops.py (ARP answers, TCP peer models that acknowledge like Linux, RBCP
requests), goodput of long transfers in each direction and the seed paper's image
measurements through the TCPROS node, in simulated cycles; results to
``ROSGATE_BENCH_OUT``."""

import json
import os
import queue
import struct
import threading
import zlib
from pathlib import Path

import cocotb
from cocotb.triggers import RisingEdge

from bench.pace import PaceMeter
from hdl.net.frames import (
    ARP_REPLY,
    ARP_REQUEST,
    DEFAULT_IP,
    DEFAULT_MAC,
    DEFAULT_RBCP_PORT,
    ETHERTYPE_ARP,
    IP_PROTO_TCP,
    IP_PROTO_UDP,
    ip_to_int,
    mac_to_int,
)
from hdl.net.tcp import TCP_COUNTERS
from hdl.ros1.registers import PHASES
from host.pcap import SimCapture
from host.ros1.rbcp import RbcpClient, rbcp_reply_ok
from host.simulator import clock_cycles, start_clock
from tb.models.tcp_peer import TcpPeerModel, udp_frame
from tb.net_bench_tops import WORD_BYTES, pattern_bytes
from tb.net_tb import CLOCK_NS, GMII_NS, PEER_MAC, read_counter_bank
from tb.streams import reset_aresetn

PEER_IP = "192.168.10.1"            # the bench tops keep the engine's default addresses
ENGINE_MAC = DEFAULT_MAC
ENGINE_IP = DEFAULT_IP
STREAMING = PHASES.index("streaming")


def pattern(n, start=0):
    return pattern_bytes(start, n)


class WordLink:
    """Python side of :class:`~tb.net_bench_tops.GmiiWordPeer`: frames in and out as words; the
    coroutine wakes once per word while frames move and every ``idle`` cycles otherwise.
    ``cycle`` counts cycles of the GMII clock, the bench's time base (8 ns)."""

    def __init__(self, dut, on_frame, idle=16):
        self.dut = dut
        self.on_frame = on_frame
        self.idle = idle
        self.words = []
        self.frames_queued = 0
        self.rx = bytearray()
        self.cycle = 0
        self.hooks = []
        self.capture = SimCapture(os.environ.get("ROSGATE_BENCH_PCAP"), clock_ns=GMII_NS)
        dut.peer_in_tvalid.value = 0
        dut.peer_out_tready.value = 0

    def send(self, frame):
        self.capture.record("in", bytes(frame).ljust(60, b"\0"), self.cycle)
        frame = bytes(frame).ljust(60, b"\0")
        frame += zlib.crc32(frame).to_bytes(4, "little")
        chunks = [frame[i:i + WORD_BYTES] for i in range(0, len(frame), WORD_BYTES)]
        for n, chunk in enumerate(chunks):
            self.words.append((int.from_bytes(chunk.ljust(WORD_BYTES, b"\0"), "little"),
                               (1 << len(chunk)) - 1, int(n == len(chunks) - 1)))
        self.frames_queued += 1

    @property
    def backlog(self):
        return len(self.words)

    async def run(self):
        dut = self.dut
        while True:
            driving = bool(self.words)
            if driving:
                data, keep, last = self.words[0]
                dut.peer_in_tdata.value = data
                dut.peer_in_tkeep.value = keep
                dut.peer_in_tlast.value = last
            dut.peer_in_tvalid.value = int(driving)
            dut.peer_out_tready.value = 1
            await RisingEdge(dut.gmii_clk)
            self.cycle += 1
            moved = False
            if driving and dut.peer_in_tready.value == 1:
                if self.words.pop(0)[2]:
                    self.frames_queued -= 1
                moved = True
            if dut.peer_out_tvalid.value == 1:
                keep = int(dut.peer_out_tkeep.value)
                data = int(dut.peer_out_tdata.value).to_bytes(WORD_BYTES, "little")
                self.rx += data[:bin(keep).count("1")]
                moved = True
                if dut.peer_out_tlast.value == 1:
                    frame, self.rx = bytes(self.rx), bytearray()
                    assert zlib.crc32(frame[:-4]).to_bytes(4, "little") == frame[-4:], \
                        "engine frame with a bad FCS"
                    self.capture.record("out", frame[:-4], self.cycle)
                    self.on_frame(frame[:-4], self.cycle)
            for hook in self.hooks:
                hook(self.cycle)
            if not moved:
                dut.peer_in_tvalid.value = 0
                dut.peer_out_tready.value = 0
                await clock_cycles(dut.gmii_clk, self.idle)
                self.cycle += self.idle


class BenchPeer:
    """ARP answers, TCP peer models by local port, RBCP requests; paces the models so the
    link queue holds at most two frames (line rate, no unbounded backlog)."""

    def __init__(self, dut):
        self.dut = dut
        self.link = WordLink(dut, self.on_frame)
        self.link.hooks.append(self.poll)
        self.models = {}
        self.rbcp_replies = {}
        self.mac = mac_to_int(PEER_MAC)
        self.ip = ip_to_int(PEER_IP)
        self.rbcp_id = 0

    def model(self, port, engine_port, **kw):
        mdl = TcpPeerModel(mac=PEER_MAC, ip=PEER_IP, port=port, engine_mac=ENGINE_MAC,
                           engine_ip=ENGINE_IP, engine_port=engine_port, **kw)
        self.models[port] = mdl
        return mdl

    def on_frame(self, frame, cycle):
        ethertype = struct.unpack("!H", frame[12:14])[0]
        if ethertype == ETHERTYPE_ARP and struct.unpack("!H", frame[20:22])[0] == ARP_REQUEST and \
                frame[38:42] == self.ip.to_bytes(4, "big"):
            reply = (frame[6:12] + self.mac.to_bytes(6, "big") + frame[12:14] +
                     frame[14:20] + ARP_REPLY.to_bytes(2, "big") + self.mac.to_bytes(6, "big") +
                     self.ip.to_bytes(4, "big") + frame[22:32])
            self.link.send(reply)
            return
        if frame[23] == IP_PROTO_UDP and len(frame) >= 42:          # RBCP reply
            payload = frame[42:14 + struct.unpack("!H", frame[16:18])[0]]
            self.rbcp_replies[payload[2]] = payload
            return
        if frame[23] == IP_PROTO_TCP:
            dport = struct.unpack("!H", frame[36:38])[0]
            if dport in self.models:
                for f in self.models[dport].on_frame(frame, cycle):
                    self.link.send(f)

    def poll(self, cycle):
        if self.link.frames_queued >= 2:
            return
        for mdl in self.models.values():
            for f in mdl.poll(cycle, max_frames=2 - self.link.frames_queued):
                self.link.send(f)



class LinkRbcp(RbcpClient):
    """:class:`host.ros1.RbcpClient` whose datagrams a cocotb coroutine carries over the bench
    link, so software code (``EndpointClient``) runs unchanged in a thread."""

    def __init__(self, peer):
        super().__init__(ENGINE_IP, sock=False)
        self.peer = peer
        self.requests = queue.Queue()

    def _exchange(self, request, cmd, ident):
        done = threading.Event()
        box = {}
        self.requests.put((request, ident, done, box))
        done.wait(600)
        reply = box.get("reply")
        return reply if reply is not None and rbcp_reply_ok(reply, cmd, ident) else None

    async def serve(self, dut):
        peer = self.peer
        while True:
            try:
                request, ident, done, box = self.requests.get_nowait()
            except queue.Empty:
                await clock_cycles(dut.aclk, 256)
                continue
            peer.link.send(udp_frame(peer.mac, mac_to_int(ENGINE_MAC), peer.ip,
                                     ip_to_int(ENGINE_IP), 50000, DEFAULT_RBCP_PORT, request))
            for _ in range(200):
                await clock_cycles(dut.aclk, 64)
                box["reply"] = peer.rbcp_replies.pop(ident, None)
                if box["reply"] is not None:
                    break
            done.set()


async def setup(dut):
    start_clock(dut.aclk, CLOCK_NS)
    start_clock(dut.gmii_clk, GMII_NS)
    peer = BenchPeer(dut)
    await reset_aresetn(dut)
    cocotb.start_soon(peer.link.run())
    return peer


async def wait_for(peer, predicate, limit, what):
    start = peer.link.cycle
    while not predicate():
        assert peer.link.cycle - start < limit, f"{what}: not within {limit} cycles"
        await clock_cycles(peer.dut.aclk, 256)


def goodput_record(nbytes, cycles, start_cycle, marks):
    """Whole-transfer and steady-state goodput (the last 75 % of the bytes)."""
    q_bytes, q_cycle = marks
    steady_cycles = cycles + start_cycle - q_cycle
    return {"bytes": nbytes, "cycles": cycles,
            "mbps": nbytes * 8 / (cycles * GMII_NS * 1e-9) / 1e6,
            "steady_mbps": (nbytes - q_bytes) * 8 / (steady_cycles * GMII_NS * 1e-9) / 1e6}


@cocotb.test()
async def measure_tcp(dut):
    """Goodput engine -> peer (pattern generator) and peer -> engine (checking sink)."""
    case = json.loads(os.environ["ROSGATE_BENCH_CASE"])
    peer = await setup(dut)
    pace = PaceMeter(GMII_NS)
    nbytes = case["bytes"]
    dut.open_req.value = 1
    dut.active.value = 0
    dut.local_port.value = 24
    dut.gen_start.value = 0
    await clock_cycles(dut.aclk, 10)
    mdl = peer.model(40000, 24, isn=0xFFFF0000, **case["peer"])
    peer.link.send(mdl.syn())
    await wait_for(peer, lambda: mdl.established, 100_000, "handshake")
    records = {}
    # engine -> peer
    start = peer.link.cycle
    dut.gen_count.value = nbytes
    dut.gen_start.value = 1
    await RisingEdge(dut.aclk)
    dut.gen_start.value = 0
    marks = []
    while len(mdl.received) < nbytes:
        if not marks and len(mdl.received) >= nbytes // 4:
            marks = (len(mdl.received), peer.link.cycle)
        assert peer.link.cycle - start < 40 * nbytes, "transmit stalled"
        await clock_cycles(dut.aclk, 256)
    cycles = peer.link.cycle - start
    assert bytes(mdl.received) == pattern(nbytes), "engine sent other bytes than generated"
    records["engine_to_peer"] = goodput_record(nbytes, cycles, start, marks)
    # peer -> engine
    mdl.queue(pattern(nbytes))
    start = peer.link.cycle
    marks = []
    while int(dut.sink_received.value) < nbytes:
        got = int(dut.sink_received.value)
        if not marks and got >= nbytes // 4:
            marks = (got, peer.link.cycle)
        assert peer.link.cycle - start < 40 * nbytes, "receive stalled"
        await clock_cycles(dut.aclk, 256)
    cycles = peer.link.cycle - start
    assert int(dut.sink_mismatches.value) == 0, "engine delivered other bytes than sent"
    records["peer_to_engine"] = goodput_record(nbytes, cycles, start, marks)
    records["engine_counters"] = await read_counter_bank(
        dut.aclk, dut.tcp_counter_index, dut.tcp_counter_value, TCP_COUNTERS)
    records["peer_acks"] = mdl.acks_sent
    pace.write()
    Path(os.environ["ROSGATE_BENCH_OUT"]).write_text(json.dumps(records))


def _header_complete(data):
    return len(data) >= 4 and len(data) >= 4 + int.from_bytes(data[:4], "little")


def _image_body(ts, width, height, encoding, channels):
    """A ROS 1 sensor_msgs/Image of the given size; its pixel bytes are the bench pattern
    from the message's byte offset of the first pixel on (what the hardware generator
    sends)."""
    import numpy as np
    t = ts.types
    n = width * height * channels
    msg = t["sensor_msgs/msg/Image"](
        header=t["std_msgs/msg/Header"](seq=1, stamp=t["builtin_interfaces/msg/Time"](
            sec=1, nanosec=2), frame_id="camera"),
        height=height, width=width, encoding=encoding, is_bigendian=0, step=width * channels,
        data=np.zeros(n, dtype=np.uint8))
    body = bytearray(ts.serialize_ros1(msg, "sensor_msgs/msg/Image"))
    prefix = len(body) - n
    body[prefix:] = pattern_bytes(prefix, n)
    return bytes(body), prefix


@cocotb.test()
async def measure_image(dut):
    """The seed paper's measurement: a sensor_msgs/Image received by a hardware subscriber,
    sent by a hardware publisher, and received and sent back (loopback), per size."""
    from rosbags.typesys import Stores, get_typestore

    from gen.msg import MessageLibrary
    from gen.msg.ros1 import encode_connection_header, md5sum, message_definition
    from host.ros1.endpoint import EndpointClient
    case = json.loads(os.environ["ROSGATE_BENCH_CASE"])
    peer = await setup(dut)
    dut.gen_start.value = 0
    rbcp = LinkRbcp(peer)
    cocotb.start_soon(rbcp.serve(dut))
    ts = get_typestore(Stores.ROS1_NOETIC)
    lib = MessageLibrary(store="ros1_noetic")
    md5 = md5sum(lib, "sensor_msgs/msg/Image")
    definition = message_definition(lib, "sensor_msgs/msg/Image")
    topics = ["/image_in", "/image_out", "/image_rt_in", "/image_rt_out"]
    models = {0: peer.model(5000, 0, isn=1 << 20), 1: peer.model(40001, 24, isn=2 << 20),
              2: peer.model(5001, 0, isn=3 << 20), 3: peer.model(40002, 25, isn=4 << 20)}
    models[0].listen()
    models[2].listen()

    def configure():
        for k, topic in enumerate(topics):
            ep = EndpointClient(rbcp, k)
            ep.configure(callerid="/fpga", topic=topic, typename="sensor_msgs/Image",
                         md5sum=md5, definition=definition)
        EndpointClient(rbcp, 1).listen(24)
        EndpointClient(rbcp, 3).listen(25)
        EndpointClient(rbcp, 0).connect(PEER_IP, 5000)
        EndpointClient(rbcp, 2).connect(PEER_IP, 5001)

    done = threading.Event()
    errors = []

    def run():
        try:
            configure()
        except Exception as exc:        # reported below, in the cocotb thread
            errors.append(exc)
        done.set()
    threading.Thread(target=run, daemon=True).start()
    await wait_for(peer, done.is_set, 20_000_000, "register configuration")
    assert not errors, errors
    for k in (1, 3):
        peer.link.send(models[k].syn())

    def pub_header(topic):
        return encode_connection_header([("callerid", "/snd_data"), ("md5sum", md5),
                                         ("type", "sensor_msgs/Image"), ("topic", topic),
                                         ("latching", "0"), ("message_definition", definition)])

    def sub_header(topic):
        return encode_connection_header([("callerid", "/rcv_data"), ("topic", topic),
                                         ("md5sum", md5), ("type", "sensor_msgs/Image"),
                                         ("tcp_nodelay", "1")])
    await wait_for(peer, lambda: all(m.established for m in models.values()), 2_000_000,
                   "connections")
    for k in (1, 3):
        models[k].queue(sub_header(topics[k]))
    for k in (0, 2):
        await wait_for(peer, lambda k=k: _header_complete(models[k].received), 2_000_000,
                       "hardware subscriber header")
        models[k].queue(pub_header(topics[k]))
        models[k].received.clear()
    await wait_for(peer, lambda: all(int(getattr(dut, f"phase{k}").value) == STREAMING
                                     for k in range(4)), 2_000_000, "streaming")
    for k in (1, 3):
        await wait_for(peer, lambda k=k: _header_complete(models[k].received), 2_000_000,
                       "hardware publisher header")
        models[k].received.clear()
    records = {}
    for label, width, height, encoding, channels in case["images"]:
        body, prefix = _image_body(ts, width, height, encoding, channels)
        frame = len(body).to_bytes(4, "little") + body
        rec = {"bytes": len(body), "size": f"{width}x{height} {encoding}"}
        # receive-only: peer publisher -> hardware subscriber -> CRC sink
        messages = int(dut.sink_messages.value)
        start = peer.link.cycle
        models[0].queue(frame)
        await wait_for(peer, lambda: int(dut.sink_messages.value) > messages, 40 * len(frame),
                       "receive-only")
        rec["receive_cycles"] = peer.link.cycle - start
        assert int(dut.sink_crc.value) == zlib.crc32(body), "receive-only: CRC differs"
        # send-only: generator -> hardware publisher -> peer subscriber
        dut.gen_prefix.value = int.from_bytes(body[:prefix].ljust(64, b"\0"), "little")
        dut.gen_prefix_len.value = prefix
        dut.gen_length.value = len(body)
        models[1].received.clear()
        start = peer.link.cycle
        dut.gen_start.value = 1
        await RisingEdge(dut.aclk)
        dut.gen_start.value = 0
        await wait_for(peer, lambda: len(models[1].received) >= len(frame), 40 * len(frame),
                       "send-only")
        rec["send_cycles"] = peer.link.cycle - start
        assert bytes(models[1].received) == frame, "send-only: message differs"
        ts.deserialize_ros1(bytes(models[1].received[4:]), "sensor_msgs/msg/Image")
        # round trip: peer -> hardware subscriber -> loopback -> hardware publisher -> peer
        models[3].received.clear()
        start = peer.link.cycle
        models[2].queue(frame)
        await wait_for(peer, lambda: len(models[3].received) >= len(frame), 80 * len(frame),
                       "round trip")
        rec["round_trip_cycles"] = peer.link.cycle - start
        assert bytes(models[3].received) == frame, "round trip: message differs"
        for key in ("receive", "send", "round_trip"):
            rec[f"{key}_ms"] = rec[f"{key}_cycles"] * GMII_NS * 1e-6
        records[label] = rec
        dut._log.info("%s: %s", label, rec)
    Path(os.environ["ROSGATE_BENCH_OUT"]).write_text(json.dumps(records))
