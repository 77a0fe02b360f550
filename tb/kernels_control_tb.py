"""The test bench of the control kernels' ``kernels`` top (merge sort, PID, inverse kinematics):
port models, the word formats of their inputs and the runs the tests share."""

import random

import cocotb
from cocotb.triggers import RisingEdge
from cocotbext.axi import AxiStreamFrame

from hdl.kernels.pid import PID_INPUT
from host.simulator import start_clock
from tb.harness import bench_params
from tb.streams import StreamPort, count_pulses, reset_aresetn

__all__ = ["CLOCK_NS", "ControlTB", "pid_word", "int16", "run_sort", "run_pid", "run_ik"]


CLOCK_NS = 10


class ControlTB:
    def __init__(self, dut, seed=None):
        self.dut = dut
        self.params = bench_params()
        self.rng = random.Random(seed if seed is not None else cocotb.RANDOM_SEED)
        start_clock(dut.aclk, CLOCK_NS)
        self.ports = {name: StreamPort(dut, name, random.Random(self.rng.random()))
                      for name, spec in self.params["kernels"].items()
                      if spec["kind"] != "servo_pwm"}     # PWM pins, no output stream
        self.cycle = 0
        cocotb.start_soon(self._count_cycles())
        self.errors = {"leg": 0, "short": 0, "long": 0}
        dut.sort_length.value = 0
        dut.pid_load.value = 0
        dut.pid_reset_integrator.value = 0
        for key, sig in (("leg", dut.ik_err_leg), ("short", dut.sort_err_short),
                         ("long", dut.sort_err_long)):
            cocotb.start_soon(count_pulses(sig, self.errors, key))

    async def _count_cycles(self):
        while True:
            await RisingEdge(self.dut.aclk)
            self.cycle += 1

    @property
    def err_leg(self):
        return self.errors["leg"]

    @property
    def sort_errors(self):
        return {"short": self.errors["short"], "long": self.errors["long"]}

    async def reset(self):
        await reset_aresetn(self.dut)

    def set_pauses(self, idle, backpressure):
        for port in self.ports.values():
            port.set_pauses(idle, backpressure)

    async def wait_words(self, name, count, timeout_cycles):
        sink = self.ports[name].sink
        for _ in range(timeout_cycles):
            if sum(len(p.beats) for p in sink.packets) >= count:
                return
            await RisingEdge(self.dut.aclk)
        raise AssertionError(f"{name}: {sum(len(p.beats) for p in sink.packets)} of {count} "
                             f"output words after {timeout_cycles} cycles")

    async def load_pid(self, p, i, d):
        dut = self.dut
        dut.pid_p_gain.value, dut.pid_i_gain.value, dut.pid_d_gain.value = p, i, d
        dut.pid_load.value = 1
        await RisingEdge(dut.aclk)
        dut.pid_load.value = 0
        for _ in range(64):
            await RisingEdge(dut.aclk)
            if dut.pid_ready.value == 1:
                return
        raise AssertionError("pid_ready did not return within 64 cycles of load")


def pid_word(sp, pv):
    return PID_INPUT.const({"set_point": sp, "measurement": pv}).as_value().value


def int16(v):
    return (v ^ 0x8000) - 0x8000


async def run_sort(tb, blocks, lengths=None):
    """Sort each block (``sort_length`` set per block); check against ``sorted``."""
    port = tb.ports["sort"]
    expected = []
    for n, block in enumerate(blocks):
        length = (lengths or [0] * len(blocks))[n]
        await port.source.wait()
        while tb.dut.sort_busy.value == 1 and length:
            await RisingEdge(tb.dut.aclk)
        tb.dut.sort_length.value = length
        data = b"".join(v.to_bytes(4, "little") for v in block)
        await port.source.send(AxiStreamFrame(data))
        want = length or 2048
        got = sorted(block[:want]) + [0xFFFFFFFF] * (want - len(block))
        expected.append(got)
    await port.source.wait()
    for _ in range(30_000 * len(blocks)):
        if len(port.sink.packets) >= len(expected):
            break
        await RisingEdge(tb.dut.aclk)
    got = [[d for d, _, _ in p.beats] for p in port.sink.packets]
    assert got == expected, "sorter output differs from sorted()"


async def run_pid(tb, pairs):
    """Stream ``pairs`` through the PID; compare with the AVR221 model."""
    port = tb.ports["pid"]
    data = b"".join(pid_word(sp, pv).to_bytes(4, "little") for sp, pv in pairs)
    await port.source.send(AxiStreamFrame(data))
    await tb.wait_words("pid", len(pairs), 20 * len(pairs) + 200)


async def run_ik(tb, words):
    port = tb.ports["ik"]
    for w in words:
        await port.source.send(AxiStreamFrame(w.to_bytes(4, "little")))
    await port.source.wait()
