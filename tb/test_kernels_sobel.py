# amaranth: UnusedElaboratable=no
"""SobelByteLanes in amaranth.sim against the spec's golden model (docs/reconos.md) on a
real photograph and on random images, under random idle and backpressure."""

import random
from pathlib import Path

import cv2
import pytest

from hdl.kernels import SobelByteLanes
from hdl.params import ParameterError

from .models.sobel import sobel_byte_lanes
from .streamsim import StreamSink, StreamSource, beats_to_messages, simulate

IMAGES = Path(__file__).resolve().parent.parent / "examples" / "images"


def words_of(payload):
    return [int.from_bytes(payload[i:i + 4], "little") for i in range(0, len(payload), 4)]


def run_frames(frames, max_words, *, idle=0.3, backpressure=0.3, seed=0):
    """``frames``: (payload, height, words); return the output payloads."""
    dut = SobelByteLanes(max_words)
    sink = StreamSink(dut.o, backpressure=backpressure, seed=seed + 1)

    async def control(ctx):
        for k, (payload, height, words) in enumerate(frames):
            ctx.set(dut.words, words)
            ctx.set(dut.height, height)
            beats = [(w, 0) for w in words_of(payload)]
            await StreamSource(dut.i, beats, idle=idle, seed=seed + k).run(ctx)
            await ctx.tick().until(~dut.busy)
        while len(beats_to_messages(sink.beats)[0]) < len(frames):
            await ctx.tick()

    simulate(dut, control, background=[sink.run])
    out, rest = beats_to_messages(sink.beats)
    assert not rest, "a frame ended without tlast"
    return [b"".join(w.to_bytes(4, "little") for w in frame) for frame in out]


def test_photograph_and_random_frames():
    img = cv2.imread(str(IMAGES / "coffee_80x60.png"), cv2.IMREAD_COLOR)
    photo = (img.tobytes(), img.shape[0], img.shape[1] * 3 // 4)
    rng = random.Random(5)
    frames = [photo]
    for height, words in ((3, 3), (7, 5), (4, 16)):
        frames.append((bytes(rng.randrange(256) for _ in range(4 * height * words)), height, words))
    out = run_frames(frames, max_words=64)
    for got, (payload, height, words) in zip(out, frames):
        want, _ = sobel_byte_lanes(payload, height, words)
        assert got == want, f"{height}x{words} words differ"


def test_bad_parameters_name_the_value():
    with pytest.raises(ParameterError, match="max_words must be an integer in 3..8192, not 2"):
        SobelByteLanes(2)
