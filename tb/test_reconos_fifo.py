"""ReconOS FIFOs in amaranth.sim (docs/reconos.md): first-word fall-through, push iff
WE & ~Full, pop iff RE & ~Empty, Fill/Remm, FIFO_Has_Data, reset; the clock-crossing version
under random writer and reader pauses with a scoreboard."""

import random

import pytest
from amaranth.hdl import ClockDomain, Module
from amaranth.lib import wiring
from amaranth.sim import Simulator

from hdl.reconos.fifo import ReconosFifo


def test_sync_fifo_semantics():
    dut = ReconosFifo(32, 8)
    sim = Simulator(dut)
    sim.add_clock(1e-8)

    async def bench(ctx):
        assert ctx.get(dut.r.empty) and not ctx.get(dut.w.full)
        assert ctx.get(dut.w_free) == 8 and ctx.get(dut.r_fill) == 0
        ctx.set(dut.w.data, 0x11)
        ctx.set(dut.w.we, 1)
        await ctx.tick()
        ctx.set(dut.w.we, 0)
        # fall-through: the word is at the read side one cycle after the push
        assert not ctx.get(dut.r.empty) and ctx.get(dut.r.data) == 0x11
        assert ctx.get(dut.has_data) and ctx.get(dut.r_fill) == 1
        # fill up: 7 more are taken, the 9th is refused (Full), nothing lost
        for k in range(8):
            ctx.set(dut.w.data, 0x20 + k)
            ctx.set(dut.w.we, 1)
            await ctx.tick()
        ctx.set(dut.w.we, 0)
        assert ctx.get(dut.w.full) and ctx.get(dut.w_free) == 0
        got = []
        ctx.set(dut.r.re, 1)
        for _ in range(10):
            if not ctx.get(dut.r.empty):
                got.append(ctx.get(dut.r.data))
            await ctx.tick()
        assert got == [0x11] + [0x20 + k for k in range(7)]
        assert ctx.get(dut.r.empty) and not ctx.get(dut.has_data)
        # reset empties it
        ctx.set(dut.r.re, 0)
        ctx.set(dut.w.we, 1)
        await ctx.tick()
        ctx.set(dut.w.we, 0)
        ctx.set(dut.rst, 1)
        await ctx.tick()
        ctx.set(dut.rst, 0)
        assert ctx.get(dut.r.empty) and ctx.get(dut.w_free) == 8

    sim.add_testbench(bench)
    sim.run()


@pytest.mark.parametrize("depth", [2, 8])
def test_sync_fifo_flags_follow_a_level_model_under_random_pushes_and_pops(depth):
    """``full`` and ``empty`` are flip-flops computed a cycle ahead: each cycle they must
    equal what a Python model of the level says, and every word comes out once, in order."""
    dut = ReconosFifo(16, depth)
    sim = Simulator(dut)
    sim.add_clock(1e-8)
    rng = random.Random(depth)

    async def bench(ctx):
        level, sent, got, expected = 0, 0, [], []
        for cycle in range(2000):
            assert ctx.get(dut.w.full) == (level == depth), cycle
            assert ctx.get(dut.r.empty) == (level == 0), cycle
            assert ctx.get(dut.r_fill) == level and ctx.get(dut.w_free) == depth - level
            we = rng.random() < (0.8 if cycle % 400 < 200 else 0.3)
            re = rng.random() < (0.3 if cycle % 400 < 200 else 0.8)
            ctx.set(dut.w.we, we)
            ctx.set(dut.w.data, sent & 0xFFFF)
            ctx.set(dut.r.re, re)
            push = we and level < depth
            pop = re and level > 0
            if pop:
                got.append(ctx.get(dut.r.data))
            if push:
                expected.append(sent & 0xFFFF)
                sent += 1
            level += push - pop
            await ctx.tick()
        assert got == expected[:len(got)] and len(got) > 500

    sim.add_testbench(bench)
    sim.run()


class _TwoClocks(wiring.Component):
    def __init__(self):
        self.fifo = ReconosFifo(16, 8, w_domain="hwt", r_domain="sync")
        super().__init__({})

    def elaborate(self, platform):
        m = Module()
        m.domains.hwt = ClockDomain("hwt")
        m.submodules.fifo = self.fifo
        return m


@pytest.mark.parametrize("seed", [1, 2])
def test_async_fifo_crosses_clocks_without_loss(seed):
    dut = _TwoClocks()
    f = dut.fifo
    sim = Simulator(dut)
    sim.add_clock(1e-8, domain="sync")
    sim.add_clock(1.37e-8, domain="hwt")
    rng = random.Random(seed)
    words = [rng.getrandbits(16) for _ in range(300)]
    got = []

    async def writer(ctx):
        for word in words:
            while rng.random() < 0.3:
                await ctx.tick("hwt")
            ctx.set(f.w.data, word)
            ctx.set(f.w.we, 1)
            while True:
                _, _, full = await ctx.tick("hwt").sample(f.w.full)
                if not full:
                    break
            ctx.set(f.w.we, 0)

    async def reader(ctx):
        while len(got) < len(words):
            ready = rng.random() < 0.6
            ctx.set(f.r.re, ready)
            _, _, empty, data = await ctx.tick().sample(f.r.empty, f.r.data)
            if ready and not empty:
                got.append(data)

    sim.add_testbench(writer)
    sim.add_testbench(reader)
    sim.run()
    assert got == words
