# amaranth: UnusedElaboratable=no
"""The clock-domain bridges of the two-lane engine (hdl/net/mac.py, docs/network.md "Clocks")
in amaranth.sim with a 125 MHz GMII clock and a 62.5 MHz core clock: RxBeatBridge behind a
GmiiRx gives every frame's bytes, length and status as GmiiRx saw them (frames of odd and
even length, bad FCS, RX_ER, runts, inter-frame gaps down to 4 bytes); with a core clock
too slow for the line a frame is lost as an RX error, never delivered wrong. TxBeatBridge
in front of a GmiiTx sends each frame as given, padded and with its FCS (checked with
``zlib.crc32``), without a TX_ER. FrameStreamBridge pairs a frame queue's bytes into
two-byte beats on the core clock, every frame whole."""

import random
import zlib

import pytest
from amaranth.hdl import ClockDomain, DomainRenamer, Elaboratable, Module
from amaranth.lib import wiring

from hdl.net.mac import GmiiRx, GmiiTx, RxBeatBridge, TxBeatBridge
from hdl.net.queue import FrameStreamBridge

from .streamsim import simulate

GMII_PERIOD, CORE_PERIOD = 8e-9, 16e-9


class RxBridgeHarness(Elaboratable):
    def __init__(self):
        self.mac = GmiiRx()
        self.bridge = RxBeatBridge()

    def elaborate(self, platform):
        m = Module()
        m.domains.gmii = ClockDomain()
        m.submodules.mac = DomainRenamer("gmii")(self.mac)
        m.submodules.bridge = self.bridge
        wiring.connect(m, self.mac.rx, self.bridge.gmii)
        return m


def random_frames(rng, count):
    """(bytes on the wire after the SFD, RX_ER at byte or None) of random frames: good ones
    of odd and even length, bad FCS, RX_ER, runts."""
    out = []
    for _ in range(count):
        body = rng.randbytes(rng.choice([60, 61, 63, rng.randrange(60, 1515)]))
        frame = body + zlib.crc32(body).to_bytes(4, "little")
        kind = rng.random()
        error = None
        if kind < 0.1:
            frame = frame[:-1] + bytes([frame[-1] ^ 0x10])          # bad FCS
        elif kind < 0.2:
            error = rng.randrange(len(frame))                      # RX_ER inside
        elif kind < 0.25:
            frame = frame[:rng.randrange(20, 60)]                   # a runt
        out.append((frame, error))
    return out


def run_rx_bridge(frames, *, gap, core_period=CORE_PERIOD):
    """Frames through GmiiRx and RxBeatBridge; returns per frame (bytes, length, ok, errs)
    as the core side saw them."""
    dut = RxBridgeHarness()
    rx = dut.bridge.rx
    got = []

    async def drive(ctx):
        for frame, error in frames:
            for k, byte in enumerate(b"\x55" * 7 + b"\xd5" + frame):
                ctx.set(dut.mac.gmii_rxd, byte)
                ctx.set(dut.mac.gmii_rx_dv, 1)
                ctx.set(dut.mac.gmii_rx_er, error is not None and k - 8 == error)
                await ctx.tick("gmii")
            ctx.set(dut.mac.gmii_rx_dv, 0)
            ctx.set(dut.mac.gmii_rx_er, 0)
            for _ in range(gap(ctx)):
                await ctx.tick("gmii")
        for _ in range(200):
            await ctx.tick("gmii")

    async def watch(ctx):
        data = bytearray()
        expected_index = 0
        while True:
            await ctx.tick()
            if ctx.get(rx.valid):
                assert ctx.get(rx.index) == expected_index, "beats out of order"
                data += ctx.get(rx.data).to_bytes(2, "little")
                expected_index += 2
            if ctx.get(rx.end):
                length = ctx.get(rx.index)
                got.append((bytes(data[:length]), length, ctx.get(rx.ok),
                            (ctx.get(rx.err_fcs), ctx.get(rx.err_rx_er), ctx.get(rx.err_size))))
                data, expected_index = bytearray(), 0

    simulate(dut, drive, background=[watch], clocks={"sync": core_period, "gmii": GMII_PERIOD})
    return got


@pytest.mark.parametrize("gap", [12, 4])
def test_rx_bridge_delivers_frames_as_received(gap):
    rng = random.Random(gap)
    frames = random_frames(rng, 40)
    got = run_rx_bridge(frames, gap=lambda ctx: gap + rng.randrange(0, 3))
    assert len(got) == len(frames)
    for (frame, error), (data, got_length, got_ok, errs) in zip(frames, got):
        length = len(frame)
        assert got_length == length
        assert data == frame, "bytes changed"
        fcs_good = zlib.crc32(frame) == 0x2144DF1C
        assert got_ok == (fcs_good and error is None and 64 <= length <= 1518)
        if not got_ok:
            err_fcs, err_rx_er, err_size = errs
            assert err_size == (not 64 <= length <= 1518)
            assert err_rx_er == (error is not None and not err_size)


