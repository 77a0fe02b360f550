"""Bench of the image kernels (hdl/kernels: Sobel, GaussianBlur, BgrToGray, BgrToHsv, InRange,
TrafficLightDetector; docs/kernels.md, docs/reconos.md) in one ``kernels`` top.

Every kernel gets real photographs (examples/images; at half size in make test, whole in
make test-full), random frames of random sizes and of the
corner sizes it accepts (narrowest, widest, fewest and most rows) under random idle at its
input and random backpressure at its output, and each output frame is
compared byte for byte with OpenCV (tb/models/image.py); ``tuser`` must mark exactly the first
beat and ``tlast`` exactly the last. Bad frames (early and late ``tlast``, a size the kernel
cannot take) must raise their error pulse once, give a well-formed (padded, cut or no) output
frame, and leave the next frame correct. At full rate the frame time must meet the spec's
budget: ``(H + R) (W/P + ceil(R/P))`` cycles for a k x k window (R = k // 2), ``W H / P`` for a
per-pixel kernel, plus 5 cycles between frames (4 before the window kernels registered their
line buffer's output for 100 MHz) and the pipeline latency.
"""

import cocotb
import numpy as np

from hdl.kernels.colour import TRAFFIC_DETECTION
from hdl.kernels import compensation
from hdl.kernels.equalize import ROUND_STAGES, TABLE_STAGES
from tb.harness import cocotb_bench

from .kernels_image_tb import KernelsTB, _k, photo, traffic_scene

#: the kernels of the ``image`` configuration: every kind, every border, P in {1, 2, 4, 8}
KERNELS = {
    "sobel_p1": _k("sobel", pixels_per_beat=1),
    "sobel_p4_const": _k("sobel", pixels_per_beat=4, border="constant"),
    "sobel_rr": _k("sobel", mode="reconros", channels=4, pixels_per_beat=1),
    "gauss3_p2": _k("gaussian", ksize=3, pixels_per_beat=2),
    "gauss5_p8_repl": _k("gaussian", ksize=5, pixels_per_beat=8, border="replicate"),
    "gauss5_mono": _k("gaussian", ksize=5, channels=1, pixels_per_beat=1),
    "gray_p2": _k("gray", pixels_per_beat=2),
    "hsv_p1": _k("hsv", pixels_per_beat=1),
    "inrange_p4": _k("inrange", pixels_per_beat=4),
    "traffic": _k("traffic_light", pixels_per_beat=2),
    "equalize_p1": _k("equalize", pixels_per_beat=1),
    "equalize_p4": _k("equalize", pixels_per_beat=4),
    "compensation_p2": _k("compensation", pixels_per_beat=2, clip_percent=1.5),
}

CONFIGS = {"image": dict(kernels=KERNELS)}

# Verilator runs it in make test-full only (its build and run would add minutes to make test)
test_kernels = cocotb_bench("kernels", CONFIGS, long=[("image", "verilator")])


@cocotb.test()
async def photos_and_random_frames_idle_backpressure(dut):
    """A photograph and two random frames per kernel (and a red and a green traffic scene
    for the detector), sizes changing from frame to frame, 30 % idle and 30 % backpressure:
    every frame equals OpenCV. (The full-rate test adds a second photograph, make bench the
    640x480 one.)"""
    tb = KernelsTB(dut)
    await tb.reset()
    tb.set_pauses(0.3, 0.3)
    photos = [photo("chelsea_96x72.png")]
    rng = np.random.default_rng(tb.rng.randrange(1 << 30))
    frames = {}
    for name, k in tb.kernels.items():
        items = [(p, {}) for p in photos]
        if k.kind == "traffic_light":
            items.append((traffic_scene(rng, 48, 32, (40, 40, 230)), {}))
            items.append((traffic_scene(rng, 64, 40, (60, 220, 40)), {}))
        items += [(tb.random_image(k), {}) for _ in range(2)]
        frames[name] = items
    await tb.run_frames(frames, timeout_cycles=200_000)
    for k in tb.kernels.values():
        assert k.errors == {"short": 0, "long": 0, "size": 0}, (k.name, k.errors)
    det = tb.kernels["traffic"]
    beats = [TRAFFIC_DETECTION.from_bits(int.from_bytes(p.data, "little"))
             for p in det.sink.packets]
    flags = [(b.red, b.green) for b in beats]
    assert flags[1] == (1, 0) and flags[2] == (0, 1), f"traffic scenes detected as {flags[1:3]}"


