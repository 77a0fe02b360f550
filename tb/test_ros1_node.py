"""The seed paper's setup (sitcp_ros_component_en.md §4, Fig. 8; docs/network.md): a software
publisher ``snd_data``, the hardware node between them, a software subscriber ``rcv_data``,
and a ROS master, all real sockets inside the TAP namespace.

The hardware node's subscriber endpoint connects (as a TCP client) to ``snd_data`` after the
software half learned it through ``publisherUpdate``/``requestTopic``; its publisher endpoint
listens, and ``rcv_data`` connects to it after ``requestTopic`` on the hardware node. Received
messages are published again unchanged in hardware (loopback). Golden models: rosbags (ROS 1
serialization, md5sum, definitions), the software peers of tb/models/ros1_peers.py written
from docs/messages.md, and the Linux TCP stack.
"""

import cocotb
import numpy as np
import pytest

from gen.msg import MessageLibrary
from gen.msg.ros1 import frame_message, md5sum, message_definition
from hdl.net.stack import global_register
from hdl.ros1.registers import PHASES
from host.ros1 import HardwareNode, RbcpClient, RosMaster
from tb.harness import run_bench
from tb.linux_tb import ENGINE_IP, KERNEL_IP, LinuxTB, namespace_unavailable, network_namespace
from tb.models.ros1_peers import SoftwarePublisher, SoftwareSubscriber
from tb.net_tb import NODE_CONFIG

IMAGE = "sensor_msgs/msg/Image"
STREAMING = PHASES.index("streaming")
#: the engine's TCP port in these tests, written before the node starts: the hardware
#: publisher has no port of its own (LOCAL_PORT 0), so it listens here, and requestTopic must
#: read it back for rcv_data to reach it (not SiTCP's default 24)
TCP_PORT = 11411


def test_ros1_node():
    why = namespace_unavailable()
    if why:
        pytest.skip(f"ROS 1 node bench skipped: {why}")
    with network_namespace():
        run_bench(__name__, "ros1_node", "loopback", NODE_CONFIG, "verilator")


class RosWorld:
    """Master, hardware node and the software peers of one test."""

    def __init__(self, tb, *, sub_md5=None, pub_md5=None):
        from rosbags.typesys import Stores, get_typestore
        self.tb = tb
        self.ts = get_typestore(Stores.ROS1_NOETIC)
        lib = MessageLibrary(store="ros1_noetic")
        self.md5 = md5sum(lib, IMAGE)
        self.definition = message_definition(lib, IMAGE)
        self.master = RosMaster(KERNEL_IP, 0).start()
        self.rbcp = RbcpClient(ENGINE_IP, timeout=2.0, retries=5)
        spec = dict(type="sensor_msgs/Image", md5sum=self.md5, definition=self.definition)
        self.node = HardwareNode("/fpga", self.master.uri, KERNEL_IP, ENGINE_IP, self.rbcp,
                                 [dict(spec, topic="/image_raw"),
                                  dict(spec, topic="/image_processed")])
        self.snd = SoftwarePublisher("/snd_data", self.master.uri, KERNEL_IP, "/image_raw",
                                     "sensor_msgs/Image", pub_md5 or self.md5, self.definition)
        self.rcv = SoftwareSubscriber("/rcv_data", self.master.uri, KERNEL_IP,
                                      "/image_processed", "sensor_msgs/Image",
                                      sub_md5 or self.md5, self.definition)

    def image(self, seq, width, height):
        rng = np.random.default_rng(seq)
        t = self.ts.types
        msg = t["sensor_msgs/msg/Image"](
            header=t["std_msgs/msg/Header"](seq=seq, stamp=t["builtin_interfaces/msg/Time"](
                sec=seq, nanosec=7), frame_id="cam"),
            height=height, width=width, encoding="rgb8", is_bigendian=0, step=3 * width,
            data=rng.integers(0, 256, 3 * width * height, dtype=np.uint8))
        return bytes(self.ts.serialize_ros1(msg, IMAGE))

    def close(self):
        for closer in (self.node.stop, self.snd.close, self.rcv.close, self.master.stop,
                       self.rbcp.close):
            try:
                closer()
            except OSError:
                pass


async def start_world(tb, **kw):
    world = RosWorld(tb, **kw)
    await tb.run_in_thread("engine TCP port", world.rbcp.write_int,
                           *global_register("tcp_port"), TCP_PORT)
    await tb.run_in_thread("hardware node start", world.node.start)
    assert world.node.listen_ports == {1: TCP_PORT}
    await tb.run_in_thread("snd_data registers", world.snd.register)
    return world


