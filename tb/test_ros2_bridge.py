"""``rosgate sim --ros2``: the co-simulated system on a Cyclone DDS domain, reached by an
independent participant (tb/models/ros2_peer.py: hand-written DDS types, rmw_cyclonedds_cpp's
request header) on loopback, each test on its own domain id.

* DDS names and types: topic, service and type names as ROS 2 maps them; the bridge's DDS
  types serialize byte for byte as rosbags does.
* The Sobel/DIP demo from DDS: images published on ``rt/image_raw`` come back on
  ``rt/image_filtered`` equal to OpenCV's Sobel edge image, their bytes equal to what rosbags
  serializes; a call of the hardware Sobel service from a DDS client; bad samples (truncated,
  wrong layout, oversized sequence, an image the hardware cannot take) rejected and counted,
  the next image delivered; SIGTERM ends the run cleanly.
* A hardware client calling a service that the test serves on DDS (the DIP node alone).
"""

import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from gen.msg import MessageLibrary
from host.ros2.graph import (
    absolute_name,
    dds_topic_name,
    dds_type_name,
    ros_interfaces,
    service_topic_names,
)

from .harness import ROOT
from .models import ros2_peer as peer
from .models.image import IMAGES

SOBEL_DIP = ROOT / "examples" / "sobel_dip" / "build.cfg"


def opencv_edges(pixels):
    gx = cv2.Sobel(pixels, cv2.CV_16S, 1, 0, ksize=3)
    gy = cv2.Sobel(pixels, cv2.CV_16S, 0, 1, ksize=3)
    return cv2.add(cv2.convertScaleAbs(gx), cv2.convertScaleAbs(gy))


def rosbags_cdr(sample, typename="sensor_msgs/msg/Image"):
    """rosbags' CDR of a hand-written Image sample."""
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_HUMBLE)
    T = store.types
    msg = T[typename](
        header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=sample.header.stamp.sec,
                                                   nanosec=sample.header.stamp.nanosec),
            frame_id=sample.header.frame_id),
        height=sample.height, width=sample.width, encoding=sample.encoding,
        is_bigendian=sample.is_bigendian, step=sample.step,
        data=np.array(sample.data, np.uint8))
    return bytes(store.serialize_cdr(msg, typename))


def test_names_follow_ros2_mapping():
    assert dds_topic_name("/image_raw") == "rt/image_raw"
    assert dds_topic_name("filtered") == "rt/filtered"
    assert dds_topic_name("/a/b") == "rt/a/b"
    assert dds_type_name("sensor_msgs/msg/Image") == "sensor_msgs::msg::dds_::Image_"
    assert dds_type_name("my_pkg/srv/Sort_Request") == "my_pkg::srv::dds_::Sort_Request_"
    assert service_topic_names("srv") == ("rq/srvRequest", "rr/srvReply")
    assert service_topic_names("/a/b") == ("rq/a/bRequest", "rr/a/bReply")
    for bad in ("", "/", "a//b", "a/", "1abc", "a b"):
        with pytest.raises(ValueError, match="not a valid ROS 2"):
            absolute_name(bad, "build.cfg:3")
    with pytest.raises(ValueError, match="pkg/msg/Type"):
        dds_type_name("Image")


def test_interfaces_of_the_examples():
    from gen.config import load_project
    graph = ros_interfaces(load_project(SOBEL_DIP))
    assert {n: (t.msgtype, t.publishers, t.subscribers) for n, t in graph.topics.items()} == {
        "/image_raw": ("sensor_msgs/msg/Image", [], ["DIP"]),
        "/image_filtered": ("sensor_msgs/msg/Image", ["DIP"], [])}
    service = graph.services["/sobelservice"]
    assert (service.srvtype, service.servers, service.clients, service.key) == \
        ("application_msgs/srv/SobelSrv", ["Sobel"], ["DIP"], "sobelservice")
    graph = ros_interfaces(load_project(ROOT / "examples" / "hwtopic_gateway" / "build.cfg"))
    assert {n: (t.publishers, t.subscribers, t.hardware_topic)
            for n, t in graph.topics.items()} == {
        "/outputtopic": (["Threada"], [], None), "/inputtopic": ([], ["Threadb"], None),
        "/topic/gateway": (["Gateway1"], ["Gateway1"], "nicehwtopic")}


def test_dds_types_serialize_as_rosbags():
    """The bridge's generated DDS types against rosbags for messages with nested types,
    strings, bounded strings, fixed and bounded arrays and sequences of messages."""
    from rosbags.typesys import Stores, get_typestore

    from host.ros2.types import DdsTypes
    store = get_typestore(Stores.ROS2_HUMBLE)
    library = MessageLibrary([], store="ros2_humble")
    types = DdsTypes(library)
    rng = random.Random()
    T = store.types
    stamp = T["builtin_interfaces/msg/Time"](sec=rng.randrange(1 << 31), nanosec=7)
    header = T["std_msgs/msg/Header"](stamp=stamp, frame_id="base_link")
    cases = {
        "sensor_msgs/msg/Image": T["sensor_msgs/msg/Image"](
            header=header, height=2, width=3, encoding="mono8", is_bigendian=0, step=3,
            data=np.frombuffer(rng.randbytes(6), np.uint8)),
        "sensor_msgs/msg/JointState": T["sensor_msgs/msg/JointState"](
            header=header, name=["a", "bc", ""], position=np.array([1.5, -2.0]),
            velocity=np.array([], np.float64), effort=np.array([0.25])),
        "geometry_msgs/msg/PoseWithCovariance": T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=3.0),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
            covariance=np.arange(36, dtype=np.float64)),
        "visualization_msgs/msg/MarkerArray": T["visualization_msgs/msg/MarkerArray"](
            markers=[]),
        "std_msgs/msg/Empty": T["std_msgs/msg/Empty"](),
    }
    for typename, msg in cases.items():
        raw = bytes(store.serialize_cdr(msg, typename))
        idl = types.message(typename)
        assert idl.__idl_typename__ == dds_type_name(typename)
        assert idl.deserialize(raw).serialize() == raw, typename


@pytest.fixture
def photo():
    return cv2.imread(str(IMAGES / "coffee_80x60.png"))


