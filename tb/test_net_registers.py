# amaranth: UnusedElaboratable=no
"""GlobalRegisters (hdl/net/registers.py) in amaranth.sim against the register map of
docs/network.md: every register reads back its reset value big-endian and takes writes byte
by byte, the counters read as big-endian words of the counter the offset names, unused
offsets read 0 and ignore writes, and every address outside the block reaches the user's
bus with its acknowledge and data coming back."""

import random

import pytest

from hdl.net.registers import GLOBAL_BASE, GLOBAL_REGS, STACK_COUNTERS, GlobalRegisters
from hdl.params import ParameterError

from .streamsim import simulate

INIT = {"mac": 0x02_00_C0_A8_0A_10, "ip": 0xC0A8_0A10, "rto_cycles": 25_000_000,
        "msl_cycles": 125_000_000, "rbcp_port": 4660, "arp_retry_cycles": 250_000_000,
        "tcp_port": 24}


class RegistersTB:
    def __init__(self, dut):
        self.dut = dut

    async def access(self, ctx, addr, write=None):
        """One byte access as the RBCP server makes it; returns (ack cycle, read data)."""
        bus = self.dut.bus
        ctx.set(bus.act, 1)
        ctx.set(bus.addr, addr)
        ctx.set(bus.we if write is not None else bus.re, 1)
        ctx.set(bus.wd, write or 0)
        await ctx.tick()
        ctx.set(bus.we, 0)
        ctx.set(bus.re, 0)
        for wait in range(8):
            if ctx.get(bus.ack):
                data = ctx.get(bus.rd)
                await ctx.tick()
                ctx.set(bus.act, 0)
                return wait, data
            await ctx.tick()
        raise AssertionError(f"no acknowledge for {addr:#x}")

    async def read(self, ctx, addr, size):
        value = 0
        for b in range(size):
            value = value << 8 | (await self.access(ctx, addr + b))[1]
        return value


def test_global_registers_map():
    rng = random.Random(51)
    dut = GlobalRegisters(INIT)
    tb = RegistersTB(dut)
    counters = [rng.randrange(2**32) for _ in STACK_COUNTERS]

    async def counter_model(ctx):
        while True:
            ctx.set(dut.counter_value, counters[ctx.get(dut.counter_index) % len(counters)])
            await ctx.delay(1e-9)

    async def bench(ctx):
        values = dict(INIT)
        for offset, (name, size, writable) in GLOBAL_REGS.items():
            if name == "counters":
                for k, expected in enumerate(counters):
                    assert await tb.read(ctx, GLOBAL_BASE + offset + 4 * k, 4) == expected, k
                continue
            assert await tb.read(ctx, GLOBAL_BASE + offset, size) == values[name], name
            assert ctx.get(getattr(dut, name)) == values[name]
            new = rng.randrange(2 ** (8 * size))
            for b, byte in enumerate(new.to_bytes(size, "big")):
                await tb.access(ctx, GLOBAL_BASE + offset + b, write=byte)
            values[name] = new
            assert ctx.get(getattr(dut, name)) == new, name
            assert await tb.read(ctx, GLOBAL_BASE + offset, size) == new
        # unused offsets: read 0, writes change nothing
        for offset in (0x06, 0x07, 0x20, 0x3F, 0xFFFF):
            await tb.access(ctx, GLOBAL_BASE + offset, write=0xA5)
            assert (await tb.access(ctx, GLOBAL_BASE + offset))[1] == 0
        assert {name: ctx.get(getattr(dut, name)) for name in values} == values

    simulate(dut, bench, background=[counter_model])


def test_global_registers_pass_the_user_window():
    dut = GlobalRegisters(INIT)
    tb = RegistersTB(dut)
    seen = []

    async def user_target(ctx):
        user = dut.user
        while True:
            *_, we, re, addr, wd = await ctx.tick().sample(user.we, user.re, user.addr, user.wd)
            ctx.set(user.ack, 0)
            if we or re:
                seen.append((addr, we, wd))
                for _ in range(3):           # a slow target
                    await ctx.tick()
                ctx.set(user.rd, (addr * 7) & 0xFF)
                ctx.set(user.ack, 1)

    async def bench(ctx):
        for addr in (0, 0x1234, GLOBAL_BASE - 1, 0xFFFE_FFFF):
            wait, data = await tb.access(ctx, addr)
            assert data == (addr * 7) & 0xFF and wait >= 3
            await tb.access(ctx, addr, write=0x5A)
        await tb.access(ctx, GLOBAL_BASE + 0x1C)          # inside: the user sees nothing

    simulate(dut, bench, background=[user_target])
    assert seen == [(a, w, d) for a in (0, 0x1234, GLOBAL_BASE - 1, 0xFFFE_FFFF)
                    for w, d in ((0, 0), (1, 0x5A))]


def test_global_registers_reject_bad_init():
    with pytest.raises(ParameterError, match="init"):
        GlobalRegisters({**INIT, "tcp_port": 70000})
    with pytest.raises(ParameterError, match="init"):
        GlobalRegisters({k: v for k, v in INIT.items() if k != "ip"})
