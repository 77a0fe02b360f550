"""Stream plans (gen.msg.plan) against rosbags and the spec (docs/messages.md; docs/topics.md):
executing a plan in Python must give rosbags' bytes (CDR, ROS 1) or the ReconROS model's."""

import random

import pytest

from gen.msg import MessageLibrary
from gen.msg.plan import stream_plan
from hdl.params import ParameterError
from tb.models.messages import golden_store, random_value, to_rosbags
from tb.models.msgstream import plan_encode, reconros_beats, reconros_fields

TEST_MSGS = "examples/messages/rosgate_test_msgs"
SORTER = "examples/messages/sorter_msgs"
TYPES = ["sensor_msgs/msg/Image", "rosgate_test_msgs/msg/Streamable",
         "rosgate_test_msgs/msg/Primitives", "sorter_msgs/srv/Sort_Request",
         "sorter_msgs/msg/Sortdata", "geometry_msgs/msg/PoseWithCovariance",
         "rosgate_test_msgs/msg/Empty"]
#: sequences of messages and strings (packed element streams): no ReconROS encoding
ELEMENT_TYPES = ["rosgate_test_msgs/msg/Elements", "rosgate_test_msgs/msg/Points",
                 "rosgate_test_msgs/msg/Mixed", "sensor_msgs/msg/JointState",
                 "sensor_msgs/msg/PointCloud2", "diagnostic_msgs/msg/DiagnosticArray",
                 "geometry_msgs/msg/PoseArray"]


@pytest.fixture(scope="module")
def ros2():
    folders = [TEST_MSGS, SORTER]
    return MessageLibrary(folders), golden_store("ros2_humble", folders)


@pytest.fixture(scope="module")
def ros1():
    folders = [TEST_MSGS]
    return MessageLibrary(folders, store="ros1_noetic"), golden_store("ros1_noetic", folders)


@pytest.mark.parametrize("typename", TYPES + ELEMENT_TYPES)
def test_cdr_plan_gives_rosbags_bytes(ros2, typename):
    library, ts = ros2
    plan = stream_plan(library, typename, "cdr")
    rng = random.Random(typename)
    for _ in range(150):
        value = random_value(library, typename, rng, max_len=9)
        want = bytes(ts.serialize_cdr(to_rosbags(ts, library, typename, value),
                                      library[typename].name))
        assert plan_encode(plan, value) == want


@pytest.mark.parametrize("typename", [t for t in TYPES + ELEMENT_TYPES if "sorter" not in t])
def test_ros1_plan_gives_rosbags_bytes(ros1, typename):
    library, ts = ros1
    plan = stream_plan(library, typename, "ros1")
    rng = random.Random(typename)
    for _ in range(150):
        value = random_value(library, typename, rng, max_len=9)
        body = bytes(ts.serialize_ros1(to_rosbags(ts, library, typename, value),
                                       library[typename].name))
        assert plan_encode(plan, value) == len(body).to_bytes(4, "little") + body


@pytest.mark.parametrize("typename", TYPES)
def test_reconros_plan_gives_model_beats(ros2, typename):
    library, _ = ros2
    plan = stream_plan(library, typename, "reconros")
    rng = random.Random(typename)
    for _ in range(100):
        value = random_value(library, typename, rng, max_len=9)
        beats = reconros_beats(library, typename, value, 3)
        assert plan_encode(plan, value, 3) == b"".join(d.to_bytes(8, "little")
                                                       for d, _, _ in beats)


def test_image_cdr_plan_matches_spec_example(ros2):
    library, _ = ros2
    plan = stream_plan(library, "sensor_msgs/msg/Image", "cdr")
    value = {"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "cam"}, "height": 2,
             "width": 4, "encoding": "rgb8", "is_bigendian": 0, "step": 12,
             "data": bytes(range(24))}
    data = plan_encode(plan, value)
    assert len(data) == 72
    assert data[:48].hex() == ("00010000" "01000000" "02000000" "04000000" "63616d00"
                               "02000000" "04000000" "05000000" "7267623800" "00" "0000"
                               "0c000000" "18000000")
    assert [s.kind for s in plan.steps] == ["run", "payload", "run", "pad", "run", "payload",
                                            "run", "pad", "run", "payload"]


def test_ros1_image_plan_matches_spec_example(ros1):
    library, _ = ros1
    plan = stream_plan(library, "sensor_msgs/msg/Image", "ros1")
    value = {"header": {"seq": 7, "stamp": {"sec": 1, "nanosec": 2}, "frame_id": "cam"},
             "height": 2, "width": 4, "encoding": "rgb8", "is_bigendian": 0, "step": 12,
             "data": bytes(range(24))}
    data = plan_encode(plan, value)
    assert data[:4] == (68).to_bytes(4, "little") and len(data) == 72
    assert data[4:] == bytes.fromhex("07000000 01000000 02000000 03000000 63616d 02000000 "
                                     "04000000 04000000 72676238 00 0c000000 18000000") + \
        bytes(range(24))


