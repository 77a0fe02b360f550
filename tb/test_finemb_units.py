# amaranth: UnusedElaboratable=no
"""FinEmbP's tables, IO descriptor, IO description files, page buffer and frame queue
(docs/finemb.md), against the protocol's definition: header and descriptor bytes built by
hand with ``struct``, the page buffer's flipping rules checked by a scoreboard under random
timing on both sides, the frame queue against the frames a Python model keeps."""

import random
import struct

import pytest

from gen.finemb import IoDescriptionError, load_io_description, parse_io_description
from hdl.finemb import IoDescriptor, PageBuffer
from hdl.finemb.protocol import (
    FINEMB_PORT, GROUP_IP, GROUP_MAC, HEADER, MsgType, PortType, decode_header, encode_header,
)
from hdl.net.queue import FrameQueue, FrameToRxBeats
from hdl.params import ParameterError

from .models.inet import ones_sum
from .harness import ROOT
from .streamsim import StreamSink, beats_to_messages, simulate

PID_IO = ROOT / "examples" / "finemb" / "pid_node.toml"


# ---- the protocol's tables

def test_header_bytes_and_addresses():
    assert FINEMB_PORT == 0xF1E0
    assert (GROUP_IP, GROUP_MAC) == ("239.255.70.69", "01:00:5e:7f:46:45")
    header = encode_header(MsgType.ISEND_REQ, 0x0203, flags=0x0102, cycle=0x0A0B0C0D,
                           length=10, seq=0x1122)
    assert header == bytes([0x46, 0x45, 0x01, 0x02, 0x03, 0x02, 0x02, 0x01,
                            0x0D, 0x0C, 0x0B, 0x0A, 0x0A, 0x00, 0x22, 0x11])
    assert len(header) == HEADER
    assert decode_header(header + bytes(10)) == (MsgType.ISEND_REQ, 0x0203, 0x0102,
                                                 0x0A0B0C0D, 10, 0x1122)


@pytest.mark.parametrize("payload, words", [
    (b"FE\x01", "shorter than the 16-byte header"),
    (b"EF" + encode_header(MsgType.SOC, 1)[2:], "magic 0x4645"),
    (encode_header(MsgType.SOC, 1)[:2] + b"\x07" + encode_header(MsgType.SOC, 1)[3:],
     "version 7"),
    (encode_header(MsgType.SOC, 1, length=4) + bytes(3), "length field 4, but 3 bytes"),
])
def test_bad_headers_are_named(payload, words):
    with pytest.raises(ValueError, match=words):
        decode_header(payload)


# ---- IO descriptors and description files

def test_pid_descriptor_layout_and_bytes():
    io = load_io_description(PID_IO)
    layout = [(p.name, p.direction, p.offset, p.size) for p in io.ports]
    assert layout == [("set_point", 0, 0, 2), ("measurement", 0, 2, 2), ("p_gain", 0, 4, 2),
                      ("i_gain", 0, 6, 2), ("d_gain", 0, 8, 2), ("output", 1, 0, 2),
                      ("updates", 1, 4, 4)]
    assert (io.page_out_bytes, io.page_in_bytes) == (10, 8)
    expected = struct.pack("<HHHH", 7, 10, 8, 3) + b"pid"
    for k, (name, direction, offset, size) in enumerate(layout):
        ptype = {"updates": PortType.U32, "output": PortType.I16}.get(
            name, PortType.I16 if name in ("set_point", "measurement") else PortType.U16)
        expected += struct.pack("<HBBHHB", k, direction, ptype, offset, size, len(name))
        expected += name.encode()
    assert io.encode() == expected
    assert IoDescriptor.decode(expected) == io
    page = io.pack(0, {"set_point": -2, "measurement": 300, "d_gain": 7})
    assert page == struct.pack("<hhHHH", -2, 300, 0, 0, 7)
    assert io.unpack(1, struct.pack("<hHI", -5, 0, 99)) == {"output": -5, "updates": 99}


