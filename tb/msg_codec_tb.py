"""The test bench of the ``msg_codec`` top: serializer and deserializer ports, random messages
and their golden wire bytes."""

import logging
import os
import random

import cocotb
from cocotb.triggers import RisingEdge, with_timeout
from cocotbext.axi import AxiStreamBus, AxiStreamFrame, AxiStreamSink, AxiStreamSource

from gen.msg import MessageLibrary
from gen.tops import message_plan
from hdl.msg import payload_port
from host.simulator import start_clock
from tb.harness import bench_params
from tb.models.messages import golden_store, random_sequence, random_value, to_rosbags
from tb.models.msgstream import (
    expected_fields,
    fixed_part,
    leaf_values,
    reconros_beats,
    set_at,
    variable_bytes,
)
from tb.streams import (HandshakeSink, HandshakeSource, PacketSink, bursty_pauses,
                        random_pauses, reset_aresetn)

__all__ = ["CLOCK_NS", "TEST_MSGS", "IMAGE", "STREAMABLE", "ELEMENTS", "POINTS", "config",
           "PARAMS", "PUBLISHER", "MsgCodecTB"]


CLOCK_NS = 10


TEST_MSGS = "examples/messages/rosgate_test_msgs"


IMAGE = "sensor_msgs/msg/Image"


STREAMABLE = "rosgate_test_msgs/msg/Streamable"


#: sequences of messages and strings (packed element streams)
ELEMENTS = "rosgate_test_msgs/msg/Elements"


#: a sequence of fixed-size messages, which the ros1 serializer takes too
POINTS = "rosgate_test_msgs/msg/Points"


def config(type_, framing, width, msg_dir=TEST_MSGS, **extra):
    return dict(type=type_, framing=framing, data_width=width, msg_dirs=[msg_dir], **extra)


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
        start_clock(clock, CLOCK_NS)

        def source(prefix):
            port = AxiStreamSource(AxiStreamBus.from_prefix(dut, prefix), clock, dut.aresetn,
                                   reset_active_level=False)
            port.log.setLevel(logging.WARNING)
            return port

        self.ser_fields = HandshakeSource(dut, "ser_fields", clock)
        self.ser_payloads = [source(f"ser_{payload_port(v, 's')}") for v in self.plan.streams]
        self.ser_out = AxiStreamSink(AxiStreamBus.from_prefix(dut, "ser_m_axis"), clock,
                                     dut.aresetn, reset_active_level=False)
        self.ser_out.log.setLevel(logging.WARNING)
        self.des_in = source("des_s_axis")
        self.des_fields = HandshakeSink(dut, "des_fields", clock)
        self.des_payloads = [PacketSink(dut, f"des_{payload_port(v, 'm')}", clock)
                             for v in self.plan.streams]
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
        await reset_aresetn(self.dut)

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
        for v in self.plan.streams:
            if v.string or v.bound or v.elements or not big:
                continue
            n = self.rng.randint(big // 2, big)
            set_at(value, v.path, random_sequence(v.element, n, self.rng))
        return value

    def empty_fields(self, value):
        """``value`` with every variable-length field empty."""
        for v in self.plan.streams:
            set_at(value, v.path, "" if v.string else [])
        return value

    def packed(self, element, item):
        """One element of a sequence of messages or strings, packed: rosbags' ROS 1
        serialization of the element (docs/messages.md)."""
        if element == "string":
            raw = item.encode()
            return len(raw).to_bytes(4, "little") + raw
        message = to_rosbags(self.golden, self.library, element, item)
        return bytes(self.golden.serialize_ros1(message, element))

    def stream_bytes(self, value):
        """What every stream port carries for ``value`` (``plan.streams`` order)."""
        return variable_bytes(self.plan, value, self.packed)

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
        payloads = payload_override or self.stream_bytes(value)
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
        for v, packet, data in zip(self.plan.streams, packets, self.stream_bytes(value)):
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

    async def wait_quiet(self, cycles=64, timeout_cycles=100_000):
        """Wait until no deserializer output has been valid for ``cycles`` cycles in a row
        (a packet an error closes may wait behind backpressure)."""
        ports = [self.dut.des_fields_valid] + [
            getattr(self.dut, f"des_{payload_port(v, 'm')}_tvalid") for v in self.plan.streams]
        quiet = 0
        for _ in range(timeout_cycles):
            await RisingEdge(self.dut.aclk)
            quiet = 0 if any(p.value == 1 for p in ports) else quiet + 1
            if quiet >= cycles:
                return
        raise AssertionError(f"deserializer outputs still busy after {timeout_cycles} cycles")

    async def wait_for(self, condition, timeout_cycles):
        for _ in range(timeout_cycles):
            if condition():
                return
            await RisingEdge(self.dut.aclk)
        raise AssertionError(f"timeout after {timeout_cycles} cycles")
