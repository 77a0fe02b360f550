"""The co-simulation's rosidl message memory (``host.reconos.messages.MessageMemory``) for
every shape of field: strings, nested messages, fixed and bounded arrays, sequences of
primitives, of strings and of messages that contain strings and sequences.

Each random message is written into a process memory (arm64 and arm32) and read back equal;
independently of the model's reader, the raw memory is checked at the offsets of the rosidl
C layout (``gen.msg.layout``, itself checked against real compilers in test_msg_layout.py):
every string and sequence is ``{data, size, capacity}`` with its elements where ``data``
points, every string NUL-terminated."""

import random
import struct

import pytest

from gen.msg import MessageLibrary
from gen.msg.layout import CLayout
from gen.msg.model import Named, Primitive, Sequence
from gen.msg.wire import STRUCT_FORMAT
from host.reconos.memory import ProcessMemory
from host.reconos.messages import MessageMemory

from .models.messages import ByteRam, random_field_value

TYPES = ["sensor_msgs/msg/JointState", "geometry_msgs/msg/PoseArray",
         "diagnostic_msgs/msg/DiagnosticArray", "tf2_msgs/msg/TFMessage",
         "sensor_msgs/msg/Image", "visualization_msgs/msg/InteractiveMarkerInit",
         "std_msgs/msg/Empty"]


def check_raw(mem, layout, va, type_name, value):
    """The bytes at ``va`` hold ``value`` in the C layout (not using the model's reader)."""
    p = layout.pointer

    def word(at):
        return int.from_bytes(mem.read(at, p), "little")

    def check(at, t, v):
        if isinstance(t, Named):
            for m in layout.struct(t.typename).members:
                if m.name != "structure_needs_at_least_one_member":
                    check(at + m.offset, m.type, v[m.name])
        elif isinstance(t, Primitive) and t.is_string:
            data, size, capacity = word(at), word(at + p), word(at + 2 * p)
            raw = v.encode()
            assert size == len(raw) and capacity >= size + 1
            assert mem.read(data, size + 1) == raw + b"\0"
        elif isinstance(t, Primitive):
            fmt = "<" + STRUCT_FORMAT[t.name]
            assert struct.unpack(fmt, mem.read(at, struct.calcsize(fmt)))[0] == v
        else:
            esize, _ = layout.size_align(t.element)
            if isinstance(t, Sequence):
                base, size, capacity = word(at), word(at + p), word(at + 2 * p)
                assert size == len(v) and capacity >= size and (base or not size)
            else:
                base = at
            for i, item in enumerate(v):
                check(base + i * esize, t.element, item)
    check(va, Named(type_name), value)


@pytest.mark.parametrize("arch", ["r64", "r32"])
@pytest.mark.parametrize("type_name", TYPES)
def test_every_field_shape_round_trips(arch, type_name):
    rng = random.Random()
    library = MessageLibrary([], store="ros2_humble")
    mem = ProcessMemory(arch, ByteRam(1 << 24), 1 << 24)
    messages = MessageMemory(mem, library)
    layout = CLayout(library, "arm64" if arch == "r64" else "arm32")
    for _ in range(5):
        value = random_field_value(library, Named(type_name), rng)
        va = messages.create(type_name)
        messages.write(va, type_name, value)
        assert messages.read(va, type_name) == value
        check_raw(mem, layout, va, type_name, value)


def test_wstring_is_refused():
    library = MessageLibrary([], store="ros2_humble")
    messages = MessageMemory(ProcessMemory("r64", ByteRam(1 << 20), 1 << 20), library)
    with pytest.raises(TypeError, match="wstring"):
        messages._write_value(messages.create("std_msgs/msg/Empty"), Primitive("wstring"), "x")
