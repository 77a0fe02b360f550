"""Bench of the image kernels (hdl/kernels: Sobel, GaussianBlur, BgrToGray, BgrToHsv, InRange,
TrafficLightDetector; spec kernels.md §1-§5, reconos.md §9.1) in one ``kernels`` top.

Every kernel gets real photographs (examples/images), random frames of random sizes and of the
corner sizes it accepts (narrowest, widest, fewest and most rows) under random idle at its
input and random backpressure at its output, and each output frame is
compared byte for byte with OpenCV (tb/models/image.py); ``tuser`` must mark exactly the first
beat and ``tlast`` exactly the last. Bad frames (early and late ``tlast``, a size the kernel
cannot take) must raise their error pulse once, give a well-formed (padded, cut or no) output
frame, and leave the next frame correct. At full rate the frame time must meet the spec's
budget: ``(H + R) (W/P + ceil(R/P))`` cycles for a k x k window (R = k // 2), ``W H / P`` for a
per-pixel kernel, plus 4 cycles between frames and the pipeline latency.
"""

import logging
import random

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, RisingEdge, with_timeout
from cocotbext.axi import AxiStreamFrame

from hdl.kernels.colour import TRAFFIC_DETECTION
from tb.harness import bench_params, cocotb_bench
from tb.models import image as golden
from tb.streams import StreamPort, count_pulses, reset_aresetn

CLOCK_NS = 10
MAX_W, MAX_H = 96, 72


def _k(kind, **params):
    return dict(kind=kind, max_width=MAX_W, max_height=MAX_H, **params)


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
}

CONFIGS = {"image": dict(kernels=KERNELS)}

# Verilator runs it in make test-full (make test stays under 10 minutes on 2 cores)
test_kernels = cocotb_bench("kernels", CONFIGS, long=[("image", "verilator")])

#: HSV bounds of the traffic-light test (red wraps around H = 0)
RED_RANGES = [((0, 100, 100), (10, 255, 255)), ((170, 100, 100), (179, 255, 255))]
GREEN_RANGE = ((45, 100, 100), (90, 255, 255))
MIN_PIXELS = 40


def bgr_bytes(values):
    """A little-endian integer of bytes (channel c of a bound in byte c)."""
    return int.from_bytes(bytes(values), "little")


