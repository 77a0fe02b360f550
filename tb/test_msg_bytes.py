# amaranth: UnusedElaboratable=no
"""Unit tests of hdl.msg.bytes (amaranth.sim): the byte packer under random chunk sizes,
random idle and random backpressure, against a model of its output written from its contract
(every beat full except a message's last; a message of no bytes is one beat with tkeep 0); the
byte unpacker under random takes and flushes against the messages' bytes."""

import random

import pytest

from hdl.msg.bytes import (BytePacker, ByteUnpacker, SettlingByteUnpacker, WideByteUnpacker,
                           byte_unpacker_class)
from hdl.params import ParameterError
from tb.streamsim import StreamSource, simulate


def packed_beats(messages, nbytes):
    """The beats ``(data, last, keep, first)`` a packer of ``nbytes``-byte beats gives."""
    beats = []
    for msg in messages:
        if not msg:
            beats.append((0, 1, 0, 1))
            continue
        for start in range(0, len(msg), nbytes):
            part = msg[start:start + nbytes]
            beats.append((int.from_bytes(bytes(part), "little"),
                          int(start + nbytes >= len(msg)), (1 << len(part)) - 1,
                          int(start == 0)))
    return beats


def random_chunks(rng, nbytes, count):
    """``count`` messages as chunk lists ``(bytes, last)``, with empty chunks anywhere
    (a message may end with one, or consist of empty chunks only)."""
    messages, chunks = [], []
    for _ in range(count):
        msg = []
        parts = rng.choice([0, 1, rng.randint(1, 12)])
        for k in range(parts + 1):
            n = rng.choice([0, nbytes, rng.randint(0, nbytes)])
            part = [rng.getrandbits(8) for _ in range(n)]
            msg += part
            chunks.append((part, int(k == parts)))
        messages.append(msg)
    return messages, chunks


def run_packer(nbytes, chunks, *, idle, backpressure, seed, limit):
    dut = BytePacker(8 * nbytes)
    rng = random.Random(seed)
    got = []
    cycles = {}

    async def source(ctx):
        ch = dut.chunk
        for part, last in chunks:
            while rng.random() < idle:
                ctx.set(ch.valid, 0)
                await ctx.tick()
            # bytes beyond ``len`` are noise the packer must ignore
            noise = rng.getrandbits(8 * nbytes) << 8 * len(part)
            ctx.set(ch.data, (int.from_bytes(bytes(part), "little") | noise)
                    & ((1 << 8 * nbytes) - 1))
            ctx.set(ch.len, len(part))
            ctx.set(ch.last, last)
            ctx.set(ch.valid, 1)
            await ctx.tick().until(ch.ready)
        ctx.set(ch.valid, 0)
        for _ in range(limit):
            if len(got) >= cycles["want"]:
                break
            await ctx.tick()

    async def sink(ctx):
        out = dut.m_axis
        cycle = 0
        sink_rng = random.Random(seed + 1)
        while True:
            ready = sink_rng.random() >= backpressure
            ctx.set(out.tready, ready)
            *_, valid, data, last, keep, first = await ctx.tick().sample(
                out.tvalid, out.tdata, out.tlast, out.tkeep, dut.first)
            cycle += 1
            if ready and valid:
                got.append((data, last, keep, first))
                cycles.setdefault("first", cycle)
                cycles["last"] = cycle

    return dut, got, cycles, source, sink


@pytest.mark.parametrize("nbytes", [1, 2, 8])
@pytest.mark.parametrize("idle,backpressure", [(0.0, 0.0), (0.4, 0.0), (0.0, 0.5), (0.3, 0.6)])
def test_packer_random(nbytes, idle, backpressure):
    """Every byte once, in order, in full beats except each message's last; ``first`` on
    each message's first beat; empty chunks and all-empty messages included."""
    rng = random.Random(nbytes * 100 + int(10 * idle) + int(100 * backpressure))
    messages, chunks = random_chunks(rng, nbytes, 60)
    want = packed_beats(messages, nbytes)
    dut, got, cycles, source, sink = run_packer(nbytes, chunks, idle=idle,
                                                backpressure=backpressure, seed=7, limit=5000)
    cycles["want"] = len(want)
    simulate(dut, source, background=[sink])
    assert got == want


@pytest.mark.parametrize("nbytes", [1, 8])
def test_packer_moves_a_beat_per_cycle(nbytes):
    """Full chunks without pauses: one beat per cycle within a message, and one cycle between
    messages (a message's first chunk waits until the previous message's last beat leaves)."""
    rng = random.Random(nbytes)
    messages = [[rng.getrandbits(8) for _ in range(nbytes * 40)] for _ in range(3)]
    chunks = [(msg[i:i + nbytes], int(i + nbytes >= len(msg)))
              for msg in messages for i in range(0, len(msg), nbytes)]
    want = packed_beats(messages, nbytes)
    dut, got, cycles, source, sink = run_packer(nbytes, chunks, idle=0.0, backpressure=0.0,
                                                seed=3, limit=1000)
    cycles["want"] = len(want)
    simulate(dut, source, background=[sink])
    assert got == want
    assert cycles["last"] - cycles["first"] + 1 == len(want) + len(messages) - 1


@pytest.mark.parametrize("unpacker,nbytes", [(ByteUnpacker, 1), (ByteUnpacker, 8),
                                             (WideByteUnpacker, 2), (WideByteUnpacker, 8),
                                             (WideByteUnpacker, 16),
                                             (SettlingByteUnpacker, 2),
                                             (SettlingByteUnpacker, 8),
                                             (SettlingByteUnpacker, 16)])
