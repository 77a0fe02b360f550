# amaranth: UnusedElaboratable=no
"""TcpTimer (hdl/net/tcp/timer.py) in amaranth.sim: the expiry time of each mode against
docs/network.md (ARP retry: the limit in cycles; retransmission: the RTO doubled per
back-off up to 32 times; TIME-WAIT: 2 MSL; FIN-WAIT-2: 64 MSL), within one tick of the
mode's prescaler, and the command rules (stop before restart before start before zero,
start leaves a running timer alone)."""

import pytest

from hdl.net.tcp import FIN_WAIT_2_SCALE, MAX_BACKOFF, TcpTimer, TimerMode

from .streamsim import simulate

LIMIT = 40


class TimerTB:
    def __init__(self, dut):
        self.dut = dut

    async def command(self, ctx, **names):
        for name in names:
            ctx.set(getattr(self.dut, name), 1)
        await ctx.tick()
        for name in names:
            ctx.set(getattr(self.dut, name), 0)

    async def cycles_to_expiry(self, ctx, limit=100000):
        for n in range(limit):
            if ctx.get(self.dut.expired):
                return n
            await ctx.tick()
        return None


def run_timer(bench_body):
    dut = TimerTB(TcpTimer())

    async def bench(ctx):
        ctx.set(dut.dut.rto_cycles, LIMIT)
        ctx.set(dut.dut.msl_cycles, LIMIT)
        ctx.set(dut.dut.arp_retry_cycles, LIMIT)
        await ctx.tick()
        await bench_body(ctx, dut)

    simulate(dut.dut, bench)


@pytest.mark.parametrize("mode, backoffs, scale", [
    (TimerMode.ARP, 0, 0), (TimerMode.RETRANSMIT, 0, 0), (TimerMode.RETRANSMIT, 1, 1),
    (TimerMode.RETRANSMIT, 3, 3), (TimerMode.RETRANSMIT, MAX_BACKOFF + 2, MAX_BACKOFF),
    (TimerMode.TIME_WAIT, 0, 1), (TimerMode.FIN_WAIT_2, 0, FIN_WAIT_2_SCALE)])
def test_tcp_timer_expires_after_its_limit(mode, backoffs, scale):
    async def body(ctx, tb):
        ctx.set(tb.dut.mode, mode)
        for _ in range(backoffs):
            await tb.command(ctx, back_off=1)
        await tb.command(ctx, restart=1)
        n = await tb.cycles_to_expiry(ctx)
        ticks = 2 ** scale
        assert LIMIT * ticks - ticks <= n <= LIMIT * ticks + ticks, (n, LIMIT * ticks)
        await tb.command(ctx, backoff_reset=1)
        ctx.set(tb.dut.mode, TimerMode.RETRANSMIT)
        await tb.command(ctx, restart=1)
        assert LIMIT - 1 <= await tb.cycles_to_expiry(ctx) <= LIMIT + 1

    run_timer(body)


def test_tcp_timer_command_rules():
    async def body(ctx, tb):
        dut = tb.dut
        ctx.set(dut.mode, TimerMode.ARP)
        await tb.command(ctx, start=1)
        assert ctx.get(dut.running) == 1
        for _ in range(20):
            await ctx.tick()
        # start leaves a running timer alone: it expires 20 cycles later than from now
        await tb.command(ctx, start=1)
        assert LIMIT - 22 <= await tb.cycles_to_expiry(ctx) <= LIMIT - 18
        # zero keeps it running from zero
        await tb.command(ctx, zero=1)
        assert ctx.get(dut.running) == 1 and ctx.get(dut.expired) == 0
        assert LIMIT - 2 <= await tb.cycles_to_expiry(ctx) <= LIMIT + 1
        # stop wins over restart in the same cycle, and a stopped timer never expires
        await tb.command(ctx, stop=1, restart=1)
        assert ctx.get(dut.running) == 0
        assert await tb.cycles_to_expiry(ctx, limit=3 * LIMIT) is None
        # zero does not start a stopped timer; restart wins over zero
        await tb.command(ctx, zero=1)
        assert ctx.get(dut.running) == 0
        await tb.command(ctx, restart=1, zero=1)
        assert ctx.get(dut.running) == 1
        # done does not need running (TIME-WAIT ends on it); stop clears the count
        n = await tb.cycles_to_expiry(ctx)
        assert LIMIT - 1 <= n <= LIMIT + 1
        await tb.command(ctx, stop=1)
        assert ctx.get(dut.done) == 0
        ctx.set(dut.arp_retry_cycles, 0)
        await ctx.tick()
        await ctx.tick()
        assert ctx.get(dut.done) == 1 and ctx.get(dut.expired) == 0

    run_timer(body)
