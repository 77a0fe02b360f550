"""The test bench of the ``topic`` top: publisher sources and subscriber sinks under random idle
and backpressure, and the delivery scoreboard.

Under Verilator the ports are compiled (:func:`host.compiled.streams.stream_harness`): packets
move and pauses are drawn in the simulator, and the beat, message and stall counts come from
its counters; under Icarus they are cocotbext-axi's, watched by :class:`PortWatch`."""

import logging
import os
import random

import cocotb
import pytest
from cocotb.triggers import RisingEdge, gather, with_timeout
from cocotbext.axi import AxiStreamFrame

from host.compiled.streams import (
    CompiledStreamSink,
    CompiledStreamSource,
    pause_randomly,
    stream_harness,
    stream_sink,
    stream_source,
)
from host.simulator import clock_cycles, start_clock
from tb.harness import bench_params
from tb.models.topic import TopicScoreboard, random_lengths, tagged_message
from tb.streams import reset_aresetn

__all__ = ["CLOCK_NS", "CONFIGS", "PARAMS", "ONE_PUBLISHER", "LOSSY", "CompiledPortWatch",
           "PortWatch", "TopicTB", "lossless", "topic_harness"]


CLOCK_NS = 10


CONFIGS = {
    "1x1_w8": dict(pubs=1, subs=1, data_width=8),
    "1x3_w8": dict(pubs=1, subs=3, data_width=8),
    "3x1_w8": dict(pubs=3, subs=1, data_width=8),
    "3x3_w8": dict(pubs=3, subs=3, data_width=8),
    "4x4_w8": dict(pubs=4, subs=4, data_width=8),
    "1x1_w64": dict(pubs=1, subs=1, data_width=64),
    "1x3_w64": dict(pubs=1, subs=3, data_width=64),
    "3x1_w64": dict(pubs=3, subs=1, data_width=64),
    "3x3_w64": dict(pubs=3, subs=3, data_width=64),
    "4x4_w64": dict(pubs=4, subs=4, data_width=64),
    "4x4_w512": dict(pubs=4, subs=4, data_width=512),
    "3x3_w64_fifo64": dict(pubs=3, subs=3, data_width=64, fifo_depth=64),
    "2x3_w64_keep_last": dict(pubs=2, subs=3, data_width=64, fifo_depth=256, qos="keep_last",
                              history=4),
    "2x3_w64_best_effort": dict(pubs=2, subs=3, data_width=64, fifo_depth=128,
                                qos="best_effort"),
    "16x16_w32": pytest.param(dict(pubs=16, subs=16, data_width=32), marks=pytest.mark.full),
    "2x2_w1024": pytest.param(dict(pubs=2, subs=2, data_width=1024), marks=pytest.mark.full),
    "1x1_w64_fifo512": pytest.param(dict(pubs=1, subs=1, data_width=64, fifo_depth=512),
                                    marks=pytest.mark.full),
    "4x4_w8_keep_last": pytest.param(dict(pubs=4, subs=4, data_width=8, fifo_depth=1024,
                                          qos="keep_last", history=8), marks=pytest.mark.full),
    "4x2_w32_best_effort_nomon": pytest.param(
        dict(pubs=4, subs=2, data_width=32, fifo_depth=64, qos="best_effort", monitor=False),
        marks=pytest.mark.full),
}


# Inside the simulator: the configuration under test (empty when pytest imports this module).
PARAMS = bench_params() if "ROSGATE_PARAMS" in os.environ else {}


ONE_PUBLISHER = PARAMS.get("pubs", 2) == 1


LOSSY = PARAMS.get("qos", "keep_all") != "keep_all"


def topic_harness(params):
    """The Verilator harness of a topic configuration: every publisher and subscriber port on
    a compiled FIFO."""
    return stream_harness(sources=[f"s{i}_axis" for i in range(params["pubs"])],
                          sinks=[f"m{j}_axis" for j in range(params["subs"])])