@pytest.mark.parametrize("idle", [0.0, 0.4])
def test_unpacker_random_takes_and_flushes(unpacker, nbytes, idle):
    """The consumer takes random amounts (0..min(avail, B)) at random, and with the settling
    unpacker whole windows (``take_full``) too: the bytes taken are each message's bytes in
    order, the window's bytes past ``avail`` are zero (but while a settling window shows
    nothing: it shows ``settling`` with ``avail`` 0 in exactly the cycle after a take of
    ``amount`` bytes or a flush, and its ``settled_window`` is the window but in a cycle after
    a ``take_full``); a flush in mid-message drops the rest of that message and
    the next message starts whole; ``ended`` comes once the last beat is absorbed."""
    rng = random.Random(nbytes * 10 + int(10 * idle))
    messages = [[rng.getrandbits(8) for _ in range(rng.choice([1, nbytes, rng.randint(1, 40)]))]
                for _ in range(50)]
    cut = {k: rng.randint(0, len(msg) - 1) for k, msg in enumerate(messages) if k % 5 == 3}
    beats = [(int.from_bytes(bytes(msg[i:i + nbytes]), "little"), int(i + nbytes >= len(msg)),
              (1 << len(msg[i:i + nbytes])) - 1)
             for msg in messages for i in range(0, len(msg), nbytes)]
    dut = unpacker(8 * nbytes)
    settling = unpacker is SettlingByteUnpacker
    source = StreamSource(dut.s_axis, beats, idle=idle, seed=5)
    got = []
    moved = False      # the last cycle took ``amount`` bytes or flushed
    moved_full = False     # the last cycle took a whole window (``take_full``)

    async def consumer(ctx):
        nonlocal moved, moved_full
        for k, msg in enumerate(messages):
            taken = []
            while True:
                avail, ended, window = ctx.get(dut.avail), ctx.get(dut.ended), ctx.get(dut.window)
                assert avail <= (nbytes if settling else 2 * nbytes)
                if settling:
                    assert ctx.get(dut.settling) == moved
                    assert avail == 0 or not moved
                    if avail and not moved_full:
                        assert ctx.get(dut.settled_window) == window
                if avail or not settling:
                    assert window >> 8 * min(avail, nbytes) == 0
                moved = moved_full = False
                if (ended and avail == 0) or len(taken) == cut.get(k, -1):
                    ctx.set(dut.flush, 1)
                    ctx.set(dut.take, 0)
                    moved = True
                    if settling:
                        # a flush comes first
                        ctx.set(dut.take_full, rng.random() < 0.5)
                    await ctx.tick()
                    ctx.set(dut.flush, 0)
                    if settling:
                        ctx.set(dut.take_full, 0)
                    break
                room = cut[k] - len(taken) if k in cut else nbytes
                amount = rng.randint(0, min(avail, nbytes, room))
                take = rng.random() < 0.7
                full = settling and take and min(avail, room) >= nbytes and rng.random() < 0.5
                if full:
                    # take_full moves a window whatever take and amount say
                    amount = nbytes
                    ctx.set(dut.take, rng.random() < 0.5)
                    ctx.set(dut.amount, rng.randint(0, nbytes))
                else:
                    ctx.set(dut.take, take)
                    ctx.set(dut.amount, amount)
                if settling:
                    ctx.set(dut.take_full, full)
                if take:
                    taken += list(window.to_bytes(nbytes, "little")[:amount])
                moved, moved_full = take and not full, full
                await ctx.tick()
            got.append(taken)

    simulate(dut, consumer, background=[source.run])
    assert got == [msg[:cut.get(k, len(msg))] for k, msg in enumerate(messages)]


@pytest.mark.parametrize("nbytes", [2, 64])
def test_settling_unpacker_moves_a_window_per_cycle(nbytes):
    """Whole windows taken (``take_full``) whenever shown, beats offered every cycle: after the
    first window, one window per cycle, the bytes in order, ``ended`` with the last."""
    rng = random.Random(nbytes)
    msg = [rng.getrandbits(8) for _ in range(40 * nbytes + nbytes // 2)]
    beats = [(int.from_bytes(bytes(msg[i:i + nbytes]), "little"), int(i + nbytes >= len(msg)),
              (1 << len(msg[i:i + nbytes])) - 1) for i in range(0, len(msg), nbytes)]
    dut = SettlingByteUnpacker(8 * nbytes)
    source = StreamSource(dut.s_axis, beats, idle=0.0, seed=1)
    taken, cycles = [], []

    async def consumer(ctx):
        for cycle in range(200):
            avail, window = ctx.get(dut.avail), ctx.get(dut.window)
            ctx.set(dut.take_full, avail == nbytes)
            if avail == nbytes:
                taken.extend(window.to_bytes(nbytes, "little"))
                cycles.append(cycle)
            elif ctx.get(dut.ended):
                taken.extend(window.to_bytes(nbytes, "little")[:avail])
                return
            await ctx.tick()

    simulate(dut, consumer, background=[source.run])
    assert taken == msg
    assert cycles[-1] - cycles[0] + 1 == len(cycles) == 40


def test_wide_unpacker_refuses_other_widths():
    """The wide unpacker's ring wraps at a power of two: another width is refused by name,
    and :func:`byte_unpacker_class` gives such a width the shifting unpacker."""
    with pytest.raises(ParameterError, match="data_width.*96"):
        WideByteUnpacker(96)
    with pytest.raises(ParameterError, match="data_width.*96"):
        SettlingByteUnpacker(96)
    assert byte_unpacker_class(512, settling=True) is SettlingByteUnpacker
    assert byte_unpacker_class(64, settling=True) is ByteUnpacker
    assert byte_unpacker_class(96) is ByteUnpacker
    assert byte_unpacker_class(64) is ByteUnpacker
    assert byte_unpacker_class(512) is WideByteUnpacker
