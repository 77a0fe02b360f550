# amaranth: UnusedElaboratable=no
"""MergeSorter in amaranth.sim against Python's ``sorted`` (docs/reconos.md: ascending
unsigned 32-bit), under random idle and backpressure, with short and long blocks."""

import random

import pytest

from hdl.kernels import MergeSorter
from hdl.params import ParameterError

from .streamsim import StreamSink, StreamSource, beats_to_messages, messages_to_beats, simulate


def run_blocks(block_size, blocks, lengths, *, idle=0.3, backpressure=0.3, seed=0, width=32):
    """Stream ``blocks`` through a sorter (``lengths[i]`` set while block i loads); return
    the output blocks, the error pulses seen and the cycles taken."""
    dut = MergeSorter(block_size, width=width)
    sink = StreamSink(dut.o, backpressure=backpressure, seed=seed + 1)
    errors = {"short": 0, "long": 0}
    cycles = [0]

    async def control(ctx):
        # the length is sampled at a block's first beat: set it before each block is offered
        for b, (block, n) in enumerate(zip(blocks, lengths)):
            ctx.set(dut.length, n)
            await StreamSource(dut.i, messages_to_beats([block]), idle=idle,
                               seed=seed + 2 * b).run(ctx)
            if b + 1 < len(blocks) and lengths[b + 1] != n:
                await ctx.tick().until(~dut.busy)
        while len(beats_to_messages(sink.beats)[0]) < len(blocks):
            await ctx.tick()

    async def watch(ctx):
        async for _, _, short, long_ in ctx.tick().sample(dut.err_short, dut.err_long):
            errors["short"] += short
            errors["long"] += long_
            cycles[0] += 1

    simulate(dut, control, background=[sink.run, watch])
    out, rest = beats_to_messages(sink.beats)
    assert not rest, "a block ended without tlast"
    return out, errors, cycles[0]


@pytest.mark.parametrize("block_size", [2, 16, 64])
def test_sorts_random_blocks(block_size):
    rng = random.Random(block_size)
    blocks = [[rng.randrange(1 << 32) for _ in range(block_size)] for _ in range(3)]
    blocks.append([rng.choice([0, 5, 0xFFFFFFFF]) for _ in range(block_size)])  # duplicates
    out, errors, _ = run_blocks(block_size, blocks, [0] * len(blocks), seed=block_size)
    assert out == [sorted(b) for b in blocks]
    assert errors == {"short": 0, "long": 0}


def test_runtime_length_below_block_size():
    rng = random.Random(7)
    lengths = [5, 1, 32, 17]
    blocks = [[rng.randrange(1 << 32) for _ in range(n)] for n in lengths]
    out, errors, _ = run_blocks(32, blocks, lengths, seed=3)
    assert out == [sorted(b) for b in blocks]
    assert errors == {"short": 0, "long": 0}


def test_short_and_long_blocks_are_flagged_and_resynchronised():
    """A block shorter than ``length`` is padded with all-ones elements, a longer one is cut;
    each raises its error pulse once and the next block is sorted correctly."""
    rng = random.Random(9)
    short = [rng.randrange(1000) for _ in range(5)]
    long_ = [rng.randrange(1000) for _ in range(12)]
    good = [rng.randrange(1 << 32) for _ in range(8)]
    out, errors, _ = run_blocks(8, [short, long_, good], [8, 8, 8], seed=4)
    assert out[0] == sorted(short) + [0xFFFFFFFF] * 3
    assert out[1] == sorted(long_[:8])
    assert out[2] == sorted(good)
    assert errors == {"short": 1, "long": 1}


def test_cycles_per_block_without_stalls():
    """(log2 N + 1) N cycles, give or take a few, when neither side stalls (issue target
    for 2048 elements: <= 25,000 cycles)."""
    rng = random.Random(1)
    n = 256
    blocks = [[rng.randrange(1 << 32) for _ in range(n)]]
    out, _, cycles = run_blocks(n, blocks, [0], idle=0.0, backpressure=0.0)
    assert out == [sorted(blocks[0])]
    assert cycles <= (8 + 1) * n + 16, cycles


def test_bad_parameters_name_the_value():
    with pytest.raises(ParameterError, match="block_size must be a power of two in 2..4096, not 3000"):
        MergeSorter(3000)
    with pytest.raises(ParameterError, match="width must be .* not 12"):
        MergeSorter(16, width=12)
