# amaranth: UnusedElaboratable=no
"""LaneDetector and LaneControl in amaranth.sim against the software nodes of
host/autorace.py (written from docs/av_chain.md, with OpenCV's HSV and inRange): bird's-eye
frames with two stripes, one stripe, none, noise, at 1 and 4 pixels per beat, under random
idle and backpressure; the control's commands for a sequence of results with stop and start
events."""

import dataclasses

import numpy as np
import pytest

from hdl.kernels.lane import DRIVE_COMMAND, LANE_RESULT, LaneControl, LaneDetector
from hdl.params import ParameterError
from host import autorace

from .streamsim import StreamSink, StreamSource, simulate

W, H = 200, 120
PARAMS = autorace.LaneParams(band_top=80, lane_width=60, min_pixels=40)


def road(rng, left=None, right=None, stripe=4):
    """A bird's-eye frame: asphalt with noise, a yellow stripe at column ``left`` and a white
    one at ``right`` (each optional), slightly slanted."""
    image = np.clip(rng.normal(95, 12, (H, W, 3)), 0, 255).astype(np.uint8)
    for row in range(H):
        shift = (row - H) * 0.1
        for centre, colour in ((left, (40, 200, 230)), (right, (235, 235, 235))):
            if centre is not None:
                lo = int(round(centre + shift - stripe / 2))
                image[row, max(lo, 0):max(lo + stripe, 0)] = colour
    return image


def detector_results(frames, p, *, seed=0):
    dut = LaneDetector(width=W, height=H, band_top=PARAMS.band_top,
                       lane_width=PARAMS.lane_width, min_pixels=PARAMS.min_pixels,
                       yellow=(PARAMS.yellow_lower, PARAMS.yellow_upper),
                       white=(PARAMS.white_lower, PARAMS.white_upper), pixels_per_beat=p)
    beats = []
    for f in frames:
        flat = f.reshape(-1, 3)
        chunks = [flat[i:i + p] for i in range(0, len(flat), p)]
        beats += [(int.from_bytes(c.tobytes(), "little"), int(k == len(chunks) - 1))
                  for k, c in enumerate(chunks)]
    source = StreamSource(dut.i, beats, idle=0.2, seed=seed)
    sink = StreamSink(dut.o, backpressure=0.5, seed=seed + 1)

    async def control(ctx):
        await source.run(ctx)
        while len(sink.beats) < len(frames):
            await ctx.tick()

    simulate(dut, control, background=[sink.run])
    out = []
    for data, _ in sink.beats:
        r = LANE_RESULT.from_bits(data)
        out.append((r.centre if r.has_centre else None, r.left if r.has_left else None,
                    r.right if r.has_right else None))
    return out


# make test runs the 4 px/clk detector (17 s in Amaranth's simulator; 1 px/clk takes 68 s, in
# make test-full, as the chain that runs it in tb/test_av_chain.py and tb/test_project_sim.py)
@pytest.mark.parametrize("p", [pytest.param(1, marks=pytest.mark.full), 4])
def test_detector_equals_the_software_node(p):
    rng = np.random.default_rng(p)
    frames = [road(rng, 70, 130), road(rng, 63.5, 141), road(rng, left=50),
              road(rng, right=120), road(rng), road(rng, right=20)]
    got = detector_results(frames, p, seed=p)
    expected = [autorace.lane_centre(f, PARAMS) for f in frames]
    assert got == expected
    assert expected[2][0] is not None and expected[4] == (None, None, None)
    assert expected[5][0] < 0                      # a white stripe far left: a negative centre


def test_detector_parameters_checked():
    with pytest.raises(ParameterError, match="lane_width"):
        LaneDetector(width=W, height=H, band_top=80, lane_width=61)
    with pytest.raises(ParameterError, match="band_top"):
        LaneDetector(width=W, height=H, band_top=H)


@pytest.mark.parametrize("max_speed", [None, 32767])
def test_control_equals_the_software_node(max_speed):
    """The chain's parameters, and the largest top speed (its division's widest quotient,
    on the results at the target)."""
    rng = np.random.default_rng(5)
    params = autorace.ControlParams()
    if max_speed is not None:
        params = dataclasses.replace(params, max_speed=max_speed)
    events = []                               # per lane result: (stop, start) before it
    results = []
    for k in range(40):
        centre = None if k % 11 == 5 else int(rng.integers(-50, 1100))
        if k in (3, 30):
            centre = params.target
        results.append(centre)
        events.append((k == 12, k == 25))
    model = autorace.LaneControl(params)
    expected = []
    for (stop, start), centre in zip(events, results):
        if stop:
            model.stop()
        if start:
            model.start()
        expected.append(model.step(centre))

    dut = LaneControl(kp=params.kp, kd=params.kd, max_speed=params.max_speed,
                      max_turn=params.max_turn, target=params.target)
    sink = StreamSink(dut.o, backpressure=0.3, seed=3)

    async def drive(ctx):
        for (stop, start), centre in zip(events, results):
            for port, on in ((dut.stop, stop), (dut.start, start)):
                if on:
                    ctx.set(port.valid, 1)
                    await ctx.tick()
                    ctx.set(port.valid, 0)
            word = LANE_RESULT.const({"centre": centre or 0, "has_centre": centre is not None})
            ctx.set(dut.lane.tdata, word.as_value().value)
            ctx.set(dut.lane.tvalid, 1)
            await ctx.tick().until(dut.lane.tready)
            ctx.set(dut.lane.tvalid, 0)
            n = len(sink.beats)
            while len(sink.beats) == n:
                await ctx.tick()

    simulate(dut, drive, background=[sink.run])
    got = []
    for data, _ in sink.beats:
        c = DRIVE_COMMAND.from_bits(data)
        got.append((c.speed, c.turn))
    assert got == expected
    assert expected[13] == (0, 0) and expected[26] != (0, 0)
    assert expected[30][0] == params.max_speed