class CompiledPortWatch:
    """:class:`PortWatch`'s counts of a compiled port, kept by the simulator."""

    def __init__(self, port):
        self.port = port
        self._keep = False

    beats = property(lambda self: self.port.counter("beats"))
    messages = property(lambda self: self.port.counter("packets"))
    stalls = property(lambda self: self.port.counter("stalls"))
    transfer_cycles = property(lambda self: self.port.transfers)

    @property
    def keep_cycles(self):
        return self._keep

    @keep_cycles.setter
    def keep_cycles(self, value):
        self._keep = bool(value)
        self.port.record_transfers(self._keep)

    def clear(self):
        self.port.clear_counters()


def port_watch(clock, port):
    """The watch of a source or sink: the simulator's counts for a compiled port, else a
    :class:`PortWatch` on its wires."""
    if isinstance(port, (CompiledStreamSource, CompiledStreamSink)):
        return CompiledPortWatch(port)
    return PortWatch(clock, port.bus)


class PortWatch:
    """Counts beats, messages and stall cycles of one port from its handshake wires."""

    def __init__(self, clock, bus):
        self.bus = bus
        self.clock = clock
        self.beats = self.messages = self.stalls = 0
        self.cycle = 0
        self.transfer_cycles = []
        self.keep_cycles = False
        cocotb.start_soon(self._run())

    async def _run(self):
        while True:
            await RisingEdge(self.clock)
            self.cycle += 1
            valid = str(self.bus.tvalid.value) == "1"
            ready = str(self.bus.tready.value) == "1"
            if valid and ready:
                self.beats += 1
                if self.keep_cycles:
                    self.transfer_cycles.append(self.cycle)
                if str(self.bus.tlast.value) == "1":
                    self.messages += 1
            elif valid:
                self.stalls += 1

    def clear(self):
        self.beats = self.messages = self.stalls = 0
        self.transfer_cycles = []


