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


def _float_round(value, sticky, bits=24):
    """IEEE round to nearest, ties to even, of ``value`` (+ a non-zero remainder below it when
    ``sticky``) to ``bits`` significant bits (24: float32, 53: float64), as
    ``mantissa * 2**shift``."""
    shift = max(value.bit_length() - bits, 0)
    kept, rest = value >> shift, value & ((1 << shift) - 1)
    half = 1 << (shift - 1) if shift else 0
    up = shift and (rest > half or (rest == half and (sticky or kept & 1)))
    kept += bool(up)
    if kept >> bits:
        kept, shift = kept >> 1, shift + 1
    return kept, shift


#: (value width, significant bits) as the kernels use the rounding: EqualizeHist's scale and
#: ImageCompensation's alpha (a 72-bit quotient to float64) and its table sum
ROUNDINGS = [(57, 24), (72, 53), (48, 24)]


@pytest.mark.parametrize("registered", [False, True])
@pytest.mark.parametrize("width,bits", ROUNDINGS)
def test_round_to_float32(registered, width, bits):
    """The rounding behind the exact table, unregistered and split by registers, against
    numpy's float32 conversion or Python's float64 one (no sticky bit) and the IEEE rule
    (with one); ties, carries into a new power of two and short values included."""
    from amaranth.hdl import Module, Signal

    from hdl.kernels.equalize import ROUND_STAGES, round_to_float32

    m = Module()
    value, sticky = Signal(width), Signal()
    toggle = Signal()           # a sync domain for the simulator's clock either way
    m.d.sync += toggle.eq(~toggle)

    def reg(v, name):
        r = Signal.like(v, name=name) if isinstance(v, Signal) else Signal(v.shape(), name=name)
        m.d.sync += r.eq(v)
        return r

    mant, shift = round_to_float32(m, value, sticky, "t", stage=reg if registered else
                                   (lambda v, name: v), bits=bits)
    rng = np.random.default_rng(5)
    top = 1 << bits
    cases = [(0, 0), (1, 0), (top - 1, 0), (top, 0), (top + 1, 0), (2 * top - 1, 0),
             (2 * top + 2, 0), (2 * top + 6, 0), (2 * top + 2, 1), ((1 << width) - 1, 0)]
    cases = [(v & ((1 << width) - 1), st) for v, st in cases]
    for _ in range(300):
        v = int.from_bytes(rng.bytes(16), "little") >> (128 - int(rng.integers(1, width + 1)))
        if rng.random() < 0.3 and v.bit_length() > bits + 1:   # an exact tie
            s = v.bit_length() - bits
            v = (v >> s << s) | (1 << (s - 1))
        cases.append((v, int(rng.integers(0, 2))))
    got = []

    async def bench(ctx):
        for v, st in cases:
            ctx.set(value, v)
            ctx.set(sticky, st)
            for _ in range(ROUND_STAGES if registered else 0):
                await ctx.tick()
            await ctx.delay(1e-9)
            got.append((ctx.get(mant), ctx.get(shift)))

    simulate(m, bench)
    for (v, st), (gm, gs) in zip(cases, got):
        assert (gm, gs) == _float_round(v, st, bits), (v, st, gm, gs)
        if st:
            continue
        if bits == 24 and v < 1 << 53:      # numpy converts through float64 above
            assert gm << gs == int(np.float32(v)), (v, gm, gs)
        if bits == 53:
            assert gm << gs == int(float(v)), (v, gm, gs)