def test_alignment_blobs_and_random_descriptors_round_trip():
    rng = random.Random(3)
    types = [t.name.lower() for t in PortType]
    for _ in range(200):
        specs = []
        for k in range(rng.randrange(1, 12)):
            t = rng.choice(types)
            specs.append((f"p{k}", rng.choice(("out", "in")), t) +
                         ((rng.randrange(1, 40),) if t == "blob" else ()))
        io = IoDescriptor(f"app{rng.randrange(100)}", specs)
        for p in io.ports:
            align = 1 if p.type == PortType.BLOB else p.size
            assert p.offset % align == 0
        for direction in (0, 1):
            ports = sorted((p for p in io.ports if p.direction == direction),
                           key=lambda p: p.offset)
            for a, b in zip(ports, ports[1:]):
                assert a.offset + a.size <= b.offset
        assert IoDescriptor.decode(io.encode()) == io


@pytest.mark.parametrize("data, words", [
    (b"\x01\x00", "not an IO descriptor"),
    (IoDescriptor("a", [("x", "out", "u8")]).encode() + b"\0", "followed by 1 more"),
    (IoDescriptor("a", [("x", "out", "u8")]).encode()[:-2] + b"\x0b\x00",
     "name of 11 bytes at byte 18 runs past the end"),
    (struct.pack("<HHHH", 1, 1, 1, 1) + b"a" + struct.pack("<HBBHHB", 0, 0, 11, 0, 1, 1) +
     b"x",
     "11 is not a valid PortType"),
])
def test_bad_descriptor_bytes(data, words):
    with pytest.raises(ValueError, match=words):
        IoDescriptor.decode(data)


@pytest.mark.parametrize("text, where", [
    ('name = "x"\n[[port]]\nname = "a"\ndirection = "out"\ntype = "i17"\n',
     r"io.toml:5: port 1: .*type must be one of .*'i17'"),
    ('name = "x"\nfoo = 1\n', r"io.toml:2: unknown key 'foo'"),
    ('[[port]]\nname = "a"\n', r"io.toml:1: missing 'name'"),
    ('name = "x"\n[[port]]\nname = "a"\ndirection = "out"\ntype = "i16"\n\n'
     '[[port]]\nname = "a"\ndirection = "in"\ntype = "u8"\n', r"io.toml:8: port 2: .*'a'"),
    ('name = "x"\n[[port]]\nname = "a"\ndirection = "sideways"\ntype = "i16"\n',
     r"io.toml:4: .*direction .*'sideways'"),
    ('name = "x"\n[[port]]\nname = "b"\ndirection = "in"\ntype = "blob"\nsize = 5000\n',
     r"io.toml:6: .*size .*5000"),
    ('name = "x"\n[[port]]\nname = "b"\ndirection = "in"\n', r"io.toml:2: port 1: missing"),
    ('name = [1\n', r"io.toml: "),
])
def test_io_description_errors_name_file_and_line(text, where):
    with pytest.raises(IoDescriptionError, match=where):
        parse_io_description(text, "io.toml")


def test_io_description_file_missing(tmp_path):
    with pytest.raises(IoDescriptionError, match="nope.toml: cannot read it"):
        load_io_description(tmp_path / "nope.toml")


# ---- the page buffer

