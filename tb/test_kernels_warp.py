# amaranth: UnusedElaboratable=no
"""PerspectiveWarp in amaranth.sim against ``cv2.warpPerspective`` (bilinear, border constant
0): a photograph and random frames through bird's-eye maps like the AutoRace projection's,
under random idle and backpressure, at 1 and 4 pixels per beat. OpenCV computes the source
positions and the interpolation in float32; the kernel computes them exactly (to 2**-16
pixel), so a pixel may differ by 1 where the interpolated value lies within float32's error
of a half; never by more (docs/kernels.md). Bad frames (short, long) are flagged and the
next frame is right; a map to infinity is refused."""


import numpy as np
import pytest

from hdl.kernels.warp import (COORD_FRACTION_BITS, QUOTIENT_BITS, CoordinateDivider,
                             PerspectiveWarp)
from hdl.params import ParameterError
from tb.models import image as golden

from .streamsim import StreamSink, StreamSource, simulate

SW, SH, DW, DH = 48, 32, 40, 24


def bird_view_map(rng):
    """A homography (camera -> bird's-eye) of a random trapezoid of the source."""
    import cv2
    top, bottom = rng.uniform(8, 14), rng.uniform(20, 23)
    y0, y1 = rng.uniform(6, 12), rng.uniform(26, 31)
    src = np.float32([[24 - top, y0], [24 + top, y0], [24 + bottom, y1], [24 - bottom, y1]])
    dst = np.float32([[8, 0], [32, 0], [32, 24], [8, 24]])
    return cv2.getPerspectiveTransform(src, dst)


def warp_frames(matrix, frames, *, p=1, idle=0.3, backpressure=0.3, seed=0, sizes=None):
    """Frames (``H x W x 3`` uint8, or raw bytes with ``sizes``) through the kernel; returns
    the output frames and the error pulses."""
    import cv2
    dut = PerspectiveWarp(cv2.invert(matrix)[1], src_width=SW, src_height=SH, dst_width=DW,
                          dst_height=DH, pixels_per_beat=p)
    beats = []
    for frame in frames:
        data = frame if isinstance(frame, bytes) else frame.tobytes()
        chunks = [data[i:i + 3 * p] for i in range(0, len(data), 3 * p)]
        beats += [(int.from_bytes(c, "little"), int(k == len(chunks) - 1))
                  for k, c in enumerate(chunks)]
    source = StreamSource(dut.i, beats, idle=idle, seed=seed)
    sink = StreamSink(dut.o, backpressure=backpressure, seed=seed + 1)
    errors = {"short": 0, "long": 0}
    expected = len(frames)

    async def control(ctx):
        await source.run(ctx)
        while sum(last for _, last in sink.beats) < expected:
            await ctx.tick()

    async def watch(ctx):
        async for _, _, short, long_ in ctx.tick().sample(dut.err_short, dut.err_long):
            errors["short"] += short
            errors["long"] += long_

    simulate(dut, control, background=[sink.run, watch])
    data = b"".join(d.to_bytes(3 * p, "little") for d, _ in sink.beats)
    n = DW * DH * 3
    return [np.frombuffer(data[i:i + n], np.uint8).reshape(DH, DW, 3)
            for i in range(0, len(data), n)], errors


