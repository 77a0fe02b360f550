"""Bench of the exported ``topic`` top (hdl.dds.Topic; spec hmt.md §1-2, issue: foundation).

Every publisher port gets random idle, every subscriber port random backpressure
(cocotbext-axi pause generators); :class:`tb.models.topic.TopicScoreboard` checks that each
subscriber gets every message exactly once, whole, in per-publisher order, never interleaved.
"""

import logging
import os
import random

import cocotb
import pytest
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, RisingEdge, gather, with_timeout
from cocotbext.axi import AxiStreamBus, AxiStreamFrame, AxiStreamSink, AxiStreamSource

from tb.harness import bench_params, cocotb_bench
from tb.models.topic import TopicScoreboard, random_lengths, tagged_message
from tb.streams import bursty_pauses, random_pauses

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

#: Verilator runs these in test-full only; make test keeps them on Icarus, and Verilator on
#: the configurations that differ in kind (one publisher, widest, FIFO depth, QoS)
LONG = [(config_id, "verilator") for config_id in
        ("1x3_w8", "3x1_w8", "4x4_w8", "1x1_w64", "1x3_w64", "3x1_w64", "3x3_w64", "4x4_w64")]
test_topic = cocotb_bench("topic", CONFIGS, long=LONG)

# Inside the simulator: the configuration under test (empty when pytest imports this module).
PARAMS = bench_params() if "ROSGATE_PARAMS" in os.environ else {}
ONE_PUBLISHER = PARAMS.get("pubs", 2) == 1
LOSSY = PARAMS.get("qos", "keep_all") != "keep_all"


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
        cocotb.start_soon(Clock(dut.aclk, CLOCK_NS, unit="ns").start())
        self.sources = [AxiStreamSource(AxiStreamBus.from_prefix(dut, f"s{i}_axis"), dut.aclk,
                                        dut.aresetn, reset_active_level=False)
                        for i in range(self.pubs)]
        self.sinks = [AxiStreamSink(AxiStreamBus.from_prefix(dut, f"m{j}_axis"), dut.aclk,
                                    dut.aresetn, reset_active_level=False)
                      for j in range(self.subs)]
        for port in self.sources + self.sinks:
            port.log.setLevel(logging.WARNING)
        self.pub_watch = [PortWatch(dut.aclk, s.bus) for s in self.sources]
        self.sub_watch = [PortWatch(dut.aclk, s.bus) for s in self.sinks]

    def set_idle_generator(self, factory=None):
        for source in self.sources:
            source.set_pause_generator(factory() if factory else None)
            if factory is None:
                source.pause = False  # the generator may have stopped on a pause

    def set_backpressure_generator(self, factory=None):
        for sink in self.sinks:
            sink.set_pause_generator(factory() if factory else None)
            if factory is None:
                sink.pause = False

    async def reset(self):
        self.dut.aresetn.value = 0
        await ClockCycles(self.dut.aclk, 4)
        self.dut.aresetn.value = 1
        await ClockCycles(self.dut.aclk, 2)
        for watch in self.pub_watch + self.sub_watch:
            watch.clear()

    async def cycles(self, n):
        await ClockCycles(self.dut.aclk, n)

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


@cocotb.test()
async def random_traffic_idle_and_backpressure(dut):
    """Random lengths (1 beat .. 4 KiB), random idle on publishers, backpressure on subscribers."""
    tb = TopicTB(dut)
    await tb.reset()
    tb.set_idle_generator(lambda: random_pauses(tb.rng, 0.3))
    if lossless(tb):
        tb.set_backpressure_generator(lambda: bursty_pauses(tb.rng, 0.35, 8))
    plan = tb.random_plan(10, max_bytes=min(4096, 32 * tb.bytes_per_beat),
                          with_4k=lossless(tb))
    if not lossless(tb):
        # Lossy FIFOs store whole messages: keep each one small enough never to overflow a
        # subscriber that keeps up (the oversize case is qos_drops_whole_messages').
        limit = tb.max_lossless_bytes()
        plan = [[m[:limit] for m in messages] for messages in plan]
    beats = sum(tb.beats(m) for messages in plan for m in messages)
    scoreboard = await tb.run_traffic(plan, timeout_cycles=20 * beats + 2000)
    await tb.cycles(4)
    tb.check_monitor(plan, scoreboard)
    if tb.monitor and lossless(tb):
        for j in range(tb.subs):
            assert tb.counter(f"drops{j}") == 0