def test_rx_bridge_loses_frames_whole_when_the_core_is_too_slow():
    """A core clock at 40 % of the GMII clock cannot keep up with back-to-back long frames:
    frames that lose bytes end as RX errors; every frame delivered as good is intact, and
    frames stay in order."""
    rng = random.Random(5)
    frames = []
    for n in range(30):
        body = bytes([n]) + rng.randbytes(rng.choice([1400, 1500, 59]))
        frames.append((body + zlib.crc32(body).to_bytes(4, "little"), None))
    got = run_rx_bridge(frames, gap=lambda ctx: 12, core_period=20e-9)
    good = [data for data, _, ok, _ in got if ok]
    lost = [errs for _, _, ok, errs in got if not ok]
    assert lost and all(errs == (0, 1, 0) for errs in lost), lost[:3]
    sent = [frame for frame, _ in frames]
    assert all(data in sent for data in good)
    order = [sent.index(data) for data in good]
    assert order == sorted(order)


class TxBridgeHarness(Elaboratable):
    def __init__(self):
        self.bridge = TxBeatBridge()
        self.mac = GmiiTx()

    def elaborate(self, platform):
        m = Module()
        m.domains.gmii = ClockDomain()
        m.submodules.bridge = self.bridge
        m.submodules.mac = DomainRenamer("gmii")(self.mac)
        wiring.connect(m, self.bridge.gmii, self.mac.s_axis)
        return m


def test_tx_bridge_sends_frames_without_underrun():
    """Frames of 1..1514 bytes, each offered a beat per core cycle once started (the
    builder's rule) after random pauses, leave GMII with their FCS, padded to 60 bytes,
    never with TX_ER."""
    rng = random.Random(9)
    frames = [rng.randbytes(rng.choice([1, 2, 41, 42, 59, 60, 61, rng.randrange(60, 1515)]))
              for _ in range(30)]
    dut = TxBridgeHarness()
    s = dut.bridge.s_axis
    wire = []

    async def source(ctx):
        for frame in frames:
            for _ in range(rng.randrange(0, 30)):
                ctx.set(s.tvalid, 0)
                await ctx.tick()
            for k in range(0, len(frame), 2):
                beat = frame[k:k + 2]
                ctx.set(s.tdata, int.from_bytes(beat, "little"))
                ctx.set(s.tkeep, (1 << len(beat)) - 1)
                ctx.set(s.tlast, k + 2 >= len(frame))
                ctx.set(s.tvalid, 1)
                await ctx.tick().until(s.tready)
            ctx.set(s.tvalid, 0)
        for _ in range(4000):
            await ctx.tick()

    async def watch(ctx):
        current = None
        while True:
            *_, en, er, data = await ctx.tick("gmii").sample(
                dut.mac.gmii_tx_en, dut.mac.gmii_tx_er, dut.mac.gmii_txd)
            assert not er, "TX_ER: the bridge ran dry inside a frame"
            if en:
                current = (current or bytearray())
                current.append(data)
            elif current is not None:
                wire.append(bytes(current))
                current = None

    simulate(dut, source, background=[watch], clocks={"sync": CORE_PERIOD, "gmii": GMII_PERIOD})
    assert len(wire) == len(frames)
    for frame, sent in zip(frames, wire):
        assert sent[:8] == b"\x55" * 7 + b"\xd5"
        body = frame.ljust(60, b"\0")
        assert sent[8:] == body + zlib.crc32(body).to_bytes(4, "little")


class FrameBridgeHarness(Elaboratable):
    def __init__(self):
        self.bridge = FrameStreamBridge()

    def elaborate(self, platform):
        m = Module()
        m.domains.gmii = ClockDomain()
        m.submodules.bridge = self.bridge
        return m


@pytest.mark.parametrize("idle,backpressure", [(0.0, 0.0), (0.3, 0.5)])
def test_frame_stream_bridge_pairs_bytes_across_clocks(idle, backpressure):
    """A queue's frames (byte stream with status on the last byte) written on the GMII clock
    come out on the core clock as two-byte beats: every frame whole, in order, odd lengths
    ending with ``tkeep`` 0b01, the status on the last beat; nothing lost under random
    pauses and backpressure."""
    rng = random.Random(int(10 * idle) + int(100 * backpressure))
    frames = [(rng.randbytes(rng.randrange(1, 200)), rng.randrange(16)) for _ in range(40)]
    dut = FrameBridgeHarness()
    s, o = dut.bridge.s_axis, dut.bridge.m_axis
    got, current = [], bytearray()

    async def source(ctx):
        for data, status in frames:
            for k, byte in enumerate(data):
                while rng.random() < idle:
                    ctx.set(s.tvalid, 0)
                    await ctx.tick("gmii")
                last = k == len(data) - 1
                ctx.set(s.tdata, byte)
                ctx.set(s.tlast, last)
                ctx.set(s.tuser, status if last else 0)
                ctx.set(s.tvalid, 1)
                await ctx.tick("gmii").until(s.tready)
            ctx.set(s.tvalid, 0)
        await ctx.tick("gmii").repeat(200)

    async def sink(ctx):
        nonlocal current
        while True:
            ready = rng.random() >= backpressure
            ctx.set(o.tready, ready)
            *_, valid, data, keep, last, user = await ctx.tick().sample(
                o.tvalid, o.tdata, o.tkeep, o.tlast, o.tuser)
            if valid and ready:
                assert keep in (0b01, 0b11) and (keep == 0b11 or last)
                current += data.to_bytes(2, "little")[:bin(keep).count("1")]
                if last:
                    got.append((bytes(current), user))
                    current = bytearray()

    simulate(dut, source, background=[sink], clocks={"sync": CORE_PERIOD, "gmii": GMII_PERIOD})
    assert got == frames
