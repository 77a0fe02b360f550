# amaranth: UnusedElaboratable=no
"""Unit tests of hdl.stream (amaranth.sim): signature, register slice, FIFOs, monitor, width
converters."""

import random

import pytest
from amaranth.hdl import ClockDomain, Module, Signal
from amaranth.sim import Simulator

from hdl.params import ParameterError
from hdl.stream import (
    AsyncStreamFIFO,
    AXIStreamSignature,
    ByteWindow,
    MessageFIFO,
    PayloadRegisterSlice,
    ReadyRegisterSlice,
    RegisterSlice,
    StreamDownsizer,
    StreamFIFO,
    StreamRepacker,
    StreamUpsizer,
    keep_count_shallow,
)
from tb.streamsim import StreamSink, StreamSource, beats_to_messages, messages_to_beats, simulate


def random_messages(rng, count, *, max_len=12, width=8):
    return [[rng.getrandbits(width) for _ in range(rng.randint(1, max_len))]
            for _ in range(count)]


# Signature -----------------------------------------------------------------------------------

def test_signature_members_and_equality():
    sig = AXIStreamSignature(64, user_width=1, id_width=2)
    assert list(sig.members) == ["tdata", "tkeep", "tlast", "tuser", "tid", "tvalid", "tready"]
    assert sig.payload_width == 64 + 8 + 1 + 1 + 2
    assert sig == AXIStreamSignature(64, user_width=1, id_width=2)
    assert sig != AXIStreamSignature(64, user_width=1)
    assert repr(sig) == "AXIStreamSignature(64, user_width=1, id_width=2)"
    assert "tkeep" not in AXIStreamSignature(8, keep=False).members


@pytest.mark.parametrize("width", [0, 4, 12, 1032, "64"])
def test_signature_rejects_bad_width(width):
    with pytest.raises(ParameterError, match=r"data_width must be an integer in 8\.\.1024 "
                                             r"and a multiple of 8, not"):
        AXIStreamSignature(width)


def test_fifo_rejects_bad_depth():
    with pytest.raises(ParameterError, match="depth must be a power of two in 2..1048576, not 48"):
        StreamFIFO(AXIStreamSignature(8), 48)
    with pytest.raises(ValueError, match="drop_new.*needs packet=True"):
        StreamFIFO(AXIStreamSignature(8), 16, overflow="drop_new")


# Lossless stages under random idle and backpressure ---------------------------------------

def run_lossless(dut, messages, *, idle, backpressure, seed):
    beats = messages_to_beats(messages)
    source = StreamSource(dut.s_axis, beats, idle=idle, seed=seed)
    sink = StreamSink(dut.m_axis, backpressure=backpressure, seed=seed + 1)

    async def drain(ctx):
        await source.run(ctx)
        for _ in range(2000):
            if len(sink.beats) == len(beats):
                break
            await ctx.tick()

    simulate(dut, drain, background=[sink.run])
    assert sink.beats == beats