def test_reconros_flattening_of_image_matches_spec(ros2):
    """docs/topics.md: primitives height, width, is_bigendian, step, header.stamp.sec,
    header.stamp.nanosec; 8-bit arrays encoding, data, header.frame_id."""
    library, _ = ros2
    plan = stream_plan(library, "sensor_msgs/msg/Image", "reconros")
    extend = [p.leaf.path for s in plan.steps if s.kind == "run" for p in s.parts
              if p.kind == "extend"]
    assert extend == ["height", "width", "is_bigendian", "step", "header.stamp.sec",
                      "header.stamp.nanosec"]
    payloads = [plan.variables[s.var].path for s in plan.steps if s.kind == "payload"]
    assert payloads == ["encoding", "data", "header.frame_id"]
    assert [p for p, _ in reconros_fields(library, "sensor_msgs/msg/Image")] == [
        "height", "width", "encoding", "is_bigendian", "step", "data", "header.frame_id",
        "header.stamp.sec", "header.stamp.nanosec"]


def test_reconros_640x480_bgr8_image_is_115217_beats(ros2):
    """docs/topics.md [derived]: 2 + 6 + 3 x 2 + 1 + 115 200 + 1 + 1 beats."""
    library, _ = ros2
    plan = stream_plan(library, "sensor_msgs/msg/Image", "reconros")
    value = {"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "cam"},
             "height": 480, "width": 640, "encoding": "bgr8", "is_bigendian": 0,
             "step": 1920, "data": bytes(640 * 480 * 3)}
    assert len(plan_encode(plan, value, 0)) // 8 == 115217


def test_reconros_defects_fixed(ros2):
    """D2 floats bit-cast, D3 bool/byte/char carried, D5 a 13-byte array takes 2 beats."""
    library, _ = ros2
    plan = stream_plan(library, "rosgate_test_msgs/msg/Primitives", "reconros")
    value = random_value(library, "rosgate_test_msgs/msg/Primitives", random.Random(1))
    value.update(f64=1.5, f32=-2.25, b=True, by=0xfe, ch=0x41, s="thirteen char")
    beats = reconros_beats(library, "rosgate_test_msgs/msg/Primitives", value, 0)
    data = [d for d, _, _ in beats]
    assert 0x3ff8000000000000 in data            # 1.5 as IEEE-754 bits, not 1
    assert 0xc0100000 in data                    # -2.25f bits, zero-extended
    assert data[2:5] == [1, data[3], data[4]] and 0xfe in data and 0x41 in data
    i = data.index(13)
    assert data[i + 1] == 13 and len(data[i + 2:i + 4]) == 2
    assert plan_encode(plan, value, 0) == b"".join(d.to_bytes(8, "little") for d in data)


@pytest.mark.parametrize("store", ["ros2_humble", "ros1_noetic"])
def test_every_type_of_the_store_streams(store):
    """Every message type rosbags ships for the distribution has a plan whose bytes are
    rosbags' (CDR for ROS 2, ROS 1 for noetic), for random values."""
    framing = "cdr" if store == "ros2_humble" else "ros1"
    library, ts = MessageLibrary([], store=store), golden_store(store, [])
    names = sorted(n for n in ts.types if "/msg/" in n)
    assert len(names) > 100
    for typename in names:
        plan = stream_plan(library, typename, framing)
        rng = random.Random(typename)
        for _ in range(5):
            value = random_value(library, typename, rng, max_len=3)
            message = to_rosbags(ts, library, typename, value)
            want = bytes(ts.serialize_cdr(message, typename) if framing == "cdr"
                         else ts.serialize_ros1(message, typename))
            got = plan_encode(plan, value)
            assert (got if framing == "cdr" else got[4:]) == want, typename


def test_element_plan_loops(ros2):
    """A sequence of messages holding a sequence of messages: nested loops whose targets
    point at each other, inner counts as ``count`` steps, no fixed-part leaf inside."""
    library, _ = ros2
    plan = stream_plan(library, "diagnostic_msgs/msg/DiagnosticArray", "cdr")
    loops = [(i, s) for i, s in enumerate(plan.steps) if s.kind in ("loop", "next")]
    assert [s.kind for _, s in loops] == ["loop", "loop", "next", "next"]
    (a, outer), (b, inner), (c, inner_next), (d, outer_next) = loops
    assert (outer.target, inner.target, inner_next.target, outer_next.target) == (d, c, b, a)
    assert [v.path for v in plan.streams] == ["header.frame_id", "status"]
    assert plan.variables[inner.var].path == "status[].values"
    assert plan.variables[inner.var].into == outer.var
    assert all(not leaf.path.startswith("status[]") for leaf in plan.leaves)
    counts = [plan.variables[s.var].path for s in plan.steps if s.kind == "count"]
    assert counts == ["status[].name", "status[].message", "status[].hardware_id",
                      "status[].values", "status[].values[].key", "status[].values[].value"]
    points = stream_plan(library, "geometry_msgs/msg/PoseArray", "cdr").streams[-1]
    assert (points.elements, points.element_bytes) == (True, 56)


@pytest.mark.parametrize("typename,field", [
    ("sensor_msgs/msg/PointCloud2", "fields"),
    ("rosgate_test_msgs/msg/Mixed", "points"),
    ("sensor_msgs/msg/JointState", "name"),
])
def test_reconros_framing_refuses_sequences_of_elements(ros2, typename, field):
    library, _ = ros2
    with pytest.raises(ParameterError, match=f"no encoding for {field}"):
        stream_plan(library, typename, "reconros")


def test_wstring_is_refused_naming_the_field(ros2):
    with pytest.raises(ParameterError, match="ws is a wstring"):
        stream_plan(ros2[0], "rosgate_test_msgs/msg/AllPrimitives", "cdr")


def test_unknown_framing(ros2):
    with pytest.raises(ParameterError, match="framing"):
        stream_plan(ros2[0], "sensor_msgs/msg/Image", "xcdr2")
