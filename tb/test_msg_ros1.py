"""ROS 1 md5sums and message definitions (gen.msg.ros1) against docs/messages.md and rosbags'
independent generator."""

import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from gen.msg import MessageLibrary, parse_msg, parse_srv
from gen.msg.ros1 import md5_text, md5sum, message_definition, service_md5sum

SPEC_MD5 = {
    "sensor_msgs/msg/Image": "060021388200f6f0f447d0fcd9c64743",
    "std_msgs/msg/String": "992ce8a1687cec8c8bd883ec73ca41d1",
    "std_msgs/msg/Header": "2176decaecbce78abc3b96ef049fabed",
    "geometry_msgs/msg/Twist": "9f195f881246fdfa2798d1d3eebca84a",
}


@pytest.fixture(scope="module")
def ros1():
    return MessageLibrary(store="ros1_noetic"), get_typestore(Stores.ROS1_NOETIC)


@pytest.mark.parametrize("typename", list(SPEC_MD5))
def test_md5_matches_spec_table(ros1, typename):
    assert md5sum(ros1[0], typename) == SPEC_MD5[typename]


def test_service_md5_matches_spec(ros1):
    library = MessageLibrary(store="ros1_noetic")
    for definition in parse_srv("bool data\n---\nbool success\nstring message\n",
                                "std_srvs/srv/SetBool"):
        library.add(definition)
    assert md5sum(library, "std_srvs/srv/SetBool_Request").startswith("8b94c1b5")
    assert md5sum(library, "std_srvs/srv/SetBool_Response").startswith("937c9679")
    assert service_md5sum(library, "std_srvs/srv/SetBool_Request",
                          "std_srvs/srv/SetBool_Response") == "09fb03525b03e7ea1fd3992bafd87e16"


def test_md5_equals_rosbags_for_every_ros1_type(ros1):
    library, ts = ros1
    wrong = [(t, md5sum(library, t), ts.generate_msgdef(t)[1]) for t in ts.fielddefs
             if md5sum(library, t) != ts.generate_msgdef(t)[1]]
    assert len(ts.fielddefs) > 100
    assert not wrong, wrong[:5]


def test_md5_of_parsed_message_with_constants_and_nesting(ros1):
    text = ("int32 MAX=10\nstring NAME=hello\nHeader header\nuint8[] data\n"
            "geometry_msgs/Point[3] corners\ntime when\n")
    library = MessageLibrary(store="ros1_noetic")
    library.add(parse_msg(text, "my_msgs/msg/Thing"))
    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg(text, "my_msgs/msg/Thing"))
    assert md5sum(library, "my_msgs/msg/Thing") == ts.generate_msgdef("my_msgs/msg/Thing")[1]
    text_lines = md5_text(library, "my_msgs/msg/Thing").splitlines()
    assert text_lines[:2] == ["int32 MAX=10", "string NAME=hello"]
    assert text_lines[2] == "2176decaecbce78abc3b96ef049fabed header"
    assert text_lines[-1] == "time when"


def test_message_definition_of_image_matches_spec(ros1):
    text = message_definition(ros1[0], "sensor_msgs/msg/Image")
    assert text.startswith("std_msgs/Header header\nuint32 height\n")
    assert text.endswith("=" * 80 + "\nMSG: std_msgs/Header\nuint32 seq\ntime stamp\n"
                         "string frame_id\n")


def test_message_definition_equals_rosbags_for_every_ros1_type(ros1):
    library, ts = ros1
    wrong = [t for t in ts.fielddefs
             if message_definition(library, t) != ts.generate_msgdef(t)[0]]
    assert not wrong, wrong[:5]


def test_message_definition_of_parsed_message(ros1):
    text = ("int32 MAX=10\nHeader header\ngeometry_msgs/PoseStamped[2] poses\n"
            "geometry_msgs/Point p\ntime when\n")
    library = MessageLibrary(store="ros1_noetic")
    library.add(parse_msg(text, "my_msgs/msg/Thing"))
    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg(text, "my_msgs/msg/Thing"))
    assert message_definition(library, "my_msgs/msg/Thing") == \
        ts.generate_msgdef("my_msgs/msg/Thing")[0]


def test_connection_header_wiki_example():
    """docs/messages.md: the ROS wiki's /chatter header, byte for byte (176-byte body)."""
    from gen.msg.ros1 import decode_connection_header, encode_connection_header, frame_message
    fields = [("message_definition", "string data\n\n"),
              ("callerid", "/rostopic_4767_1316912741557"), ("latching", "1"),
              ("md5sum", "992ce8a1687cec8c8bd883ec73ca41d1"), ("topic", "/chatter"),
              ("type", "std_msgs/String")]
    header = encode_connection_header(fields)
    assert header[:4] == bytes.fromhex("b0000000") and len(header) == 4 + 176
    assert header[4:8] == (len("message_definition=string data\n\n")).to_bytes(4, "little")
    assert decode_connection_header(header, prefixed=True) == dict(fields)
    assert decode_connection_header(header[4:]) == dict(fields)
    assert frame_message((5).to_bytes(4, "little") + b"hello") == bytes.fromhex(
        "09000000" "05000000" "68656c6c6f")
    import pytest

    from gen.msg.ros1 import ConnectionHeaderError
    with pytest.raises(ConnectionHeaderError, match="offset 0"):
        decode_connection_header(b"\x05\x00\x00\x00abc")