class PageSides:
    """Both sides of a page buffer, stepped one cycle at a time in one process so that every
    same-cycle case (a claim in the cycle of a commit) is exact: the writer of received
    pages, the application that claims, reads twice and releases, and, for the input
    direction, the application that writes and commits and the sender that claims."""

    def __init__(self, dut, po, pi, rng, frames, lanes=1):
        self.dut, self.po, self.pi, self.rng, self.frames = dut, po, pi, rng, frames
        self.lanes = lanes
        self.cycle = 0
        # output direction: commits (cycle, page), the claim the application holds
        self.out_commits = []
        self.held = None                # (index of the commit held, its page)
        self.last_claimed = -1          # index of the commit the previous claim got
        self.refused = self.out_claims = 0
        # input direction: commits (cycle, page)
        self.in_commits = []
        self.in_claims = 0

    def newest(self, cycle):
        """Index of the newest output page committed at or before ``cycle``."""
        return max((k for k, (c, _) in enumerate(self.out_commits) if c <= cycle), default=-1)

    def writer(self):
        """Received output pages: begin (with the first byte), the bytes, a commit unless
        the frame is bad; refusals checked against the flipping rule."""
        dut, rng = self.dut, self.rng
        for _ in range(self.frames):
            for _ in range(rng.randrange(0, 30)):
                yield ()
            page, good = rng.randbytes(self.po), rng.random() < 0.8
            # refused exactly when the only page it may go to is the one held: a page was
            # committed after the held one
            expect_refused = self.held is not None and self.newest(self.cycle) > self.held[0]
            L = self.lanes

            def beat(k):
                part = page[k:k + L]
                return ((dut.out_we, (1 << len(part)) - 1), (dut.out_waddr, k),
                        (dut.out_wdata, int.from_bytes(part, "little")))
            accepted = yield ((dut.out_begin, 1),) + beat(0)
            assert accepted == (not expect_refused), (self.cycle, self.held, accepted)
            self.refused += not accepted
            for k in range(L, self.po, L):
                while rng.random() < 0.2:
                    yield ()
                yield beat(k)
            if good and accepted:
                self.out_commits.append((self.cycle, page))
                yield ((dut.out_commit, 1),)

    def reader(self):
        """The application: claim, read the page twice (with a pause that may outlast a
        frame), compare, release."""
        app, rng = self.dut.app, self.rng
        while True:
            for _ in range(rng.randrange(0, 60)):
                yield ()
            claim_cycle = self.cycle
            yield ((app.out_claim, 1),)
            self.out_claims += 1
            index = self.newest(claim_cycle)
            claimed, new = self.get(app.out_claimed), self.get(app.out_new)
            if index < 0:
                assert not claimed, "a page claimed before any arrived"
                continue
            assert claimed and new == (index > self.last_claimed), (index, self.last_claimed)
            self.last_claimed = index
            self.held = (index, self.out_commits[index][1])
            reads = []
            for _ in range(2):
                got = bytearray()
                for k in range(self.po):
                    yield ((app.out_raddr, k),)
                    got.append(self.get(app.out_rdata))
                reads.append(bytes(got))
                for _ in range(rng.randrange(0, 80)):
                    yield ()
            assert reads[0] == reads[1] == self.held[1], "the held page changed or is stale"
            yield ((app.out_release, 1),)
            self.held = None

    def app_writer(self):
        """The application's input pages: bytes while ``in_ready``, then a commit."""
        app, rng = self.dut.app, self.rng
        for _ in range(self.frames):
            page = rng.randbytes(self.pi)
            for k in range(self.pi):
                while not self.get(app.in_ready) or rng.random() < 0.2:
                    yield ()
                yield ((app.in_we, 1), (app.in_waddr, k), (app.in_wdata, page[k]))
            while not self.get(app.in_ready):
                yield ()
            self.in_commits.append((self.cycle, page))
            yield ((app.in_commit, 1),)
            for _ in range(rng.randrange(0, 40)):
                yield ()

    def sender(self):
        """The communication side sending ISEND_RES: claim, read with the sum, release. The
        page must be the newest committed one whose sum is done (a commit is summed within
        ``pi + 4`` cycles), whole."""
        dut, rng = self.dut, self.rng
        while True:
            for _ in range(rng.randrange(0, 50)):
                yield ()
            claim_cycle = self.cycle
            yield ((dut.in_claim, 1),)
            self.in_claims += 1
            done = [p for c, p in self.in_commits if c + self.pi + 4 <= claim_cycle]
            recent = [p for c, p in self.in_commits if c + self.pi + 4 > claim_cycle]
            if not self.get(dut.in_held):
                assert not done, "no input page held though one was committed long ago"
                continue
            got = bytearray()
            for k in range(0, self.pi, self.lanes):
                yield ((dut.in_raddr, k),)
                got += self.get(dut.in_rdata).to_bytes(self.lanes, "little")
                for _ in range(rng.randrange(0, 3)):
                    yield ()
            got = got[:self.pi]
            assert bytes(got) in done[-1:] + recent, "the held input page is not the newest"
            assert self.get(dut.in_sum) == ones_sum(got)
            yield ((dut.in_release, 1),)

    async def run(self, ctx):
        self.get = ctx.get
        finite = [self.writer(), self.app_writer()]
        endless = [self.reader(), self.sender()]
        replies = {id(g): None for g in finite + endless}
        pulses = [self.dut.out_begin, self.dut.out_we, self.dut.out_commit,
                  self.dut.app.out_claim, self.dut.app.out_release, self.dut.app.in_we,
                  self.dut.app.in_commit, self.dut.in_claim, self.dut.in_release]
        while finite:
            settings = []
            # the application sides first: what they learned from the last edge (a claim, a
            # release) is in place before the writer checks the flipping rule
            for gen in endless + list(finite):
                try:
                    settings += gen.send(replies[id(gen)])
                except StopIteration:
                    finite.remove(gen)
            for sig in pulses:
                ctx.set(sig, 0)
            for sig, value in settings:
                ctx.set(sig, value)
            accepted = ctx.get(self.dut.out_accept)
            await ctx.tick()
            self.cycle += 1
            for gen in finite + endless:
                replies[id(gen)] = accepted