class KernelPort:
    """One kernel of the group: its source, sink, error counters and golden model."""

    def __init__(self, tb, name, spec):
        self.tb, self.name, self.spec = tb, name, dict(spec)
        dut = tb.dut
        self.kind = spec["kind"]
        self.p = spec.get("pixels_per_beat", 1)
        self.max_width, self.max_height = spec["max_width"], spec["max_height"]
        self.port = StreamPort(dut, name, random.Random(tb.rng.random()),
                               out="det" if self.kind == "traffic_light" else "o")
        self.source, self.sink = self.port.source, self.port.sink
        self.width = getattr(dut, f"{name}_width")
        self.height = getattr(dut, f"{name}_height")
        self.errors = {"short": 0, "long": 0, "size": 0}
        self.err = {e: getattr(dut, f"{name}_err_{e}") for e in self.errors}
        self.expected = []          # expected output frames (bytes)
        self.first_in = []          # cycle of the first input beat of each frame
        if self.kind == "sobel" and spec.get("mode") == "reconros":
            self.channels = 4
        elif self.kind == "gaussian":
            self.channels = spec.get("channels", 3)
        elif self.kind == "equalize":
            self.channels = 1
        else:
            self.channels = 3
        if self.kind == "inrange":
            self.lower, self.upper = (40, 30, 20), (200, 180, 250)
            dut_lower, dut_upper = (getattr(dut, f"{name}_{b}") for b in ("lower", "upper"))
            dut_lower.value, dut_upper.value = bgr_bytes(self.lower), bgr_bytes(self.upper)
        if self.kind == "traffic_light":
            bounds = [v for r in RED_RANGES for v in r] + list(GREEN_RANGE)
            for port, value in zip(("red_lower0", "red_upper0", "red_lower1", "red_upper1",
                                    "green_lower", "green_upper"), bounds):
                getattr(dut, f"{name}_{port}").value = bgr_bytes(value)
            getattr(dut, f"{name}_min_pixels").value = MIN_PIXELS

    @property
    def radius(self):
        return {"sobel": 1, "gaussian": self.spec.get("ksize", 3) // 2}.get(self.kind, 0)

    @property
    def min_width(self):
        r = self.radius
        lead = -(-r // self.p)
        return max(2 * r + 1, (2 * lead + 1) * self.p) if r else self.p

    @property
    def min_height(self):
        return 2 * self.radius + 1

    def image_widths(self):
        """``(smallest, largest, step)``: the widths of bgr8 images the kernel accepts."""
        step = self.p * (4 if self.channels == 4 else 1)
        lo = -(-self.min_width // step) * step
        if self.channels == 4:
            lo = max(lo, -(-self.min_width * 4 // 3 // step) * step)
            hi = self.max_width * 4 // 3 // step * step
            hi = min(hi, self.max_width)
        else:
            hi = self.max_width // step * step
        return lo, hi, step

    def frame_image(self, image):
        """The image as this kernel's input pixels (``H x W x C``)."""
        if self.channels == 4:
            h, w = image.shape[:2]
            return np.ascontiguousarray(image).reshape(h, w * 3 // 4, 4)
        if self.channels == 1:
            return golden.gray(image)[:, :, None]
        return image

    def golden(self, pixels):
        """Expected output bytes of one well-formed frame of input ``pixels``."""
        if self.kind == "sobel":
            if self.spec.get("mode") == "reconros":
                return golden.sobel_reconros(pixels).tobytes()
            return golden.sobel(pixels, self.spec.get("border", "reflect101")).tobytes()
        if self.kind == "gaussian":
            out = golden.gaussian(pixels[:, :, 0] if self.channels == 1 else pixels,
                                  self.spec["ksize"], self.spec.get("border", "reflect101"))
            return out.tobytes()
        if self.kind == "gray":
            return golden.gray(pixels).tobytes()
        if self.kind == "equalize":
            return golden.equalize(pixels[:, :, 0]).tobytes()
        if self.kind == "hsv":
            return golden.hsv(pixels).tobytes()
        if self.kind == "inrange":
            return golden.in_range(pixels, self.lower, self.upper).tobytes()
        rc, red, gc, green = golden.traffic_lights(pixels, RED_RANGES, GREEN_RANGE, MIN_PIXELS)
        word = TRAFFIC_DETECTION.const({"red_pixels": rc, "red": red, "green_pixels": gc,
                                        "green": green}).as_value().value
        return word.to_bytes(8, "little")

    def frame_bytes(self, width, height):
        return width * height * self.channels

    async def send(self, pixels, *, width=None, height=None, data=None):
        """Send one frame (``data``: other bytes than the pixels, for bad frames) with the
        size registers set to ``width`` x ``height`` (default: the image's); record the
        expected output."""
        h, w = pixels.shape[:2]
        width, height = width or w, height or h
        await self.source.wait()
        self.width.value, self.height.value = width, height
        data = pixels.tobytes() if data is None else data
        size_ok = (width % self.p == 0 and self.min_width <= width <= self.max_width and
                   self.min_height <= height <= self.max_height)
        if size_ok:
            size = self.frame_bytes(width, height)
            frame = np.frombuffer(golden.guard_frame(data, size), np.uint8)
            self.expected.append(self.golden(frame.reshape(height, width, self.channels)))
        await self.source.send(AxiStreamFrame(data))
        await self.source.wait()
        return size_ok

    def check(self):
        """Compare the received frames with the expected ones, beat flags included."""
        got = self.sink.packets
        assert len(got) == len(self.expected), \
            f"{self.name}: {len(got)} output frames, expected {len(self.expected)}"
        for n, (packet, want) in enumerate(zip(got, self.expected)):
            if self.kind != "traffic_light":
                users = [u for _, _, u in packet.beats]
                assert users[0] == 1 and not any(users[1:]), \
                    f"{self.name} frame {n}: tuser on beats {[i for i, u in enumerate(users) if u]}"
            data = bytes(packet.data)
            if data != want:
                a, b = np.frombuffer(data, np.uint8), np.frombuffer(want, np.uint8)
                if len(a) != len(b):
                    raise AssertionError(f"{self.name} frame {n}: {len(a)} bytes, expected "
                                         f"{len(b)}")
                bad = np.flatnonzero(a != b)
                raise AssertionError(f"{self.name} frame {n}: {len(bad)} bytes differ from "
                                     f"OpenCV, first at byte {bad[0]}: {a[bad[0]]} != "
                                     f"{b[bad[0]]}")


class KernelsTB:
    def __init__(self, dut, seed=None):
        self.dut = dut
        self.params = bench_params()
        self.rng = random.Random(seed if seed is not None else cocotb.RANDOM_SEED)
        self.log = logging.getLogger("cocotb.tb")
        cocotb.start_soon(Clock(dut.aclk, CLOCK_NS, unit="ns").start())
        self.kernels = {name: KernelPort(self, name, spec)
                        for name, spec in self.params["kernels"].items()}
        self.cycle = 0
        cocotb.start_soon(self._count_cycles())
        for k in self.kernels.values():
            for e, sig in k.err.items():
                cocotb.start_soon(count_pulses(sig, k.errors, e))

    async def _count_cycles(self):
        while True:
            await RisingEdge(self.dut.aclk)
            self.cycle += 1

    def set_pauses(self, idle, backpressure):
        """Random idle at every kernel's input, backpressure at every output (0: none)."""
        for k in self.kernels.values():
            k.port.set_pauses(idle, backpressure)

    async def reset(self):
        await reset_aresetn(self.dut)

    def random_image(self, kernel, *, width=None, height=None, min_height=1):
        """Random bgr8 pixels of a random size the kernel accepts (as a bgr8 image), at least
        ``min_height`` rows."""
        lo, hi, step = kernel.image_widths()
        width = width or self.rng.randrange(lo, hi + 1, step)
        height = height or self.rng.randrange(max(kernel.min_height, min_height), 24)
        rng = np.random.default_rng(self.rng.randrange(1 << 30))
        return rng.integers(0, 256, (height, width, 3), dtype=np.uint8)

    async def run_frames(self, frames, *, timeout_cycles):
        """Send each kernel its frames (``name -> [(image, kwargs)]``), concurrently; wait for
        every expected output; check."""
        async def feed(k, items):
            for image, kwargs in items:
                await k.send(k.frame_image(image), **kwargs)

        tasks = [cocotb.start_soon(feed(self.kernels[n], items)) for n, items in frames.items()]
        for task in tasks:
            await with_timeout(task, timeout_cycles * CLOCK_NS, "ns")
        for _ in range(timeout_cycles):
            if all(len(k.sink.packets) >= len(k.expected) for k in self.kernels.values()):
                break
            await RisingEdge(self.dut.aclk)
        await ClockCycles(self.dut.aclk, 50)
        for k in self.kernels.values():
            k.check()


def traffic_scene(rng, width, height, colour):
    """A dark street scene with a lit lamp (``colour`` bgr) and noise."""
    import cv2
    image = (rng.integers(0, 60, (height, width, 3))).astype(np.uint8)
    cv2.rectangle(image, (width // 3, 4), (2 * width // 3, height - 4), (30, 30, 30), -1)
    cv2.circle(image, (width // 2, height // 3), max(3, height // 8), colour, -1)
    return image


@cocotb.test()
async def photos_and_random_frames_idle_backpressure(dut):
    """A photograph and two random frames per kernel (and a red and a green traffic scene
    for the detector), sizes changing from frame to frame, 30 % idle and 30 % backpressure:
    every frame equals OpenCV. (The full-rate test adds a second photograph, make bench the
    640x480 one.)"""
    tb = KernelsTB(dut)
    await tb.reset()
    tb.set_pauses(0.3, 0.3)
    photos = [golden.load_image("chelsea_96x72.png")]
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
        short = data[:len(data) // 2 // row * row + row // 2 // k.p * k.p]
        assert 0 < len(short) < len(data), (name, pixels.shape, len(short))
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
    """No idle, no backpressure, two 80x60 photographs back to back: the frame time meets
    the budget of the spec (see the module docstring)."""
    tb = KernelsTB(dut)
    await tb.reset()
    tb.set_pauses(0, 0)
    image = golden.load_image("coffee_80x60.png")
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
            # one frame of latency; the table: 256 bins and a 57-step division per frame
            latency += budget
            budget += 256 + 64
        ends = [p.cycles[-1] - start for p in k.sink.packets]
        tb.log.info("%s: frame ends at cycles %s (budget %d per frame)", k.name, ends, budget)
        assert ends[1] - ends[0] <= budget + 4, (k.name, ends, budget)
        assert ends[0] <= budget + latency, (k.name, ends, budget)
