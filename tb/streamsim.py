"""amaranth.sim drivers for AXI4-Stream ports: fast unit tests of internal blocks.

The same roles as the cocotb benches (source with random idle, sink with random
backpressure), for blocks that are not exported tops. Beats are ``(tdata, tlast)`` tuples,
or ``(tdata, tlast, tkeep)`` where ``tkeep`` matters; messages are lists of ``tdata`` values.
"""

import random

from amaranth.sim import Simulator

__all__ = ["StreamSource", "StreamSink", "simulate", "messages_to_beats", "beats_to_messages"]


def messages_to_beats(messages):
    return [(data, int(i == len(message) - 1))
            for message in messages for i, data in enumerate(message)]


def beats_to_messages(beats):
    messages, current = [], []
    for data, last in beats:
        current.append(data)
        if last:
            messages.append(current)
            current = []
    return messages, current


class StreamSource:
    """Drives ``port`` (an ``In`` stream of the DUT) with beats, pausing at random.

    ``tvalid`` stays high with a stable payload until the beat transfers (AXI rule). A beat
    without ``tkeep`` keeps every byte.
    """

    def __init__(self, port, beats, *, idle=0.0, seed=0, domain_tick=None):
        self.port = port
        self.beats = list(beats)
        self.idle = idle
        self.rng = random.Random(seed)
        self.sent = 0
        self.tick = domain_tick

    async def run(self, ctx):
        port = self.port
        tick = self.tick or (lambda: ctx.tick())
        for data, last, *keep in self.beats:
            while self.rng.random() < self.idle:
                ctx.set(port.tvalid, 0)
                await tick()
            ctx.set(port.tdata, data)
            ctx.set(port.tlast, last)
            if hasattr(port, "tkeep"):
                ctx.set(port.tkeep, keep[0] if keep else (1 << len(port.tkeep)) - 1)
            ctx.set(port.tvalid, 1)
            await tick().until(port.tready)
            self.sent += 1
        ctx.set(port.tvalid, 0)


class StreamSink:
    """Takes beats from ``port`` (an ``Out`` stream of the DUT) with random backpressure;
    ``keep`` records ``(tdata, tlast, tkeep)``."""

    def __init__(self, port, *, backpressure=0.0, seed=1, domain_tick=None, keep=False):
        self.port = port
        self.keep = keep
        self.backpressure = backpressure
        self.rng = random.Random(seed)
        self.beats = []
        self.tick = domain_tick
        self.paused = False

    async def run(self, ctx):
        port = self.port
        tick = self.tick or (lambda: ctx.tick())
        while True:
            ready = not self.paused and self.rng.random() >= self.backpressure
            ctx.set(port.tready, ready)
            *_, valid, data, last, tkeep = await tick().sample(
                port.tvalid, port.tdata, port.tlast, port.tkeep if self.keep else port.tlast)
            if ready and valid:
                self.beats.append((data, last, tkeep) if self.keep else (data, last))


def simulate(dut, *testbenches, background=(), clocks=None, vcd=None):
    """Run ``testbenches`` (async functions of ``ctx``) to completion against ``dut``.

    ``background`` testbenches (sinks) run while the others are alive. ``clocks`` maps domain
    names to periods in seconds (default: ``sync`` at 10 ns).
    """
    sim = Simulator(dut)
    for domain, period in (clocks or {"sync": 10e-9}).items():
        sim.add_clock(period, domain=domain)
    for bench in testbenches:
        sim.add_testbench(bench)
    for bench in background:
        sim.add_testbench(bench, background=True)
    if vcd:
        with sim.write_vcd(str(vcd)):
            sim.run()
    else:
        sim.run()
