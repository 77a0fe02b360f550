"""The test bench of the MNIST CNN kernel's ``kernels`` top: images in, results out, and the
held-out digits of gen.mnist."""

import random

import cocotb
from cocotb.triggers import RisingEdge
from cocotbext.axi import AxiStreamFrame

from gen import mnist
from hdl.kernels.mnist import MNIST_RESULT
from host.simulator import start_clock
from tb.harness import bench_params
from tb.streams import StreamPort, count_pulses, reset_aresetn

__all__ = ["CLOCK_NS", "TARGET_ACCURACY", "LATENCY_BUDGET", "MnistTB", "held_out", "check"]


CLOCK_NS = 10


TARGET_ACCURACY = 0.98


#: cycles from a digit's first beat to its result, by pixels per beat
LATENCY_BUDGET = {4: 500, 1: 1100}


class MnistTB:
    def __init__(self, dut):
        self.dut = dut
        self.params = bench_params()
        self.rng = random.Random(cocotb.RANDOM_SEED)
        start_clock(dut.aclk, CLOCK_NS)
        self.port = StreamPort(dut, "cnn", self.rng)
        self.pixels_per_beat = self.params["kernels"]["cnn"]["pixels_per_beat"]
        self.source, self.sink = self.port.source, self.port.sink
        self.errors = {"short": 0, "long": 0}
        for e in self.errors:
            cocotb.start_soon(count_pulses(getattr(dut, f"cnn_err_{e}"), self.errors, e))

    async def reset(self):
        await reset_aresetn(self.dut)

    def set_pauses(self, idle, backpressure):
        self.port.set_pauses(idle, backpressure)

    async def classify(self, images, timeout_cycles=2000):
        """Send the images, wait for their results; return ``[(digit, scores)]`` and the
        cycles from each image's first beat to its result."""
        results, latencies = [], []
        for image in images:
            before = len(self.sink.packets)
            await self.source.send(AxiStreamFrame(image.tobytes()))
            start = self.sink.cycle
            for _ in range(timeout_cycles):
                if len(self.sink.packets) > before:
                    break
                await RisingEdge(self.dut.aclk)
            else:
                raise AssertionError(f"no result within {timeout_cycles} cycles")
            packet = self.sink.packets[-1]
            result = MNIST_RESULT.from_bits(int.from_bytes(packet.data, "little"))
            results.append((result.digit, [result.scores[k] for k in range(10)]))
            latencies.append(packet.cycles[-1] - start)
        return results, latencies


def held_out():
    images, labels = mnist.load_mnist()
    _, _, test_x, test_y = mnist.split(images, labels)
    return test_x, test_y


def check(results, images):
    digits, scores = mnist.infer_batch(images)
    for n, ((digit, got), want_d, want) in enumerate(zip(results, digits, scores)):
        assert got == [int(v) for v in want] and digit == want_d, \
            f"image {n}: hardware {digit} {got}, model {want_d} {list(want)}"