@pytest.mark.parametrize("lanes", [1, 2])
@pytest.mark.parametrize("po, pi, seed", [(10, 8, 1), (1, 3, 2), (37, 64, 3)])
def test_page_buffer_flipping_under_random_timing(po, pi, seed, lanes):
    """Output pages: frames (a fifth of them bad, never committed) written at random times
    while the application claims, reads twice and releases at random times; a claimed page is
    always the newest committed one (a commit in the claim's cycle included), whole and
    unchanged while held, ``out_new`` says whether a page arrived since the last claim, and a
    frame is refused (overrun) exactly when it would have to go to the held page. Input pages
    mirrored, with the page's sum. With 2 lanes the communication side writes and reads two
    bytes at a time (odd page sizes end with one)."""
    dut = PageBuffer(po, pi, lanes=lanes)
    sides = PageSides(dut, po, pi, random.Random(seed), frames=150, lanes=lanes)
    simulate(dut, sides.run)
    assert sides.out_claims > 20 and sides.in_claims > 20
    # both cases happened: pages taken, and pages refused while the application held one
    assert len(sides.out_commits) > 20 and sides.refused > 5, sides.refused


def test_page_buffer_refuses_bad_sizes():
    with pytest.raises(ParameterError, match="page_out_bytes must be an integer in 1..1024"):
        PageBuffer(0, 4)
    with pytest.raises(ParameterError, match="page_in_bytes .* not 1025"):
        PageBuffer(4, 1025)


# ---- the frame queue

def run_queue(frames, *, depth=2048, backpressure=0.0, seed=0, hold_from=None,
              registered=False):
    """Feed ``frames`` (``(bytes, keep, ok)``) through a FrameQueue as a MAC would, the
    decision at byte 6 (the reader held off from frame ``hold_from`` until all arrived);
    return ``(frames out with their status, overflows)``."""
    dut = FrameQueue(depth, registered=registered)
    rng = random.Random(seed)
    sink = StreamSink(dut.m_axis, backpressure=backpressure, seed=seed)
    statuses = []
    overflow = [0]

    async def mac(ctx):
        rx = dut.rx
        for k, (data, keep, ok) in enumerate(frames):
            if k == hold_from:
                await ctx.tick().repeat(2 * depth)     # the reader empties the queue first
                sink.paused = True
            for i, byte in enumerate(data):
                ctx.set(rx.valid, 1)
                ctx.set(rx.data, byte)
                ctx.set(rx.index, min(i, 2047))
                ctx.set(dut.decide, int(i == 6))
                ctx.set(dut.keep, int(keep))
                await ctx.tick()
            ctx.set(rx.valid, 0)
            ctx.set(dut.decide, 0)
            ctx.set(rx.end, 1)
            ctx.set(rx.index, len(data))
            ctx.set(rx.ok, int(ok))
            ctx.set(rx.err_fcs, int(not ok))
            *_, ovf = await ctx.tick().sample(dut.overflow)
            overflow[0] += ovf
            ctx.set(rx.end, 0)
            for _ in range(rng.randrange(12, 30)):     # inter-frame gap
                await ctx.tick()
        sink.paused = False
        await ctx.tick().repeat(4 * sum(len(f) for f, _, _ in frames) + 100)

    async def status(ctx):
        m = dut.m_axis
        async for _, _, valid, ready, last, user in ctx.tick().sample(
                m.tvalid, m.tready, m.tlast, m.tuser):
            if valid and ready and last:
                statuses.append(user)

    simulate(dut, mac, background=[sink.run, status])
    messages, tail = beats_to_messages(sink.beats)
    assert tail == [], "a frame left without tlast"
    return [(bytes(msg), st) for msg, st in zip(messages, statuses)], overflow[0]