@pytest.mark.full
def test_sobel_dip_from_dds(tmp_path, photo):
    """A DDS participant drives the Sobel/DIP system (Verilator) as ROS 2 nodes would. In
    make test-full only (40 s): make test drives hardware services, topics and actions from
    DDS in the tests below, and the Sobel/DIP system in tb/test_project_sim.py."""
    rng = np.random.default_rng()
    odd = rng.integers(0, 256, (17, 33, 3), np.uint8)
    domain = peer.unique_domain()
    out = tmp_path / "out"
    bag, trace = tmp_path / "bag", tmp_path / "trace.txt"
    sent, received = [], []
    with peer.ros2_sim(SOBEL_DIP, "verilator", out, domain, "--record", str(bag),
                       "--trace", str(trace)):
        p = peer.Peer(domain)
        raw_writer = p.writer("rt/image_raw", peer.Image)
        filtered = p.reader("rt/image_filtered", peer.Image)
        p.wait_matched(raw_writer, filtered)

        def round_trip(pixels, sec):
            raw_writer.write(peer.image(pixels, sec))
            sent.append(pixels)
            data = p.take_raw(filtered)
            received.append(data)
            sample = peer.Image.deserialize(data)
            got = np.array(sample.data, np.uint8).reshape(pixels.shape)
            assert (sample.height, sample.width, sample.encoding, sample.step) == \
                (pixels.shape[0], pixels.shape[1], "bgr8", pixels.shape[1] * 3)
            assert np.array_equal(got, opencv_edges(pixels))
            cdr = rosbags_cdr(sample)
            assert data[4:len(cdr)] == cdr[4:] and not any(data[len(cdr):]), \
                "the sample's bytes differ from rosbags' CDR"
            assert data[:3] == cdr[:3] and data[3] & 3 == -len(cdr) % 4

        round_trip(photo, 1)
        round_trip(odd, 2)

        # bad samples: each rejected with a log line and counted; the next image arrives.
        # (Cyclone itself refuses structurally broken CDR, such as a sequence count past the
        # end, at the writer and at the reader: test_bridge_rejects_undecodable_samples.)
        full = peer.image(photo, 4)
        wrong_layout = peer.ImageWideFlag(full.header, full.height, full.width, full.encoding,
                                          full.is_bigendian, full.step, full.data).serialize()
        trailing = peer.image(photo[:20, :30], 3).serialize() + bytes(range(1, 9))
        longer = peer.image(photo[:20, :30], 5)
        longer.data = longer.data * 3                   # more data than 30x20 bgr8 holds
        too_big = peer.image(np.zeros((500, 700, 3), np.uint8), 6).serialize()
        for data in (wrong_layout, trailing, longer.serialize(), too_big):
            p.write_raw(raw_writer, data)
        round_trip(photo[5:50, 7:70], 6)

        # a burst faster than the hardware: DDS and the hardware's subscription keep the last
        # 10 images (ROS 2's default history); every image the bridge delivered is filtered
        # or counted as dropped, and the last one arrives
        burst = [rng.integers(0, 256, (6, 8, 3), np.uint8) for _ in range(25)]
        for k, pixels in enumerate(burst):
            raw_writer.write(peer.image(pixels, 100 + k))
        filtered_burst = {}
        while 124 not in filtered_burst:
            sample = peer.Image.deserialize(p.take_raw(filtered))
            filtered_burst[sample.header.stamp.sec] = sample
        for sec, sample in filtered_burst.items():
            assert np.array_equal(np.array(sample.data, np.uint8).reshape(6, 8, 3),
                                  opencv_edges(burst[sec - 100]))

        # the hardware Sobel service, called from DDS with rmw_cyclonedds_cpp's header
        request_writer = p.writer("rq/sobelserviceRequest", peer.SobelSrvRequest)
        replies = p.reader("rr/sobelserviceReply", peer.SobelSrvResponse)
        p.wait_matched(request_writer, replies)
        crop = photo[10:40, 20:61]
        request_writer.write(peer.SobelSrvRequest(0x1122334455667788, 41, peer.image(crop)))
        reply = peer.SobelSrvResponse.deserialize(p.take_raw(replies))
        assert (reply.guid, reply.seq) == (0x1122334455667788, 41)
        assert np.array_equal(np.array(reply.img.data, np.uint8).reshape(crop.shape),
                              opencv_edges(crop))
    got = peer.results(out)["ros2"]
    raw = got["counts"]["/image_raw"]
    burst_delivered = raw["delivered"] - 3
    assert raw["received"] == raw["delivered"] + 4 and raw["rejected"] == 4, got
    assert len(filtered_burst) <= burst_delivered <= len(burst), got
    assert got["counts"]["/image_filtered"]["sent"] == 3 + len(filtered_burst), got
    assert got["dropped_by_history"]["/image_raw"] == burst_delivered - len(filtered_burst), \
        got
    assert got["counts"]["/sobelservice"]["delivered"] == 1, got
    reasons = [r["reason"] for r in got["rejections"]]
    assert "left over" in reasons[1] and "5400 data bytes" in reasons[2], reasons
    assert "700x500" in reasons[3], reasons
    console = (tmp_path / "out.console").read_text()
    assert console.count("rejected a sensor_msgs/msg/Image from DDS") == 4, console
    assert "stopping on SIGTERM" in console and "wrote" in console.splitlines()[-1], console
    assert not (out / "sim_error.json").exists()
    check_recording(bag, trace, sent, received, burst_delivered, len(filtered_burst))


