# amaranth: UnusedElaboratable=no
"""GmiiRxCrossing (docs/boards.md "Clocks") in amaranth.sim with two free-running clocks:
frames of random length and gap, some with RX_ER bytes, written on the PHY's clock and
collected on the local one, against the frames sent. At 500 ppm apart in either direction
(five times what IEEE 802.3 allows) every frame arrives byte for byte; with the local clock
far too slow or too fast frames are lost or spoilt, but each such frame carries RX_ER (the MAC
drops it), the pulses count them, and every frame without RX_ER is one that was sent, in
order."""

import random

import pytest
from amaranth.hdl import Module

from hdl.net.gmii_crossing import GmiiRxCrossing

from .streamsim import simulate

PHY_NS = 8.0


def frames_for(seed, count, longest=1530):
    rng = random.Random(seed)
    frames = []
    for _ in range(count):
        n = rng.choice([rng.randint(1, 80), rng.randint(60, longest), longest])
        data = [(rng.randrange(256), 0) for _ in range(n)]
        if rng.random() < 0.1:
            k = rng.randrange(n)
            data[k] = (data[k][0], 1)
        frames.append((data, rng.randint(1, 24)))
    return frames


def run_crossing(frames, local_ns):
    """Send ``frames`` ((bytes as (rxd, er), gap)) on the PHY's clock; return the frames the
    local side put out (lists of (rxd, er)) and the two pulse counts."""
    dut = GmiiRxCrossing(i_domain="phy", o_domain="sync")
    received, counts = [], {"overruns": 0, "underruns": 0}
    done = []

    async def send(ctx):
        for data, gap in frames:
            for rxd, er in data:
                ctx.set(dut.rxd, rxd)
                ctx.set(dut.rx_er, er)
                ctx.set(dut.rx_dv, 1)
                await ctx.tick("phy")
                counts["overruns"] += ctx.get(dut.overruns)
            ctx.set(dut.rx_dv, 0)
            ctx.set(dut.rx_er, 0)
            for _ in range(gap):
                await ctx.tick("phy")
                counts["overruns"] += ctx.get(dut.overruns)
        for _ in range(200):
            await ctx.tick("phy")
        done.append(True)

    async def collect(ctx):
        frame = None
        while True:
            await ctx.tick("sync")
            counts["underruns"] += ctx.get(dut.underruns)
            if ctx.get(dut.out_rx_dv):
                frame = frame if frame is not None else []
                frame.append((ctx.get(dut.out_rxd), ctx.get(dut.out_rx_er)))
            elif frame is not None:
                received.append(frame)
                frame = None

    top = Module()
    top.submodules.dut = dut
    simulate(top, send, background=[collect],
             clocks={"phy": PHY_NS * 1e-9, "sync": local_ns * 1e-9})
    return received, counts


@pytest.mark.parametrize("ppm", [+500, -500])
def test_frames_cross_byte_for_byte_between_clocks_500_ppm_apart(ppm):
    frames = frames_for(ppm, 36)
    received, counts = run_crossing(frames, PHY_NS * (1 + ppm * 1e-6))
    assert received == [data for data, _ in frames]
    assert counts == {"overruns": 0, "underruns": 0}


@pytest.mark.parametrize("local_ns, pulse", [(PHY_NS * 1.25, "overruns"),
                                             (PHY_NS * 0.8, "underruns")])
def test_a_far_off_clock_spoils_frames_visibly_and_loses_no_good_one(local_ns, pulse):
    frames = frames_for(7, 24)
    received, counts = run_crossing(frames, local_ns)
    sent = [data for data, _ in frames]
    spoilt = [f for f in received if any(er for _, er in f)]
    good = [f for f in received if f not in spoilt]
    assert counts[pulse] > 0
    assert len(spoilt) >= counts[pulse]
    # every frame without RX_ER is one sent without RX_ER, in the order sent
    clean = iter([f for f in sent if not any(er for _, er in f)])
    for frame in good:
        assert frame in clean
    # short frames with long gaps still cross whole: the crossing resynchronises
    short = [d for d, gap in frames if len(d) <= 30 and not any(er for _, er in d)]
    assert sum(f in good for f in short) >= len(short) // 2
