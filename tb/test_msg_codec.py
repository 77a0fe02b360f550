# amaranth: UnusedElaboratable=no
"""Bench of the exported ``msg_codec`` top: hdl.msg.Serializer and Deserializer
(docs/messages.md; docs/topics.md; issue: ROS messages in hardware).

Golden models: rosbags serializes every random message (CDR with the ROS 2 store, ROS 1 with
the noetic store); the ReconROS framing comes from :func:`tb.models.msgstream.reconros_beats`,
written from docs/topics.md. Every input port gets random idle, every output port random
backpressure.
"""

import struct

import cocotb
import pytest
from cocotb.triggers import ClockCycles, with_timeout

from gen.msg.wire import BYTE_ELEMENTS, STRUCT_FORMAT, WireError, decode_cdr, default_value
from gen.tops import message_plan
from hdl.msg import DeserializerError, ReconrosDeserializer, ReconrosSerializer, SerializerError
from hdl.params import ParameterError
from tb.harness import amount, cocotb_bench
from tb.models.messages import random_sequence
from tb.models.msgstream import set_at, value_at

from .msg_codec_tb import (ELEMENTS, IMAGE, PARAMS, POINTS, STREAMABLE, TEST_MSGS, MsgCodecTB,
                           config)

CONFIGS = {
    "image_cdr_w8": config(IMAGE, "cdr", 8, max_count=8192),
    "image_cdr_w512": config(IMAGE, "cdr", 512, max_count=8192),
    "image_ros1_w64": config(IMAGE, "ros1", 64, max_count=8192),
    "streamable_cdr_w64": config(STREAMABLE, "cdr", 64, max_count=4096),
    "streamable_ros1_w8": config(STREAMABLE, "ros1", 8, max_count=4096),
    "streamable_reconros_w64": config(STREAMABLE, "reconros", 64, max_count=4096),
    "streamable_reconros_beats_w64": config(STREAMABLE, "reconros", 64, max_count=4096,
                                            beats=True),
    "image_reconros_beats_w64": config(IMAGE, "reconros", 64, max_count=8192, beats=True),
    "elements_cdr_w64": config(ELEMENTS, "cdr", 64, max_count=4096),
    "elements_cdr_w8": pytest.param(config(ELEMENTS, "cdr", 8, max_count=4096),
                                    marks=pytest.mark.full),
    "elements_cdr_w512": pytest.param(config(ELEMENTS, "cdr", 512, max_count=4096),
                                      marks=pytest.mark.full),
    "points_ros1_w16": pytest.param(config(POINTS, "ros1", 16, max_count=4096),
                                    marks=pytest.mark.full),
    "image_cdr_w64": pytest.param(config(IMAGE, "cdr", 64, max_count=8192),
                                  marks=pytest.mark.full),
    "image_reconros_w64": pytest.param(config(IMAGE, "reconros", 64, max_count=8192),
                                       marks=pytest.mark.full),
    "streamable_cdr_w512": pytest.param(config(STREAMABLE, "cdr", 512, max_count=4096),
                                        marks=pytest.mark.full),
    "streamable_cdr_w8": pytest.param(config(STREAMABLE, "cdr", 8, max_count=4096),
                                      marks=pytest.mark.full),
    "sort_cdr_w128": pytest.param(config("sorter_msgs/srv/Sort_Request", "cdr", 128,
                                         msg_dir="examples/messages/sorter_msgs",
                                         max_count=4096),
                                  marks=pytest.mark.full),
}

#: these run in test-full only (make test keeps both simulators on the other configurations)
LONG = [("streamable_ros1_w8", "verilator"), ("streamable_ros1_w8", "icarus"),
        ("image_cdr_w512", "verilator"), ("streamable_cdr_w64", "verilator"),
        ("image_cdr_w8", "verilator"), ("streamable_reconros_w64", "verilator"),
        ("elements_cdr_w64", "verilator")]

test_msg_codec = cocotb_bench("msg_codec", CONFIGS, long=LONG)

