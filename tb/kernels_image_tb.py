"""The test bench of the image kernels' ``kernels`` top: a port model per kernel, frames under
random idle and backpressure, each output frame compared with OpenCV."""

import logging
import random

import cocotb
import numpy as np
from cocotb.triggers import ClockCycles, RisingEdge, with_timeout
from cocotbext.axi import AxiStreamFrame

from hdl.kernels.colour import TRAFFIC_DETECTION
from host.simulator import start_clock
from tb.harness import amount, bench_params
from tb.models import image as golden
from tb.streams import StreamPort, count_pulses, reset_aresetn

__all__ = ["CLOCK_NS", "MAX_W", "MAX_H", "_k", "RED_RANGES", "GREEN_RANGE", "MIN_PIXELS",
           "bgr_bytes", "KernelPort", "KernelsTB", "photo", "traffic_scene"]


CLOCK_NS = 10


MAX_W, MAX_H = 96, 72


def _k(kind, **params):
    return dict(kind=kind, max_width=MAX_W, max_height=MAX_H, **params)


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
        if self.kind == "compensation":
            return golden.compensate(pixels, self.spec["clip_percent"])[0].tobytes()
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
        start_clock(dut.aclk, CLOCK_NS)
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


def photo(name):
    """A photograph of ``examples/images`` as ``bgr8``: whole in ``make test-full``, at half its
    width and height in ``make test`` (OpenCV's area resampling keeps it a photograph, with a
    quarter of the pixels to simulate)."""
    image = golden.load_image(name)
    divisor = amount(2, 1)
    if divisor == 1:
        return image
    import cv2
    height, width = image.shape[:2]
    return cv2.resize(image, (width // divisor, height // divisor),
                      interpolation=cv2.INTER_AREA)


def traffic_scene(rng, width, height, colour):
    """A dark street scene with a lit lamp (``colour`` bgr) and noise."""
    import cv2
    image = (rng.integers(0, 60, (height, width, 3))).astype(np.uint8)
    cv2.rectangle(image, (width // 3, 4), (2 * width // 3, height - 4), (30, 30, 30), -1)
    cv2.circle(image, (width // 2, height // 3), max(3, height // 8), colour, -1)
    return image
