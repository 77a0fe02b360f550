"""Bench of the exported ``msg_codec`` top: hdl.msg.Serializer and Deserializer (ros_wire.md
§1.2, §2; hmt.md §5; issue: ROS messages in hardware).

Golden models: rosbags serializes every random message (CDR with the ROS 2 store, ROS 1 with
the noetic store); the ReconROS framing comes from :func:`tb.models.msgstream.reconros_beats`,
written from hmt.md §5. Every input port gets random idle, every output port random
backpressure.
"""

import logging
import os
import random
import struct

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, RisingEdge, with_timeout
from cocotbext.axi import AxiStreamBus, AxiStreamFrame, AxiStreamSink, AxiStreamSource
import pytest

from gen.msg import MessageLibrary
from gen.msg.wire import BYTE_ELEMENTS, STRUCT_FORMAT, WireError, decode_cdr
from gen.tops import message_plan
from hdl.msg import DeserializerError, SerializerError, payload_port
from tb.harness import bench_params, cocotb_bench
from tb.models.messages import golden_store, random_sequence, random_value, to_rosbags
from tb.models.msgstream import (expected_fields, fixed_part, leaf_values, reconros_beats,
                                 set_at, value_at, variable_bytes)
from tb.streams import HandshakeSink, HandshakeSource, PacketSink, bursty_pauses, random_pauses

CLOCK_NS = 10
TEST_MSGS = "examples/messages/rosgate_test_msgs"
IMAGE = "sensor_msgs/msg/Image"
STREAMABLE = "rosgate_test_msgs/msg/Streamable"


def config(type_, framing, width, msg_dir=TEST_MSGS, **extra):
    return dict(type=type_, framing=framing, data_width=width, msg_dirs=[msg_dir], **extra)


CONFIGS = {
    "image_cdr_w8": config(IMAGE, "cdr", 8, max_count=8192),
    "image_cdr_w512": config(IMAGE, "cdr", 512, max_count=8192),
    "image_ros1_w64": config(IMAGE, "ros1", 64, max_count=8192),
    "streamable_cdr_w64": config(STREAMABLE, "cdr", 64, max_count=4096),
    "streamable_ros1_w8": config(STREAMABLE, "ros1", 8, max_count=4096),
    "streamable_reconros_w64": config(STREAMABLE, "reconros", 64, max_count=4096),
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
        ("image_cdr_w8", "verilator"), ("streamable_reconros_w64", "verilator")]
test_msg_codec = cocotb_bench("msg_codec", CONFIGS, long=LONG)

PARAMS = bench_params() if "ROSGATE_PARAMS" in os.environ else {}
PUBLISHER = 5