def check_recording(bag, trace, sent, received, burst, burst_filtered):
    """The bag, read back with rosbags: both topics with their type, the images sent on
    /image_raw and the samples DDS delivered on /image_filtered, in order, at increasing
    simulated times (after them the burst: every image published, the filtered ones); the
    trace has one line per message."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == {
            "/image_raw": "sensor_msgs/msg/Image", "/image_filtered": "sensor_msgs/msg/Image"}
        got = {"/image_raw": [], "/image_filtered": []}
        times = []
        for connection, stamp, data in reader.messages():
            got[connection.topic].append(reader.deserialize(data, connection.msgtype))
            times.append(stamp)
            if connection.topic == "/image_filtered" and \
                    len(got["/image_filtered"]) <= len(received):
                out = received[len(got["/image_filtered"]) - 1]
                assert bytes(data[4:]) == out[4:len(data)]   # DDS sets the padding count
    total = 2 * len(sent) + burst + burst_filtered
    assert times == sorted(times) and len(times) == total
    assert [m.data.tobytes() for m in got["/image_raw"][:len(sent)]] == \
        [p.tobytes() for p in sent]
    assert [(m.height, m.width) for m in got["/image_filtered"][:len(sent)]] == \
        [p.shape[:2] for p in sent]
    lines = trace.read_text().splitlines()[1:]
    assert len(lines) == total
    assert all(" sensor_msgs/msg/Image " in x and "encoding='bgr8'" in x for x in lines)


class FakeBroker:
    def __init__(self):
        self.published = []

    def publish(self, topic, value, origin=None):
        self.published.append((topic, value))


def test_bridge_rejects_undecodable_samples():
    """Samples Cyclone lets through only from peers that do not check CDR: truncated, a
    sequence count past the end, non-zero padding; each rejected and counted, the broker
    untouched; a good sample after them delivered. A Cyclone writer refuses the same bytes."""
    from host.ros2.bridge import Ros2Bridge, _Endpoint
    library = MessageLibrary([], store="ros2_humble")
    lines = []
    broker = FakeBroker()
    bridge = Ros2Bridge(None, library, broker, domain=0, log=lines.append, spawn=None)
    ep = _Endpoint("/image_raw", "sensor_msgs/msg/Image", None, "/image_raw")
    pixels = np.arange(24, dtype=np.uint8).reshape(2, 4, 3)
    good = peer.image(pixels).serialize()
    count_at = len(good) - 24 - 4
    bad = [good[:40], good[:count_at] + (1 << 31).to_bytes(4, "little") + good[count_at + 4:],
           good[:-1], b"\x00\x00\x00\x00" + good[4:]]
    for data in bad + [good]:
        bridge._topic_sample(ep, data)
    assert bridge.counts["/image_raw"] == {"received": 0, "delivered": 1, "rejected": 4,
                                           "sent": 0}
    assert len(lines) == 4 and all("rejected a sensor_msgs/msg/Image" in x for x in lines)
    assert "big-endian" in lines[3] or "little-endian" in lines[3], lines
    assert [v["data"] for _, v in broker.published] == [pixels.tobytes()]


def test_hardware_client_calls_a_dds_service(tmp_path, photo):
    """The DIP node alone (Icarus): its Sobel service is served by this test on DDS; the
    image it publishes is what the test's server answered. A reply to a call nobody made is
    rejected and counted."""
    project = tmp_path / "dip_only"
    shutil.copytree(SOBEL_DIP.parent, project)
    text = (project / "build.cfg").read_text()
    text = text.replace("[HwSlot@SobelDIP(0:1)]", "[HwSlot@SobelDIP(0:0)]")
    text = text[:text.index("[ResourceGroup@ResourceGroupSobel]")] + \
        text[text.index("[ResourceGroup@ResourceGroupDIP]"):text.index("[ReconosThread@Sobel]")] \
        + text[text.index("[ReconosThread@DIP]"):].replace("SobelDIP(1)", "SobelDIP(0)")
    (project / "build.cfg").write_text(text)
    domain = peer.unique_domain()
    out = tmp_path / "out"
    pixels = photo[:12, :16]
    with peer.ros2_sim(project / "build.cfg", "icarus", out, domain):
        p = peer.Peer(domain)
        requests = p.reader("rq/sobelserviceRequest", peer.SobelSrvRequest)
        replies = p.writer("rr/sobelserviceReply", peer.SobelSrvResponse)
        raw_writer = p.writer("rt/image_raw", peer.Image)
        filtered = p.reader("rt/image_filtered", peer.Image)
        p.wait_matched(requests, replies, raw_writer, filtered)
        raw_writer.write(peer.image(pixels, 9))
        request = peer.SobelSrvRequest.deserialize(p.take_raw(requests))
        assert np.array_equal(np.array(request.img.data, np.uint8).reshape(pixels.shape),
                              pixels)
        answer = opencv_edges(pixels)[::-1].copy()       # anything the hardware cannot make
        replies.write(peer.SobelSrvResponse(request.guid, request.seq + 100,
                                            peer.image(answer)))
        replies.write(peer.SobelSrvResponse(request.guid, request.seq, peer.image(answer)))
        sample = peer.Image.deserialize(p.take_raw(filtered))
        assert np.array_equal(np.array(sample.data, np.uint8).reshape(pixels.shape), answer)
    got = peer.results(out)["ros2"]
    assert got["counts"]["/sobelservice"] == {"received": 2, "delivered": 1, "rejected": 1,
                                              "sent": 1}, got
    assert "did not make" in got["rejections"][0]["reason"]


def test_ros2_options_need_ros2(capsys):
    from host.cli import main as rosgate
    for option in (["--domain", "3"], ["--with-nodes"], ["--service-queue", "5"],
                   ["--clock", "wall"], ["--goal-policy", "reject"]):
        assert rosgate(["sim", str(SOBEL_DIP), *option]) == 2
        assert "--domain, --with-nodes, --service-queue, --clock and --goal-policy need " \
            "--ros2" in capsys.readouterr().err
    assert rosgate(["sim", str(SOBEL_DIP), "--ros2", "--domain", "300"]) == 2
    assert "--domain 300" in capsys.readouterr().err



SORT_ACTION = ROOT / "examples" / "sort_action" / "build.cfg"


def test_hardware_action_from_dds(tmp_path):
    """The hardware sort action server (Icarus) used by a DDS action client the way
    rcl_action does: send_goal, feedback, get_result, status; a goal larger than the server's
    block size refused; cancels of a finished and of an unknown goal answered with their
    error codes; a result request for an unknown goal answered STATUS_UNKNOWN."""
    domain = peer.unique_domain()
    out = tmp_path / "out"
    rng = random.Random()
    with peer.ros2_sim(SORT_ACTION, "icarus", out, domain):
        p = peer.Peer(domain)
        e = _action_endpoints(p, status=True)
        send, sent, ask, results = e["send"], e["sent"], e["ask"], e["results"]
        cancel, cancelled, feedback, status = (e["cancel"], e["cancelled"], e["feedback"],
                                               e["status"])
        guid = rng.randrange(1, 1 << 63)
        uuid = peer.UUID(list(rng.randbytes(16)))
        values = [rng.randrange(1 << 32) for _ in range(rng.randrange(100, 257))]
        send.write(peer.SortSendGoalRequest(guid, 1, uuid, peer.SortGoal(values)))
        reply = peer.SortSendGoalResponse.deserialize(p.take_raw(sent))
        assert (reply.guid, reply.seq, reply.accepted) == (guid, 1, True)
        ask.write(peer.SortGetResultRequest(guid, 2, uuid))
        result = peer.SortGetResultResponse.deserialize(p.take_raw(results))
        assert (result.seq, result.status, list(result.result.sorted)) == \
            (2, 4, sorted(values))
        percents = []
        while not percents or percents[-1] < 100:
            message = peer.SortFeedbackMessage.deserialize(p.take_raw(feedback))
            assert list(message.goal_id.uuid) == list(uuid.uuid)
            percents.append(message.feedback.percent)
        assert percents == sorted(percents) and len(percents) >= 2
        latest = peer.GoalStatusArray.deserialize(p.take_raw(status))
        while latest.status_list[-1].status != 4:
            latest = peer.GoalStatusArray.deserialize(p.take_raw(status))
        assert list(latest.status_list[-1].goal_info.goal_id.uuid) == list(uuid.uuid)

        too_many = [1] * 300
        send.write(peer.SortSendGoalRequest(guid, 3, peer.UUID(list(rng.randbytes(16))),
                                            peer.SortGoal(too_many)))
        reply = peer.SortSendGoalResponse.deserialize(p.take_raw(sent))
        assert (reply.seq, reply.accepted) == (3, False)
        stranger = peer.UUID(list(rng.randbytes(16)))
        for seq, goal_id, code in ((4, uuid, 3), (5, stranger, 2)):
            cancel.write(peer.CancelGoalRequest(guid, seq, peer.GoalInfo(goal_id,
                                                                         peer.Time(0, 0))))
            answer = peer.CancelGoalResponse.deserialize(p.take_raw(cancelled))
            assert (answer.seq, answer.return_code) == (seq, code)
        ask.write(peer.SortGetResultRequest(guid, 6, stranger))
        result = peer.SortGetResultResponse.deserialize(p.take_raw(results))
        assert (result.seq, result.status, list(result.result.sorted)) == (6, 0, [])
    got = peer.results(out)["ros2"]
    assert got["counts"]["/sort/_action/cancel_goal"]["rejected"] == 1, got
    assert got["counts"]["/sort/_action/get_result"]["rejected"] == 1, got


GATEWAY_DEMO = ROOT / "examples" / "hwtopic_gateway" / "build.cfg"


def test_gateway_demo_from_dds(tmp_path):
    """examples/hwtopic_gateway (Icarus) from DDS: images a participant publishes on
    /inputtopic come back on /outputtopic (Threadb -> hardware topic -> Threada) and on
    /topic/gateway (the generated gateway), unchanged; the bag holds the hardware topic's
    traffic as it appeared on /topic/gateway."""
    domain = peer.unique_domain()
    out = tmp_path / "out"
    bag = tmp_path / "bag"
    rng = np.random.default_rng()
    with peer.ros2_sim(GATEWAY_DEMO, "icarus", out, domain, "--record", str(bag)):
        p = peer.Peer(domain)
        writer = p.writer("rt/inputtopic", peer.Image)
        outputs = p.reader("rt/outputtopic", peer.Image)
        gateway = p.reader("rt/topic/gateway", peer.Image)
        p.wait_matched(writer, outputs, gateway)
        sent = []
        for k in range(3):
            height, width = (int(x) for x in rng.integers(1, 20, 2))
            sample = peer.image(rng.integers(0, 256, (height, width, 3), np.uint8), k,
                                frame_id="f" * int(rng.integers(0, 12)))
            writer.write(sample)
            sent.append(sample)
            for reader in (outputs, gateway):
                assert peer.Image.deserialize(p.take_raw(reader)) == sample
    got = peer.results(out)["ros2"]["counts"]
    assert got["/inputtopic"]["delivered"] == 3 and got["/outputtopic"]["sent"] == 3, got
    assert got["/topic/gateway"]["sent"] == 3, got
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts == {"/inputtopic": 3, "/outputtopic": 3, "/topic/gateway": 3}, counts


SORT_SERVICE = ROOT / "examples" / "sort_service" / "build.cfg"


def call_sort(p, service, guid, calls):
    """Calls of the ``my_reconros_services/srv/Sort`` service ``service`` from participant
    ``p`` as client ``guid``, written back to back (``calls``: sequence number -> values);
    the replies, sequence number -> sorted values, each checked to be this client's."""
    requests = p.writer(f"rq/{service}Request", peer.SortRequest)
    replies = p.reader(f"rr/{service}Reply", peer.SortResponse)
    p.wait_matched(requests, replies)
    for seq, values in calls.items():
        requests.write(peer.SortRequest(guid, seq, values))
    got = {}
    for _ in calls:
        reply = peer.SortResponse.deserialize(p.take_raw(replies))
        assert reply.guid == guid, (reply.guid, guid)
        got[reply.seq] = list(reply.sorted)
    return got


