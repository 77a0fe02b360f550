"""``rosgate sim --ros2`` inside the simulator: start the bridge, serve until told to stop.

The run has no simulated-time limit. Every ``POLL_CYCLES`` the bridge moves what waits in
either direction. Once every hardware thread waits in an OS call and nothing has happened (no
OS call, register access, memory access or message) for ``IDLE_POLLS`` polls, the system
cannot move by itself: the simulator blocks on DDS, first for ``IDLE_WAIT_S`` of wall time and,
while the quiet lasts, for twice as long each time up to ``IDLE_WAIT_MAX_S``, so an idle system
costs almost no processor time (a wake-up a second). A thread that computes without OS calls
keeps the simulation running. SIGINT or SIGTERM (or the stop file the ``rosgate`` process
writes when it gets them) ends the run cleanly: the participant is deleted, the results and
files are written, the simulator exits.
"""

import signal
from pathlib import Path

import cocotb
from cocotb.triggers import Timer

from .bridge import Ros2Bridge
from .graph import ros_interfaces

__all__ = ["start_bridge", "serve_ros2", "start_recorders", "catch_stop_signals",
           "clock_offset_ns", "CLOCK_PERIOD_NS", "JOINED", "POLL_CYCLES", "IDLE_POLLS",
           "IDLE_WAIT_S", "IDLE_WAIT_MAX_S"]

POLL_CYCLES = 200
IDLE_POLLS = 1
IDLE_WAIT_S = 0.05
IDLE_WAIT_MAX_S = 1.0
#: how the line the simulation logs once the bridge is on DDS starts
JOINED = "ros2 bridge: joined DDS domain"
#: simulated time between two samples of ``/clock`` (10 kHz of simulated time)
CLOCK_PERIOD_NS = 100_000

_stop = {"signal": None}


def _on_signal(signum, frame):
    _stop["signal"] = signal.Signals(signum).name


def start_bridge(ctx, module, options):
    """Create and start the bridge for ``ctx.project``; log what it shows on DDS.

    ``options``: ``domain`` (int), ``stop_file`` (path or None), ``service_queue`` (int: calls
    of one service held for the hardware), ``clock`` (``"zero"``, ``"wall"`` or ``"none"``:
    ``/clock`` from simulated time, from simulated time plus ``clock_start_ns``, or no
    ``/clock``), ``goal_policy`` (``"queue"`` or ``"reject"``: a goal while the hardware
    is busy). ``module`` is the project's
    ``sim.py``: its ``accepts(ctx, name, value)``, if any, states the hardware's limits for
    messages arriving from DDS."""
    import cocotb

    from gen.config import project_library

    from .bridge import SERVICE_QUEUE, BridgeQos
    accepts = getattr(module, "accepts", None) if module is not None else None
    offset = clock_offset_ns(options)
    bridge = Ros2Bridge(
        ros_interfaces(ctx.project), project_library(ctx.project), ctx.broker,
        domain=int(options["domain"]), log=ctx.log, spawn=cocotb.start_soon,
        now_ns=lambda: round(cocotb.utils.get_sim_time("ns")) + offset,
        publish_clock=options.get("clock", "zero") != "none",
        goal_policy=options.get("goal_policy", "queue"),
        accepts=(lambda name, value: accepts(ctx, name, value)) if accepts else None,
        qos=BridgeQos(service_queue=int(options.get("service_queue", SERVICE_QUEUE))))
    shown = bridge.start()
    ctx.log(f"{JOINED} {bridge.domain} with "
            f"{len(shown)} interfaces: {'; '.join(shown) or 'none'}")
    return bridge


def clock_offset_ns(options):
    """What the bridge's clock adds to simulated time: 0 (``--clock zero``, or none), or the
    wall time at the start (``--clock wall``: stamps and ``/clock`` read as today's date)."""
    return int(options.get("clock_start_ns", 0)) if options.get("clock") == "wall" else 0


def catch_stop_signals():
    """From the simulation's start: SIGINT and SIGTERM (a terminal's Ctrl-C reaches the
    simulator too) are a stop request, served once the bridge runs, never a traceback."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _on_signal)


def start_recorders(ctx, record, trace, offset_ns=0):
    """A :class:`BagRecorder` at ``record`` and a :class:`TraceWriter` at ``trace`` (either
    may be ``None``), fed by every publication on the project's topics, stamped with
    simulated time plus ``offset_ns`` (the bridge's clock)."""
    from gen.config import project_library

    from .recorder import BagRecorder, TraceWriter
    if record is None and trace is None:
        return []
    topics = ros_interfaces(ctx.project).topics
    by_key = {t.key: t for t in topics.values()}
    types = {t.name: t.msgtype for t in topics.values()}
    recorders = []
    if record is not None:
        recorders.append(BagRecorder(record, project_library(ctx.project), types))
    if trace is not None:
        recorders.append(TraceWriter(trace, types))
    unknown = set()

    def observe(key, value):
        topic = by_key.get(key)
        if topic is None:
            if key not in unknown:
                unknown.add(key)
                ctx.log(f"recorder: {key!r} is not a topic of the build.cfg; not recorded")
            return
        now = round(cocotb.utils.get_sim_time("ns")) + offset_ns
        for recorder in recorders:
            recorder.write(topic.name, value, now)
    ctx.broker.observers.append(observe)
    ctx.log("recording " + ", ".join(f"{len(types)} topics to {r.path}" for r in recorders))
    return recorders


def _stop_requested(options):
    if _stop["signal"] is not None:
        return _stop["signal"]
    stop_file = options.get("stop_file")
    if stop_file and Path(stop_file).exists():
        return Path(stop_file).read_text().strip() or "a stop request"
    return None


async def serve_ros2(cosim, ctx, bridge, options, failures, slots):
    """Run the system and the bridge until a signal, a stop file, or a node fails.
    ``slots``: the slots that run a thread."""
    def activity():
        return (cosim.runtime.commands, cosim.runtime.bus_accesses, cosim.memory_accesses,
                cosim.broker.events)
    last, quiet = activity(), 0
    idle_wait = IDLE_WAIT_S
    offset = clock_offset_ns(options)
    clock_due = 0
    # one timer, not ClockCycles: cocotb would run Python at every one of the clock edges
    poll = Timer(round(POLL_CYCLES * 1000 / ctx.clock_mhz), "ns")
    while not failures and (why := _stop_requested(options)) is None:
        moved = bridge.poll()
        now_ns = round(cocotb.utils.get_sim_time("ns"))
        if now_ns >= clock_due:
            bridge.write_clock(now_ns + offset)
            clock_due = now_ns + CLOCK_PERIOD_NS
        await poll
        now = activity()
        if moved or now != last or ctx._sleeping:
            last, quiet, idle_wait = now, 0, IDLE_WAIT_S
            continue
        quiet += 1
        if quiet >= IDLE_POLLS and all(s in cosim.runtime.pending for s in slots):
            # DDS data ends the wait at once; the longer the quiet, the longer the wait, so a
            # system left idle wakes about once a second (and sees a stop request then)
            bridge.write_clock(round(cocotb.utils.get_sim_time("ns")) + offset)
            bridge.wait(idle_wait)
            idle_wait = min(2 * idle_wait, IDLE_WAIT_MAX_S)
    if not failures:
        waiting = ", ".join(f"slot {s} in {m.upper()}" for s, (m, _) in
                            sorted(cosim.runtime.pending.items())) or "no slot in an OS call"
        ctx.log(f"ros2 bridge: stopping on {why} after {ctx.now()} cycles ({waiting})")
