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


@pytest.mark.parametrize("p", [1, 4])
def test_store_keeps_only_the_window_the_map_reads(p):
    """A map that magnifies a part of the source in both directions: the store keeps a
    window of the frame (smaller both ways), and every pixel still equals OpenCV's, the
    window's edges included."""
    import cv2
    rng = np.random.default_rng(20 + p)
    src = np.float32([[13.3, 7.6], [33.8, 9.1], [31.2, 21.7], [11.4, 19.9]])
    dst = np.float32([[0, 0], [DW - 1, 0], [DW - 1, DH - 1], [0, DH - 1]])
    matrix = cv2.getPerspectiveTransform(src, dst)
    x0, y0, kw, kh = PerspectiveWarp(cv2.invert(matrix)[1], src_width=SW, src_height=SH,
                                     dst_width=DW, dst_height=DH,
                                     pixels_per_beat=p).stored_window
    assert 0 < x0 and x0 + kw < SW and 0 < y0 and y0 + kh < SH
    frames = [rng.integers(0, 256, (SH, SW, 3), dtype=np.uint8)]
    outs, errors = warp_frames(matrix, frames, p=p, seed=p)
    assert errors == {"short": 0, "long": 0}
    check(outs[0], frames[0], matrix)


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
    """``floor(2**16 n / w)`` and whether it lies outside ``[-2**quotient_bits,
    2**quotient_bits)``."""
    q = (n << COORD_FRACTION_BITS) // w
    return q, not -(1 << quotient_bits) <= q < 1 << quotient_bits


@pytest.mark.parametrize("width, denominator_range, quotient_bits, per_stage", [
    (40, (1, (1 << 24) - 1), QUOTIENT_BITS, 1),   # a wide range, scaled up (w < 2**T)
    (76, (15 << 60, 77 << 60), 26, 1),            # the chain's: scaled down by 2**34
    (76, (15 << 60, 77 << 60), 26, 2),
    (48, (1 << 29, 1 << 29), 21, 1),              # one denominator, a power of two
    (36, (3, 5000), 17, 3)])
def test_coordinate_divider_shares_its_denominator(width, denominator_range, quotient_bits,
                                                   per_stage):
    """Pairs of numerators over one denominator, a new set every cycle: each quotient within
    1 of exact integer division (floor, negative numerators included), ``outside`` where the
    exact quotient does not fit (within 1 of the limit, either answer), each ``latency``
    cycles after its inputs (one to three reciprocal bits per stage); numerators far beyond
    the limit, the range's ends, exact quotients."""
    lo, hi = denominator_range
    dut = CoordinateDivider(width, 2, denominator_range=denominator_range,
                            quotient_bits=quotient_bits, bits_per_stage=per_stage)
    limit = 1 << (quotient_bits - COORD_FRACTION_BITS)
    top = (1 << (width - 1)) - 1
    rng = np.random.default_rng(11 + quotient_bits)

    def numerator(x, w):
        return min(max(int(round(x * w)), -top - 1), top)

    cases = []
    for _ in range(100):
        w = lo + int(rng.random() * (hi - lo + 1))
        cases.append(([numerator(rng.uniform(-1.2, 1.2) * limit, w) for _ in range(2)], w))
    for _ in range(40):
        # quotients around the outside limit, both signs
        w = lo + int(rng.random() * (hi - lo + 1))
        x = limit + rng.uniform(-2, 2) / (1 << COORD_FRACTION_BITS)
        cases.append(([numerator(x, w), numerator(-x, w)], w))
    for _ in range(20):
        # anything the numerator's width holds
        w = lo + int(rng.random() * (hi - lo + 1))
        cases.append(([int(rng.integers(-(1 << 62), 1 << 62)) >> max(0, 63 - width)
                       for _ in range(2)], w))
    cases += [([numerator(5, w), numerator(-5, w)], w) for w in (lo, hi)]   # exact quotients
    cases += [([top, -top - 1], w) for w in (lo, hi)]                          # widest
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
        cycle = 0
        async for _, _, valid, q0, q1, o0, o1 in ctx.tick().sample(
                dut.q_valid, dut.q[0], dut.q[1], dut.outside[0], dut.outside[1]):
            if valid:
                got.append((cycle, (q0, o0), (q1, o1)))
            cycle += 1

    simulate(dut, drive, background=[watch])
    assert len(got) == len(cases)
    assert [cycle for cycle, _, _ in got] == list(range(dut.latency, dut.latency + len(cases)))
    edge = 1 << quotient_bits
    for (ns, w), (_, *answer) in zip(cases, got):
        for n, (q, outside) in zip(ns, answer):
            want, want_outside = divide_model(n, w, quotient_bits)
            if bool(outside) != want_outside:
                assert min(abs(want - edge), abs(want + 1 - edge), abs(want + edge),
                           abs(want + 1 + edge)) <= 1, (n, w, want, q, outside)
            elif not want_outside:
                assert abs(q - want) <= 1, (n, w, q, want)


@pytest.mark.parametrize("width, count, extra, name", [
    (1, 2, {}, "width"), (40, 0, {}, "count"), (40, "2", {}, "count"),
    (40, 2, {"denominator_range": (0, 5)}, "denominator_range"),
    (40, 2, {"denominator_range": (9, 5)}, "denominator_range"),
    (40, 2, {"denominator_range": "wide"}, "denominator_range"),
    (40, 2, {"precision": QUOTIENT_BITS + 2}, "precision"),
    (40, 2, {"bits_per_stage": 0}, "bits_per_stage"),
    (40, 2, {"bits_per_stage": 5}, "bits_per_stage"),
    (40, 2, {"quotient_bits": COORD_FRACTION_BITS}, "quotient_bits")])
def test_coordinate_divider_refuses_bad_parameters(width, count, extra, name):
    with pytest.raises(ParameterError, match=name):
        CoordinateDivider(width, count, **{"denominator_range": (1, 100), **extra})