def test_sort_service_from_dds(tmp_path):
    """examples/sort_service (two hardware servers of "srv" in slots on their own 120 MHz
    clock, Icarus) called from a DDS client: concurrent calls with their own sequence
    numbers come back sorted, each with its own header."""
    domain = peer.unique_domain()
    out = tmp_path / "out"
    rng = random.Random()
    with peer.ros2_sim(SORT_SERVICE, "icarus", out, domain):
        guid = rng.randrange(1, 1 << 63)
        calls = {seq: [rng.randrange(1 << 32) for _ in range(rng.randrange(1, 80))]
                 for seq in (7, 8, 9)}
        got = call_sort(peer.Peer(domain), "srv", guid, calls)
    assert got == {seq: sorted(values) for seq, values in calls.items()}


def test_sort_service_burst_is_answered_call_for_call(tmp_path):
    """Two DDS clients write 50 calls each back to back, 3 of them larger than the sort thread
    takes: every call is answered to its own client and sequence number, 97 sorted, the 3
    with the empty response, which the bridge counts and logs as rejected (received =
    delivered + rejected). The thread's block is 64 values here, so a call takes ~800
    cycles instead of 22,500."""
    domain = peer.unique_domain()
    out = tmp_path / "out"
    rng = random.Random()
    block = 64
    with peer.ros2_sim(SORT_SERVICE, "icarus", out, domain, "--param",
                       f"SortDemo.block_size={block}"):
        p = peer.Peer(domain)
        writers = [p.writer("rq/srvRequest", peer.SortRequest) for _ in range(2)]
        replies = p.reader("rr/srvReply", peer.SortResponse)
        p.wait_matched(*writers, replies)
        guids = [rng.randrange(1, 1 << 63) for _ in writers]
        calls = {}
        too_large = set(rng.sample(range(100), 3))
        for k in range(100):
            client, seq = k % 2, k // 2 + 1
            n = rng.choice([block + 1, 1000]) if k in too_large else rng.randrange(1, block + 1)
            values = [rng.randrange(1 << 32) for _ in range(n)]
            calls[(guids[client], seq)] = values
            writers[client].write(peer.SortRequest(guids[client], seq, values))
        got = {}
        for _ in calls:
            reply = peer.SortResponse.deserialize(p.take_raw(replies))
            assert (reply.guid, reply.seq) not in got, "answered twice"
            got[(reply.guid, reply.seq)] = list(reply.sorted)
    assert set(got) == set(calls)
    for key, values in calls.items():
        assert got[key] == ([] if len(values) > block else sorted(values)), key
    counts = peer.results(out)["ros2"]["counts"]["/srv"]
    assert counts == {"received": 100, "delivered": 97, "rejected": 3, "sent": 100}, counts
    console = (tmp_path / "out.console").read_text()
    refused = re.findall(r"/srv: rejected a my_reconros_services/srv/Sort_Request from DDS: "
                         r"(\d+) values; the sort thread takes 1 to 64", console)
    assert sorted(map(int, refused)) == sorted(len(calls[k]) for k in calls
                                               if len(calls[k]) > block), console