@cocotb.test()
async def back_to_back_full_rate(dut):
    """All ports ready: one beat per cycle, no idle cycle between messages, latency <= 2."""
    tb = TopicTB(dut)
    await tb.reset()
    watch = tb.sub_watch[0]
    watch.keep_cycles = True
    for w in tb.pub_watch:
        w.keep_cycles = True
    lengths = [1, 2 * tb.bytes_per_beat, 3 * tb.bytes_per_beat + 1, tb.bytes_per_beat, 37, 300]
    if not lossless(tb):
        # Equal lengths: a store-and-forward FIFO whose reader keeps up never drops them.
        lengths = [min(4 * tb.bytes_per_beat, tb.max_lossless_bytes())] * len(lengths)
    plan = [[tagged_message(pub, seq, n, tb.rng) for seq, n in enumerate(lengths)]
            for pub in range(tb.pubs)]
    # Queue everything before the first beat, so publishers never run dry.
    for source in tb.sources:
        source.pause = True
    scoreboard = TopicScoreboard(tb.pubs, tb.subs)
    total = sum(len(p) for p in plan)
    receivers = [cocotb.start_soon(tb.run_subscriber(scoreboard, j, total))
                 for j in range(tb.subs)]
    for pub, messages in enumerate(plan):
        for message in messages:
            scoreboard.publish(pub, message)
            await tb.sources[pub].send(tb.frame(message))
    await RisingEdge(dut.aclk)
    for source in tb.sources:
        source.pause = False
    beats = sum(tb.beats(m) for messages in plan for m in messages)
    await with_timeout(gather(*receivers), (beats * 4 + 200) * CLOCK_NS, "ns")
    scoreboard.check_complete()
    first_in = min(w.transfer_cycles[0] for w in tb.pub_watch)
    cycles = watch.transfer_cycles
    latency = cycles[0] - first_in
    span = cycles[-1] - cycles[0] + 1
    tb.log.info("beats %d, span %d cycles, latency %d cycles", beats, span, latency)
    assert len(cycles) == beats
    if tb.qos == "keep_all":
        assert span == beats, f"{span - beats} idle cycles between back-to-back messages"
    if not tb.fifo_depth:
        assert latency <= 2, f"latency {latency} cycles"


@cocotb.skipif(ONE_PUBLISHER or LOSSY, reason="needs several publishers and keep_all")
@cocotb.test()
async def round_robin_order(dut):
    """A waiting publisher is served before a publisher that sends again; rotation is strict."""
    tb = TopicTB(dut)
    await tb.reset()
    for source in tb.sources:
        source.pause = True
    rounds = 3
    plan = [[tagged_message(pub, seq, 2 * tb.bytes_per_beat + pub + 1, tb.rng)
             for seq in range(rounds)] for pub in range(tb.pubs)]
    scoreboard = TopicScoreboard(tb.pubs, tb.subs)
    for pub, messages in enumerate(plan):
        for message in messages:
            scoreboard.publish(pub, message)
            await tb.sources[pub].send(tb.frame(message))
    receivers = [cocotb.start_soon(tb.run_subscriber(scoreboard, j, tb.pubs * rounds))
                 for j in range(tb.subs)]
    await RisingEdge(dut.aclk)
    for source in tb.sources:
        source.pause = False
    await with_timeout(gather(*receivers), 4000 * CLOCK_NS, "ns")
    expected = [(pub, seq) for seq in range(rounds) for pub in range(tb.pubs)]
    for j in range(tb.subs):
        assert scoreboard.received[j] == expected, \
            f"sub {j}: order {scoreboard.received[j]}, expected strict rotation {expected}"


@cocotb.skipif(LOSSY, reason="store-and-forward FIFOs hold the message anyway")
@cocotb.test()
async def publisher_pauses_mid_message(dut):
    """A publisher that drops tvalid mid-message stalls only its message: no interleaving."""
    tb = TopicTB(dut)
    await tb.reset()
    long_message = tagged_message(0, 0, 12 * tb.bytes_per_beat, tb.rng)
    others = [tagged_message(pub, 0, 3 * tb.bytes_per_beat, tb.rng)
              for pub in range(1, tb.pubs)]
    scoreboard = TopicScoreboard(tb.pubs, tb.subs)
    receivers = [cocotb.start_soon(tb.run_subscriber(scoreboard, j, tb.pubs))
                 for j in range(tb.subs)]
    scoreboard.publish(0, long_message)
    await tb.sources[0].send(tb.frame(long_message))
    while tb.pub_watch[0].beats < 4:
        await RisingEdge(dut.aclk)
    tb.sources[0].pause = True
    for pub, message in enumerate(others, start=1):
        scoreboard.publish(pub, message)
        await tb.sources[pub].send(tb.frame(message))
    await tb.cycles(50)
    assert all(w.messages == 0 for w in tb.sub_watch), "a message completed inside another"
    tb.sources[0].pause = False
    await with_timeout(gather(*receivers), 2000 * CLOCK_NS, "ns")
    for j in range(tb.subs):
        assert scoreboard.received[j][0] == (0, 0), f"sub {j}: paused message not first"
    if tb.monitor and tb.pubs > 1:
        assert tb.counter("pub1_stalls") >= 40, "waiting publisher was not held back"