@pytest.mark.parametrize("registered", [False, True])
@pytest.mark.parametrize("backpressure", [0.0, 0.5])
def test_frame_queue_keeps_what_it_is_told(backpressure, registered):
    """Kept frames leave whole, in order, with their status (bit 0 bad, bit 1 FCS); dropped
    ones never. A reader at full speed loses nothing; one that takes a byte every other cycle
    falls behind, and each kept frame that finds the queue full is dropped whole and
    counted: the frames out are the kept ones less exactly that many, in order."""
    rng = random.Random(11)
    frames = [(rng.randbytes(rng.randrange(64, 300)), rng.random() < 0.6, rng.random() < 0.8)
              for _ in range(40)]
    out, overflows = run_queue(frames, backpressure=backpressure, seed=5,
                               registered=registered)
    expected = [(data, 0 if ok else 0b11) for data, keep, ok in frames if keep]
    if backpressure == 0:
        assert out == expected and overflows == 0
        return
    assert overflows >= 1, "the slow reader was expected to overflow the queue"
    assert len(out) == len(expected) - overflows
    rest = iter(expected)
    assert all(frame in rest for frame in out), "frames out of order, changed or duplicated"


def test_frame_queue_drops_whole_frames_when_full():
    """A reader that waits: 300-byte frames are kept until 1 KiB is full (three), each
    further one is dropped whole and counted; then the three leave whole."""
    frames = [(bytes([k]) * 300, True, True) for k in range(10)]
    out, overflows = run_queue(frames, depth=1024, hold_from=0, seed=1)
    assert out == [(d, 0) for d, _, _ in frames[:3]]
    assert overflows == 7


@pytest.mark.parametrize("before", [11, 15, 20])
def test_frame_queue_is_full_at_any_pointer_phase(before):
    """The same once the queue's pointers have gone round (``before`` 100-byte frames read
    out first: the writer's pointer wraps while the queue fills): the queue still fills at
    1 KiB and drops
    whole frames, whatever the pointers' phase. (A fullness check on the pointers' full-width
    difference missed it once the writer had wrapped and the reader not, and overwrote bytes
    not yet read.)"""
    first = [(bytes([0x80 + k]) * 100, True, True) for k in range(before)]
    held = [(bytes([k]) * 300, True, True) for k in range(10)]
    out, overflows = run_queue(first + held, depth=1024, hold_from=before, seed=2)
    assert out == [(d, 0) for d, _, _ in first + held[:3]]
    assert overflows == 7


@pytest.mark.parametrize("seed, registered", [(3, False), (4, False), (3, True)])
def test_frame_queue_cuts_a_begun_frame_that_no_longer_fits(seed, registered):
    """A kept frame longer than the queue, read cut-through by a reader that takes a byte
    every other cycle: the reader has begun it when the queue fills, so it cannot be rewound;
    it leaves cut short where the queue filled, marked bad with a size error, and counted; the
    frames after it leave whole. (Before this was handled the reader ran on through stale
    bytes: a frame of old data marked good.)"""
    depth = 256
    long_frame = bytes(range(256)) * 4
    frames = [(long_frame, True, True), (bytes([0x55]) * 100, True, True),
              (bytes([0x66]) * 70, True, True)]
    out, overflows = run_queue(frames, depth=depth, backpressure=0.5, seed=seed,
                               registered=registered)
    assert overflows == 1
    (cut, cut_status), *rest = out
    assert cut_status == 0b1001
    assert depth // 2 <= len(cut) < len(long_frame) and long_frame.startswith(cut)
    assert rest == [(d, 0) for d, _, _ in frames[1:]]