def test_service_calls_beyond_the_queue_are_refused_not_lost(tmp_path):
    """--service-queue 3: ten calls written at once; those beyond the three the bridge holds
    for the hardware are answered with the empty response at once, counted and logged; none
    is lost."""
    domain = peer.unique_domain()
    out = tmp_path / "out"
    rng = random.Random()
    with peer.ros2_sim(SORT_SERVICE, "icarus", out, domain, "--service-queue", "3",
                       "--param", "SortDemo.block_size=64"):
        calls = {seq: [rng.randrange(1 << 32) for _ in range(rng.randrange(1, 65))]
                 for seq in range(1, 11)}
        got = call_sort(peer.Peer(domain), "srv", 7, calls)
    assert set(got) == set(calls)
    refused = [seq for seq in calls if got[seq] == []]
    assert all(got[seq] == sorted(calls[seq]) for seq in calls if seq not in refused)
    counts = peer.results(out)["ros2"]["counts"]["/srv"]
    assert counts["received"] == 10 and counts["rejected"] == len(refused) >= 1, counts
    assert counts["delivered"] == 10 - len(refused) >= 3, counts
    assert (tmp_path / "out.console").read_text().count(
        "calls wait for the hardware already (the bridge's service queue, --service-queue "
        "3)") == len(refused)


IMAGE_ECHO = ROOT / "examples" / "image_echo" / "build.cfg"


def process_tree_cpu_seconds(pid):
    """User + system CPU seconds of process ``pid`` and all its descendants (/proc)."""
    def tree(p):
        found = [p]
        for task in Path(f"/proc/{p}/task").iterdir():
            for child in (task / "children").read_text().split():
                found += tree(int(child))
        return found
    ticks = 0
    for p in tree(pid):
        try:
            fields = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
        except FileNotFoundError:
            continue
        ticks += int(fields[11]) + int(fields[12])
    return ticks / os.sysconf("SC_CLK_TCK")


def test_idle_system_costs_no_processor_time(tmp_path):
    """examples/image_echo on DDS with nothing arriving: over 5 s of wall time the whole
    rosgate sim process tree uses under 5 % of a core (it blocks on DDS; a run that polled
    would use most of one), and a message written after the quiet is still echoed."""
    domain = peer.unique_domain()
    with peer.ros2_sim(IMAGE_ECHO, "icarus", tmp_path / "out", domain) as process:
        time.sleep(3)
        before = process_tree_cpu_seconds(process.pid)
        time.sleep(5)
        used = process_tree_cpu_seconds(process.pid) - before
        p = peer.Peer(domain)
        writer = p.writer("rt/image_in", peer.Image)
        reader = p.reader("rt/image_out", peer.Image)
        p.wait_matched(writer, reader)
        sent = peer.image(np.zeros((2, 3, 3), np.uint8), sec=5)
        writer.write(sent)
        got = peer.Image.deserialize(p.take_raw(reader))
    assert used < 0.25, f"{used:.2f} CPU seconds in 5 s of an idle system"
    assert got.header.stamp.sec == 5 and bytes(got.data) == bytes(sent.data)


ACTION_CLIENT_CFG = """[General]
Name = SortClient
TargetBoard = zcu104,0
TargetPart = xczu7ev-ffvc1156-2-e
CPUArchitecture = arm64
ROS2Distribution = humble
ReferenceDesign = timer
TargetOS = linux64
TargetXil = vivado,2021.2
TargetHls = vivado,2021.2
SystemClock = System

[Clock@System]
ClockSource = static
ClockFreq = 100000000

[HwSlot@Client(0:0)]
Id = 0
Clock = System

[ResourceGroup@ClientGroup]
report = mbox, 16
node = rosnode, "sort_client"
sort_msg = rosactionmsg, sorter_msgs, action, Sort
client = rosactionc, node, sort_msg, "sort", 10000

[ReconosThread@Client]
Slot = Client(0)
HwSource = hls
ResourceGroup = ClientGroup
"""

ACTION_CLIENT_THREAD = '''
from hdl.reconos.threads import CallSequenceThread


def build(ctx):
    ac, goal = ctx.handle("client"), ctx.handle("sort_msg_goal_req")
    res, fb = ctx.handle("sort_msg_result_res"), ctx.handle("sort_msg_feedback")
    return CallSequenceThread(ctx.arch, h_report=ctx.handle("report"), program=[
        ("ros_actionc_goal_send", [ac, goal]), ("ros_actionc_goal_take", [ac]),
        ("ros_actionc_result_send", [ac]), ("ros_actionc_feedback_take", [ac, fb]),
        ("ros_actionc_result_take", [ac, res])])
'''

ACTION_CLIENT_SIM = '''
GOAL = "sorter_msgs/action/Sort_SendGoal_Request"


def setup(ctx):
    goal = ctx.resource("Client", "sort_msg_goal_req")
    ctx.messages.write(goal.ptr, GOAL, {"goal_id": {"uuid": bytes(range(40, 56))},
                                        "goal": {"unsorted": [9, 4, 7, 1]}})


async def watch(ctx):
    await ctx.runtime.exited[0].wait()
    read = ctx.messages.read
    ctx.results["calls"] = [[m, list(r)] for m, _, r in ctx.runtime.log[0]]
    ctx.results["result"] = read(ctx.resource("Client", "sort_msg_result_res").ptr,
                                 "sorter_msgs/action/Sort_GetResult_Response")
    feedback = read(ctx.resource("Client", "sort_msg_feedback").ptr,
                    "sorter_msgs/action/Sort_FeedbackMessage")
    feedback["goal_id"]["uuid"] = list(feedback["goal_id"]["uuid"])
    ctx.results["feedback"] = feedback
    ctx.log("client: the hardware action client has exited")


NODES = [watch]
'''


def test_hardware_action_client_uses_a_dds_action(tmp_path):
    """A hardware action client (Icarus) whose action nobody in the build.cfg serves: the
    bridge calls it on DDS, where this test serves it as rcl_action would; the hardware gets
    the acceptance, the feedback of its own goal (not another goal's) and the result."""
    project = tmp_path / "project"
    (project / "src" / "rt_client" / "amaranth").mkdir(parents=True)
    shutil.copytree(ROOT / "examples" / "sort_action" / "msg", project / "msg")
    (project / "build.cfg").write_text(ACTION_CLIENT_CFG)
    (project / "src" / "rt_client" / "amaranth" / "thread.py").write_text(ACTION_CLIENT_THREAD)
    (project / "sim.py").write_text(ACTION_CLIENT_SIM)
    domain = peer.unique_domain()
    out = tmp_path / "out"
    with peer.ros2_sim(project / "build.cfg", "icarus", out, domain, "--with-nodes"):
        p = peer.Peer(domain)
        base = "sort/_action/"
        goals = p.reader(f"rq/{base}send_goalRequest", peer.SortSendGoalRequest)
        accept = p.writer(f"rr/{base}send_goalReply", peer.SortSendGoalResponse)
        asks = p.reader(f"rq/{base}get_resultRequest", peer.SortGetResultRequest)
        answer = p.writer(f"rr/{base}get_resultReply", peer.SortGetResultResponse)
        feedback = p.writer(f"rt/{base}feedback", peer.SortFeedbackMessage)
        p.wait_matched(goals, accept, asks, answer, feedback)
        goal = peer.SortSendGoalRequest.deserialize(p.take_raw(goals))
        assert list(goal.goal_id.uuid) == list(range(40, 56))
        assert list(goal.goal.unsorted) == [9, 4, 7, 1]
        accept.write(peer.SortSendGoalResponse(goal.guid, goal.seq, True, peer.Time(1, 2)))
        ask = peer.SortGetResultRequest.deserialize(p.take_raw(asks))
        assert (ask.guid, list(ask.goal_id.uuid)) == (goal.guid, list(range(40, 56)))
        feedback.write(peer.SortFeedbackMessage(peer.UUID([0] * 16), peer.SortFeedback(7.0)))
        feedback.write(peer.SortFeedbackMessage(goal.goal_id, peer.SortFeedback(42.5)))
        answer.write(peer.SortGetResultResponse(ask.guid, ask.seq, 4,
                                                peer.SortResult([1, 4, 7, 9])))
        progress = out / "sim_progress.jsonl"
        deadline = time.monotonic() + 120
        while "has exited" not in progress.read_text():
            assert time.monotonic() < deadline, progress.read_text()
            time.sleep(0.1)
    got = peer.results(out)
    calls = dict((m, r) for m, r in got["calls"])
    assert calls["ros_actionc_goal_take"][0] == 1          # accepted
    assert got["result"] == {"status": 4, "result": {"sorted": [1, 4, 7, 9]}}
    assert got["feedback"]["feedback"]["percent"] == 42.5
    assert got["feedback"]["goal_id"]["uuid"] == list(range(40, 56))