def test_reconros_codec_refuses_other_plans():
    """The beat-at-a-time pair takes only the ``reconros`` framing at 64 bits, and says which
    value it refuses."""
    folders = [TEST_MSGS]
    cdr = message_plan(IMAGE, "cdr", folders)
    with pytest.raises(ParameterError, match="'cdr'"):
        ReconrosDeserializer(cdr)
    with pytest.raises(ParameterError, match="'cdr'"):
        ReconrosSerializer(cdr)
    reconros = message_plan(IMAGE, "reconros", folders)
    with pytest.raises(ParameterError, match="data_width.*32"):
        ReconrosSerializer(reconros, 32)
    with pytest.raises(ParameterError, match="max_count.*0"):
        ReconrosDeserializer(reconros, max_count=0)


#: the element tests skip every configuration but Elements: only its type has packed element
#: streams, and their cases name its fields (the other configurations' streams are covered
#: by the tests above)
NOT_ELEMENTS = PARAMS.get("type") != ELEMENTS

#: random messages per direction: 2 big ones in make test, 6 in make test-full
RANDOM_MESSAGES = amount(8, 24)


@cocotb.test()
async def serializer_random_messages(dut):
    """Random messages (``RANDOM_MESSAGES``: small, and every fourth a big one up to 1500
    elements, 400 on 8-bit streams) under random idle and backpressure equal rosbags' bytes
    (CDR, ROS 1) or the ReconROS model, tuser included."""
    tb = MsgCodecTB(dut)
    await tb.reset()
    tb.set_idle(0.3)
    tb.set_backpressure(0.35)
    values = [tb.random_message(big=tb.big_elements if i % 4 == 3 else 0)
              for i in range(RANDOM_MESSAGES)]
    values[1] = tb.empty_fields(values[1])   # the message ends with an empty field
    await tb.run_serializer(values)
    assert not tb.errors["ser"], tb.errors


@cocotb.test()
async def deserializer_random_messages(dut):
    """rosbags' bytes of random messages come out as the same fields and field bytes,
    one packet per variable-length field, under random idle and backpressure."""
    tb = MsgCodecTB(dut)
    await tb.reset()
    tb.set_idle(0.3)
    tb.set_backpressure(0.35)
    values = [tb.random_message(big=tb.big_elements if i % 4 == 3 else 0)
              for i in range(RANDOM_MESSAGES)]
    values[1] = tb.empty_fields(values[1])
    await tb.run_deserializer(values)


@cocotb.test()
async def round_trip_full_rate(dut):
    """Without idle or backpressure, a >= 4 KiB payload leaves the deserializer at W/8 bytes
    per cycle (>= 99 %), and the serializer's output for it equals the golden bytes and
    deserializes to the input."""
    tb = MsgCodecTB(dut)
    await tb.reset()
    B = tb.bytes_per_beat
    big = max(4096, 64 * B)
    value = tb.random_message()
    target = max(primitive_sequences(tb.plan), key=lambda v: v.element_bytes)
    n = big // target.element_bytes
    set_at(value, target.path, random_sequence(target.element, n, tb.rng))
    await tb.serialize(value)
    frame = await with_timeout(tb.ser_out.recv(compact=False), 2_000_000, "ns")
    tb.check_serialized(frame, value, 0)
    await tb.run_deserializer([value])
    packet = tb.des_payloads[tb.plan.streams.index(target)].packets[-1]
    cycles = packet.cycles[-1] - packet.cycles[0] + 1
    rate = len(packet.data) / cycles
    tb.log.info("deserializer payload %s: %d bytes in %d cycles = %.3f B/cycle (W/8 = %d)",
                target.path, len(packet.data), cycles, rate, B)
    assert rate >= 0.99 * B, f"payload rate {rate:.3f} B/cycle < 99 % of {B}"