def check(out, frame, matrix):
    import cv2
    expected = cv2.warpPerspective(frame, matrix, (DW, DH), flags=cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    diff = np.abs(out.astype(int) - expected.astype(int))
    assert diff.max() <= 1, f"differs by {diff.max()} at {np.argwhere(diff > 1)[:3].tolist()}"
    return int((diff.max(axis=2) > 0).sum())


@pytest.mark.parametrize("p", [1, 4])
def test_photo_and_random_frames(p):
    rng = np.random.default_rng(p)
    matrix = bird_view_map(rng)
    frames = [golden.load_image("chelsea_96x72.png")[:SH, :SW].copy(),
              rng.integers(0, 256, (SH, SW, 3), dtype=np.uint8),
              np.full((SH, SW, 3), 255, np.uint8)]
    outs, errors = warp_frames(matrix, frames, p=p, seed=p)
    assert errors == {"short": 0, "long": 0}
    off_by_one = [check(o, f, matrix) for o, f in zip(outs, frames)]
    assert len(outs) == 3
    # a uniform frame has nothing to round: exact
    assert off_by_one[2] == 0


def test_bad_frames_flagged_then_resynchronised():
    rng = np.random.default_rng(7)
    matrix = bird_view_map(rng)
    good = rng.integers(0, 256, (SH, SW, 3), dtype=np.uint8)
    short = good.tobytes()[:3 * SW * 5]                    # tlast after 5 rows: zero-padded
    long_ = good.tobytes() + bytes(3 * SW)                 # a row too many: cut
    outs, errors = warp_frames(matrix, [short, long_, good], idle=0.2, backpressure=0.2)
    assert errors == {"short": 1, "long": 1}
    padded = np.frombuffer(short + bytes(3 * SW * SH - len(short)), np.uint8).reshape(SH, SW, 3)
    check(outs[0], padded, matrix)
    check(outs[1], good, matrix)
    check(outs[2], good, matrix)


def test_map_to_infinity_refused():
    import cv2
    matrix = bird_view_map(np.random.default_rng(3))
    inverse = cv2.invert(matrix)[1]
    inverse[2] = [0.0, -0.1, 1.0]          # the denominator reaches 0 within the destination
    with pytest.raises(ParameterError, match="infinity or behind the camera"):
        PerspectiveWarp(inverse, src_width=SW, src_height=SH, dst_width=DW, dst_height=DH)
    with pytest.raises(ParameterError, match="3 rows of 3"):
        PerspectiveWarp([[1, 0], [0, 1]], src_width=SW, src_height=SH, dst_width=DW,
                        dst_height=DH)


def divide_model(n, w, quotient_bits=QUOTIENT_BITS):
    """``floor(2**16 n / w)`` as the divider defines it, and whether its magnitude reaches
    ``2**quotient_bits`` (outside)."""
    mag = (abs(n) << COORD_FRACTION_BITS) // w
    exact = (abs(n) << COORD_FRACTION_BITS) % w == 0
    q = mag if n >= 0 else -mag - (0 if exact else 1)
    return q, mag >= 1 << quotient_bits


@pytest.mark.parametrize("width, denominator_width, quotient_bits",
                         [(40, None, QUOTIENT_BITS), (48, 30, 21), (36, 36, 17)])
def test_coordinate_divider_shares_its_denominator(width, denominator_width, quotient_bits):
    """Pairs of numerators over one denominator, a new set every cycle: both quotients equal
    exact integer division (floor, negative numerators included), ``outside`` where the
    quotient's magnitude does not fit, each ``latency`` cycles after its inputs; numerators
    wider than the denominator (the warp's) and fewer quotient bits included."""
    dut = CoordinateDivider(width, 2, denominator_width=denominator_width,
                            quotient_bits=quotient_bits)
    assert dut.latency == quotient_bits + 1
    wd = denominator_width or width
    limit = 1 << (quotient_bits - COORD_FRACTION_BITS)
    rng = np.random.default_rng(11 + quotient_bits)
    cases = []
    for _ in range(120):
        w = int(rng.integers(1, 1 << int(rng.integers(1, wd + 1))))
        ns = [int(rng.integers(-(1 << (width - 2)), 1 << (width - 2))) for _ in range(2)]
        cases.append((ns, w))
    for _ in range(60):
        # quotients around the outside limit, both signs
        w = int(rng.integers(1, 1 << wd))
        ns = [min(max(int(w * (limit + int(rng.integers(-2, 2))) + int(rng.integers(-w, w))),
                      -(1 << (width - 1))), (1 << (width - 1)) - 1) * s for s in (1, -1)]
        cases.append((ns, w))
    cases += [([w * 5, -w * 5], w) for w in (1, 3, 1 << 20) if w < 1 << wd]  # exact quotients
    cases += [([limit * ((1 << 18) - 1), -limit * (1 << 18)], 1 << 18)]      # at the limit
    cases += [([-(1 << (width - 1)), (1 << (width - 1)) - 1], (1 << wd) - 1)]  # widest
    got = []

    async def drive(ctx):
        for ns, w in cases:
            ctx.set(dut.n[0], ns[0])
            ctx.set(dut.n[1], ns[1])
            ctx.set(dut.w, w)
            ctx.set(dut.valid, 1)
            await ctx.tick()
        ctx.set(dut.valid, 0)
        await ctx.tick().repeat(dut.latency + 2)

    async def watch(ctx):
        async for _, _, valid, q0, q1, o0, o1 in ctx.tick().sample(
                dut.q_valid, dut.q[0], dut.q[1], dut.outside[0], dut.outside[1]):
            if valid:
                got.append(((q0, o0), (q1, o1)))

    simulate(dut, drive, background=[watch])
    assert len(got) == len(cases)
    for (ns, w), answer in zip(cases, got):
        for n, (q, outside) in zip(ns, answer):
            want, want_outside = divide_model(n, w, quotient_bits)
            assert bool(outside) == want_outside, (n, w)
            if not want_outside:
                assert q == want, (n, w, q, want)


@pytest.mark.parametrize("width, count, extra, name", [
    (1, 2, {}, "width"), (40, 0, {}, "count"), (40, "2", {}, "count"),
    (40, 2, {"denominator_width": 0}, "denominator_width"),
    (40, 2, {"quotient_bits": COORD_FRACTION_BITS}, "quotient_bits")])
def test_coordinate_divider_refuses_bad_parameters(width, count, extra, name):
    with pytest.raises(ParameterError, match=name):
        CoordinateDivider(width, count, **extra)