def test_image_echo_from_dds(tmp_path):
    """examples/image_echo (Icarus): 60 images in a row, each echoed by the hardware and
    back on DDS unchanged. (The bridge once mistook a new message for one it had injected
    itself when Python reused a freed object's id: an echo went missing after a few dozen.)"""
    domain = peer.unique_domain()
    rng = np.random.default_rng()
    with peer.ros2_sim(IMAGE_ECHO, "icarus", tmp_path / "out", domain):
        p = peer.Peer(domain)
        writer = p.writer("rt/image_in", peer.Image)
        reader = p.reader("rt/image_out", peer.Image)
        p.wait_matched(writer, reader)
        for k in range(60):
            sample = peer.image(rng.integers(0, 256, (2, 3, 3), np.uint8), k)
            writer.write(sample)
            assert peer.Image.deserialize(p.take_raw(reader, timeout=60)) == sample, k


@pytest.mark.parametrize("how", ["ctrl-c", "sigint-ignored-at-start", "sigterm"])
def test_stop_while_building_ends_cleanly(how, tmp_path):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it), SIGINT to a process that
    was started with SIGINT ignored (a script's background job), or SIGTERM, while the
    simulator is being built: rosgate sim ends at once with one line, status 128 + signal,
    no traceback, and leaves no build running."""
    env = dict(peer.loopback_environment(), ROSGATE_CACHE=str(tmp_path / "cache"))
    ignore = (lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) \
        if how == "sigint-ignored-at-start" else None
    process = subprocess.Popen(
        [sys.executable, "-m", "host.cli", "sim", str(IMAGE_ECHO), "--ros2", "--domain",
         str(peer.unique_domain()), "-o", str(tmp_path / "out")], cwd=ROOT, env=env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        preexec_fn=ignore)
    line = process.stdout.readline()
    assert "exporting and building ImageEcho" in line, line
    time.sleep(4)                                    # Verilator is compiling the model
    if how == "ctrl-c":
        os.killpg(process.pid, signal.SIGINT)
    else:
        process.send_signal(signal.SIGTERM if how == "sigterm" else signal.SIGINT)
    out, err = process.communicate(timeout=120)
    name = "SIGTERM" if how == "sigterm" else "SIGINT"
    assert process.returncode == 128 + getattr(signal, name), (process.returncode, err)
    assert err.strip() == f"rosgate sim: stopped by {name}", err
    time.sleep(1)
    leftovers = subprocess.run(["pgrep", "-f", str(tmp_path / "cache")], capture_output=True,
                               text=True).stdout
    assert leftovers == "", leftovers


@pytest.mark.parametrize("clock", ["zero", "wall"])
def test_clock_is_simulated_time(clock, tmp_path):
    """/clock (rosgraph_msgs/msg/Clock, read with rclcpp's clock QoS: best effort, keep last
    1) carries simulated time: it only grows, an image echoed between two samples moves it
    by the cycles the hardware took, and a recording's stamps are on the same clock. With
    --clock wall it starts from the wall time at the start."""
    from cyclonedds.core import Policy, Qos
    domain = peer.unique_domain()
    out, bag = tmp_path / "out", tmp_path / "bag"
    started_ns = time.time_ns()
    with peer.ros2_sim(IMAGE_ECHO, "icarus", out, domain, "--clock", clock,
                       "--record", str(bag)):
        p = peer.Peer(domain)
        clocks = p.reader("rt/clock", peer.Clock,
                          qos=Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1)))
        writer = p.writer("rt/image_in", peer.Image)
        reader = p.reader("rt/image_out", peer.Image)
        p.wait_matched(writer, reader, clocks)

        def sample():
            c = peer.Clock.deserialize(p.take_raw(clocks, timeout=30)).clock
            return c.sec * 1_000_000_000 + c.nanosec
        before = sample()
        writer.write(peer.image(np.zeros((4, 4, 3), np.uint8), sec=1))
        peer.Image.deserialize(p.take_raw(reader))
        after = sample()
    assert after > before, (before, after)
    if clock == "wall":
        assert started_ns <= before <= time.time_ns()
    else:
        assert before < 10**9, "simulated time from zero: well under a second here"
    from rosbags.highlevel import AnyReader
    with AnyReader([bag]) as recording:
        stamps = [t for _, t, _ in recording.messages()]
    assert stamps and all(before - 10**9 <= s <= after + 10**9 for s in stamps), \
        (before, after, stamps)


def test_hardware_nodes_are_on_the_ros_graph(tmp_path):
    """ros_discovery_info (rmw_dds_common/msg/ParticipantEntitiesInfo, decoded with types
    written from its definition): the bridge's participant gid, the hardware node "/echo"
    with one reader and one writer, and the bridge's own node with the /clock writer; every
    gid is the GUID (and 8 zero bytes) of the endpoint DDS matches on the right topic, read
    with a transient-local reader that joins after the bridge."""
    from cyclonedds.core import Policy, Qos
    domain = peer.unique_domain()
    with peer.ros2_sim(IMAGE_ECHO, "icarus", tmp_path / "out", domain):
        p = peer.Peer(domain)
        info_reader = p.reader("ros_discovery_info", peer.ParticipantEntitiesInfo,
                               qos=Qos(Policy.Reliability.Reliable(10**9),
                                       Policy.History.KeepLast(1),
                                       Policy.Durability.TransientLocal))
        info = peer.ParticipantEntitiesInfo.deserialize(p.take_raw(info_reader, timeout=30))
        # the GUIDs of the bridge's endpoints, as DDS matching reports them to our own
        image_in = p.writer("rt/image_in", peer.Image)
        image_out = p.reader("rt/image_out", peer.Image)
        clock = p.reader("rt/clock", peer.Clock)
        p.wait_matched(image_in, image_out, clock)
        guids = {
            "rt/image_in": [image_in.get_matched_subscription_data(h).key.bytes
                            for h in image_in.get_matched_subscriptions()],
            "rt/image_out": [image_out.get_matched_publication_data(h).key.bytes
                             for h in image_out.get_matched_publications()],
            "rt/clock": [clock.get_matched_publication_data(h).key.bytes
                         for h in clock.get_matched_publications()]}
    nodes = {(n.node_namespace, n.node_name): n for n in info.node_entities_info_seq}
    assert set(nodes) == {("/", "echo"), ("/", "rosgate_sim")}, nodes
    for gid in [info.gid] + [g for n in nodes.values()
                             for g in n.reader_gid_seq + n.writer_gid_seq]:
        assert bytes(gid.data[16:]) == bytes(8), gid
    echo, sim = nodes[("/", "echo")], nodes[("/", "rosgate_sim")]
    assert [bytes(g.data[:16]) for g in echo.reader_gid_seq] == guids["rt/image_in"]
    assert [bytes(g.data[:16]) for g in echo.writer_gid_seq] == guids["rt/image_out"]
    assert [bytes(g.data[:16]) for g in sim.writer_gid_seq] == guids["rt/clock"]
    assert not sim.reader_gid_seq
    # the participant's gid: the GUID prefix of each of its endpoints
    assert all(bytes(g.data[:12]) == bytes(info.gid.data[:12])
               for n in nodes.values() for g in n.reader_gid_seq + n.writer_gid_seq)


def _action_endpoints(p, action="sort", types="Sort", status=False):
    """The DDS endpoints of an rcl_action client of ``action`` (types ``peer.<types>...``),
    matched with the bridge's: ``send``, ``sent``, ``ask``, ``results``, ``cancel``,
    ``cancelled``, ``feedback`` (and ``status``)."""
    base = f"{action}/_action/"
    kind = {name: getattr(peer, f"{types}{name}") for name in (
        "SendGoalRequest", "SendGoalResponse", "GetResultRequest", "GetResultResponse",
        "FeedbackMessage")}
    eps = {"send": p.writer(f"rq/{base}send_goalRequest", kind["SendGoalRequest"]),
           "sent": p.reader(f"rr/{base}send_goalReply", kind["SendGoalResponse"]),
           "ask": p.writer(f"rq/{base}get_resultRequest", kind["GetResultRequest"]),
           "results": p.reader(f"rr/{base}get_resultReply", kind["GetResultResponse"]),
           "cancel": p.writer(f"rq/{base}cancel_goalRequest", peer.CancelGoalRequest),
           "cancelled": p.reader(f"rr/{base}cancel_goalReply", peer.CancelGoalResponse),
           "feedback": p.reader(f"rt/{base}feedback", kind["FeedbackMessage"])}
    if status:
        eps["status"] = p.status_reader(f"rt/{base}status", peer.GoalStatusArray)
    p.wait_matched(*eps.values())
    return eps


def test_goals_are_answered_at_once_and_execute_on_acceptance(tmp_path):
    """As rclcpp_action: three goals written back to back are all answered at once (the
    second and third accepted into the queue while the hardware sorts the first); the first
    executes without a get_result (its feedback comes first); a queued goal is canceled
    (CANCELED, its result empty); a reused goal id is refused; the counters add up."""
    domain = peer.unique_domain()
    out = tmp_path / "out"
    rng = random.Random()
    with peer.ros2_sim(SORT_ACTION, "icarus", out, domain):
        p = peer.Peer(domain)
        e = _action_endpoints(p)
        guid = rng.randrange(1, 1 << 63)
        ids = [peer.UUID(list(rng.randbytes(16))) for _ in range(3)]
        values = [[rng.randrange(1 << 32) for _ in range(200)] for _ in ids]
        for k, (uuid, v) in enumerate(zip(ids, values)):
            e["send"].write(peer.SortSendGoalRequest(guid, k + 1, uuid, peer.SortGoal(v)))
        replies = [peer.SortSendGoalResponse.deserialize(p.take_raw(e["sent"]))
                   for _ in ids]
        assert sorted((r.seq, r.accepted) for r in replies) == [(1, True), (2, True),
                                                              (3, True)]
        # executing without anybody asking for the result: feedback of the first goal
        first = peer.SortFeedbackMessage.deserialize(p.take_raw(e["feedback"]))
        assert list(first.goal_id.uuid) == list(ids[0].uuid)
        e["cancel"].write(peer.CancelGoalRequest(guid, 10, peer.GoalInfo(ids[2],
                                                                        peer.Time(0, 0))))
        answer = peer.CancelGoalResponse.deserialize(p.take_raw(e["cancelled"]))
        assert answer.return_code == 0 and \
            [list(g.goal_id.uuid) for g in answer.goals_canceling] == [list(ids[2].uuid)]
        e["send"].write(peer.SortSendGoalRequest(guid, 11, ids[0], peer.SortGoal([1])))
        refused = peer.SortSendGoalResponse.deserialize(p.take_raw(e["sent"]))
        assert (refused.seq, refused.accepted) == (11, False)
        got = {}
        for k, uuid in enumerate(ids):
            e["ask"].write(peer.SortGetResultRequest(guid, 20 + k, uuid))
        for _ in ids:
            r = peer.SortGetResultResponse.deserialize(p.take_raw(e["results"]))
            got[r.seq] = (r.status, list(r.result.sorted))
    assert got == {20: (4, sorted(values[0])), 21: (4, sorted(values[1])), 22: (5, [])}
    counts = peer.results(out)["ros2"]["counts"]["/sort/_action/send_goal"]
    assert counts["received"] == 4 and counts["delivered"] == 3 and counts["rejected"] == 1, \
        counts


def test_goal_policy_reject_refuses_goals_while_busy(tmp_path):
    domain = peer.unique_domain()
    rng = random.Random()
    with peer.ros2_sim(SORT_ACTION, "icarus", tmp_path / "out", domain,
                       "--goal-policy", "reject"):
        p = peer.Peer(domain)
        e = _action_endpoints(p)
        for k in range(2):
            e["send"].write(peer.SortSendGoalRequest(
                7, k + 1, peer.UUID(list(rng.randbytes(16))),
                peer.SortGoal([rng.randrange(1 << 32) for _ in range(200)])))
        replies = sorted((r.seq, r.accepted) for r in (
            peer.SortSendGoalResponse.deserialize(p.take_raw(e["sent"])) for _ in range(2)))
    assert replies == [(1, True), (2, False)]


def test_canceling_an_executing_goal_stops_the_hardware(tmp_path):
    """A goal the hardware sorts is canceled after its first feedback: the cancel is answered
    ERROR_NONE with the goal listed, the thread sees it after its next merge pass
    (ACTIONS_CANCEL_TRYTAKE), resets its sorter and ends the goal (ACTIONS_CANCEL_SEND): the
    result is CANCELED and empty, the feedback stops before 100 %. The next goal is sorted
    correctly by the reset sorter."""
    domain = peer.unique_domain()
    out = tmp_path / "out"
    rng = random.Random()
    with peer.ros2_sim(SORT_ACTION, "icarus", out, domain, "--param",
                       "Sorter.block_size=2048"):
        p = peer.Peer(domain)
        e = _action_endpoints(p)
        first, second = (peer.UUID(list(rng.randbytes(16))) for _ in range(2))
        values = [rng.randrange(1 << 32) for _ in range(2048)]
        e["send"].write(peer.SortSendGoalRequest(5, 1, first, peer.SortGoal(values)))
        assert peer.SortSendGoalResponse.deserialize(p.take_raw(e["sent"])).accepted
        feedback = [peer.SortFeedbackMessage.deserialize(p.take_raw(e["feedback"]))]
        e["cancel"].write(peer.CancelGoalRequest(5, 2, peer.GoalInfo(first, peer.Time(0, 0))))
        answer = peer.CancelGoalResponse.deserialize(p.take_raw(e["cancelled"]))
        e["ask"].write(peer.SortGetResultRequest(5, 3, first))
        result = peer.SortGetResultResponse.deserialize(p.take_raw(e["results"]))
        while (raw := p.take_raw(e["feedback"], timeout=1, missing_ok=True)) is not None:
            feedback.append(peer.SortFeedbackMessage.deserialize(raw))
        e["send"].write(peer.SortSendGoalRequest(5, 4, second, peer.SortGoal(values[:300])))
        assert peer.SortSendGoalResponse.deserialize(p.take_raw(e["sent"])).accepted
        e["ask"].write(peer.SortGetResultRequest(5, 5, second))
        after = peer.SortGetResultResponse.deserialize(p.take_raw(e["results"]))
    assert answer.return_code == 0 and \
        [list(g.goal_id.uuid) for g in answer.goals_canceling] == [list(first.uuid)]
    assert (result.status, list(result.result.sorted)) == (5, [])
    percents = [f.feedback.percent for f in feedback]
    assert percents == sorted(percents) and percents[-1] < 100.0, percents
    assert (after.status, list(after.result.sorted)) == (4, sorted(values[:300]))
    log = (out / "sim.log").read_text()
    assert "protocol" not in log.lower(), log[-2000:]


HW_SERVICES = ROOT / "examples" / "hw_services" / "build.cfg"
#: the hw_services configuration of test_project_sim's run too: one build for all of them
HW_SERVICES_PARAMS = ("--param", "SortServer.block_size=64", "--param",
                      "FibServer.step_cycles=40")


def test_hardware_service_between_threads_from_dds(tmp_path):
    """examples/hw_services: the sort service exists between hardware threads (its server a
    hardware node on hardware topics); its generated gateway ([ROSGateway@SortGateway],
    ServiceGatewayThread) serves /sort on DDS. Calls of random sizes come back sorted to
    their own sequence numbers, a call larger than the server's block (64 here) gets the
    empty response and the next call is served."""
    domain = peer.unique_domain()
    rng = random.Random()
    with peer.ros2_sim(HW_SERVICES, "icarus", tmp_path / "out", domain, *HW_SERVICES_PARAMS):
        calls = {seq: [rng.randrange(1 << 32) for _ in range(n)]
                 for seq, n in ((1, 64), (2, 1), (3, 65), (4, 0), (5, rng.randrange(2, 64)))}
        got = call_sort(peer.Peer(domain), "sort", 99, calls)
    assert got == {seq: sorted(v) if len(v) <= 64 else [] for seq, v in calls.items()}


def test_hardware_action_between_threads_from_dds(tmp_path):
    """examples/hw_services: ROS 2's Fibonacci action between hardware threads, reached from
    DDS through its generated gateway ([ROSGateway@FibGateway], ActionGatewayThread). A goal
    of order 10 is accepted, its 10 feedbacks come as F(0..k) and its result is F(0..10),
    SUCCEEDED; order 47 is rejected by the hardware server; a goal of order 46 canceled after
    its first feedback is answered ERROR_NONE and ends CANCELED with the values sent before."""
    domain = peer.unique_domain()
    rng = random.Random()
    with peer.ros2_sim(HW_SERVICES, "icarus", tmp_path / "out", domain, *HW_SERVICES_PARAMS):
        p = peer.Peer(domain)
        e = _action_endpoints(p, "fibonacci", "Fibonacci")
        send, sent, ask, results = e["send"], e["sent"], e["ask"], e["results"]
        cancel, cancelled, feedback = e["cancel"], e["cancelled"], e["feedback"]

        def goal(seq, order):
            uuid = peer.UUID(list(rng.randbytes(16)))
            send.write(peer.FibonacciSendGoalRequest(3, seq, uuid, peer.FibonacciGoal(order)))
            return uuid, peer.FibonacciSendGoalResponse.deserialize(p.take_raw(sent)).accepted

        def result(seq, uuid):
            ask.write(peer.FibonacciGetResultRequest(3, seq, uuid))
            r = peer.FibonacciGetResultResponse.deserialize(p.take_raw(results))
            return r.status, list(r.result.sequence)

        ten, accepted = goal(1, 10)
        assert accepted
        assert result(2, ten) == (4, [0, 1, 1, 2, 3, 5, 8, 13, 21, 34, 55])
        seen = [peer.FibonacciFeedbackMessage.deserialize(p.take_raw(feedback))
                for _ in range(10)]
        assert [list(f.feedback.sequence) for f in seen] == \
            [[0, 1, 1, 2, 3, 5, 8, 13, 21, 34, 55][:k + 2] for k in range(10)]
        assert all(list(f.goal_id.uuid) == list(ten.uuid) for f in seen)
        assert goal(3, 47)[1] is False
        long, accepted = goal(4, 46)
        assert accepted
        peer.FibonacciFeedbackMessage.deserialize(p.take_raw(feedback))
        cancel.write(peer.CancelGoalRequest(3, 5, peer.GoalInfo(long, peer.Time(0, 0))))
        answer = peer.CancelGoalResponse.deserialize(p.take_raw(cancelled))
        status, values = result(6, long)
    assert answer.return_code == 0
    fib = [0, 1]
    while len(fib) < 47:
        fib.append(fib[-1] + fib[-2])
    assert status == 5 and 2 <= len(values) < 47 and values == fib[:len(values)], values