@pytest.mark.parametrize("lanes", [1, 2])
def test_frame_to_rx_beats_as_a_mac_hands_them_on(lanes):
    """Frames (random pauses inside and between them, random status) come out as a MAC hands
    them on: the beat of bytes ``i`` .. ``i + lanes - 1`` with index ``i``, the end pulse the
    cycle after the last beat with the frame's length and its status, then at least ``gap``
    idle cycles; and no ``rx`` member follows the input within a cycle (all from
    flip-flops)."""
    gap = 16
    dut = FrameToRxBeats(lanes=lanes, gap=gap)
    rng = random.Random(7 + lanes)
    frames = [(rng.randbytes(rng.randrange(1, 120)), rng.randrange(16)) for _ in range(30)]
    members = ("valid", "data", "index", "end", "ok", "err_fcs", "err_rx_er", "err_size")
    seen = []

    async def source(ctx):
        s = dut.s_axis
        for data, status in frames:
            for i in range(0, len(data), lanes):
                beat = data[i:i + lanes]
                while rng.random() < 0.3:
                    ctx.set(s.tvalid, 0)
                    await ctx.tick()
                last = i + lanes >= len(data)
                value = int.from_bytes(beat, "little")
                before = [ctx.get(getattr(dut.rx, n)) for n in members]
                for valid, junk, user in ((1, value ^ 0xFF, 15), (0, value, 0)):
                    ctx.set(s.tvalid, valid)
                    ctx.set(s.tdata, junk)
                    ctx.set(s.tlast, not last)
                    ctx.set(s.tuser, user)
                    assert [ctx.get(getattr(dut.rx, n)) for n in members] == before
                ctx.set(s.tdata, value)
                if lanes > 1:
                    ctx.set(s.tkeep, (1 << len(beat)) - 1)
                ctx.set(s.tlast, last)
                ctx.set(s.tuser, status if last else 0)
                ctx.set(s.tvalid, 1)
                await ctx.tick().until(s.tready)
            ctx.set(s.tvalid, 0)
        await ctx.tick().repeat(gap + 4)

    async def monitor(ctx):
        while True:
            seen.append({n: ctx.get(getattr(dut.rx, n)) for n in members})
            await ctx.tick()

    simulate(dut, source, background=[monitor])
    cycle, last_end = 0, None
    for data, status in frames:
        while not seen[cycle]["valid"]:
            assert not seen[cycle]["end"]
            cycle += 1
        if last_end is not None:
            assert cycle - last_end - 1 >= gap
        for i in range(0, len(data), lanes):
            while not seen[cycle]["valid"]:
                assert not seen[cycle]["end"]
                cycle += 1
            beat = data[i:i + lanes]
            got = seen[cycle]["data"].to_bytes(lanes, "little")[:len(beat)]
            assert (got, seen[cycle]["index"]) == (beat, i)
            cycle += 1
        end = seen[cycle]
        assert end["end"] and not end["valid"] and end["index"] == len(data)
        assert (end["ok"], end["err_fcs"], end["err_rx_er"], end["err_size"]) == (
            1 - (status & 1), status >> 1 & 1, status >> 2 & 1, status >> 3 & 1)
        last_end = cycle
        cycle += 1
    assert not any(c["valid"] or c["end"] for c in seen[cycle:])


def test_frame_queue_parameters():
    with pytest.raises(ParameterError, match="depth must be a power of two"):
        FrameQueue(3000)
    with pytest.raises(ParameterError, match="frames must be an integer in 2..64"):
        FrameQueue(2048, frames=1)
