"""Bench of the exported ``topic`` top (hdl.dds.Topic; docs/topics.md, issue: foundation).

Every publisher port gets random idle, every subscriber port random backpressure (drawn in
the simulator on Verilator's compiled ports, by cocotbext-axi pause generators on Icarus);
:class:`tb.models.topic.TopicScoreboard` checks that each
subscriber gets every message exactly once, whole, in per-publisher order, never interleaved.
"""

import logging

import cocotb
from cocotb.triggers import RisingEdge, gather, with_timeout

from tb.harness import cocotb_bench
from tb.models.topic import TopicScoreboard, tagged_message

from .topic_tb import CLOCK_NS, CONFIGS, LOSSY, ONE_PUBLISHER, TopicTB, lossless, topic_harness

#: Verilator runs these in test-full only; make test keeps them on Icarus, and Verilator on
#: the configurations that differ in kind (one publisher, widest, FIFO depth, QoS)
LONG = [(config_id, "verilator") for config_id in
        ("1x3_w8", "3x1_w8", "4x4_w8", "1x1_w64", "1x3_w64", "3x1_w64", "3x3_w64", "4x4_w64")]

test_topic = cocotb_bench("topic", CONFIGS, long=LONG, harness=topic_harness)


@cocotb.test()
async def random_traffic_idle_and_backpressure(dut):
    """Random lengths (1 beat .. 4 KiB), random idle on publishers, backpressure on subscribers."""
    tb = TopicTB(dut)
    await tb.reset()
    tb.set_idle(0.3)
    if lossless(tb):
        tb.set_backpressure(0.35, max_run=8)
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
    tb.set_idle(0.2)
    tb.set_backpressure(0.2)
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
        tb.set_backpressure(0)
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