@cocotb.test()
async def bad_frames_are_flagged_and_resynchronised(dut):
    """Per kernel: a frame with ``tlast`` half-way (padded with zeros), one with an extra
    row (cut), one with a height above the maximum (dropped), each followed by a good frame;
    each error pulses once and every output frame is well-formed and correct."""
    tb = KernelsTB(dut)
    await tb.reset()
    tb.set_pauses(0.2, 0.2)
    frames = {}
    for name, k in tb.kernels.items():
        # two rows at least: a one-row frame of one beat has no shorter frame (AXI-Stream
        # has no empty packet), and the cut below would send nothing at all
        image = tb.random_image(k, min_height=2)
        pixels = k.frame_image(image)
        data = pixels.tobytes()
        row = pixels.shape[1] * k.channels
        # half the frame's beats, less half a beat of pixels: the kernel's stream has no
        # tkeep, so a cut inside the frame's last beat would not be short at all
        beat = k.p * k.channels
        short = data[:len(data) // beat // 2 * beat - k.p // 2 * k.channels]
        assert 0 < len(short) <= len(data) - beat, (name, pixels.shape, len(short))
        long_ = data + bytes(reversed(data[:row]))
        frames[name] = [(image, {"data": short}), (tb.random_image(k), {}),
                        (image, {"data": long_}), (tb.random_image(k), {}),
                        (image, {"height": k.max_height + 1, "data": data}), (image, {})]
    await tb.run_frames(frames, timeout_cycles=100_000)
    for k in tb.kernels.values():
        assert k.errors == {"short": 1, "long": 1, "size": 1}, (k.name, k.errors)


@cocotb.test()
async def smallest_and_largest_sizes(dut):
    """Per kernel, random pixels at the corners of the sizes it accepts: the narrowest width
    with the fewest rows (one beat for a per-pixel kernel) and with the most rows, the widest
    with the fewest, under 20 % idle and 20 % backpressure: every frame equals OpenCV and no
    error pulses."""
    tb = KernelsTB(dut)
    await tb.reset()
    tb.set_pauses(0.2, 0.2)
    frames = {}
    for name, k in tb.kernels.items():
        lo, hi, _ = k.image_widths()
        fewest = k.min_height
        sizes = [(lo, fewest), (lo, k.max_height), (hi, fewest), (lo, fewest)]
        frames[name] = [(tb.random_image(k, width=w, height=h), {}) for w, h in sizes]
    await tb.run_frames(frames, timeout_cycles=100_000)
    for k in tb.kernels.values():
        assert k.errors == {"short": 0, "long": 0, "size": 0}, (k.name, k.errors)


@cocotb.test()
async def full_rate_frame_time(dut):
    """No idle, no backpressure, two photographs back to back (80x60 in make test-full, 40x30 in
    make test): the frame time meets the budget of the spec (see the module docstring)."""
    tb = KernelsTB(dut)
    await tb.reset()
    tb.set_pauses(0, 0)
    image = photo("coffee_80x60.png")
    start = tb.cycle
    await tb.run_frames({n: [(image, {}), (image, {})] for n in tb.kernels},
                        timeout_cycles=50_000)
    for k in tb.kernels.values():
        pixels = k.frame_image(image)
        h, w = pixels.shape[:2]
        r = k.radius
        budget = (h + r) * (w // k.p + -(-r // k.p)) if r else w * h // k.p
        latency = 16
        if k.kind == "equalize":
            # one frame of latency; the table: 256 bins and a 57-step division per frame, and
            # the table pipeline's stages
            latency += budget
            budget += 256 + 64 + TABLE_STAGES + ROUND_STAGES
        if k.kind == "compensation":
            # one frame of latency; per frame 256 bins, a 72-step division, the constants'
            # and the table's pipelines and 256 entries
            latency += budget
            budget += 256 + 72 + 256 + compensation.CONSTANT_STAGES + \
                compensation.TABLE_STAGES + 7
        ends = [p.cycles[-1] - start for p in k.sink.packets]
        tb.log.info("%s: frame ends at cycles %s (budget %d per frame)", k.name, ends, budget)
        assert ends[1] - ends[0] <= budget + 5, (k.name, ends, budget)
        assert ends[0] <= budget + latency, (k.name, ends, budget)
