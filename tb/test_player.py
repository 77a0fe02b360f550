"""``rosgate sim --play``: rosbag2 recordings played into a co-simulated system
(host/ros2/player.py, docs/simulation.md).

Every bag here is written or read by rosbags with its own serializer and type store (ROS 2
Humble's definitions), never by rosgate's CDR code: a recording of one example played into
another and recorded again (MCAP, bag time), a sqlite3 bag played as fast as the hardware
takes it with a message that does not decode, a camera bag into the lane-following chain
(every stage against the software chain) and the same frames as image files, a bag into a
system on a DDS domain, and bags and options that are refused before anything is built.
"""

import json
import random
import sys

import cv2
import numpy as np
import pytest

from host.project_sim import ProjectError, run_project_sim

from .harness import ROOT, run_rosgate
from .models import ros2_peer as peer

IMAGE_INVERT = ROOT / "examples" / "image_invert" / "build.cfg"
IMAGE_ECHO = ROOT / "examples" / "image_echo" / "build.cfg"
AV_CHAIN = ROOT / "examples" / "av_chain" / "build.cfg"
CHAIN_PARAMS = ["*.scale=0.2", "*.pixels_per_beat=1"]


def typestore():
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_HUMBLE)


def image_message(store, pixels, sec, encoding="bgr8"):
    """A ``sensor_msgs/msg/Image`` of rosbags' type store."""
    Image = store.types["sensor_msgs/msg/Image"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    height, width = pixels.shape[:2]
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    return Image(Header(Time(sec, 7), "camera"), height, width, encoding, 0,
                 width * channels * pixels.itemsize,
                 np.frombuffer(pixels.tobytes(), np.uint8))


def write_bag(path, messages, storage="mcap"):
    """A rosbag2 at ``path`` of ``(topic, msgtype, time_ns, message or raw bytes)``."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    store = typestore()
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as writer:
        connections = {}
        for topic, msgtype, stamp, message in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
            data = message if isinstance(message, bytes) else \
                store.serialize_cdr(message, msgtype)
            writer.write(connections[topic], stamp, data)


def read_bag(path):
    """``{topic: [(time_ns, message), ...]}`` read with rosbags' own deserializer."""
    from rosbags.highlevel import AnyReader
    out = {}
    with AnyReader([path], default_typestore=typestore()) as reader:
        for connection, stamp, raw in reader.messages():
            out.setdefault(connection.topic, []).append(
                (stamp, reader.deserialize(raw, connection.msgtype)))
    return out


def pixels_of(msg):
    return np.asarray(msg.data, np.uint8).reshape(msg.height, msg.step)


def test_recording_of_one_example_plays_into_another(tmp_path):
    """image_invert's recording (--record, MCAP): its /image_inverted played in bag time into
    image_echo's /image_in (--play-topic, --remap) while image_echo records. The second bag
    holds each inverted image once, in order, at the first bag's times shifted to the start,
    and image_echo's answer to each is its bytes; the summary counts them."""
    first, second = tmp_path / "inverted", tmp_path / "echoed"
    run_project_sim(IMAGE_INVERT, "verilator", out=tmp_path / "a", record=first)
    results = run_project_sim(
        IMAGE_ECHO, "verilator", out=tmp_path / "b", record=second,
        play={"path": str(first), "topics": ["/image_inverted"],
              "remaps": ["/image_inverted:=/image_in"]})
    recorded, replayed = read_bag(first), read_bag(second)
    originals = recorded["/image_in"]
    inverted = recorded["/image_inverted"]
    assert len(originals) == len(inverted) >= 4
    for (_, original), (_, inv) in zip(originals, inverted):
        assert np.array_equal(pixels_of(inv), 255 - pixels_of(original)), "image_invert"
    played, echoed = replayed["/image_in"], replayed["/image_out"]
    assert [pixels_of(m).tobytes() for _, m in played] == \
        [pixels_of(m).tobytes() for _, m in inverted]
    assert [pixels_of(m).tobytes() for _, m in echoed] == \
        [pixels_of(m).tobytes() for _, m in inverted]
    assert [m.header.stamp.sec for _, m in echoed] == [m.header.stamp.sec for _, m in inverted]
    # bag time: the gaps between the messages kept, to the cycle (10 ns at 100 MHz)
    gaps_then = [t - inverted[0][0] for t, _ in inverted]
    gaps_now = [t - played[0][0] for t, _ in played]
    assert all(abs(a - b) <= 10 for a, b in zip(gaps_then, gaps_now)), (gaps_then, gaps_now)
    play = results["play"]
    assert play["played"] == {"/image_in": len(inverted)} and play["finished"]
    assert play["ignored"] == {"/image_in": "not chosen with --play-topic"}
    assert play["published_by_system"] == {"/image_out": len(inverted)}
    assert not play["skipped"]


def test_sqlite_bag_as_fast_as_the_hardware_takes_it(tmp_path):
    """A sqlite3 bag of random bgr8 images (1 to 40 pixels a side, a second apart
    in the bag) and one message whose bytes are cut short, played fast: the run takes far
    less simulated time than the bag spans; the cut message is skipped and counted, every
    other image echoed in order."""
    rng = random.Random(5)
    store = typestore()
    images, messages = [], []
    for k in range(8):
        h, w = rng.randint(1, 40), rng.randint(1, 40)
        pixels = np.random.default_rng(k).integers(0, 256, (h, w, 3), np.uint8)
        msg = image_message(store, pixels, k)
        data = bytes(store.serialize_cdr(msg, "sensor_msgs/msg/Image"))
        if k == 3:
            data = data[:len(data) // 2]
        else:
            images.append(pixels)
        messages.append(("/image_in", "sensor_msgs/msg/Image", (k + 1) * 10**9, data))
    write_bag(tmp_path / "images", messages, storage="sqlite3")
    bag = next((tmp_path / "images").glob("*.db3"))
    results = run_project_sim(IMAGE_ECHO, "verilator", out=tmp_path / "o", record=tmp_path / "r",
                              play={"path": str(bag), "pace": "fast"})
    play = results["play"]
    assert play["played"] == {"/image_in": 7}
    assert [(s["topic"], s["index"]) for s in play["skipped"]] == [("/image_in", 3)]
    assert "do not decode" in play["skipped"][0]["reason"]
    echoed = read_bag(tmp_path / "r")["/image_out"]
    assert [pixels_of(m).tobytes() for _, m in echoed] == [p.tobytes() for p in images]
    assert results["cycles"] < 100_000, "fast: not the bag's 8 seconds"


def camera_frames(count, seed):
    sys.path.insert(0, str(AV_CHAIN.parent))
    try:
        import scene
    finally:
        sys.path.remove(str(AV_CHAIN.parent))
    from gen.av_chain import scaled_config
    width = scaled_config(0.2, 1).camera[0]
    geometry = scene.Geometry(width / scene.CAMERA_SIZE[0])
    return list(scene.frames(count, seed=seed, red_from=1, green_from=2, geometry=geometry))


def test_camera_bag_into_the_lane_following_chain(tmp_path):
    """A camera recording (rosbags, MCAP, 30 frames a second on /front_camera/image_raw) of
    dark, red and green scenes and a frame of the wrong size, remapped onto /camera/image and
    played as fast as the chain takes it (bag time would simulate 33 ms per frame):
    the wrong frame is skipped and counted before it reaches the chain, every other frame
    goes through the seven threads with every stage equal to the software chain (OpenCV; the
    projection within 1) and the stop and start events on the red and green frames, without
    ground truth. The same frames as image files (--arg images=) give the same commands."""
    store = typestore()
    frames = camera_frames(3, seed=4)
    pixels = [f.image for f in frames]
    pixels.insert(1, np.zeros((50, 60, 3), np.uint8))
    messages = [("/front_camera/image_raw", "sensor_msgs/msg/Image", 10**18 + k * 33_333_333,
                 image_message(store, p, 100 + k)) for k, p in enumerate(pixels)]
    messages.append(("/imu", "std_msgs/msg/String", 10**18,
                     store.types["std_msgs/msg/String"]("x")))
    write_bag(tmp_path / "camera", messages)
    results = run_project_sim(
        AV_CHAIN, "verilator", out=tmp_path / "o", thread_params=CHAIN_PARAMS, limit_ms=20,
        play={"path": str(tmp_path / "camera"), "pace": "fast",
              "remaps": ["/front_camera/image_raw:=/camera/image"]})
    play = results["play"]
    assert play["played"] == {"/camera/image": 3}
    assert [s["index"] for s in play["skipped"]] == [1]
    assert "60x50" in play["skipped"][0]["reason"]
    assert play["ignored"] == {"/imu": "/imu is not a topic of the system"}
    assert results["stages_bit_exact"], results["frames"]
    assert not results["ground_truth"] and results["lane_centre_max_error_px"] is None
    assert (results["stops"], results["starts"]) == ([1], [2])
    assert [f["speed"] > 0 for f in results["frames"]] == [True, False, True]
    files = []
    for k, frame in enumerate(frames):
        files.append(tmp_path / f"frame{k}.png")
        cv2.imwrite(str(files[-1]), frame.image)
    from_files = run_project_sim(AV_CHAIN, "verilator", out=tmp_path / "f",
                                 thread_params=CHAIN_PARAMS, limit_ms=20,
                                 args={"images": ",".join(map(str, files))})
    assert from_files["stages_bit_exact"]
    assert [(f["speed"], f["turn"]) for f in from_files["frames"]] == \
        [(f["speed"], f["turn"]) for f in results["frames"]]


def test_bag_into_a_system_on_dds(tmp_path):
    """--ros2 --play: the bag's images go into image_echo while it is on a DDS domain; an
    independent participant (hand-written types) receives each echo on rt/image_out."""
    store = typestore()
    images = [np.full((3 + k, 5, 3), 10 * k, np.uint8) for k in range(3)]
    write_bag(tmp_path / "bag", [("/image_in", "sensor_msgs/msg/Image", k * 10**6,
                                  image_message(store, p, k)) for k, p in enumerate(images)])
    domain = peer.unique_domain()
    out = tmp_path / "out"
    with peer.ros2_sim(IMAGE_ECHO, "icarus", out, domain, "--play", str(tmp_path / "bag"),
                       "--play-delay", "3"):
        p = peer.Peer(domain)
        reader = p.reader("rt/image_out", peer.Image)
        p.wait_matched(reader)
        got = [peer.Image.deserialize(p.take_raw(reader, timeout=60)) for _ in images]
    assert [bytes(g.data) for g in got] == [i.tobytes() for i in images]
    assert peer.results(out)["play"]["played"] == {"/image_in": 3}


def plan(bag, build_cfg=IMAGE_ECHO, **options):
    from gen.config import load_project, project_library
    from host.ros2.graph import ros_interfaces
    from host.ros2.player import plan_playback
    project = load_project(build_cfg)
    return plan_playback(bag, ros_interfaces(project), project_library(project), **options)


def test_bad_bags_and_options_are_refused_before_anything_is_built(tmp_path):
    """Each refusal names the option and the reason: a bag that is missing, not a bag, cut
    in half; a topic of the wrong type; a --play-topic or --remap naming what is not there;
    a remap without ':='; a bag with nothing for the system. The CLI refuses play options
    without --play, and a rate with the fast pace, with exit status 2."""
    from host.ros2.player import PlaybackError
    store = typestore()
    write_bag(tmp_path / "good", [("/image_in", "sensor_msgs/msg/Image", 1,
                                   image_message(store, np.zeros((2, 2, 3), np.uint8), 0))])
    write_bag(tmp_path / "strings", [("/image_in", "std_msgs/msg/String", 1,
                                      store.types["std_msgs/msg/String"]("hello"))])
    write_bag(tmp_path / "elsewhere", [("/other", "sensor_msgs/msg/Image", 1,
                                        image_message(store, np.zeros((2, 2, 3), np.uint8), 0))])
    mcap = next((tmp_path / "good").glob("*.mcap"))
    (tmp_path / "cut.mcap").write_bytes(mcap.read_bytes()[:mcap.stat().st_size // 2])
    (tmp_path / "text.mcap").write_text("not a bag\n")
    cases = [
        (dict(bag=tmp_path / "missing"), "no such file or folder"),
        (dict(bag=tmp_path / "text.mcap"), "not a rosbag2 that rosbags can read"),
        (dict(bag=tmp_path / "cut.mcap"), "not a rosbag2 that rosbags can read"),
        (dict(bag=tmp_path / "strings"),
         "topic /image_in of the bag carries std_msgs/msg/String; the system's /image_in is "
         "sensor_msgs/msg/Image"),
        (dict(bag=tmp_path / "good", topics=["/camera"]),
         "--play-topic /camera: the bag has no such topic (its topics: /image_in)"),
        (dict(bag=tmp_path / "good", remaps=["/image_in=/x"]), "expected FROM:=TO"),
        (dict(bag=tmp_path / "good", remaps=["/image_in:=/x"]),
         "--remap /image_in:=/x: the system has no topic /x"),
        (dict(bag=tmp_path / "elsewhere"), "no topic of the bag goes into the system"),
        (dict(bag=tmp_path / "good", pace="slow"), "--play-pace 'slow'"),
    ]
    for options, message in cases:
        bag = options.pop("bag")
        with pytest.raises(PlaybackError) as caught:
            plan(bag, **options)
        assert message in str(caught.value), (options, str(caught.value))
    with pytest.raises(ProjectError, match="carries std_msgs/msg/String"):
        run_project_sim(IMAGE_ECHO, "verilator", out=tmp_path / "o",
                        play={"path": str(tmp_path / "strings")})
    assert not (tmp_path / "o").exists(), "refused before anything was written"
    for extra, message in ((["--play-pace", "fast"], "need --play"),
                           (["--play", str(tmp_path / "good"), "--play-pace", "fast",
                             "--play-rate", "2"], "--play-rate applies to --play-pace bag"),
                           (["--play", str(tmp_path / "good"), "--play-rate", "0"],
                            "expected a number above 0")):
        result = run_rosgate("sim", IMAGE_ECHO, *extra, "-o", str(tmp_path / "cli"))
        assert result.returncode == 2 and message in result.stderr, result.stderr
    good = plan(tmp_path / "good")
    assert json.loads(json.dumps(good.to_json()))["counts"] == {"/image_in": 1}