@cocotb.test()
async def sequences_at_max_count(dut):
    """Every unbounded sequence with exactly ``max_count`` elements, the most the hardware
    takes (one more is the LENGTH error of ``deserializer_bad_input_recovers``): serialized as
    rosbags (or the ReconROS model) does, deserialized to the same fields and bytes, with no
    error, under 10 % idle and backpressure."""
    tb = MsgCodecTB(dut)
    await tb.reset()
    tb.set_idle(0.1)
    tb.set_backpressure(0.1)
    value = tb.random_message()
    for v in primitive_sequences(tb.plan):
        set_at(value, v.path, random_sequence(v.element, tb.max_count, tb.rng))
    await tb.run_serializer([value])
    assert not tb.errors["ser"], tb.errors
    await tb.run_deserializer([value])


@cocotb.test()
async def deserializer_bad_input_recovers(dut):
    """Each malformed message raises the error output with its reason code, emits no more
    payload bytes than declared, and the next good message comes through intact."""
    tb = MsgCodecTB(dut)
    await tb.reset()
    tb.set_idle(0.2)
    tb.set_backpressure(0.2)
    cases = bad_messages(tb)
    assert len(cases) >= 4
    await run_bad_input(tb, cases, lambda: [tb.random_message()])


ENDS_IN_FIXED_FIELD = "ends early in a fixed field"
BIG_ENDIAN = "big-endian encapsulation"
#: bad cases that fail in or before the step that reads the message's first field, so offer
#: no fields (a case that fails later may have offered them: once the last one is read)
FAIL_BEFORE_FIELDS = (ENDS_IN_FIXED_FIELD, BIG_ENDIAN)


async def run_bad_input(tb, cases, next_values):
    """Deserialize each malformed case: exactly its error code, no fields if it fails before
    them (:data:`FAIL_BEFORE_FIELDS`), no packet with bytes that are not its field's, no
    packet left open, then ``next_values()`` intact."""
    for name, data, code, value in cases:
        tb.errors["des"].clear()
        start = [len(p.packets) for p in tb.des_payloads]
        start_fields = len(tb.des_fields.values)
        await tb.deserialize(data)
        await tb.wait_for(lambda: tb.errors["des"], 200_000)
        # fields offered before the error stay offered until taken, and packets it closed
        # wait behind random backpressure
        await tb.wait_quiet()
        assert tb.errors["des"] == [int(code)], f"{name}: errors {tb.errors['des']}, want {code!r}"
        if name in FAIL_BEFORE_FIELDS:
            assert len(tb.des_fields.values) == start_fields, f"{name}: fields offered"
        for v, p, s, field in zip(tb.plan.streams, tb.des_payloads, start,
                                  tb.stream_bytes(value)):
            for packet in p.packets[s:]:
                assert field.startswith(bytes(packet.data)), \
                    f"{name}: {v.path} emitted {bytes(packet.data).hex()}, not from {field.hex()}"
            assert p.current.beats == [], f"{name}: {v.path} packet left open"
        tb.errors["des"].clear()
        await tb.run_deserializer(next_values())
        tb.log.info("bad input %s -> error %s, next message intact", name, code.name)
    assert int(tb.dut.des_error_count.value) == len(cases)