@pytest.mark.parametrize("idle,backpressure", [(0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (0.4, 0.6)])
@pytest.mark.parametrize("ready_only", [False, True], ids=["full", "ready_only"])
def test_register_slice_random(ready_only, idle, backpressure):
    rng = random.Random(3)
    run_lossless(RegisterSlice(AXIStreamSignature(8), ready_only=ready_only),
                 random_messages(rng, 40), idle=idle, backpressure=backpressure, seed=11)


@pytest.mark.parametrize("idle,backpressure", [(0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (0.4, 0.6)])
@pytest.mark.parametrize("cls,latency", [(PayloadRegisterSlice, 1), (ReadyRegisterSlice, 0)])
def test_payload_register_slice_random(cls, latency, idle, backpressure):
    """The lib.stream slices under random idle and backpressure: every payload once, in
    order; with neither, one transfer per cycle, the first after the slice's latency."""
    from amaranth.lib import data
    layout = data.StructLayout({"addr": 20, "write": 1, "tag": 3})
    dut = cls(layout)
    rng = random.Random(int(idle * 10) * 7 + int(backpressure * 10))
    sent = [{"addr": rng.getrandbits(20), "write": rng.getrandbits(1), "tag": rng.getrandbits(3)}
            for _ in range(200)]
    got, cycles = [], []

    async def source(ctx):
        for item in sent:
            while rng.random() < idle:
                await ctx.tick()
            ctx.set(dut.i.valid, 1)
            ctx.set(dut.i.payload, item)
            await ctx.tick().until(dut.i.ready)
            ctx.set(dut.i.valid, 0)

    async def sink(ctx):
        cycle = 0
        while True:
            ready = rng.random() >= backpressure
            ctx.set(dut.o.ready, ready)
            _, _, valid, payload = await ctx.tick().sample(dut.o.valid, dut.o.payload)
            cycle += 1
            if valid and ready:
                got.append({"addr": payload.addr, "write": payload.write, "tag": payload.tag})
                cycles.append(cycle)

    async def bench(ctx):
        await source(ctx)
        for _ in range(5):
            await ctx.tick()

    simulate(dut, bench, background=[sink])
    assert got == sent
    if idle == backpressure == 0:
        assert cycles[0] == 1 + latency
        assert cycles[-1] - cycles[0] + 1 == len(sent)


def run_sampled(dut, source, sink, probe, *, tail=10):
    """Run ``source`` into ``dut`` and ``sink`` from it until ``tail`` cycles after the
    source's last beat; return ``probe()`` sampled after every cycle."""
    samples = []

    async def bench(ctx):
        await source.run(ctx)
        for _ in range(tail):
            await ctx.tick()

    async def sample(ctx):
        while True:
            await ctx.tick()
            samples.append(probe())

    simulate(dut, bench, background=[sink.run, sample])
    return samples


def test_register_slice_full_throughput():
    dut = RegisterSlice(AXIStreamSignature(8))
    beats = [(i & 0xFF, int(i % 5 == 4)) for i in range(100)]
    sink = StreamSink(dut.m_axis)
    taken = run_sampled(dut, StreamSource(dut.s_axis, beats), sink, lambda: len(sink.beats),
                        tail=5)
    assert sink.beats == beats
    first = next(n for n, got in enumerate(taken) if got)
    last = next(n for n, got in enumerate(taken) if got == len(beats))
    assert last - first + 1 == len(beats)


@pytest.mark.parametrize("depth", [2, 4, 16])
@pytest.mark.parametrize("packet", [False, True])
@pytest.mark.parametrize("idle,backpressure", [(0.3, 0.0), (0.0, 0.6), (0.5, 0.5)])
def test_stream_fifo_random(depth, packet, idle, backpressure):
    rng = random.Random(depth * 7 + packet)
    run_lossless(StreamFIFO(AXIStreamSignature(8), depth, packet=packet),
                 random_messages(rng, 30, max_len=3 * depth), idle=idle,
                 backpressure=backpressure, seed=depth)


def test_packet_fifo_stores_and_forwards():
    dut = StreamFIFO(AXIStreamSignature(8), 16, packet=True)
    message = list(range(1, 11))
    source = StreamSource(dut.s_axis, messages_to_beats([message]), idle=0.5, seed=2)
    sink = StreamSink(dut.m_axis)
    early = []

    async def bench(ctx):
        await source.run(ctx)
        for _ in range(20):
            await ctx.tick()

    async def watch(ctx):
        while True:
            *_, valid = await ctx.tick().sample(dut.m_axis.tvalid)
            if valid and source.sent < len(message):
                early.append(source.sent)

    simulate(dut, bench, background=[sink.run, watch])
    assert not early, f"output before the message was complete (after {early[0]} beats)"
    assert sink.beats == messages_to_beats([message])


def test_packet_fifo_passes_oversize_message():
    """A message longer than the FIFO is cut through instead of deadlocking."""
    rng = random.Random(5)
    messages = [[rng.getrandbits(8) for _ in range(40)], [1, 2, 3]]
    run_lossless(StreamFIFO(AXIStreamSignature(8), 8, packet=True), messages,
                 idle=0.2, backpressure=0.5, seed=4)


def test_stream_fifo_level():
    dut = StreamFIFO(AXIStreamSignature(8), 8)
    levels = []

    async def bench(ctx):
        ctx.set(dut.m_axis.tready, 0)
        for i in range(10):
            ctx.set(dut.s_axis.tdata, i)
            ctx.set(dut.s_axis.tvalid, 1)
            *_, ready = await ctx.tick().sample(dut.s_axis.tready)
            levels.append(ready)
        ctx.set(dut.s_axis.tvalid, 0)
        await ctx.tick()
        levels.append(ctx.get(dut.level))

    simulate(dut, bench)
    # 8 memory entries + 1 in the output register, then tready falls.
    assert levels[:9] == [1] * 9 and levels[9] == 0 and levels[10] == 9


# Drop policies --------------------------------------------------------------------------

def run_lossy(dut, messages, *, stall_cycles, idle=0.0, seed=0):
    beats = messages_to_beats(messages)
    source = StreamSource(dut.s_axis, beats, idle=idle, seed=seed)
    sink = StreamSink(dut.m_axis)
    sink.paused = True

    async def bench(ctx):
        await source.run(ctx)
        for _ in range(stall_cycles):
            await ctx.tick()
        sink.paused = False
        for _ in range(400):
            await ctx.tick()
        return

    result = {}

    async def final(ctx):
        await bench(ctx)
        result["drops"] = ctx.get(dut.drops)

    simulate(dut, final, background=[sink.run])
    got, partial = beats_to_messages(sink.beats)
    assert partial == [], "a partial message came out"
    return got, result["drops"]


def is_subsequence(got, sent):
    it = iter(sent)
    return all(any(g == s for s in it) for g in got)


def test_drop_new_keeps_first_messages_and_counts():
    rng = random.Random(9)
    messages = [[i] + [rng.getrandbits(8) for _ in range(4)] for i in range(12)]
    dut = StreamFIFO(AXIStreamSignature(8), 16, packet=True, overflow="drop_new")
    got, drops = run_lossy(dut, messages, stall_cycles=20)
    assert is_subsequence(got, messages)
    assert drops == len(messages) - len(got)
    # 16 entries + output register: the first three 5-beat messages fit, the 4th is cut at 16.
    assert got == messages[:3]


def test_drop_new_oversize_then_good():
    messages = [list(range(30)), [7, 8, 9]]
    dut = StreamFIFO(AXIStreamSignature(8), 16, packet=True, overflow="drop_new")
    got, drops = run_lossy(dut, messages, stall_cycles=0)
    assert got == [[7, 8, 9]] and drops == 1


@pytest.mark.parametrize("slots", [2, 4, 8])
def test_message_fifo_keeps_newest(slots):
    rng = random.Random(slots)
    messages = [[i] + [rng.getrandbits(8) for _ in range(rng.randint(0, 6))] for i in range(20)]
    dut = MessageFIFO(AXIStreamSignature(8), slots, 8)
    got, drops = run_lossy(dut, messages, stall_cycles=10)
    # The first message is in delivery from the start; the newest slots-1 are kept.
    assert got == [messages[0]] + messages[-(slots - 1):]
    assert drops == len(messages) - len(got)


@pytest.mark.parametrize("idle,backpressure", [(0.0, 0.0), (0.3, 0.0), (0.0, 0.3)])
def test_message_fifo_lossless_when_reader_keeps_up(idle, backpressure):
    """Equal-length messages and a reader as fast as the writer: KEEP_LAST loses nothing.

    (Store and forward makes the reader lag one message, so a long message followed by many
    short ones can legitimately fill the slots; that case is a drop, tested elsewhere.)
    """
    rng = random.Random(21)
    messages = [[rng.getrandbits(8) for _ in range(5)] for _ in range(60)]
    dut = MessageFIFO(AXIStreamSignature(8), 4, 8)
    if backpressure:
        idle = 0.6  # the writer must be slower than the reader for no loss
    run_lossless(dut, messages, idle=idle, backpressure=backpressure, seed=8)


def test_message_fifo_oversize_dropped_whole():
    messages = [[1, 2], list(range(20)), [3, 4, 5]]
    dut = MessageFIFO(AXIStreamSignature(8), 4, 8)
    got, drops = run_lossy(dut, messages, stall_cycles=0)
    assert got == [[1, 2], [3, 4, 5]] and drops == 1


# Asynchronous FIFO -------------------------------------------------------------------------

@pytest.mark.parametrize("w_period,r_period", [(10e-9, 17e-9), (23e-9, 7e-9)])
def test_async_fifo_crosses_domains(w_period, r_period):
    rng = random.Random(4)
    messages = random_messages(rng, 25)
    beats = messages_to_beats(messages)
    fifo = AsyncStreamFIFO(AXIStreamSignature(8), 8, w_domain="write", r_domain="read")
    m = Module()
    m.domains.write = ClockDomain("write")
    m.domains.read = ClockDomain("read")
    m.submodules.fifo = fifo
    source = StreamSource(fifo.s_axis, beats, idle=0.3, seed=1)
    sink = StreamSink(fifo.m_axis, backpressure=0.4, seed=2)

    async def send(ctx):
        source.tick = lambda: ctx.tick("write")
        await source.run(ctx)
        for _ in range(400):
            await ctx.tick("write")

    async def receive(ctx):
        sink.tick = lambda: ctx.tick("read")
        await sink.run(ctx)

    simulate(m, send, background=[receive], clocks={"write": w_period, "read": r_period})
    assert sink.beats == beats


# Width converters --------------------------------------------------------------------------
# The golden model is the byte sequence: bytes of a beat are its tkeep bytes from byte 0.

def run_converter(dut, beats, *, idle, backpressure, seed, expected_beats):
    source = StreamSource(dut.s_axis, beats, idle=idle, seed=seed)
    sink = StreamSink(dut.m_axis, backpressure=backpressure, seed=seed + 1,
                      keep=hasattr(dut.m_axis, "tkeep"))

    async def drain(ctx):
        await source.run(ctx)
        for _ in range(2000):
            if expected_beats(sink.beats):
                break
            await ctx.tick()

    simulate(dut, drain, background=[sink.run])
    return sink.beats


def beat_bytes(data, keep):
    return [(data >> 8 * i) & 0xFF for i in range(keep.bit_length()) if keep >> i & 1]


@pytest.mark.parametrize("width", [16, 32, 64])
@pytest.mark.parametrize("idle,backpressure", [(0.0, 0.0), (0.4, 0.0), (0.0, 0.5), (0.3, 0.6)])
def test_downsizer_random(width, idle, backpressure):
    """Every kept byte once, in order; tlast on the last byte of a beat with tlast; beats
    with tkeep 0 give nothing."""
    rng = random.Random(width + int(10 * idle) + int(100 * backpressure))
    B = width // 8
    beats, want = [], []
    for _ in range(120):
        n = rng.choice([B, B, rng.randint(0, B)])
        last = int(n < B or rng.random() < 0.2)
        data = rng.getrandbits(width)
        beats.append((data, last, (1 << n) - 1))
        chunk = beat_bytes(data, (1 << n) - 1)
        want += [(b, int(last and i == n - 1)) for i, b in enumerate(chunk)]
    got = run_converter(StreamDownsizer(width), beats, idle=idle, backpressure=backpressure,
                        seed=5, expected_beats=lambda got: len(got) >= len(want))
    assert got == want


@pytest.mark.parametrize("width", [16, 32, 64])
@pytest.mark.parametrize("idle,backpressure", [(0.0, 0.0), (0.4, 0.0), (0.0, 0.5), (0.3, 0.6)])
def test_upsizer_random(width, idle, backpressure):
    """The bytes once, in order, tkeep contiguous from byte 0; a byte with tlast ends a beat
    with tlast; a partial beat carries tlast; with an input that never pauses, every beat
    but those ending at tlast is full (backpressure does not split beats)."""
    rng = random.Random(width * 3 + int(10 * idle) + int(100 * backpressure))
    B = width // 8
    beats = [(rng.getrandbits(8), int(rng.random() < 0.05)) for _ in range(600)]
    got = run_converter(StreamUpsizer(width), beats, idle=idle, backpressure=backpressure,
                        seed=7, expected_beats=lambda got: sum(
                            bin(k).count("1") for _, _, k in got) >= len(beats))
    flat = []
    for data, last, keep in got:
        n = bin(keep).count("1")
        assert keep == (1 << n) - 1 and n >= 1, f"tkeep {keep:#x} not contiguous from byte 0"
        assert last or n == B, f"a partial beat ({n} of {B} bytes) without tlast"
        chunk = beat_bytes(data, keep)
        flat += [(b, int(last and i == n - 1)) for i, b in enumerate(chunk)]
    assert [b for b, _ in flat] == [b for b, _ in beats]
    ends = {i for i, (_, last) in enumerate(flat) if last}
    assert {i for i, (_, last) in enumerate(beats) if last} <= ends
    if idle == 0:
        tlast_at = {i for i, (_, last) in enumerate(beats) if last}
        assert ends - tlast_at <= {len(beats) - 1}, "a beat flushed while bytes kept coming"


def repacked(beats, out_bytes):
    """The repacker's golden output: each message's bytes in order, in beats of
    ``out_bytes``, the last beat of a message partial with tlast."""
    out, held = [], []
    for data, last, keep in beats:
        held += beat_bytes(data, keep)
        while len(held) > out_bytes or (len(held) == out_bytes and not last):
            chunk, held = held[:out_bytes], held[out_bytes:]
            out.append((int.from_bytes(bytes(chunk), "little"), 0, (1 << out_bytes) - 1))
        if last and held:
            out.append((int.from_bytes(bytes(held), "little"), 1, (1 << len(held)) - 1))
            held = []
    return out


REPACKINGS = [(8, 3), (3, 8), (4, 3), (3, 4), (1, 3), (3, 1), (5, 5), (2, 7), (16, 3)]


@pytest.mark.parametrize("in_bytes,out_bytes", REPACKINGS)
@pytest.mark.parametrize("idle,backpressure", [(0.0, 0.0), (0.4, 0.0), (0.0, 0.5), (0.3, 0.6)])
def test_repacker_random(in_bytes, out_bytes, idle, backpressure):
    """Messages of random lengths (one byte to many beats, partial last beats, a last beat
    with tkeep 0) come out as the same bytes in beats of the new size, the last beat of each
    message partial with tlast; nothing lost, repeated or reordered."""
    rng = random.Random(in_bytes * 31 + out_bytes + int(10 * idle) + int(100 * backpressure))
    beats = []
    for _ in range(60):
        n_beats = rng.choice([1, 1, 2, rng.randint(3, 12)])
        for k in range(n_beats):
            last = k == n_beats - 1
            n = rng.choice([in_bytes, rng.randint(0 if k else 1, in_bytes)]) if last \
                else in_bytes
            beats.append((rng.getrandbits(8 * in_bytes), int(last), (1 << n) - 1))
    want = repacked(beats, out_bytes)
    got = run_converter(StreamRepacker(in_bytes, out_bytes), beats, idle=idle,
                        backpressure=backpressure, seed=3,
                        expected_beats=lambda got: len(got) >= len(want))
    got = [(d & ((1 << 8 * bin(k).count("1")) - 1), last, k) for d, last, k in got]
    assert got == want


@pytest.mark.parametrize("in_bytes,out_bytes", [(8, 3), (3, 8), (4, 3)])
def test_repacker_full_rate(in_bytes, out_bytes):
    """With neither side pausing, the slower side moves a beat every cycle."""
    total = 3 * 8 * 40
    beats = [(random.Random(i).getrandbits(8 * in_bytes), int(i == total // in_bytes - 1),
              (1 << in_bytes) - 1) for i in range(total // in_bytes)]
    dut = StreamRepacker(in_bytes, out_bytes)
    source = StreamSource(dut.s_axis, beats)
    sink = StreamSink(dut.m_axis, keep=True)
    taken = run_sampled(dut, source, sink, lambda: len(sink.beats), tail=5)
    assert sink.beats == [(d, l, k) for d, l, k in repacked(beats, out_bytes)]
    beats_out = total // out_bytes
    first = next(i for i, n in enumerate(taken) if n)
    done = taken.index(beats_out)
    assert done - first + 1 <= max(len(beats), beats_out) + 1, (first, done)


@pytest.mark.parametrize("in_bytes,out_bytes", [(2, 4), (2, 3), (1, 4), (4, 2)])
@pytest.mark.parametrize("idle,backpressure", [(0.0, 0.0), (0.5, 0.0), (0.3, 0.5)])
def test_repacker_eager_never_holds_bytes(in_bytes, out_bytes, idle, backpressure):
    """With ``eager``, a byte stream without message boundaries (beats of 1..in_bytes bytes,
    no tlast, as a TCP session delivers) comes out whole and in order; a partial beat
    carries tlast; once the input stops, every byte is out within a few cycles."""
    rng = random.Random(in_bytes * 7 + out_bytes + int(10 * idle) + int(100 * backpressure))
    beats = []
    for _ in range(300):
        n = rng.choice([in_bytes, rng.randint(1, in_bytes)])
        beats.append((rng.getrandbits(8 * in_bytes), 0, (1 << n) - 1))
    sent = [b for data, _, keep in beats for b in beat_bytes(data, keep)]
    dut = StreamRepacker(in_bytes, out_bytes, eager=True)
    source = StreamSource(dut.s_axis, beats, idle=idle, seed=5)
    sink = StreamSink(dut.m_axis, backpressure=backpressure, seed=6, keep=True)
    left = {}

    async def bench(ctx):
        await source.run(ctx)
        for _ in range(6):              # the input has stopped: everything leaves
            await ctx.tick()
        ctx.set(dut.m_axis.tready, 1)
        sink.paused = True
        left["count"] = len(sent) - sum(bin(k).count("1") for _, _, k in sink.beats)

    simulate(dut, bench, background=[sink.run])
    got = [b for data, _, keep in sink.beats for b in beat_bytes(data, keep)]
    assert got == sent[:len(got)]
    assert all(last or keep == (1 << out_bytes) - 1 for _, last, keep in sink.beats)
    assert left["count"] <= out_bytes


@pytest.mark.parametrize("nbytes", [1, 2, 4])
@pytest.mark.parametrize("idle", [0.0, 0.4])
def test_byte_window_gives_every_byte_once_in_order(nbytes, idle):
    """Beats of 1..nbytes bytes in; a consumer that takes random amounts (0..what the
    window holds) at random cycles gets every byte once, in order."""
    rng = random.Random(nbytes * 13 + int(10 * idle))
    beats = [(rng.getrandbits(8 * nbytes), 0, (1 << rng.randint(1, nbytes)) - 1)
             for _ in range(300)]
    sent = [b for data, _, keep in beats for b in beat_bytes(data, keep)]
    dut = ByteWindow(nbytes)
    source = StreamSource(dut.s_axis, beats, idle=idle, seed=3)
    got = []

    async def consume(ctx):
        while len(got) < len(sent):
            avail = ctx.get(dut.avail)
            amount = rng.randint(0, min(avail, nbytes)) if rng.random() < 0.8 else 0
            window = ctx.get(dut.window)
            ctx.set(dut.amount, amount)
            ctx.set(dut.take, 1)
            got.extend((window >> 8 * k) & 0xFF for k in range(amount))
            await ctx.tick()
        ctx.set(dut.take, 0)

    simulate(dut, consume, background=[source.run])
    assert got == sent


@pytest.mark.parametrize("nbytes", [2, 4])
def test_byte_window_full_rate(nbytes):
    """Full beats in and ``nbytes`` taken every cycle: a beat a cycle."""
    beats = [(random.Random(i).getrandbits(8 * nbytes), 0, (1 << nbytes) - 1)
             for i in range(100)]
    dut = ByteWindow(nbytes)
    source = StreamSource(dut.s_axis, beats)
    cycles = {"n": 0}

    async def consume(ctx):
        taken = 0
        while taken < 100 * nbytes:
            avail = ctx.get(dut.avail)
            amount = min(avail, nbytes)
            ctx.set(dut.amount, amount)
            ctx.set(dut.take, 1)
            taken += amount
            cycles["n"] += 1
            await ctx.tick()

    simulate(dut, consume, background=[source.run])
    assert cycles["n"] <= 100 + 2, cycles


def test_repacker_rejects_bad_sizes():
    with pytest.raises(ParameterError, match="in_bytes must be an integer in 1..128, not 0"):
        StreamRepacker(0, 3)
    with pytest.raises(ParameterError, match="out_bytes"):
        StreamRepacker(8, 129)


def test_byte_window_rejects_bad_size():
    with pytest.raises(ParameterError, match=r"nbytes must be an integer in 1\.\.16, not 0"):
        ByteWindow(0)
    with pytest.raises(ParameterError, match="not 17"):
        ByteWindow(17)


@pytest.mark.parametrize("converter", [StreamDownsizer, StreamUpsizer])
def test_converters_full_throughput(converter):
    """One byte per cycle through either converter, whatever the beat width."""
    B = 4
    if converter is StreamDownsizer:
        beats = [(0x04030201 + i, int(i % 7 == 6), 0xF) for i in range(50)]
        total = 50 * B
    else:
        beats = [(i & 0xFF, 0) for i in range(200)]
        total = 200
    dut = converter(8 * B)
    source = StreamSource(dut.s_axis, beats)
    sink = StreamSink(dut.m_axis, keep=converter is StreamUpsizer)
    sent = run_sampled(dut, source, sink, lambda: source.sent)
    moved = sum(bin(b[2]).count("1") for b in sink.beats) if converter is StreamUpsizer \
        else len(sink.beats)
    assert moved == total
    input_cycles = sent.index(len(beats)) + 1
    assert input_cycles <= (len(beats) if converter is StreamUpsizer else total) + 2, input_cycles


@pytest.mark.parametrize("converter", [StreamDownsizer, StreamUpsizer])
def test_converters_reject_byte_width(converter):
    with pytest.raises(ParameterError, match=r"data_width must be an integer in 16\.\.1024 and "
                                             r"a multiple of 8, not 8"):
        converter(8)


@pytest.mark.parametrize("nbits", [1, 2, 3, 8, 16, 64])
def test_keep_count_shallow_counts_every_contiguous_keep(nbits):
    """For every contiguous ``tkeep`` (0..nbits ones from bit 0), the shallow count is the
    number of ones."""
    m = Module()
    keep, count = Signal(nbits), Signal(range(nbits + 1))
    m.d.comb += count.eq(keep_count_shallow(keep))
    got = []

    async def bench(ctx):
        for ones in range(nbits + 1):
            ctx.set(keep, (1 << ones) - 1)
            got.append(ctx.get(count))

    sim = Simulator(m)
    sim.add_testbench(bench)
    sim.run()
    assert got == list(range(nbits + 1))
