# amaranth: UnusedElaboratable=no
"""MnistMacArray (hdl.kernels.mnist; docs/kernels.md) in amaranth.sim against a Python model
of its contract: per lane the sum over beats of its 4-bit weights times the shared
activations, restarted by ``first``, reported ``LATENCY`` cycles after ``last`` with the
beat's tag; beats with idle cycles between them, accumulations of one and of many beats, the
extreme operands (activation 255, weights -8 and 7, in every combination of a multiplier's
two lanes, where the low lane's product is negative and the high lane needs its borrow
back). Also the canonical signed digits behind conv1's constant products, and MnistCnn's
refusals of malformed weights.

The array with ECP5 multipliers (``multipliers="ecp5"``, MULT18X18D instances with their own
registers, as the timing bench places it) runs on Icarus and Verilator with the cycle-level
MULT18X18D model of host/compiled/ecp5_primitives.v, against the same contract, cycle for
cycle: every result comes LATENCY cycles after its last beat."""

import random

import cocotb
import pytest
from cocotb.triggers import ReadOnly, RisingEdge

from gen import mnist
from gen.export.verilog import write_if_changed
from hdl.kernels import MnistCnn, MnistMacArray
from hdl.kernels.mnist import csd_digits
from hdl.params import ParameterError
from host.board_sim import PRIMITIVES
from host.simulator import QUICK_CXX_OPT, export_top, run_top, start_clock, top_params

from .harness import ROOT, SIM_BUILD
from .streams import reset_aresetn
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
            weights = [rng.choice([-8, 7, -1, rng.randrange(-8, 8)])
                       for _ in range(lanes * taps)]
            beats.append((act, weights))
        accumulations.append((k % 256, beats))
    return accumulations


@pytest.mark.parametrize("lanes,taps,idle", [(16, 18, 0.0), (16, 18, 0.4), (2, 1, 0.3),
                                             (4, 5, 0.0), (6, 15, 0.2)])
def test_sums_match_the_contract(lanes, taps, idle):
    rng = random.Random(lanes * 100 + taps)
    accumulations = random_accumulations(rng, lanes, taps, 12, 40)
    got = run_mac(lanes, taps, accumulations, idle=idle, seed=taps)
    assert got == expected(accumulations)


def test_extreme_operands_over_32_beats():
    """32 beats of 18 x 255 x -8 then one of 255 x 7, and the four sign combinations of a
    multiplier's two lanes (lane pairs (-8, -8), (-8, 7), (7, -8), (7, 7))."""
    pattern = [-8, -8, -8, 7, 7, -8, 7, 7]
    lanes = [([w] * 18) for w in pattern * 2]
    mixed = ([255] * 18, [w for lane in lanes for w in lane])
    beats = [([255] * 18, [-8] * 288)] * 32 + [([255] * 18, [7] * 288)]
    runs = [(1, beats), (2, beats[:1]), (3, [mixed] * 5)]
    got = run_mac(16, 18, runs, idle=0.0, seed=0)
    assert got == expected(runs)
    assert got[0][1][0] == 32 * 18 * 255 * -8 + 18 * 255 * 7
    assert got[2][1][:4] == [5 * 18 * 255 * w for w in pattern[:4]]


def test_latency_is_as_documented():
    """A one-beat accumulation presented at cycle 0 comes out at cycle LATENCY."""
    dut = MnistMacArray(4, 18)
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


ECP5_ARRAY = dict(lanes=4, taps=18, tag_width=8)


def _words(values, bits):
    return sum((v & ((1 << bits) - 1)) << (bits * n) for n, v in enumerate(values))


def _signed(word, bits):
    return word - (1 << bits) if word >> (bits - 1) else word