@cocotb.test()
async def run_snd_process_rcv(dut):
    """snd_data -> hardware subscriber -> loopback -> hardware publisher -> rcv_data."""
    tb = LinuxTB(dut)
    await tb.reset()
    world = await start_world(tb)
    try:
        await tb.poll("hardware subscriber streaming", lambda: int(dut.phase0.value) == STREAMING,
                      3_000_000)
        await tb.run_in_thread("rcv_data registers", world.rcv.register)
        await tb.poll("hardware publisher streaming", lambda: int(dut.phase1.value) == STREAMING,
                      3_000_000)
        # a second subscriber is refused: one TCP session per hardware publisher
        code, msg, _ = await tb.run_in_thread("second requestTopic", world.node.requestTopic,
                                              "/other", "/image_processed", [["TCPROS"]])
        assert code == 0, msg
        state = world.master.getSystemState("/test")[2]
        assert ["/image_raw", ["/fpga"]] in state[1] and ["/image_processed", ["/fpga"]] in state[0]
        sizes = [(8, 6), (64, 48), (1, 1), (33, 17)]
        sent = [world.image(seq, w, h) for seq, (w, h) in enumerate(sizes)]
        for body in sent:
            await tb.run_in_thread("publish", world.snd.publish, body)
        await tb.poll("messages at rcv_data", lambda: len(world.rcv.messages) >= len(sent),
                      40 * sum(len(b) for b in sent) + 1_000_000)
        assert world.rcv.messages == sent, "messages changed on their way through hardware"
        for body in world.rcv.messages:
            world.ts.deserialize_ros1(body, IMAGE)
        header = world.rcv.headers[0]
        assert (header["type"], header["md5sum"], header["topic"], header["callerid"]) == (
            "sensor_msgs/Image", world.md5, "/image_processed", "/fpga")
        assert header["message_definition"] == world.definition
        # what the hardware subscriber received from snd_data, as software reads it back
        pub_header = await tb.run_in_thread("read HDR_RX", world.node.clients[0].received_header)
        assert pub_header["callerid"] == "/snd_data" and pub_header["md5sum"] == world.md5
        # the endpoints' counters (the session's through its counter port): the publisher
        # sent its header (with its length prefix) and the framed messages, the subscriber
        # received snd_data's header (HDR_RX holds its body, framed like a message) and the
        # same messages
        sub, pub = world.node.clients
        framed = sum(len(frame_message(body)) for body in sent)
        counts = await tb.run_in_thread("counters", pub.counters)
        hdr_tx = await tb.run_in_thread("HDR_TX_LEN", pub.read, "HDR_TX_LEN")
        assert counts["messages_tx"] == len(sent) and counts["header_rejects"] == 0, counts
        assert counts["bytes_tx"] == hdr_tx + framed, (counts, hdr_tx, framed)
        sub_counts = await tb.run_in_thread("counters", sub.counters)
        hdr_rx = await tb.run_in_thread("HDR_RX_LEN", sub.read, "HDR_RX_LEN")
        assert sub_counts["messages_rx"] == len(sent), sub_counts
        assert sub_counts["bytes_rx"] == len(frame_message(bytes(hdr_rx))) + framed, (
            sub_counts, hdr_rx, framed)
        # CTRL.CLR_CNT zeroes them and leaves the connection streaming
        await tb.run_in_thread("clear counters", pub.clear_counters)
        counts = await tb.run_in_thread("counters", pub.counters)
        assert set(counts.values()) == {0}, counts
        assert int(dut.phase1.value) == STREAMING
        assert not world.rcv.errors and not world.snd.errors and not world.node.errors
    finally:
        world.close()


@cocotb.test()
async def run_header_mismatch(dut):
    """A subscriber with a wrong md5sum gets the hardware publisher's ``error=`` header and a
    close; a publisher that refuses the hardware subscriber's md5sum is reported."""
    tb = LinuxTB(dut)
    await tb.reset()
    world = await start_world(tb, sub_md5="0" * 32, pub_md5="1" * 32)
    try:
        await tb.run_in_thread("rcv_data registers", world.rcv.register)
        await tb.poll("error header at rcv_data", lambda: world.rcv.closed.is_set(), 3_000_000)
        assert world.rcv.headers and "error" in world.rcv.headers[0], (world.rcv.headers,
                                                                        world.rcv.errors)
        client = world.node.clients[1]
        await tb.poll("publisher listening again", lambda: PHASES[int(dut.phase1.value)] in ("idle", "connecting"),
                      3_000_000)
        counts = await tb.run_in_thread("counters", client.counters)
        assert counts["header_rejects"] == 1, counts
        errors = await tb.run_in_thread("errors", lambda: client.errors)
        assert "header_rejected" in errors, errors
        # snd_data (md5 1111...) refused the hardware subscriber's header with error=
        await tb.poll("snd_data refused", lambda: len(world.snd.rejected) >= 1, 3_000_000)
        sub_errors = await tb.run_in_thread("errors", lambda: world.node.clients[0].errors)
        assert "peer_error" in sub_errors or "header_rejected" in sub_errors, sub_errors
    finally:
        world.close()
