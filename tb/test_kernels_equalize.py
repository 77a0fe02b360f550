"""EqualizeHist in amaranth.sim against ``cv2.equalizeHist`` on many small frames with
awkward histograms (one grey level, two levels, narrow and skewed ranges, every size class):
the exact float32 look-up table (docs/kernels.md) must agree on every pixel."""

import cv2
import numpy as np
import pytest

from hdl.kernels import EqualizeHist

from .streamsim import StreamSink, StreamSource, simulate


def frames(rng):
    out = []
    for n in range(24):
        h, w = int(rng.integers(1, 13)), int(rng.integers(1, 9)) * 4
        kind = n % 6
        if kind == 0:
            img = rng.integers(0, 256, (h, w))
        elif kind == 1:
            img = np.full((h, w), rng.integers(0, 256))
        elif kind == 2:
            img = rng.choice(rng.integers(0, 256, 2), (h, w))
        elif kind == 3:
            lo = int(rng.integers(0, 250))
            img = rng.integers(lo, lo + 6, (h, w))
        elif kind == 4:
            img = np.minimum(rng.exponential(12, (h, w)), 255)
        else:
            img = 255 - np.minimum(rng.exponential(3, (h, w)), 255)
        out.append(img.astype(np.uint8))
    return out


@pytest.mark.parametrize("pixels_per_beat", [1, 4])
def test_equalize_matches_opencv(pixels_per_beat):
    rng = np.random.default_rng(pixels_per_beat)
    images = frames(rng)
    P = pixels_per_beat
    dut = EqualizeHist(pixels_per_beat=P, max_width=32, max_height=12)
    sink = StreamSink(dut.o, backpressure=0.2, seed=2)
    total = sum(img.size // P for img in images)

    def beats(img):
        flat = img.reshape(-1)
        return [(int.from_bytes(flat[i:i + P].tobytes(), "little"), i + P == flat.size)
                for i in range(0, flat.size, P)]

    async def control(ctx):
        for img in images:
            ctx.set(dut.width, img.shape[1])
            ctx.set(dut.height, img.shape[0])
            await StreamSource(dut.i, beats(img), idle=0.2, seed=img.size).run(ctx)
        while len(sink.beats) < total:
            await ctx.tick()

    simulate(dut, control, background=[sink.run])
    pos = 0
    for n, img in enumerate(images):
        count = img.size // P
        got = b"".join(d.to_bytes(P, "little") for d, _ in sink.beats[pos:pos + count])
        lasts = [last for _, last in sink.beats[pos:pos + count]]
        pos += count
        want = cv2.equalizeHist(img).tobytes()
        assert got == want, f"frame {n} ({img.shape}): {np.frombuffer(got, np.uint8)} != " \
                            f"{np.frombuffer(want, np.uint8)}"
        assert lasts == [False] * (count - 1) + [True]