def bad_messages(tb):
    """(name, bytes, expected code, the value the bytes came from) per malformed case."""
    rng, plan, B = tb.rng, tb.plan, tb.bytes_per_beat
    cases = []
    value = tb.random_message()
    for v in plan.streams:   # give every field some bytes so truncation lands inside one
        if v.string:
            set_at(value, v.path, "abcdefghijk"[:v.bound or 11])
    good = tb.wire_bytes(value)
    cases.append((ENDS_IN_FIXED_FIELD, good[:6], DeserializerError.EARLY_END, value))
    big = tb.random_message()
    seq = primitive_sequences(plan)[-1]
    n = 64
    set_at(big, seq.path, random_sequence(seq.element, n, rng))
    big_bytes = tb.wire_bytes(big)
    cases.append(("ends early inside a payload", big_bytes[:-(n * seq.element_bytes) // 2],
                  DeserializerError.EARLY_END, big))
    cases.append(("goes on after the message", good + bytes(range(1, 2 * B + 4)),
                  DeserializerError.LATE_END, value))
    # a count above the bound: rewrite the count of an unbounded field to max_count + 1
    offset = count_offset(tb, value, seq)
    data = bytearray(good)
    data[offset:offset + 4] = (tb.max_count + 1).to_bytes(4, "little")
    cases.append(("count above max_count", bytes(data), DeserializerError.LENGTH, value))
    # the same on an empty sequence of 8-byte elements: the count is followed by no padding,
    # so the bytes after it are not zero; the count is still what gets reported
    empty = _copy(value)
    set_at(empty, seq.path, b"" if seq.element in BYTE_ELEMENTS else [])
    offset = count_offset(tb, empty, seq)
    data = bytearray(tb.wire_bytes(empty))
    data[offset:offset + 4] = (tb.max_count + 1).to_bytes(4, "little")
    cases.append(("count above max_count, empty sequence", bytes(data),
                  DeserializerError.LENGTH, empty))
    if tb.framing == "cdr":
        data = bytearray(good)
        data[0:2] = b"\x00\x00"   # CDR_BE
        cases.append((BIG_ENDIAN, bytes(data), DeserializerError.FORMAT, value))
        pad = padding_offsets(tb, good)
        if pad:
            data = bytearray(good)
            data[pad[0]] = 0x5a
            cases.append(("non-zero padding", bytes(data), DeserializerError.PADDING, value))
        strings = [v for v in plan.streams if v.string]
        if strings:
            nul = count_offset(tb, value, strings[0]) + 4 + len(
                value_at(value, strings[0].path).encode())
            data = bytearray(good)
            data[nul] = ord("!")
            cases.append(("string without NUL", bytes(data), DeserializerError.FORMAT, value))
    if tb.framing == "reconros":
        fixed = [leaf for leaf in plan.leaves if leaf.length > 1]
        if fixed:
            # the size beat of a fixed array is two beats before its first data beat: the
            # first beat that changes with the array's first element
            other = _copy(value)
            items = list(value_at(value, fixed[0].path))
            items[0] = items[0] ^ 1 if isinstance(items[0], int) else items[0] + 1.0
            set_at(other, fixed[0].path, items)
            changed = tb.wire_bytes(other)
            size_at = next(i for i in range(len(good)) if good[i] != changed[i]) // 8 * 8 - 16
            data = bytearray(good)
            data[size_at] ^= 0x01
            cases.append(("fixed array size beat changed", bytes(data), DeserializerError.FORMAT,
                          value))
    if tb.framing == "ros1":
        data = bytearray(good)
        data[0:4] = (len(good) - 4 + 1).to_bytes(4, "little")
        cases.append(("length prefix disagrees", bytes(data), DeserializerError.FORMAT, value))
    return cases


def count_offset(tb, value, variable):
    """Byte offset of ``variable``'s count in the golden bytes of ``value``: the first
    position where changing the field's length changes the count."""
    a = tb.wire_bytes(value)
    other = _copy(value)
    item = value_at(value, variable.path)
    longer = (item + "z") if isinstance(item, str) else (
        item + b"\x01" if isinstance(item, (bytes, bytearray)) else list(item) + [item[0] if item
                                                                                  else 0])
    set_at(other, variable.path, longer)
    b = tb.wire_bytes(other)
    if tb.framing == "ros1":      # unaligned; skip the length prefix, which changes too
        return next(i for i in range(4, min(len(a), len(b))) if a[i] != b[i])
    first = next(i for i in range(min(len(a), len(b))) if a[i] != b[i])
    return first - first % (8 if tb.framing == "reconros" else 4)


def padding_offsets(tb, data):
    """Offsets of CDR alignment padding, found with rosgate's tested Python decoder."""
    offsets = []
    for i in range(4, len(data)):
        if data[i] != 0:
            continue
        changed = bytearray(data)
        changed[i] = 0x5a
        try:
            decode_cdr(tb.library, tb.typename, bytes(changed))
        except WireError as exc:
            if "padding" in str(exc):
                offsets.append(i)
    return offsets


def _copy(value):
    if isinstance(value, dict):
        return {k: _copy(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_copy(v) for v in value]
    return value


@cocotb.test()
async def serializer_bad_payload_recovers(dut):
    """A payload stream shorter than its count is completed with zeros, a longer one is cut and
    drained; both are reported, and the next message is exact."""
    tb = MsgCodecTB(dut)
    await tb.reset()
    tb.set_idle(0.2)
    tb.set_backpressure(0.2)
    seq = primitive_sequences(tb.plan)[-1]
    for name, delta, code in (("short", -3, SerializerError.PAYLOAD_SHORT),
                              ("long", +2 * tb.bytes_per_beat + 1,
                               SerializerError.PAYLOAD_LONG)):
        value = tb.random_message()
        n = 40
        set_at(value, seq.path, random_sequence(seq.element, n, tb.rng))
        payloads = tb.stream_bytes(value)
        declared = payloads[tb.plan.streams.index(seq)]
        if delta < 0:
            sent = declared[:len(declared) // 2 + 1]
            expected_field = sent + bytes(len(declared) - len(sent))
        else:
            sent = declared + bytes(range(1, delta + 1))
            expected_field = declared
        payloads[tb.plan.streams.index(seq)] = sent
        tb.errors["ser"].clear()
        await tb.serialize(value, payloads)
        frame = await with_timeout(tb.ser_out.recv(compact=False), 2_000_000, "ns")
        expected_value = _copy(value)
        if seq.element in BYTE_ELEMENTS:
            set_at(expected_value, seq.path, expected_field)
        else:
            set_at(expected_value, seq.path, decode_elements(seq, expected_field))
        tb.check_serialized(frame, expected_value, 0)
        await ClockCycles(dut.aclk, 10)
        assert tb.errors["ser"] == [int(code)], f"{name}: errors {tb.errors['ser']}"
        tb.errors["ser"].clear()
        await tb.run_serializer([tb.random_message()])
        assert not tb.errors["ser"]


def primitive_sequences(plan):
    """The unbounded sequences of primitives that have a stream of their own."""
    return [v for v in plan.streams if not v.string and not v.bound and not v.elements]


def decode_elements(variable, raw):
    fmt = STRUCT_FORMAT[variable.element]
    return list(struct.unpack(f"<{len(raw) // variable.element_bytes}{fmt}", raw))


def elements_value(tb):
    """An ``Elements`` value whose strings and sequences inside elements all hold something."""
    value = tb.random_message()
    value["short_names"] = ["ab", "cdef"]
    value["names"] = ["first", "second name"]
    value["items"] = [
        {"label": "lab", "weight": 1.5, "samples": [1, 2, 3],
         "corners": [{"x": 1.0, "y": 2.0, "z": 3.0}, {"x": -1.0, "y": 0.5, "z": 0.0}],
         "values": [{"key": "k1", "value": "one"}, {"key": "key2", "value": "two2"}]},
        {"label": "second", "weight": -2.0, "samples": [],
         "corners": [{"x": 0.0, "y": 0.0, "z": 0.0}] * 2,
         "values": [{"key": "x", "value": "y"}]}]
    return value


def first_difference(tb, a, b):
    x, y = tb.wire_bytes(a), tb.wire_bytes(b)
    return next(i for i in range(min(len(x), len(y))) if x[i] != y[i])


def element_bad_messages(tb):
    """(name, bytes, code, value) of malformed messages inside packed elements (CDR)."""
    value = elements_value(tb)
    good = tb.wire_bytes(value)
    cases = []

    def changed(edit):
        other = _copy(value)
        edit(other)
        return other

    # the count of short_names[0] ("ab", bound 6): the first byte that changes with its length
    at = first_difference(tb, value, changed(lambda v: v["short_names"].__setitem__(0, "abc")))
    at -= at % 4
    data = bytearray(good)
    data[at:at + 4] = (7 + 1).to_bytes(4, "little")       # 7 characters + NUL > bound 6
    cases.append(("inner string above its bound", bytes(data), DeserializerError.LENGTH, value))
    data[at:at + 4] = bytes(4)
    cases.append(("inner CDR string count 0", bytes(data), DeserializerError.FORMAT, value))
    # items holds 2 of at most 4: a count of 5
    at = first_difference(tb, value, changed(lambda v: v["items"].append(v["items"][1])))
    at -= at % 4
    data = bytearray(good)
    data[at:at + 4] = (5).to_bytes(4, "little")
    cases.append(("sequence of messages above its bound", bytes(data),
                  DeserializerError.LENGTH, value))
    # the NUL of items[0].values[1].key
    at = first_difference(tb, value, changed(
        lambda v: v["items"][0]["values"][1].__setitem__("key", "key2+")))
    at += -at % 4 + 4 + len("key2")      # past the count (the first difference) and the key
    data = bytearray(good)
    data[at] = ord("!")
    cases.append(("inner string without NUL", bytes(data), DeserializerError.FORMAT, value))
    # cut inside items[0].values[1].value
    cases.append(("ends early in a nested element", good[:at + 6], DeserializerError.EARLY_END,
                  value))
    return cases


@cocotb.skipif(NOT_ELEMENTS, reason="only the Elements type has packed element streams; the other configurations' streams are covered by the tests above")
@cocotb.test()
async def elements_bad_input_recovers(dut):
    """Malformed counts and strings inside packed elements, and a message cut inside a nested
    element: the error code, only bytes of the field on the element stream, every packet
    closed, and the next message intact."""
    tb = MsgCodecTB(dut)
    await tb.reset()
    tb.set_idle(0.2)
    tb.set_backpressure(0.2)
    await run_bad_input(tb, element_bad_messages(tb),
                        lambda: [elements_value(tb), tb.random_message()])


@cocotb.skipif(NOT_ELEMENTS, reason="only the Elements type has packed element streams; the other configurations' streams are covered by the tests above")
@cocotb.test()
async def serializer_bad_elements_recover(dut):
    """A packed elements stream one element short is completed with a zero (default) element,
    one that goes on is cut and drained, and an inner count above its bound is written as 0:
    each reported once with its code, and the next message is exact."""
    tb = MsgCodecTB(dut)
    await tb.reset()
    tb.set_idle(0.2)
    tb.set_backpressure(0.2)
    items = tb.plan.streams.index(next(v for v in tb.plan.streams if v.path == "items"))
    shorts = tb.plan.streams.index(next(v for v in tb.plan.streams if v.path == "short_names"))
    for name, code in (("short", SerializerError.PAYLOAD_SHORT),
                       ("long", SerializerError.PAYLOAD_LONG),
                       ("inner count", SerializerError.LENGTH)):
        value = elements_value(tb)
        payloads = tb.stream_bytes(value)
        expected = _copy(value)
        if name == "short":
            payloads[items] = tb.packed(tb.plan.streams[items].element, value["items"][0])
            expected["items"][1] = default_value(tb.library, tb.plan.streams[items].element)
        elif name == "long":
            payloads[items] += bytes(range(1, 20))
        else:       # "ab" declared as 7 characters (bound 6): written as "", the rest dropped
            value["short_names"] = expected["short_names"] = ["ab"]
            payloads[shorts] = (7).to_bytes(4, "little") + b"ab"
            expected["short_names"] = [""]
        tb.errors["ser"].clear()
        await tb.serialize(value, payloads)
        frame = await with_timeout(tb.ser_out.recv(compact=False), 2_000_000, "ns")
        tb.check_serialized(frame, expected, 0)
        await ClockCycles(dut.aclk, 10)
        assert tb.errors["ser"] == [int(code)], f"{name}: errors {tb.errors['ser']}"
        tb.errors["ser"].clear()
        await tb.run_serializer([tb.random_message(), elements_value(tb)])
        assert not tb.errors["ser"]