@cocotb.test()
async def ecp5_array_matches_the_contract(dut):
    """Random accumulations (random idle cycles, extreme operands), each result equal to the
    contract and out LATENCY cycles after its last beat."""
    p = top_params()
    lanes, taps, latency = p["lanes"], p["taps"], p["latency"]
    rng = random.Random(random.getrandbits(32))        # cocotb seeds random
    accumulations = random_accumulations(rng, lanes, taps, 40, 12)
    start_clock(dut.aclk, 10)
    dut.valid.value = 0
    await reset_aresetn(dut)
    seen, cycle, last_at = [], 0, []

    async def watch():
        nonlocal cycle
        while True:
            await RisingEdge(dut.aclk)
            await ReadOnly()
            cycle += 1
            if dut.out_valid.value:
                sums = int(dut.sums.value)
                seen.append((cycle, int(dut.out_tag.value),
                             [_signed((sums >> (32 * o)) & 0xFFFFFFFF, 32)
                              for o in range(lanes)]))

    cocotb.start_soon(watch())
    for tag, beats in accumulations:
        for n, (act, weights) in enumerate(beats):
            while rng.random() < 0.3:
                dut.valid.value = 0
                await RisingEdge(dut.aclk)
            dut.valid.value = 1
            dut.first.value = int(n == 0)
            dut.last.value = int(n == len(beats) - 1)
            dut.tag.value = tag
            dut.act.value = _words(act, 8)
            dut.weights.value = _words(weights, 4)
            await RisingEdge(dut.aclk)
            if n == len(beats) - 1:
                last_at.append(cycle)
    dut.valid.value = 0
    for _ in range(latency + 4):
        await RisingEdge(dut.aclk)
    assert [(tag, sums) for _, tag, sums in seen] == expected(accumulations)
    assert [at for at, _, _ in seen] == [at + latency for at in last_at]


@pytest.mark.parametrize("sim", ["icarus", "verilator"])
def test_ecp5_multipliers_match_the_contract(sim):
    """MnistMacArray(multipliers="ecp5") with the MULT18X18D model: the contract, on time."""
    build = SIM_BUILD / f"mnist_mac_ecp5-{sim}"
    array = MnistMacArray(**ECP5_ARRAY, multipliers="ecp5")
    vfile = export_top(array, "mnist_mac", build, icarus=sim == "icarus")
    combined = build / "mnist_mac_with_ecp5_models.v"
    write_if_changed(combined, PRIMITIVES.read_text() + vfile.read_text())
    params = {**ECP5_ARRAY, "latency": array.LATENCY}
    run_top(__name__, "mnist_mac", None, sim, build, params=params, exported=combined,
            lint=False, cxx_opt=QUICK_CXX_OPT, extra_env={"PYTHONPATH": str(ROOT)})


@pytest.mark.parametrize("param,value", [("lanes", 0), ("lanes", 3), ("taps", -1),
                                         ("tag_width", "8"), ("multipliers", "ice40")])
def test_bad_parameters_are_named(param, value):
    with pytest.raises(ParameterError, match=param):
        MnistMacArray(**{param: value})


def test_csd_digits_sum_to_the_value():
    """Every weight's canonical signed digits add up to it, no two of them adjacent, at most
    two for a 4-bit weight (so conv1's sums have at most 18 terms)."""
    for value in range(-300, 301):
        digits = csd_digits(value)
        assert sum(sign << shift for sign, shift in digits) == value
        shifts = [shift for _, shift in digits]
        assert all(b - a >= 2 for a, b in zip(shifts, shifts[1:])), (value, digits)
        if -8 <= value <= 7:
            assert len(digits) <= 2


def cnn_weights(rng):
    """A well-formed weight set of the network's shapes."""
    import numpy as np
    gen = np.random.default_rng(rng.randrange(1 << 30))
    shapes = {name: mnist.shape_of(name) for name, *_ in mnist.LAYERS}
    return {name: (gen.integers(-8, 8, shape).astype(np.int8),
                   gen.integers(-1000, 1000, shape[0]).astype(np.int32),
                   gen.integers(0, 8, shape[0])) for name, shape in shapes.items()}


@pytest.mark.parametrize("case,match", [
    ("missing", "weights\\['conv3'\\]"), ("shape", "weights\\['fc'\\]"),
    ("range", "weights\\['conv2'\\].*-9"), ("shifts", "biases and shifts"),
    ("negative shift", "shift 3"), ("pixels", "pixels_per_beat"),
    ("multipliers", "multipliers.*xilinx")])
def test_bad_cnn_parameters_are_named(case, match):
    import numpy as np
    weights = cnn_weights(random.Random(1))
    kwargs = {}
    if case == "missing":
        del weights["conv3"]
    elif case == "shape":
        weights["fc"] = (np.zeros((10, 144), np.int8),) + weights["fc"][1:]
    elif case == "range":
        weights["conv2"][0][0, 0, 0, 0] = -9
    elif case == "shifts":
        weights["conv1"] = weights["conv1"][:2] + (weights["conv1"][2][:7],)
    elif case == "negative shift":
        weights["conv3"][2][3] = -1
    elif case == "multipliers":
        kwargs["multipliers"] = "xilinx"
    else:
        kwargs["pixels_per_beat"] = 2
    with pytest.raises(ParameterError, match=match):
        MnistCnn(weights, **kwargs)
