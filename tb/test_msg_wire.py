"""CDR and ROS 1 encodings (gen.msg.wire) byte for byte against rosbags (docs/messages.md)."""

import random
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gen.msg import MessageLibrary
from gen.msg.wire import WireError, decode_cdr, decode_ros1, encode_cdr, encode_ros1
from tb.models.messages import golden_store, random_value, to_rosbags

MESSAGES = Path(__file__).resolve().parents[1] / "examples" / "messages"
ROS2_TYPES = ["sensor_msgs/msg/Image", "sensor_msgs/msg/PointCloud2",
              "rosgate_test_msgs/msg/Primitives", "rosgate_test_msgs/msg/Mixed",
              "rosgate_test_msgs/msg/Empty", "sorter_msgs/srv/Sort_Request",
              "sorter_msgs/srv/Sort_Response", "geometry_msgs/msg/PoseWithCovariance"]
ROS1_TYPES = ["sensor_msgs/msg/Image", "std_msgs/msg/String", "geometry_msgs/msg/Twist",
              "rosgate_test_msgs/msg/Primitives", "rosgate_test_msgs/msg/Mixed"]

IMAGE = {"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "cam"}, "height": 2,
         "width": 4, "encoding": "rgb8", "is_bigendian": 0, "step": 12,
         "data": bytes(range(24))}


@pytest.fixture(scope="module")
def ros2():
    return MessageLibrary([MESSAGES]), golden_store("ros2_humble", [MESSAGES])


@pytest.fixture(scope="module")
def ros1():
    # ROS 1 has no ROS 2 actions (no unique_identifier_msgs): plain messages only.
    folder = MESSAGES / "rosgate_test_msgs"
    return (MessageLibrary([folder], store="ros1_noetic"),
            golden_store("ros1_noetic", [folder]))


def test_cdr_image_example_from_spec(ros2):
    library, _ = ros2
    expected = bytes.fromhex(
        "00010000" "01000000" "02000000" "04000000" "63616d00" "02000000" "04000000"
        "05000000" "7267623800" "00" "0000" "0c000000" "18000000") + bytes(range(24))
    assert encode_cdr(library, "sensor_msgs/Image", IMAGE) == expected  # 72 bytes
    assert decode_cdr(library, "sensor_msgs/Image", expected) == IMAGE


def test_ros1_image_example_from_spec(ros1):
    library, _ = ros1
    value = dict(IMAGE, header={"seq": 7, "stamp": {"sec": 1, "nanosec": 2},
                                "frame_id": "cam"})
    expected = bytes.fromhex("07000000" "01000000" "02000000" "03000000" "63616d" "02000000"
                             "04000000" "04000000" "72676238" "00" "0c000000" "18000000") \
        + bytes(range(24))
    assert encode_ros1(library, "sensor_msgs/Image", value) == expected  # 68 bytes
    assert decode_ros1(library, "sensor_msgs/Image", expected) == value


def check_against_rosbags(library, ts, typename, seed, encode, decode, serialize):
    value = random_value(library, typename, random.Random(seed))
    golden = bytes(serialize(to_rosbags(ts, library, typename, value), typename))
    assert encode(library, typename, value) == golden
    assert decode(library, typename, golden) == value


@settings(max_examples=150, deadline=None)
@given(typename=st.sampled_from(ROS2_TYPES), seed=st.integers(0, 2 ** 32 - 1))
def test_cdr_equals_rosbags(ros2, typename, seed):
    library, ts = ros2
    check_against_rosbags(library, ts, typename, seed, encode_cdr, decode_cdr, ts.serialize_cdr)


@settings(max_examples=100, deadline=None)
@given(typename=st.sampled_from(ROS1_TYPES), seed=st.integers(0, 2 ** 32 - 1))
def test_ros1_equals_rosbags(ros1, typename, seed):
    library, ts = ros1
    check_against_rosbags(library, ts, typename, seed, encode_ros1, decode_ros1,
                          ts.serialize_ros1)


def test_encode_errors_name_the_field(ros2):
    library, _ = ros2
    with pytest.raises(WireError, match=r"height: -1 does not fit uint32"):
        encode_cdr(library, "sensor_msgs/Image", dict(IMAGE, height=-1))
    value = random_value(library, "rosgate_test_msgs/msg/Mixed", random.Random(1))
    value["bounded_f64"] = [1.0] * 5
    with pytest.raises(WireError, match=r"bounded_f64: 5 elements exceed the bound"):
        encode_cdr(library, "rosgate_test_msgs/msg/Mixed", value)
    value = random_value(library, "rosgate_test_msgs/msg/Mixed", random.Random(2))
    value["fixed_u16"] = [1, 2]
    with pytest.raises(WireError, match=r"fixed_u16: uint16\[3\] needs 3 elements, got 2"):
        encode_cdr(library, "rosgate_test_msgs/msg/Mixed", value)
    with pytest.raises(WireError, match=r"value has no field 'width'"):
        encode_cdr(library, "sensor_msgs/Image", {k: v for k, v in IMAGE.items()
                                                  if k != "width"})


def test_decode_errors(ros2):
    library, _ = ros2
    good = encode_cdr(library, "sensor_msgs/Image", IMAGE)
    with pytest.raises(WireError, match=r"data: message ends early"):
        decode_cdr(library, "sensor_msgs/Image", good[:-1])
    with pytest.raises(WireError, match=r"1 bytes left over"):
        decode_cdr(library, "sensor_msgs/Image", good + b"\x00")
    bad_pad = bytearray(good)
    bad_pad[4 + 34] = 0xFF  # the padding after is_bigendian
    with pytest.raises(WireError, match=r"step: alignment padding is not zero"):
        decode_cdr(library, "sensor_msgs/Image", bytes(bad_pad))
    with pytest.raises(WireError, match=r"not a little-endian CDR encapsulation"):
        decode_cdr(library, "sensor_msgs/Image", b"\x00\x00\x00\x00" + good[4:])
    # a string that is not UTF-8 (what a non-checking DDS peer may send) is a WireError
    # naming it, not a UnicodeDecodeError that would escape the ROS 2 bridge's rejection
    frame = good.index(IMAGE["header"]["frame_id"].encode())
    not_utf8 = bytearray(good)
    not_utf8[frame] = 0xD5
    with pytest.raises(WireError, match=r"header.frame_id: string is not UTF-8"):
        decode_cdr(library, "sensor_msgs/Image", bytes(not_utf8))