class MsgCodecTB:
    def __init__(self, dut, seed=None):
        self.dut = dut
        self.params = bench_params()
        self.framing = self.params["framing"]
        self.typename = self.params["type"]
        self.width = self.params["data_width"]
        self.bytes_per_beat = self.width // 8
        self.max_count = self.params["max_count"]
        #: elements of a "big" sequence in the random tests (fewer on byte-wide streams)
        self.big_elements = 1500 if self.bytes_per_beat >= 8 else 400
        folders = [os.path.join(os.environ.get("ROSGATE_ROOT", os.getcwd()), d)
                   for d in self.params["msg_dirs"]]
        self.plan = message_plan(self.typename, self.framing, folders)
        store = "ros1_noetic" if self.framing == "ros1" else "ros2_humble"
        self.library = MessageLibrary(folders, store=store)
        self.golden = golden_store(store, folders)
        self.rng = random.Random(seed if seed is not None else cocotb.RANDOM_SEED)
        self.log = logging.getLogger("cocotb.tb")
        clock = dut.aclk
        cocotb.start_soon(Clock(clock, CLOCK_NS, unit="ns").start())

        def source(prefix):
            port = AxiStreamSource(AxiStreamBus.from_prefix(dut, prefix), clock, dut.aresetn,
                                   reset_active_level=False)
            port.log.setLevel(logging.WARNING)
            return port

        self.ser_fields = HandshakeSource(dut, "ser_fields", clock)
        self.ser_payloads = [source(f"ser_{payload_port(v, 's')}") for v in self.plan.variables]
        self.ser_out = AxiStreamSink(AxiStreamBus.from_prefix(dut, "ser_m_axis"), clock,
                                     dut.aresetn, reset_active_level=False)
        self.ser_out.log.setLevel(logging.WARNING)
        self.des_in = source("des_s_axis")
        self.des_fields = HandshakeSink(dut, "des_fields", clock)
        self.des_payloads = [PacketSink(dut, f"des_{payload_port(v, 'm')}", clock)
                             for v in self.plan.variables]
        self.errors = {"ser": [], "des": []}
        self.cycle = 0
        cocotb.start_soon(self._watch_errors())

    async def _watch_errors(self):
        while True:
            await RisingEdge(self.dut.aclk)
            self.cycle += 1
            for side in ("ser", "des"):
                if getattr(self.dut, f"{side}_error_valid").value == 1:
                    self.errors[side].append(int(getattr(self.dut, f"{side}_error_code").value))

    async def reset(self):
        self.dut.aresetn.value = 0
        await ClockCycles(self.dut.aclk, 4)
        self.dut.aresetn.value = 1
        await ClockCycles(self.dut.aclk, 2)

    def set_idle(self, probability):
        for port in [self.ser_fields, self.des_in] + self.ser_payloads:
            port.set_pause_generator(random_pauses(self.rng, probability) if probability
                                     else None)
            if not probability and hasattr(port, "pause"):
                port.pause = False

    def set_backpressure(self, probability):
        for port in [self.ser_out, self.des_fields] + self.des_payloads:
            port.set_pause_generator(bursty_pauses(self.rng, probability) if probability
                                     else None)
            if not probability and hasattr(port, "pause"):
                port.pause = False

    # messages --------------------------------------------------------------------------
    def random_message(self, big=0):
        """A random value; with ``big``, unbounded sequences get up to ``big`` elements."""
        value = random_value(self.library, self.typename, self.rng, max_len=6)
        for v in self.plan.variables:
            if v.string or v.bound or not big:
                continue
            n = self.rng.randint(big // 2, big)
            set_at(value, v.path, random_sequence(v.element, n, self.rng))
        return value

    def empty_fields(self, value):
        """``value`` with every variable-length field empty."""
        for v in self.plan.variables:
            set_at(value, v.path, "" if v.string else [])
        return value

    def wire_bytes(self, value):
        """Golden bytes of ``value`` in the framing (rosbags or the ReconROS model)."""
        if self.framing == "reconros":
            beats = reconros_beats(self.library, self.typename, value, PUBLISHER)
            return b"".join(d.to_bytes(8, "little") for d, _, _ in beats)
        message = to_rosbags(self.golden, self.library, self.typename, value)
        if self.framing == "cdr":
            return bytes(self.golden.serialize_cdr(message, self.plan.typename))
        body = bytes(self.golden.serialize_ros1(message, self.plan.typename))
        return len(body).to_bytes(4, "little") + body

    def frame(self, data):
        return AxiStreamFrame(data)

    # serializer ------------------------------------------------------------------------
    async def serialize(self, value, payload_override=None):
        """Offer ``value`` to the serializer (fields and every payload stream)."""
        payloads = payload_override or variable_bytes(self.plan, value)
        for port, data in zip(self.ser_payloads, payloads):
            await port.send(self.frame(data or b"\x00"))   # an empty field: one ignored byte
        await self.ser_fields.send(fixed_part(self.plan, value, PUBLISHER))

    async def run_serializer(self, values):
        sender = cocotb.start_soon(self._serialize_all(values))
        for n, value in enumerate(values):
            self.log.debug("waiting for message %d (%d bytes)", n, len(self.wire_bytes(value)))
            frame = await with_timeout(self.ser_out.recv(compact=False), 2_000_000, "ns")
            self.check_serialized(frame, value, n)
        await sender

    async def _serialize_all(self, values):
        for value in values:
            await self.serialize(value)

    def check_serialized(self, frame, value, n):
        expected = self.wire_bytes(value)
        keep = list(frame.tkeep)
        length = sum(keep)
        assert keep == [1] * length + [0] * (len(keep) - length), f"message {n}: tkeep {keep}"
        got = bytes(frame.tdata[:length])
        assert got == expected, (f"message {n}: serializer gave {len(got)} bytes\n{got.hex()}"
                                 f"\nrosbags/model {len(expected)} bytes\n{expected.hex()}")
        if self.framing == "reconros":
            beats = reconros_beats(self.library, self.typename, value, PUBLISHER)
            per_beat = [int(u) for u in frame.tuser[::self.bytes_per_beat]]  # cocotbext: per byte
            assert per_beat == [u for _, u, _ in beats], f"message {n}: tuser {per_beat}"

    # deserializer ----------------------------------------------------------------------
    async def deserialize(self, data):
        await self.des_in.send(self.frame(data))

    def check_deserialized(self, value, fields, packets, n):
        got = leaf_values(self.plan, fields)
        want = expected_fields(self.plan, value, PUBLISHER)
        bad = {k: (got[k].hex(), want[k].hex()) for k in want if got[k] != want[k]}
        assert not bad, f"message {n}: fields (got, want) {bad}"
        for v, packet, data in zip(self.plan.variables, packets,
                                   variable_bytes(self.plan, value)):
            assert bytes(packet.data) == data, \
                f"message {n}: {v.path}: got {bytes(packet.data).hex()} want {data.hex()}"
            B = self.bytes_per_beat
            users = [u for _, _, u in packet.beats]
            assert users == [1] + [0] * (len(users) - 1), f"{v.path}: tuser {users}"
            keeps = [k for _, k, _ in packet.beats]
            full = (1 << B) - 1
            assert all(k == full for k in keeps[:-1]), f"{v.path}: partial beat inside {keeps}"
            assert len(packet.beats) == max(1, -(-len(data) // B)), f"{v.path}: beat count"

    async def run_deserializer(self, values, timeout_cycles=2_000_000):
        start_fields = len(self.des_fields.values)
        start = [len(p.packets) for p in self.des_payloads]
        for value in values:
            await self.deserialize(self.wire_bytes(value))
        await self.wait_for(lambda: len(self.des_fields.values) - start_fields >= len(values)
                            and all(len(p.packets) - s >= len(values)
                                    for p, s in zip(self.des_payloads, start)),
                            timeout_cycles)
        assert len(self.des_fields.values) - start_fields == len(values)
        for n, value in enumerate(values):
            self.check_deserialized(value, self.des_fields.values[start_fields + n],
                                    [p.packets[s + n] for p, s in zip(self.des_payloads, start)],
                                    n)
        assert not self.errors["des"], f"unexpected deserializer errors {self.errors['des']}"

    async def wait_for(self, condition, timeout_cycles):
        for _ in range(timeout_cycles):
            if condition():
                return
            await RisingEdge(self.dut.aclk)
        raise AssertionError(f"timeout after {timeout_cycles} cycles")


@cocotb.test()
async def serializer_random_messages(dut):
    """Random messages (small, and big ones up to 1500 elements, 400 on 8-bit streams) under
    random idle and backpressure
    equal rosbags' bytes (CDR, ROS 1) or the ReconROS model, tuser included."""
    tb = MsgCodecTB(dut)
    await tb.reset()
    tb.set_idle(0.3)
    tb.set_backpressure(0.35)
    values = [tb.random_message(big=tb.big_elements if i % 4 == 3 else 0)
              for i in range(24)]
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
              for i in range(24)]
    values[1] = tb.empty_fields(values[1])
    await tb.run_deserializer(values)


@cocotb.test()
async def round_trip_full_rate(dut):
    """Without idle or backpressure, a >= 4 KiB payload moves at W/8 bytes per cycle in both
    directions (>= 99 %), and the serializer's output deserializes to the input."""
    tb = MsgCodecTB(dut)
    await tb.reset()
    B = tb.bytes_per_beat
    big = max(4096, 64 * B)
    value = tb.random_message()
    target = max((v for v in tb.plan.variables if not v.string and not v.bound),
                 key=lambda v: v.element_bytes)
    n = big // target.element_bytes
    set_at(value, target.path, random_sequence(target.element, n, tb.rng))
    await tb.serialize(value)
    frame = await with_timeout(tb.ser_out.recv(compact=False), 2_000_000, "ns")
    tb.check_serialized(frame, value, 0)
    await tb.run_deserializer([value])
    packet = tb.des_payloads[target.index].packets[-1]
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
    for v in tb.plan.variables:
        if v.string or v.bound:
            continue
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
    for name, data, code, value in cases:
        tb.errors["des"].clear()
        start = [len(p.packets) for p in tb.des_payloads]
        await tb.deserialize(data)
        await tb.wait_for(lambda: tb.errors["des"], 200_000)
        # fields offered before the error stay offered until taken (random backpressure)
        await tb.wait_for(lambda: dut.des_fields_valid.value == 0, 10_000)
        await ClockCycles(dut.aclk, 20)
        assert tb.errors["des"] == [int(code)], f"{name}: errors {tb.errors['des']}, want {code!r}"
        declared = variable_bytes(tb.plan, value)
        for v, p, s in zip(tb.plan.variables, tb.des_payloads, start):
            for packet in p.packets[s:]:
                assert declared[v.index].startswith(bytes(packet.data)), \
                    f"{name}: {v.path} emitted bytes that are not the field's"
            assert p.current.beats == [], f"{name}: {v.path} packet left open"
        tb.errors["des"].clear()
        good = tb.random_message()
        await tb.run_deserializer([good])
        tb.log.info("bad input %s -> error %s, next message intact", name, code.name)
    assert int(dut.des_error_count.value) == len(cases)


def bad_messages(tb):
    """(name, bytes, expected code, the value the bytes came from) per malformed case."""
    rng, plan, B = tb.rng, tb.plan, tb.bytes_per_beat
    cases = []
    value = tb.random_message()
    for v in plan.variables:   # give every field some bytes so truncation lands inside one
        if v.string:
            set_at(value, v.path, "abcdefghijk"[:v.bound or 11])
    good = tb.wire_bytes(value)
    cases.append(("ends early in a fixed field", good[:6], DeserializerError.EARLY_END, value))
    big = tb.random_message()
    seq = [v for v in plan.variables if not v.string and not v.bound][-1]
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
        cases.append(("big-endian encapsulation", bytes(data), DeserializerError.FORMAT, value))
        pad = padding_offsets(tb, good)
        if pad:
            data = bytearray(good)
            data[pad[0]] = 0x5a
            cases.append(("non-zero padding", bytes(data), DeserializerError.PADDING, value))
        strings = [v for v in plan.variables if v.string]
        if strings:
            nul = count_offset(tb, value, strings[0]) + 4 + len(
                value_at(value, strings[0].path).encode())
            data = bytearray(good)
            data[nul] = ord("!")
            cases.append(("string without NUL", bytes(data), DeserializerError.FORMAT, value))
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
    seq = [v for v in tb.plan.variables if not v.string and not v.bound][-1]
    for name, delta, code in (("short", -3, SerializerError.PAYLOAD_SHORT),
                              ("long", +2 * tb.bytes_per_beat + 1,
                               SerializerError.PAYLOAD_LONG)):
        value = tb.random_message()
        n = 40
        set_at(value, seq.path, random_sequence(seq.element, n, tb.rng))
        payloads = variable_bytes(tb.plan, value)
        declared = payloads[seq.index]
        if delta < 0:
            sent = declared[:len(declared) // 2 + 1]
            expected_field = sent + bytes(len(declared) - len(sent))
        else:
            sent = declared + bytes(range(1, delta + 1))
            expected_field = declared
        payloads[seq.index] = sent
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


def decode_elements(variable, raw):
    fmt = STRUCT_FORMAT[variable.element]
    return list(struct.unpack(f"<{len(raw) // variable.element_bytes}{fmt}", raw))
