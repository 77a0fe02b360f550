"""TcprosEndpoint's message framing on its own, against a Python model of the session
(docs/network.md, "TCPROS in hardware"): a subscriber drops empty messages and those longer
than MAX_MSG whole and stays in step with the stream; a publisher pads a message whose
``tlast`` comes before its ``tuser`` length with zeros and cuts one that runs past it, so the
peer's framing survives (``length_mismatch``). The session's byte streams and the message
streams run under random idle and backpressure, with beats of one byte anywhere in the
session's stream. The inputs are framed by gen.msg.ros1; the publisher's expected bytes
are TCPROS' framing as the ROS 1 wiki gives it (``uint32_le`` length, then the body),
written out here, not taken from the RTL or from gen.msg.ros1."""

import random
import struct

import pytest

from gen.msg.ros1 import encode_connection_header, frame_message
from hdl.net.tcp import TcpState
from hdl.ros1.registers import COUNTERS, COUNTERS_OFFSET, CTRL, ERRORS, REG
from hdl.ros1.tcpros import TcprosEndpoint
from tb.streamsim import simulate


async def handshake(ctx, port):
    """Wait for the clock edge at which the beat on ``port`` transfers."""
    while True:
        *_, ready = await ctx.tick().sample(port.tready)
        if ready:
            return


def session_beats(data, lanes, rng):
    """``data`` as session beats ``(tdata, tkeep)``: ``lanes`` bytes, or one at random."""
    beats, i = [], 0
    while i < len(data):
        n = 1 if lanes == 1 or rng.random() < 0.3 or i + 1 == len(data) else 2
        chunk = data[i:i + n]
        beats.append((int.from_bytes(chunk, "little"), (1 << n) - 1))
        i += n
    return beats


def message_beats(body, declared, lanes):
    """A message on ``s_axis``: ``(tdata, tkeep, tlast, tuser)`` beats, ``tuser`` the length
    the sender declares (an empty body still has one beat, with nothing kept past lane 0)."""
    beats = []
    chunks = [body[i:i + lanes] for i in range(0, len(body), lanes)] or [b"\0"]
    for k, chunk in enumerate(chunks):
        beats.append((int.from_bytes(chunk, "little"), (1 << len(chunk)) - 1,
                      int(k == len(chunks) - 1), declared))
    return beats


class EndpointTB:
    """One endpoint with a session model: the session opens when the endpoint asks, carries
    ``rx_bytes`` to it with random gaps and takes its transmit bytes with random
    backpressure."""

    def __init__(self, role, lanes, rx_bytes, *, seed, idle=0.3, backpressure=0.3):
        self.rx_bytes = rx_bytes
        self.dut = TcprosEndpoint(role, lanes=lanes)
        self.lanes = lanes
        self.rng = random.Random(seed)
        self.idle, self.backpressure = idle, backpressure
        self.tx_bytes = bytearray()
        self.done = False

    async def write(self, ctx, name, value):
        offset, size, _ = REG[name]
        regs = self.dut.regs
        for b, byte in enumerate(value.to_bytes(size, "big")):
            ctx.set(regs.addr, offset + b)
            ctx.set(regs.wd, byte)
            ctx.set(regs.we, 1)
            await ctx.tick()
            ctx.set(regs.we, 0)
            while not ctx.get(regs.ack):
                await ctx.tick()

    async def read(self, ctx, offset, size):
        regs = self.dut.regs
        value = 0
        for b in range(size):
            ctx.set(regs.addr, offset + b)
            ctx.set(regs.re, 1)
            await ctx.tick()
            ctx.set(regs.re, 0)
            while not ctx.get(regs.ack):
                await ctx.tick()
            value = value << 8 | ctx.get(regs.rd)
        return value

    async def counter(self, ctx, name):
        return await self.read(ctx, COUNTERS_OFFSET + 4 * COUNTERS.index(name), 4)

    async def run_session(self, ctx):
        tcp = self.dut.tcp
        while True:
            opened = ctx.get(tcp.open_req)
            ctx.set(tcp.open_ack, opened)
            ctx.set(tcp.state, TcpState.ESTABLISHED if opened else TcpState.CLOSED)
            ready = self.rng.random() >= self.backpressure
            tx = tcp.tx
            ctx.set(tx.tready, ready)
            *_, valid, data, keep = await ctx.tick().sample(
                tx.tvalid, tx.tdata, tx.tkeep if self.lanes > 1 else tx.tvalid)
            if ready and valid:
                self.tx_bytes += bytes((data >> 8 * k) & 0xFF for k in range(self.lanes)
                                       if keep >> k & 1)

    async def run_rx(self, ctx):
        rx = self.dut.tcp.rx
        for tdata, tkeep in session_beats(self.rx_bytes, self.lanes, self.rng):
            while self.rng.random() < self.idle:
                ctx.set(rx.tvalid, 0)
                await ctx.tick()
            ctx.set(rx.tdata, tdata)
            if self.lanes > 1:
                ctx.set(rx.tkeep, tkeep)
            ctx.set(rx.tvalid, 1)
            await handshake(ctx, rx)
        ctx.set(rx.tvalid, 0)