@cocotb.test()
async def reset_in_mid_traffic(dut):
    """Reset during traffic leaves no stuck grant or partial message behind."""
    tb = TopicTB(dut)
    await tb.reset()
    tb.set_idle_generator(lambda: random_pauses(tb.rng, 0.2))
    tb.set_backpressure_generator(lambda: random_pauses(tb.rng, 0.2))
    for pub, source in enumerate(tb.sources):
        for seq in range(3):
            await source.send(tb.frame(tagged_message(pub, seq, 40 * tb.bytes_per_beat, tb.rng)))
    await tb.cycles(60)
    assert any(w.beats for w in tb.pub_watch), "no traffic before the reset"
    for source in tb.sources:
        source.log.setLevel(logging.ERROR)  # the flushed frames are the point of this test
    dut.aresetn.value = 0
    await tb.cycles(3)
    for source in tb.sources:
        source.clear()
    dut.aresetn.value = 1
    await tb.cycles(2)
    for sink in tb.sinks:
        sink.clear()
    for watch in tb.pub_watch + tb.sub_watch:
        watch.clear()
    if tb.monitor:
        assert all(tb.counter(f"pub{i}_beats") == 0 for i in range(tb.pubs))
    plan = tb.random_plan(4, max_bytes=8 * tb.bytes_per_beat, with_4k=False)
    if not lossless(tb):
        tb.set_backpressure_generator(None)
    beats = sum(tb.beats(m) for messages in plan for m in messages)
    scoreboard = await tb.run_traffic(plan, timeout_cycles=20 * beats + 2000)
    await tb.cycles(4)
    tb.check_monitor(plan, scoreboard)


@cocotb.skipif(not LOSSY, reason="keep_all never drops: the lossless tests cover it")
@cocotb.test()
async def qos_drops_whole_messages(dut):
    """keep_last / best_effort: a stalled subscriber loses whole messages, counted exactly."""
    tb = TopicTB(dut)
    await tb.reset()
    slot_beats = (tb.fifo_depth // tb.params["history"] if tb.qos == "keep_last"
                  else tb.fifo_depth // 4)
    count = 24
    plan = [[] for _ in range(tb.pubs)]
    # Messages of equal beat count, so the subscribers that keep up never drop (see
    # run_traffic); only the stalled one does.
    beats = max(1, slot_beats // 2)
    for seq in range(count):
        pub = seq % tb.pubs
        length = max(3, beats * tb.bytes_per_beat - tb.rng.randrange(tb.bytes_per_beat))
        plan[pub].append(tagged_message(pub, len(plan[pub]), length, tb.rng))
    stalled = tb.sinks[0]
    stalled.pause = True
    scoreboard = TopicScoreboard(tb.pubs, tb.subs, lossless=False)
    ready_subs = [cocotb.start_soon(tb.run_subscriber(scoreboard, j, count))
                  for j in range(1, tb.subs)]
    await tb.run_publishers(scoreboard, plan)
    await with_timeout(gather(*ready_subs), 50000 * CLOCK_NS, "ns")
    stalled.pause = False
    await tb.cycles(4 * slot_beats + 50)
    while not stalled.empty():
        scoreboard.deliver(0, tb.check_frame(0, stalled.recv_nowait(compact=False)))
    drops = [tb.counter(f"drops{j}") for j in range(tb.subs)] if tb.monitor else None
    scoreboard.check_complete(drops=drops)
    got = scoreboard.received[0]
    tb.log.info("stalled subscriber got %d of %d messages", len(got), count)
    assert 1 <= len(got) < count
    if tb.subs > 1:
        reference = scoreboard.received[1]
        assert len(reference) == count
        if tb.qos == "keep_last":
            history = tb.params["history"]
            expected = [reference[0]] + reference[-(history - 1):]
            assert got == expected, (f"keep_last kept {got}, expected the message in delivery "
                                     f"and the newest {history - 1}: {expected}")
        else:
            assert got[0] == reference[0]
            kept_beats = sum(tb.beats(scoreboard.sent[p][i]) for p, i in got)
            assert kept_beats <= tb.fifo_depth + 1

    # An oversize message fits no FIFO: every subscriber drops it whole, the next one arrives.
    oversize = tagged_message(0, len(plan[0]), (tb.fifo_depth + 3) * tb.bytes_per_beat, tb.rng)
    after = tagged_message(0, len(plan[0]) + 1, 2 * tb.bytes_per_beat + 1, tb.rng)
    receivers = [cocotb.start_soon(tb.run_subscriber(scoreboard, j, 1)) for j in range(tb.subs)]
    await tb.run_publishers(scoreboard, [[oversize, after]] + [[] for _ in range(tb.pubs - 1)])
    await with_timeout(gather(*receivers), (tb.fifo_depth * 4 + 500) * CLOCK_NS, "ns")
    drops = [tb.counter(f"drops{j}") for j in range(tb.subs)] if tb.monitor else None
    scoreboard.check_complete(drops=drops)
    for j in range(tb.subs):
        assert scoreboard.received[j][-1] == (0, len(plan[0]) + 1)