class TopicTB:
    def __init__(self, dut, seed=None):
        self.dut = dut
        self.params = bench_params()
        self.pubs = self.params["pubs"]
        self.subs = self.params["subs"]
        self.bytes_per_beat = self.params["data_width"] // 8
        self.qos = self.params.get("qos", "keep_all")
        self.fifo_depth = self.params.get("fifo_depth", 0)
        self.monitor = self.params.get("monitor", True)
        self.rng = random.Random(seed if seed is not None else cocotb.RANDOM_SEED)
        self.log = logging.getLogger("cocotb.tb")
        start_clock(dut.aclk, CLOCK_NS)
        self.sources = [stream_source(dut, f"s{i}_axis") for i in range(self.pubs)]
        self.sinks = [stream_sink(dut, f"m{j}_axis") for j in range(self.subs)]
        self.pub_watch = [port_watch(dut.aclk, s) for s in self.sources]
        self.sub_watch = [port_watch(dut.aclk, s) for s in self.sinks]

    def set_idle(self, probability, max_run=1):
        """Random idle cycles on every publisher port (0: none)."""
        for source in self.sources:
            pause_randomly(source, self.rng, probability, max_run)

    def set_backpressure(self, probability, max_run=1):
        """Random backpressure on every subscriber port (0: none)."""
        for sink in self.sinks:
            pause_randomly(sink, self.rng, probability, max_run)

    async def reset(self):
        await reset_aresetn(self.dut)
        for watch in self.pub_watch + self.sub_watch:
            watch.clear()

    async def cycles(self, n):
        await clock_cycles(self.dut.aclk, n)

    def frame(self, message):
        return AxiStreamFrame(message)

    def check_frame(self, sub, frame):
        """Return the message bytes of a received frame after checking its ``tkeep``."""
        keep = list(frame.tkeep) if frame.tkeep else [1] * len(frame.tdata)
        length = sum(keep)
        bpb = self.bytes_per_beat
        assert len(frame.tdata) % bpb == 0, f"sub {sub}: frame not a whole number of beats"
        assert keep == [1] * length + [0] * (len(keep) - length), \
            f"sub {sub}: tkeep not contiguous from byte 0: {keep}"
        assert len(keep) - length < bpb, f"sub {sub}: a whole beat with tkeep = 0"
        return bytes(frame.tdata[:length])

    def counter(self, name):
        return int(getattr(self.dut, f"monitor_{name}").value)

    async def run_publishers(self, scoreboard, plan):
        """Send ``plan[pub]`` (lists of messages) from every publisher; wait until sent."""
        for pub, messages in enumerate(plan):
            for message in messages:
                scoreboard.publish(pub, message)
                await self.sources[pub].send(self.frame(message))
        await gather(*(source.wait() for source in self.sources))

    async def run_subscriber(self, scoreboard, sub, count):
        for _ in range(count):
            frame = await self.sinks[sub].recv(compact=False)
            scoreboard.deliver(sub, self.check_frame(sub, frame))

    async def run_traffic(self, plan, *, timeout_cycles):
        """Publish ``plan`` and check every subscriber's deliveries.

        ``keep_all``: everything arrives. Lossy QoS: what arrives is whole and in order, and
        every missing message is counted in the subscriber's drop counter.
        """
        lossy = self.qos != "keep_all"
        scoreboard = TopicScoreboard(self.pubs, self.subs, lossless=not lossy)
        total = sum(len(messages) for messages in plan)
        if lossy:
            await self.run_publishers(scoreboard, plan)
            window = 4 * max(map(self.beats, sum(plan, []))) + 50
            for _ in range(timeout_cycles // window + 1):
                before = [w.beats for w in self.sub_watch]
                await self.cycles(window)
                if [w.beats for w in self.sub_watch] == before:
                    break
            for j, sink in enumerate(self.sinks):
                while not sink.empty():
                    scoreboard.deliver(j, self.check_frame(j, sink.recv_nowait(compact=False)))
            if self.monitor:
                scoreboard.check_complete(drops=[self.counter(f"drops{j}")
                                                 for j in range(self.subs)])
            return scoreboard
        receivers = [cocotb.start_soon(self.run_subscriber(scoreboard, j, total))
                     for j in range(self.subs)]
        await self.run_publishers(scoreboard, plan)
        await with_timeout(gather(*receivers), timeout_cycles * CLOCK_NS, "ns")
        scoreboard.check_complete()
        return scoreboard

    def random_plan(self, messages_per_pub, *, max_bytes, with_4k=True):
        """Tagged messages per publisher, random lengths; one of 4 KiB somewhere if asked."""
        lengths = [random_lengths(self.rng, messages_per_pub, max_bytes=max_bytes,
                                  bytes_per_beat=self.bytes_per_beat, long_share=0)
                   for _ in range(self.pubs)]
        if with_4k:
            pub = self.rng.randrange(self.pubs)
            lengths[pub].insert(self.rng.randrange(len(lengths[pub]) + 1), 4096)
        return [[tagged_message(pub, seq, n, self.rng) for seq, n in enumerate(ls)]
                for pub, ls in enumerate(lengths)]

    def max_lossless_bytes(self):
        """Longest message a lossy subscriber FIFO always takes while its reader keeps up."""
        if self.qos == "keep_last":
            return self.fifo_depth // self.params["history"] * self.bytes_per_beat
        return self.fifo_depth // 2 * self.bytes_per_beat

    def beats(self, message):
        return -(-len(message) // self.bytes_per_beat)

    def check_monitor(self, plan, scoreboard):
        """The topic's monitor counters equal what the bench saw on the wires."""
        if not self.monitor:
            return
        for i, watch in enumerate(self.pub_watch):
            assert self.counter(f"pub{i}_messages") == watch.messages == len(plan[i])
            assert self.counter(f"pub{i}_beats") == watch.beats == sum(map(self.beats, plan[i]))
            assert self.counter(f"pub{i}_stalls") == watch.stalls
        for j, watch in enumerate(self.sub_watch):
            assert self.counter(f"sub{j}_messages") == watch.messages == \
                len(scoreboard.received[j])
            assert self.counter(f"sub{j}_beats") == watch.beats
            assert self.counter(f"sub{j}_stalls") == watch.stalls


def lossless(tb):
    return tb.qos == "keep_all"
