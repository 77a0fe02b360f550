# amaranth: UnusedElaboratable=no
"""PidController (hdl/kernels/pid.py, docs/kernels.md) in amaranth.sim against the AVR221
model (tb/models/pid.py) at the edges its gain-dependent limits make: for gains at 0, 1,
their largest value and random ones, errors one below, at and one above ``maxError`` and
integrator sums driven to ``maxSumError`` and back, so that each limit the load's dividers
compute is checked to the unit."""

import random

import pytest

from hdl.kernels.pid import PidController

from .models.pid import AvrPid, wrap16
from .streamsim import simulate

GAINS = [(0, 0, 0), (1, 1, 1), (32767, 32767, 32767), (32767, 0, 1), (0, 32767, 0),
         (255, 3, 32767)]


def pairs_at_the_limits(rng, model, count):
    """(set point, measurement) pairs whose errors sit at the P limit's edges and push the
    integrator to its limit both ways (the model's limits, computed on their own)."""
    edge = model.max_error
    out = []
    for _ in range(count):
        e = rng.choice([edge - 1, edge, edge + 1, -edge - 1, -edge, -edge + 1,
                        rng.randrange(-32768, 32768), 32767, -32768])
        pv = rng.randrange(-32768, 32768)
        out.append((wrap16(pv + e), pv))
    return out


@pytest.mark.parametrize("seed", range(3))
def test_pid_matches_avr221_at_its_limits(seed):
    rng = random.Random(seed)
    dut = PidController()
    gains = GAINS + [tuple(rng.randrange(32768) for _ in range(3)) for _ in range(4)]
    got, want = [], []

    async def bench(ctx):
        ctx.set(dut.o.tready, 1)
        for p, i, d in gains:
            ctx.set(dut.p_gain, p)
            ctx.set(dut.i_gain, i)
            ctx.set(dut.d_gain, d)
            ctx.set(dut.load, 1)
            await ctx.tick()
            ctx.set(dut.load, 0)
            await ctx.tick().until(dut.ready)
            model = AvrPid(p, i, d)
            for sp, pv in pairs_at_the_limits(rng, model, 60):
                want.append(((p, i, d), sp, pv, model.update(sp, pv)))
                ctx.set(dut.i.tdata, (sp & 0xFFFF) | (pv & 0xFFFF) << 16)
                ctx.set(dut.i.tvalid, 1)
                await ctx.tick().until(dut.i.tready)
            ctx.set(dut.i.tvalid, 0)
            await ctx.tick().repeat(8)

    async def sink(ctx):
        while True:
            *_, valid, data = await ctx.tick().sample(dut.o.tvalid, dut.o.tdata)
            if valid:
                got.append(data - (1 << 16) if data & 0x8000 else data)

    simulate(dut, bench, background=[sink])
    assert len(got) == len(want)
    bad = [(g, w) for g, w in zip(got, want) if g != w[3]]
    assert not bad, f"{len(bad)} of {len(want)} outputs differ: {bad[:3]}"
