# amaranth: UnusedElaboratable=no
"""MnistMacArray (hdl.kernels.mnist; docs/kernels.md) in amaranth.sim against a Python model
of its contract: per lane the sum over beats of its weights times the shared activations,
restarted by ``first``, reported ``LATENCY`` cycles after ``last`` with the beat's tag;
beats with idle cycles between them, accumulations of one and of many beats, the extreme
operands (activation 255, weights -128 and 127)."""

import random

import pytest

from hdl.kernels import MnistMacArray
from hdl.params import ParameterError

from .streamsim import simulate


def expected(accumulations):
    """``[(tag, sums)]`` of ``[(tag, [(act, weights)])]``, from the contract."""
    results = []
    for tag, beats in accumulations:
        lanes = len(beats[0][1]) // len(beats[0][0])
        taps = len(beats[0][0])
        sums = [sum(w[o * taps + t] * a[t] for a, w in beats for t in range(taps))
                for o in range(lanes)]
        results.append((tag, sums))
    return results


def run_mac(lanes, taps, accumulations, *, idle, seed):
    dut = MnistMacArray(lanes, taps, tag_width=8)
    rng = random.Random(seed)
    seen = []

    async def drive(ctx):
        for tag, beats in accumulations:
            for n, (act, weights) in enumerate(beats):
                while rng.random() < idle:
                    ctx.set(dut.valid, 0)
                    await ctx.tick()
                ctx.set(dut.valid, 1)
                ctx.set(dut.first, n == 0)
                ctx.set(dut.last, n == len(beats) - 1)
                ctx.set(dut.tag, tag)
                for t, a in enumerate(act):
                    ctx.set(dut.act[t], a)
                for k, w in enumerate(weights):
                    ctx.set(dut.weights[k], w)
                await ctx.tick()
        ctx.set(dut.valid, 0)
        await ctx.tick().repeat(dut.LATENCY + 2)

    async def watch(ctx):
        async for _, _, valid, tag, sums in ctx.tick().sample(dut.out_valid, dut.out_tag,
                                                              dut.sums):
            if valid:
                seen.append((tag, [sums[o] for o in range(lanes)]))

    simulate(dut, drive, background=[watch])
    return seen


def random_accumulations(rng, lanes, taps, count, max_beats):
    accumulations = []
    for k in range(count):
        beats = []
        for _ in range(rng.randint(1, max_beats)):
            act = [rng.choice([0, 255, rng.randrange(256)]) for _ in range(taps)]
            weights = [rng.choice([-128, 127, rng.randrange(-128, 128)])
                       for _ in range(lanes * taps)]
            beats.append((act, weights))
        accumulations.append((k % 256, beats))
    return accumulations


@pytest.mark.parametrize("lanes,taps,idle", [(16, 9, 0.0), (16, 9, 0.4), (3, 1, 0.3),
                                             (2, 5, 0.0)])
def test_sums_match_the_contract(lanes, taps, idle):
    rng = random.Random(lanes * 100 + taps)
    accumulations = random_accumulations(rng, lanes, taps, 12, 40)
    got = run_mac(lanes, taps, accumulations, idle=idle, seed=taps)
    assert got == expected(accumulations)


def test_extreme_operands_over_32_beats():
    """The largest magnitude the CNN can reach per lane: 32 beats of 9 x 255 x -128."""
    beats = [([255] * 9, [-128] * 144)] * 32 + [([255] * 9, [127] * 144)]
    got = run_mac(16, 9, [(1, beats), (2, beats[:1])], idle=0.0, seed=0)
    assert got == expected([(1, beats), (2, beats[:1])])
    assert got[0][1][0] == 32 * 9 * 255 * -128 + 9 * 255 * 127


def test_latency_is_as_documented():
    """A one-beat accumulation presented at cycle 0 comes out at cycle LATENCY."""
    dut = MnistMacArray(4, 9)
    times = {}

    async def drive(ctx):
        ctx.set(dut.valid, 1)
        ctx.set(dut.first, 1)
        ctx.set(dut.last, 1)
        ctx.set(dut.act[0], 1)
        ctx.set(dut.weights[0], 3)
        await ctx.tick()
        ctx.set(dut.valid, 0)
        for cycle in range(1, 20):
            if ctx.get(dut.out_valid):
                times["out"] = cycle
                times["sum"] = ctx.get(dut.sums[0])
                break
            await ctx.tick()

    simulate(dut, drive)
    assert times == {"out": dut.LATENCY, "sum": 3}


@pytest.mark.parametrize("param,value", [("lanes", 0), ("taps", -1), ("tag_width", "8")])
def test_bad_parameters_are_named(param, value):
    with pytest.raises(ParameterError, match=param):
        MnistMacArray(**{param: value})
