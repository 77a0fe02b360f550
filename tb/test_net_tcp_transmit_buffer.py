# amaranth: UnusedElaboratable=no
"""TcpTransmitBuffer (hdl/net/tcp/transmit_buffer.py) in amaranth.sim: the user's bytes
under random idle come back as segments that tile the sequence space without a gap, each at
most MSS long and ending at every ``tlast``, each with the ones'-complement sum scapy
computes for its bytes (RFC 1071), read back from the buffer byte for byte across the 2**32
wrap; acknowledged segments are freed, a rewind resends the same segments, a reset drops
them, and the buffer never takes more than it can hold."""

import random

import pytest

from hdl.net.tcp import TcpTransmitBuffer
from hdl.params import ParameterError

from .models.inet import ones_sum
from .streamsim import StreamSource, simulate

DEPTH = 2048
DESCRIPTORS = 8
MSS = 64


def user_beats(messages, lanes, rng):
    """``messages`` as ``(tdata, tlast, tkeep)`` beats of ``lanes`` bytes; with 2 lanes some
    beats carry one byte anywhere in a message (a segment's length then changes parity)."""
    beats = []
    for msg in messages:
        k = 0
        while k < len(msg):
            n = min(lanes, len(msg) - k)
            if n == 2 and rng.random() < 0.2:
                n = 1
            beats.append((int.from_bytes(bytes(msg[k:k + n]), "little"),
                          int(k + n == len(msg)), (1 << n) - 1))
            k += n
    return beats


class TransmitBufferTB:
    """Plays the session around the buffer: sends segments (``advance``), reads their bytes
    as the frame builder does, and acknowledges them (``snd_una``)."""

    def __init__(self, dut, lanes=1):
        self.dut = dut
        self.lanes = lanes
        self.segments = []          # (seq, len, sum, bytes) as sent, in order

    async def load(self, ctx, seq):
        ctx.set(self.dut.load, 1)
        ctx.set(self.dut.load_value, seq)
        ctx.set(self.dut.snd_una, seq)
        await ctx.tick()
        ctx.set(self.dut.load, 0)

    async def read(self, ctx, seq, length):
        """The bytes a frame builder reads: ``lanes`` a cycle from ``seq`` (any alignment)."""
        data = bytearray()
        for k in range(0, length, self.lanes):
            ctx.set(self.dut.rd_addr, (seq + k) & 0xFFFF)
            await ctx.tick()
            data += ctx.get(self.dut.rd_data).to_bytes(self.lanes, "little")
        return bytes(data[:length])

    async def send_next(self, ctx):
        dut = self.dut
        seq, length, total = (ctx.get(dut.next_seq), ctx.get(dut.next_len),
                              ctx.get(dut.next_sum))
        ctx.set(dut.advance, 1)
        await ctx.tick()
        ctx.set(dut.advance, 0)
        data = await self.read(ctx, seq, length)
        self.segments.append((seq, length, total, data))
        return seq, length, total, data


@pytest.mark.parametrize("lanes", [1, 2])
def test_tcp_transmit_buffer_segments_match_the_user_stream(lanes):
    rng = random.Random(21)
    dut = TcpTransmitBuffer(depth=DEPTH, descriptors=DESCRIPTORS, lanes=lanes)
    messages = [list(rng.randbytes(rng.choice([1, 2, 17, 63, 64, 65, 150, 300])))
                for _ in range(40)]
    stream = bytes(b for msg in messages for b in msg)
    ends = set()
    position = 0
    for msg in messages:
        position += len(msg)
        ends.add(position)
    source = StreamSource(dut.s_axis, user_beats(messages, lanes, rng), idle=0.15, seed=4)
    tb = TransmitBufferTB(dut, lanes)
    start = 0xFFFFFC03       # the sequence numbers wrap during the test, at an odd number
    fills = []

    async def bench(ctx):
        ctx.set(dut.mss, MSS)
        await tb.load(ctx, start)
        ctx.set(dut.accept, 1)
        una = start
        sent_bytes = 0
        for _ in range(200000):
            if sent_bytes == len(stream):
                break
            fills.append(ctx.get(dut.fill))
            if ctx.get(dut.unsent) and rng.random() < 0.5:
                seq, length, _, _ = await tb.send_next(ctx)
                sent_bytes += length
            elif tb.segments and rng.random() < 0.3:
                # acknowledge up to the end of a random sent segment
                seq, length, _, _ = rng.choice(tb.segments[-3:])
                end = (seq + length) & 0xFFFFFFFF
                if (end - una) & 0xFFFFFFFF < 0x80000000:
                    una = end
                    ctx.set(dut.snd_una, una)
                await ctx.tick()
            else:
                await ctx.tick()
        assert sent_bytes == len(stream), (sent_bytes, len(stream))
        ctx.set(dut.snd_una, (start + len(stream)) & 0xFFFFFFFF)
        for _ in range(DESCRIPTORS + 2):
            await ctx.tick()
        assert ctx.get(dut.in_flight) == 0 and ctx.get(dut.fill) == 0
        assert ctx.get(dut.all_sent) == 1
        assert ctx.get(dut.wr_seq) == (start + len(stream)) & 0xFFFFFFFF

    simulate(dut, bench, source.run)
    expected_seq = start
    offset = 0
    for seq, length, total, data in tb.segments:
        assert seq == expected_seq, (hex(seq), hex(expected_seq))
        assert 1 <= length <= MSS
        assert data == stream[offset:offset + length]
        assert total == ones_sum(data), (hex(total), hex(ones_sum(data)))
        # no segment runs across a tlast
        assert not any(offset < end < offset + length for end in ends)
        expected_seq = (expected_seq + length) & 0xFFFFFFFF
        offset += length
    assert max(fills) <= DEPTH - 1


