"""The co-simulation's process heap (``host.reconos.memory.ProcessMemory``): ``free`` gives a
block back and ``malloc`` reuses it, zeroed; free extents merge; a bad ``free`` is refused
by address; running out names the memory's size, what is in use and the option that raises
it; and rosidl's message handling (``host.reconos.messages``) frees what a struct held
when a new message is stored into it or a sequence is resized, so that any number of
messages fits in bounded memory."""

import functools
import random

import pytest

from gen.msg import MessageLibrary
from gen.msg.model import Named
from host.compiled import MEMORY_OPTION
from host.reconos.memory import PAGE, ProcessMemory
from host.reconos.messages import MessageMemory

from .models.messages import ByteRam, random_field_value


@functools.cache
def standard_library():
    return MessageLibrary([], store="ros2_humble")


def memory(size=1 << 22, arch="r64"):
    return ProcessMemory(arch, ByteRam(size), size)


def test_freed_blocks_are_reused_zeroed_and_merge():
    mem = memory()
    a, b, c = (mem.malloc(1000) for _ in range(3))
    mem.write(b, b"\xff" * 1000)
    mem.free(b)
    assert mem.malloc(600) == b                       # first fit, in the freed block
    assert mem.read(b, 600) == bytes(600)             # zeroed as the docstring promises
    mem.free(a)
    mem.free(b)
    assert mem.usage()["free"] >= 1600 and len(mem._free) == 1   # a and b merged
    big = mem.malloc(1500)                            # fits only in the merged extent
    assert big == a
    assert mem.usage()["in_use"] == 1500 + 1000 and mem.usage()["blocks"] == 2
    assert mem.translate(big) and mem.read(c, 4) == bytes(4)


def test_random_malloc_free_never_overlaps_and_stays_bounded():
    """Thousands of random allocations and frees: live blocks never overlap, every byte
    written to a block reads back, and the physical memory used stays near the peak in use."""
    rng = random.Random(4)
    mem = memory(1 << 24)
    live = {}
    for step in range(4000):
        if live and rng.random() < 0.5:
            va = rng.choice(list(live))
            assert mem.read(va, len(live[va])) == live.pop(va)
            mem.free(va)
        else:
            n = rng.choice([1, 7, 64, 700, 5000, 70000])
            va = mem.malloc(n, align=rng.choice([8, 64, PAGE]))
            data = rng.randbytes(n)
            mem.write(va, data)
            live[va] = data
        spans = sorted((va, va + len(d)) for va, d in live.items())
        assert all(end <= nxt for (_, end), (nxt, _) in zip(spans, spans[1:]))
    assert mem.usage()["physical"] < 4 * mem.peak + (1 << 20)


@pytest.mark.parametrize("va", [0, 12345])
def test_a_bad_free_is_refused_by_address(va):
    mem = memory()
    block = mem.malloc(64)
    mem.free(block)
    for bad in (va, block, block + 8):
        with pytest.raises(ValueError, match=f"0x{bad:x}"):
            mem.free(bad)


def test_running_out_names_the_size_what_is_used_and_the_option():
    mem = memory(1 << 20)
    mem.malloc(300_000)
    with pytest.raises(MemoryError) as info:
        for _ in range(10):
            mem.malloc(300_000)
    text = str(info.value)
    assert str(1 << 20) in text and "live heap blocks" in text and MEMORY_OPTION in text


@pytest.mark.parametrize("arch", ["r64", "r32"])
@pytest.mark.parametrize("type_name", ["sensor_msgs/msg/JointState", "geometry_msgs/msg/PoseArray",
                                       "diagnostic_msgs/msg/DiagnosticArray",
                                       "sensor_msgs/msg/Image", "std_msgs/msg/Empty"])
def test_storing_messages_again_and_again_stays_in_bounded_memory(arch, type_name):
    """A struct that receives 300 random messages (a subscriber's message taking every
    sample) holds the last one exactly, and the heap holds no more than one message's
    buffers: without freeing, the same run would need the sum of all of them."""
    rng = random.Random(type_name)
    mem = memory(1 << 24, arch)
    lib = standard_library()
    msgs = MessageMemory(mem, lib)
    va = msgs.create(type_name)
    base = mem.in_use
    most = 0
    for _ in range(300):
        value = random_field_value(lib, Named(type_name), rng)
        msgs.write(va, type_name, value)
        most = max(most, mem.in_use - base)
        assert msgs.read(va, type_name) == value
    msgs.fini(va, type_name)
    assert mem.in_use == base and msgs.foreign == 0
    assert mem.peak - base <= most


def test_resizing_a_sequence_frees_its_old_buffer_and_leaves_foreign_pointers():
    mem = memory()
    msgs = MessageMemory(mem, standard_library())
    va = msgs.create("sensor_msgs/msg/Image")
    data = va + msgs.member("sensor_msgs/msg/Image", "data")
    base = mem.in_use
    for count in (100, 5000, 10, 0, 64):
        msgs.set_sequence(data, 1, count)
        assert mem.in_use - base == count
    # a data pointer the hardware wrote itself (inside another block) is not freed
    other = mem.malloc(256)
    msgs._ptr(data, other + 16)
    msgs.fini(va, "sensor_msgs/msg/Image")
    assert msgs.foreign == 1 and mem.owns(other)
