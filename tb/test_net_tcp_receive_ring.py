# amaranth: UnusedElaboratable=no
"""TcpReceiveRing (hdl/net/tcp/receive_ring.py) in amaranth.sim against a byte model of
docs/network.md "TCP session": segments written as they arrive, kept on commit, dropped on
rollback, duplicate bytes skipped, nothing written past a full ring, unread bytes dropped on
discard, the window equal to the free space; the reader under random backpressure."""

import random

import pytest

from hdl.net.tcp import TcpReceiveRing
from hdl.params import ParameterError

from .streamsim import StreamSink, simulate

DEPTH = 2048


def received(sink, lanes):
    """The bytes ``sink`` took from a ring of ``lanes`` bytes per beat, in order."""
    if lanes == 1:
        return [data for data, _ in sink.beats]
    return [(data >> 8 * k) & 0xFF for data, _, keep in sink.beats
            for k in range(lanes) if keep >> k & 1]


class ReceiveRingTB:
    """Drives segments into the ring and keeps the model: ``expected`` is every committed
    byte in order."""

    def __init__(self, dut, rng, lanes=1):
        self.dut = dut
        self.rng = rng
        self.lanes = lanes
        self.expected = []
        self.written_seen = []

    async def idle(self, ctx, cycles):
        for _ in range(cycles):
            await ctx.tick()

    async def drain(self, ctx, sink, count, limit=20000):
        """Wait until ``sink`` holds ``count`` bytes (a bounded wait)."""
        for _ in range(limit):
            if len(received(sink, self.lanes)) >= count:
                return
            await ctx.tick()
        raise AssertionError(f"{len(received(sink, self.lanes))} bytes read, {count} expected")

    async def send_segment(self, ctx, payload, *, accept, skip, good, gap=0.0):
        """One frame: payload beats at offsets 0.., the verdict, then commit or rollback."""
        dut, L = self.dut, self.lanes
        ctx.set(dut.accept, accept)
        ctx.set(dut.skip, skip)
        for offset in range(0, len(payload), L):
            beat = payload[offset:offset + L]
            while self.rng.random() < gap:
                ctx.set(dut.payload_valid, 0)
                await ctx.tick()
            ctx.set(dut.payload_data, int.from_bytes(beat, "little"))
            ctx.set(dut.payload_keep, (1 << len(beat)) - 1)
            ctx.set(dut.payload_offset, offset)
            ctx.set(dut.payload_valid, 1)
            await ctx.tick()
        ctx.set(dut.payload_valid, 0)
        await self.idle(ctx, self.rng.randrange(1, 4))
        written = ctx.get(dut.written)
        self.written_seen.append(written)
        ctx.set(dut.frame_end, 1)
        await ctx.tick()
        ctx.set(dut.frame_end, 0)
        await self.idle(ctx, self.rng.randrange(0, 12))
        ctx.set(dut.commit if good else dut.rollback, 1)
        await ctx.tick()
        ctx.set(dut.commit, 0)
        ctx.set(dut.rollback, 0)
        if good:
            self.expected += list(payload[skip:skip + written] if accept else [])
        return written


@pytest.mark.parametrize("lanes", [1, 2])
def test_tcp_receive_ring_commits_good_segments_only(lanes):
    rng = random.Random(11)
    dut = TcpReceiveRing(DEPTH, lanes=lanes)
    sink = StreamSink(dut.m_axis, backpressure=0.3, seed=3, keep=lanes > 1)
    tb = ReceiveRingTB(dut, rng, lanes)
    plan = []

    async def bench(ctx):
        for _ in range(60):
            payload = rng.randbytes(rng.randrange(1, 200))
            accept = rng.random() < 0.85
            skip = rng.choice([0, 0, 0, rng.randrange(0, len(payload) + 1)])
            good = rng.random() < 0.75
            written = await tb.send_segment(ctx, payload, accept=accept, skip=skip, good=good,
                                            gap=0.2)
            plan.append((len(payload), accept, skip, written))
        await tb.drain(ctx, sink, len(tb.expected))
        await tb.idle(ctx, 20)
        assert ctx.get(dut.window) == DEPTH - 1

    simulate(dut, bench, background=[sink.run])
    for length, accept, skip, written in plan:
        assert written == (length - skip if accept else 0), (length, accept, skip, written)
    assert received(sink, lanes) == tb.expected
    assert all(beat[1] == 0 for beat in sink.beats)


@pytest.mark.parametrize("lanes", [1, 2])
def test_tcp_receive_ring_stops_at_full_and_discards(lanes):
    rng = random.Random(12)
    dut = TcpReceiveRing(DEPTH, lanes=lanes)
    sink = StreamSink(dut.m_axis, backpressure=0.0, keep=lanes > 1)
    sink.paused = True
    tb = ReceiveRingTB(dut, rng, lanes)

    async def bench(ctx):
        total = 0
        while total < DEPTH - 1:
            payload = rng.randbytes(300)
            written = await tb.send_segment(ctx, payload, accept=1, skip=0, good=True)
            assert written == min(300, DEPTH - 1 - total)
            total += written
            assert ctx.get(dut.window) == DEPTH - 1 - total
        # full: a further segment writes nothing and the window stays closed
        assert await tb.send_segment(ctx, rng.randbytes(50), accept=1, skip=0, good=True) == 0
        assert ctx.get(dut.window) == 0
        # the reader takes 100 bytes: the next segment's first 100 bytes fit, the rest not
        sink.paused = False
        await tb.drain(ctx, sink, 100)
        sink.paused = True
        await tb.idle(ctx, 2)
        taken = len(received(sink, lanes))
        assert ctx.get(dut.window) == taken
        assert await tb.send_segment(ctx, rng.randbytes(400), accept=1, skip=0,
                                     good=True) == taken
        # discard drops everything committed and unread
        ctx.set(dut.discard, 1)
        await ctx.tick()
        ctx.set(dut.discard, 0)
        await tb.idle(ctx, 2)
        assert ctx.get(dut.window) == DEPTH - 1
        assert ctx.get(dut.m_axis.tvalid) == 0
        tb.expected = tb.expected[:len(received(sink, lanes))]
        fresh = rng.randbytes(30)
        assert await tb.send_segment(ctx, fresh, accept=1, skip=0, good=True) == 30
        sink.paused = False
        await tb.drain(ctx, sink, len(tb.expected))
        await tb.idle(ctx, 5)

    simulate(dut, bench, background=[sink.run])
    assert received(sink, lanes) == tb.expected


def test_tcp_receive_ring_rejects_bad_depth():
    with pytest.raises(ParameterError, match="depth"):
        TcpReceiveRing(3000)