@pytest.mark.parametrize("lanes", [1, 2])
def test_tcp_transmit_buffer_idle_closes_and_rewind_resends(lanes):
    rng = random.Random(22)
    dut = TcpTransmitBuffer(depth=DEPTH, descriptors=DESCRIPTORS, lanes=lanes)
    tb = TransmitBufferTB(dut, lanes)

    async def put(ctx, data, last):
        for k in range(0, len(data), lanes):
            beat = data[k:k + lanes]
            ctx.set(dut.s_axis.tdata, int.from_bytes(beat, "little"))
            if lanes > 1:
                ctx.set(dut.s_axis.tkeep, (1 << len(beat)) - 1)
            ctx.set(dut.s_axis.tlast, last and k + len(beat) == len(data))
            ctx.set(dut.s_axis.tvalid, 1)
            await ctx.tick().until(dut.s_axis.tready)
        ctx.set(dut.s_axis.tvalid, 0)

    async def bench(ctx):
        ctx.set(dut.mss, MSS)
        await tb.load(ctx, 1000)
        ctx.set(dut.accept, 1)
        # 10 bytes without tlast: a segment only after 16 idle cycles
        await put(ctx, b"0123456789", False)
        for _ in range(14):
            await ctx.tick()
            assert ctx.get(dut.unsent) == 0 and ctx.get(dut.all_sent) == 0
        for _ in range(4):
            await ctx.tick()
        assert ctx.get(dut.unsent) == 1
        first = await tb.send_next(ctx)
        assert first[:2] == (1000, 10) and first[3] == b"0123456789"
        data = rng.randbytes(100)
        await put(ctx, data, True)             # 64 + 36
        await ctx.tick()
        second = await tb.send_next(ctx)
        third = await tb.send_next(ctx)
        assert (second[1], third[1]) == (64, 36)
        assert ctx.get(dut.in_flight) == 3
        # SND.UNA at the end of the first: it is freed; a rewind resends the second
        ctx.set(dut.snd_una, 1010)
        ctx.set(dut.rewind, 1)
        await ctx.tick()
        ctx.set(dut.rewind, 0)
        await ctx.tick()
        assert ctx.get(dut.in_flight) == 0 and ctx.get(dut.unsent) == 1
        again = await tb.send_next(ctx)
        assert again == second
        assert ctx.get(dut.fill) == 100
        # accept low: nothing taken; reset drops the segments, the write pointer stays
        ctx.set(dut.accept, 0)
        await ctx.tick()
        assert ctx.get(dut.s_axis.tready) == 0
        ctx.set(dut.reset, 1)
        await ctx.tick()
        ctx.set(dut.reset, 0)
        await ctx.tick()
        assert ctx.get(dut.unsent) == 0 and ctx.get(dut.in_flight) == 0
        assert ctx.get(dut.wr_seq) == 1110

    simulate(dut, bench)


@pytest.mark.parametrize("lanes", [1, 2])
def test_tcp_transmit_buffer_stops_when_full(lanes):
    dut = TcpTransmitBuffer(depth=DEPTH, descriptors=DESCRIPTORS, lanes=lanes)
    tb = TransmitBufferTB(dut, lanes)
    taken = []
    # with 2 lanes a beat of two waits for room for two: the buffer holds DEPTH - 2 bytes
    room = DEPTH - 1 if lanes == 1 else DEPTH - 2
    pattern = bytes(k & 0xFF for k in range(2 * DEPTH))

    async def bench(ctx):
        ctx.set(dut.mss, 1460)
        await tb.load(ctx, 5)
        ctx.set(dut.accept, 1)
        ctx.set(dut.s_axis.tvalid, 1)
        if lanes > 1:
            ctx.set(dut.s_axis.tkeep, 0b11)
        k = 0
        for _ in range(2 * DEPTH):
            ctx.set(dut.s_axis.tdata, int.from_bytes(pattern[k:k + lanes], "little"))
            *_, ready = await ctx.tick().sample(dut.s_axis.tready)
            taken.append(ready)
            k += lanes * ready
        assert ctx.get(dut.fill) == room
        assert ctx.get(dut.wr_seq) == 5 + room
        # the bytes kept are the first ones, in place
        assert await tb.read(ctx, 5, 300) == pattern[:300]

    simulate(dut, bench)
    assert sum(taken) * lanes == room


def test_tcp_transmit_buffer_rejects_bad_parameters():
    with pytest.raises(ParameterError, match="descriptors"):
        TcpTransmitBuffer(depth=DEPTH, descriptors=3)
    with pytest.raises(ParameterError, match="depth"):
        TcpTransmitBuffer(depth=1000)