@pytest.mark.parametrize("lanes", [1, 2])
def test_subscriber_drops_empty_and_oversized_messages_and_stays_in_step(lanes):
    """MAX_MSG 40: bodies of 0 (nothing delivered), 1 .. 40 bytes (delivered whole, ``tuser``
    their length, ``tlast`` on the last byte), 41 and 300 (skipped to their end and counted);
    every message after a dropped one arrives intact."""
    rng = random.Random(lanes)
    lengths = [5, 0, 1, 2, 3, 41, 4, 40, 300, 39, 0, 7, 2, 41, 1] + \
        [rng.randrange(0, 60) for _ in range(30)]
    bodies = [rng.randbytes(n) for n in lengths]
    stream = encode_connection_header({"type": "std_msgs/String", "md5sum": "*"}) + \
        b"".join(frame_message(b) for b in bodies)
    expected = [b for b in bodies if 1 <= len(b) <= 40]
    tb = EndpointTB("subscriber", lanes, stream, seed=lanes)
    dut = tb.dut
    got, current, tusers = [], bytearray(), []

    async def sink(ctx):
        mo = dut.m_axis
        while True:
            ready = tb.rng.random() >= 0.3
            ctx.set(mo.tready, ready)
            *_, valid, data, keep, last, tuser = await ctx.tick().sample(
                mo.tvalid, mo.tdata, mo.tkeep if lanes > 1 else mo.tvalid, mo.tlast, mo.tuser)
            if ready and valid:
                current.extend((data >> 8 * k) & 0xFF for k in range(lanes) if keep >> k & 1)
                tusers.append(tuser)
                if last:
                    assert set(tusers) == {len(current)}, (tusers, len(current))
                    got.append(bytes(current))
                    current.clear()
                    tusers.clear()

    counts = {}

    async def bench(ctx):
        await tb.write(ctx, "CHECK", 0)
        await tb.write(ctx, "MAX_MSG", 40)
        await tb.write(ctx, "CTRL", CTRL["START"])
        for _ in range(20 * len(stream) + 2000):
            if len(got) == len(expected):
                break
            await ctx.tick()
        await ctx.tick().repeat(50)
        for name in ("messages_rx", "messages_dropped"):
            counts[name] = await tb.counter(ctx, name)

    simulate(dut, bench, background=[tb.run_session, sink, tb.run_rx])
    assert got == expected
    assert current == bytearray()
    assert counts == {"messages_rx": len(expected),
                      "messages_dropped": len(bodies) - len(expected)}


@pytest.mark.parametrize("lanes", [1, 2])
def test_publisher_pads_short_and_cuts_long_messages(lanes):
    """Each message leaves as its declared (``tuser``) length and that many bytes: a body
    shorter than declared padded with zeros, a longer one cut (the rest discarded up to its
    ``tlast``), a declared length of 0 as four zero bytes alone; the next message follows in
    step, and ERROR says ``length_mismatch``."""
    rng = random.Random(10 + lanes)
    cases = [(5, 5), (3, 7), (8, 2), (0, 0), (1, 1), (2, 1), (1, 2), (6, 0), (9, 9)]
    cases += [(rng.randrange(0, 40), rng.randrange(0, 40)) for _ in range(30)]
    messages = [(rng.randbytes(actual), declared) for actual, declared in cases]
    expected = b"".join(struct.pack("<I", declared) +
                        (body[:declared] + bytes(max(0, declared - len(body))))
                        for body, declared in messages)
    subscriber = encode_connection_header({"topic": "/chatter", "type": "std_msgs/String",
                                           "md5sum": "*"})
    tb = EndpointTB("publisher", lanes, subscriber, seed=20 + lanes)
    dut = tb.dut
    state = {}

    async def source(ctx):
        s = dut.s_axis
        while "started" not in state:
            await ctx.tick()
        for body, declared in messages:
            for tdata, tkeep, tlast, tuser in message_beats(body, declared, lanes):
                while tb.rng.random() < 0.3:
                    ctx.set(s.tvalid, 0)
                    await ctx.tick()
                ctx.set(s.tdata, tdata)
                if lanes > 1:
                    ctx.set(s.tkeep, tkeep)
                ctx.set(s.tlast, tlast)
                ctx.set(s.tuser, tuser)
                ctx.set(s.tvalid, 1)
                await handshake(ctx, s)
        ctx.set(s.tvalid, 0)

    async def bench(ctx):
        await tb.write(ctx, "CHECK", 0)
        # BLOCK: messages wait for the subscriber instead of being dropped
        await tb.write(ctx, "CTRL", CTRL["START"] | CTRL["BLOCK"])
        state["started"] = True
        for _ in range(40 * len(expected) + 2000):
            if len(tb.tx_bytes) >= len(expected):
                break
            await ctx.tick()
        await ctx.tick().repeat(100)
        state["error"] = await tb.read(ctx, *REG["ERROR"][:2])
        state["messages_tx"] = await tb.counter(ctx, "messages_tx")

    simulate(dut, bench, background=[tb.run_session, source, tb.run_rx])
    assert bytes(tb.tx_bytes) == expected
    assert state["messages_tx"] == len(messages)
    assert state["error"] & ERRORS["length_mismatch"]
