"""``rosgate sim``: co-simulate a ReconROS project's system top with its software side.

:func:`run_project_sim` exports the project's ``rosgate_system``, builds it for the simulator
and runs :func:`run_project` (a cocotb test) against it: the ReconOS runtime model
(:mod:`host.reconos`) starts, every Amaranth hardware thread of the project is created in its
slots with the resources of its ``build.cfg`` groups (handles in build.cfg order), and the
project's software nodes run.

Software nodes live in ``<project>/sim.py``:

``NODES``
    A list of ``async def node(ctx)`` callables, run concurrently; the simulation ends when
    all of them have returned.
``setup(ctx)`` (optional)
    Called after the threads are created and before the nodes start, as a ReconROS
    application's ``main()`` prepares messages after ``reconos_app_init``.
``ARGS`` (optional)
    The ``--arg`` keys the nodes read, as :class:`host.sim_args.SimArg` (help, default, kind):
    ``rosgate sim`` refuses any other key and a value that does not read as its kind.
``check(ctx)`` (optional)
    Called in the ``rosgate`` process before the simulator is built (the system's Verilog is
    written first, in seconds), with a :class:`CheckContext`:
    raise ``ValueError`` to refuse the run's arguments (for example an image the hardware
    cannot take) with a message naming the bad value.
``summary(results, clock_mhz)`` (optional)
    Returns the lines ``rosgate sim`` prints for the nodes' results.

``ctx`` of the nodes is a :class:`SimContext`. An exception raised in ``sim.py`` ends the run
and reaches the user as its own message with the file and line it came from; a run in which
nothing happens for ``stall_ms`` of simulated time (no OS call, no memory access, no message)
while no node sleeps on purpose ends with what each slot and node waits for.
"""

import hashlib
import importlib.util
import json
import os
import re
import signal
import sys
import threading
import time
import traceback
from pathlib import Path

import cocotb
from cocotb.triggers import Event, First

from .compiled import DEFAULT_MEMORY_MB, memory_harness
from .console import Interrupted
from .reconos import ReconosCosim, Resource
from .ros2.bridge import SERVICE_QUEUE, BridgeQos
from .ros2.cosim import (JOINED, catch_stop_signals, clock_offset_ns, serve_ros2,
                         start_bridge, start_recorders)
from .sim_args import ArgumentError, check_args
from .simulator import (SimulationFailed, clock_cycles, export_top, project_cxx_opt,
                        run_top, source_digest, top_params)
from .toolchain import cache_dir

__all__ = ["SimContext", "CheckContext", "ProjectError", "run_project_sim", "model_resources",
           "top_ports", "load_sim_module", "project_build_dir"]

TOP = "rosgate_system"
#: files the simulation writes into the output folder, besides the nodes' own
RESULTS, ERROR, PROGRESS, LOG, STOP = "sim_results.json", "sim_error.json", \
    "sim_progress.jsonl", "sim.log", "sim.stop"
#: the waveform of a run with ``waves``, in the output folder
WAVES = f"{TOP}.fst"


#: wall seconds between two status events of a running simulation
STATUS_SECONDS = 2.0


class ProjectError(Exception):
    """The project's ``sim.py`` refused the run or failed in it; the message names the file
    and line the error came from."""


def model_resources(thread):
    """The software model's resource list of ``thread`` (index = handle)."""
    from gen.config import unquote
    out = []
    for r in thread.resources:
        a = r.args
        if r.type in ("mbox", "mem"):
            args = (int(a[0]),)
        elif r.type == "sem":
            args = (int(a[-1]),)
        elif r.type in ("mutex", "cond"):
            args = ()
        elif r.type == "rosnode":
            args = (unquote(a[0]),)
        elif r.msgtype is not None:
            args = (r.msgtype,)
        elif r.type in ("rossub", "rospub"):
            args = (unquote(a[2]),)
        elif r.type in ("rossrvs", "rossrvc", "rosactions", "rosactionc"):
            args = (unquote(a[2]) if len(a) > 2 else r.name,)
        else:
            args = tuple(a)
        out.append(Resource(r.type, *args, name=r.name))
        if thread.gateway is not None and r.type in ("rossub", "rospub"):
            out[-1].origin = thread.name
    return out


class CheckContext:
    """What a project's ``check(ctx)`` gets, before the simulator is built.

    Attributes
    ----------
    project : gen.config.Project
    args : dict
        ``--arg key=value`` options (strings).
    threads : dict
        Thread name -> the Amaranth component of its first slot (``None`` for a thread
        without Amaranth source), to read the limits the hardware was built with.
    clock_mhz : float
        The system clock.
    """

    def __init__(self, project, args, threads):
        self.project = project
        self.args = dict(args)
        self.threads = threads
        self.clock_mhz = project.clock_mhz


class SimContext:
    """What a project's software nodes get.

    Attributes
    ----------
    project : gen.config.Project
    broker : host.reconos.Broker
        Topics, services and actions: ``publish``, ``subscribe``, ``call``, ``serve``,
        ``send_goal``.
    runtime, messages, memory :
        The ReconOS runtime model, the rosidl message memory and the process memory.
    args : dict
        ``--arg key=value`` options of ``rosgate sim`` (strings).
    out : pathlib.Path
        A folder for the nodes' files.
    results : dict
        Anything JSON-serialisable; ``rosgate sim`` prints and saves it.
    clock_mhz : float
        The system clock.
    threads : dict
        As :class:`CheckContext`'s (built on first use).
    playback : host.ros2.player.BagPlayer or None
        With ``rosgate sim --play``: the bag's player; ``await ctx.playback.next(topic)`` is
        the next message it published on ``topic`` (``None`` at the end). Such a run runs
        ``sim.py``'s ``PLAY_NODES`` instead of its ``NODES``.
    """

    def __init__(self, cosim, project, args, out):
        self.cosim = cosim
        self.project = project
        self.broker = cosim.broker
        self.runtime = cosim.runtime
        self.messages = cosim.messages
        self.memory = cosim.memory
        self.args = args
        self.out = Path(out)
        self.results = {}
        self.clock_mhz = project.clock_mhz
        self._resources = {}
        self._start = cocotb.utils.get_sim_time("ns")
        self._sleeping = 0
        self._progress = None
        self._threads = None
        self._work = None
        #: the :class:`~host.ros2.player.BagPlayer` of ``--play`` (``None`` without)
        self.playback = None

    @property
    def threads(self):
        if self._threads is None:
            from gen.system import build_system
            self._threads = thread_components(self.project, build_system(self.project))
        return self._threads

    def now(self):
        """System clock cycles since the nodes started."""
        return round((cocotb.utils.get_sim_time("ns") - self._start) * self.clock_mhz / 1000)

    async def cycles(self, n):
        """Sleep ``n`` system clock cycles (the stall check waits while a node sleeps)."""
        self._sleeping += 1
        try:
            await clock_cycles(self.cosim.dut.aclk, n)
        finally:
            self._sleeping -= 1

    def resource(self, thread, name, slot=None):
        """The model object of resource ``name`` of ``thread`` (in its first slot by default):
        ``.ptr`` is the message's address for message resources."""
        t = next(t for t in self.project.threads if t.name == thread)
        slot = t.slots[0].id if slot is None else slot
        return self._resources[slot][t.handle(name)]

    def log(self, text):
        """Log a line; ``rosgate sim`` shows it while the simulation runs."""
        self.cosim.dut._log.info(text)
        self._event({"cycle": self.now(), "text": str(text)})

    def progress(self, done, total, unit):
        """Say how far the run is: ``done`` of ``total`` ``unit`` (``"frames"``); ``rosgate
        sim``'s status line shows it with an estimate of the time left."""
        self._work = (int(done), int(total), str(unit))

    def _event(self, event):
        if self._progress is not None:
            self._progress.write(json.dumps(event) + "\n")
            self._progress.flush()

    def _status(self, seconds):
        """A status event: wall seconds since the nodes started, cycles, simulated ms,
        messages, memory in use, the nodes' work."""
        usage = self.cosim.memory.usage()
        cycle = self.now()
        status = {"seconds": round(seconds, 1), "cycle": cycle,
                  "ms": round(cycle / (self.clock_mhz * 1000), 3),
                  "messages": self.cosim.broker.events, "memory_in_use": usage["in_use"],
                  "memory_size": usage["size"]}
        if self._work is not None:
            status["done"], status["total"], status["unit"] = self._work
        return {"status": status}


def load_sim_module(project):
    """Import the project's ``sim.py`` (``None`` if it has none); an error in it becomes a
    :class:`ProjectError` naming its file and line."""
    path = project.dir / "sim.py"
    if not path.is_file():
        return None
    spec = importlib.util.spec_from_file_location(f"rosgate_sim_{project.name.lower()}", path)
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(project.dir))
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        raise ProjectError(_located(exc, path)) from exc
    finally:
        sys.path.remove(str(project.dir))
    return module


def _origin(exc, path):
    """(file, line) of the deepest frame of ``exc``'s traceback in ``path``, else its last."""
    frames = traceback.extract_tb(exc.__traceback__)
    if isinstance(exc, SyntaxError) and exc.filename:
        return exc.filename, exc.lineno
    inside = [f for f in frames if Path(f.filename).resolve() == Path(path).resolve()]
    frame = (inside or frames or [None])[-1]
    return (frame.filename, frame.lineno) if frame else (str(path), None)


def _located(exc, path):
    file, line = _origin(exc, path)
    where = f"{file}:{line}" if line else str(file)
    return f"{where}: {type(exc).__name__}: {exc}"


def _stall_report(cosim, running):
    """What everything waits for, for a stall or time-out message."""
    slots = ", ".join(f"slot {s} in {m.upper()}{tuple(a)}" for s, (m, a) in
                      sorted(cosim.runtime.pending.items())) or "no slot in an OS call"
    nodes = ", ".join(getattr(n, "__name__", str(n)) for n in running) or "none"
    errors = cosim.runtime.errors
    recorded = (f"; ReconOS protocol errors before: {'; '.join(errors[:5])}"
                f"{f' (and {len(errors) - 5} more)' if len(errors) > 5 else ''}"
                if errors else "")
    return f"{slots}; nodes still running: {nodes}{recorded}"


async def _watch_progress(cosim, ctx, stall_cycles, running, failures, ended, period=20_000,
                          status_seconds=STATUS_SECONDS):
    """End the run when nothing happens for ``stall_cycles`` while no node sleeps on
    purpose."""
    def activity():
        return (cosim.runtime.commands, cosim.memory_accesses, cosim.broker.events)
    last, quiet = activity(), 0
    started = shown = time.monotonic()
    while True:
        await clock_cycles(cosim.dut.aclk, period)
        if time.monotonic() - shown >= status_seconds:
            shown = time.monotonic()
            ctx._event(ctx._status(shown - started))
        now = activity()
        if now != last or ctx._sleeping:
            last, quiet = now, 0
            continue
        quiet += period
        if quiet >= stall_cycles:
            failures.append(ProjectError(
                f"no progress for {quiet} cycles ({quiet / (ctx.clock_mhz * 1000):g} ms "
                f"simulated at {ctx.clock_mhz:g} MHz): no OS call, memory access or message; "
                f"{_stall_report(cosim, running)}"))
            ended.set()
            return


def _write_error(out, message):
    Path(out).mkdir(parents=True, exist_ok=True)
    (Path(out) / ERROR).write_text(json.dumps({"error": message}) + "\n")


@cocotb.test()
async def run_project(dut):
    """Create the project's threads and run its software nodes to completion."""
    from gen.config import apply_parameters, load_project, project_library
    from gen.system import thread_module_path

    p = top_params()
    if p.get("ros2"):
        catch_stop_signals()
    out = Path(p["out"])
    project = apply_parameters(load_project(p["build_cfg"]), p.get("thread_params", []))
    sim_py = project.dir / "sim.py"
    try:
        module = load_sim_module(project)
    except ProjectError as exc:
        _write_error(out, str(exc))
        raise
    cosim = ReconosCosim(dut, arch=p["arch"], num_hwts=len(p["threads"]),
                         clock_ns=p["clock_ns"],
                         slot_clocks={int(k): v for k, v in p["slot_clock_ns"].items()
                                      if int(k) in p["async_slots"]},
                         ram_size=p["memory_mb"] << 20)
    for name in os.environ.get("ROSGATE_EXTERNAL_INPUTS", "").split():
        getattr(dut, name).value = 0     # ports of slots without a thread: idle
    await cosim.reset()
    ros2 = p.get("ros2")
    if ros2:
        # a ROS 2 graph does not pace itself to the hardware: subscriptions keep the last
        # messages, as ROS 2's default QoS does
        cosim.broker.history = BridgeQos().depth
    await cosim.start_runtime(project_library(project))
    ctx = SimContext(cosim, project, p.get("args", {}), out)
    out.mkdir(parents=True, exist_ok=True)
    ctx._progress = open(out / PROGRESS, "a")
    created = []
    for thread in project.threads:
        if not thread_module_path(project, thread).is_file() and thread.gateway is None:
            continue
        for slot in thread.slots:
            res = model_resources(thread)
            ctx._resources[slot.id] = res
            await cosim.runtime.create_thread(slot.id, res)
            created.append(slot.id)
    play = p.get("play")
    nodes = list(getattr(module, "PLAY_NODES" if play else "NODES", [])) \
        if module is not None else []
    if ros2 and not ros2.get("nodes"):
        nodes = []
    if play:
        from .ros2.player import BagPlayer, PlayPlan
        ctx.playback = BagPlayer(PlayPlan.from_json(play), ctx,
                                 accepts=getattr(module, "accepts", None),
                                 settle=not nodes and not ros2)

        async def play_bag(ctx):
            await ctx.playback.run()
        nodes.append(play_bag)
    ended, failures, running = Event(), [], {}

    async def guarded(node):
        try:
            await node(ctx)
        except Exception as exc:
            failures.append(exc)
        finally:
            running.pop(node, None)
            if failures or (not running and not ros2):
                ended.set()

    bridge, recorders = None, []
    try:
        if module is not None and hasattr(module, "setup"):
            module.setup(ctx)
        recorders = start_recorders(ctx, p.get("record"), p.get("trace"),
                                    clock_offset_ns(ros2) if ros2 else 0)
        if ros2:
            bridge = start_bridge(ctx, module, ros2)
        ctx._start = cocotb.utils.get_sim_time("ns")
        cpu_start = time.process_time()
        running.update((node, cocotb.start_soon(guarded(node))) for node in nodes)
        if ros2:
            await serve_ros2(cosim, ctx, bridge, ros2, failures, created)
            if failures:
                raise failures[0]
        else:
            if not nodes:
                ended.set()
            limit_cycles = round(float(p["limit_ms"]) * 1000 * ctx.clock_mhz)
            stall_cycles = round(float(p["stall_ms"]) * 1000 * ctx.clock_mhz)
            watch = cocotb.start_soon(_watch_progress(
                cosim, ctx, stall_cycles, running, failures, ended,
                status_seconds=float(p.get("status_seconds", STATUS_SECONDS))))
            await First(ended.wait(), cosim.runtime.failed.wait(),
                        clock_cycles(dut.aclk, limit_cycles))
            watch.cancel()
            if cosim.runtime.fatal is not None:
                raise cosim.runtime.fatal
            if failures:
                raise failures[0]
            if running:
                raise ProjectError(
                    f"the software nodes did not finish within {p['limit_ms']:g} ms of "
                    f"simulated time ({limit_cycles} cycles); {_stall_report(cosim, running)}")
    except ProjectError as exc:
        _write_error(out, str(exc))
        raise
    except Exception as exc:
        _write_error(out, _located(exc, sim_py))
        raise
    finally:
        if ctx.playback is not None:
            ctx.results["play"] = ctx.playback.summary()
        if bridge is not None:
            ctx.results["ros2"] = bridge.summary()
            bridge.close()
        for recorder in recorders:
            recorder.close()
            ctx.results.setdefault("recorded", {})[str(recorder.path)] = recorder.counts
        ctx._progress.close()
    if cosim.runtime.errors:
        message = f"ReconOS protocol errors: {'; '.join(cosim.runtime.errors)}"
        _write_error(out, message)
        raise ProjectError(message)
    ctx.results.setdefault("cycles", ctx.now())
    # the simulator process's CPU time while the nodes ran: the co-simulation's pace
    ctx.results.setdefault("cpu_seconds", round(time.process_time() - cpu_start, 3))
    ctx.results.setdefault("memory", cosim.memory.usage())
    ctx.results.setdefault("slots_running", created)
    (out / RESULTS).write_text(json.dumps(ctx.results, indent=2) + "\n")


def _follow(path, show, stop):
    """Call ``show(line)`` for each line appended to ``path`` until ``stop`` is set."""
    position = 0
    while True:
        finished = stop.wait(0.5)
        if Path(path).is_file():
            with open(path) as f:
                f.seek(position)
                for line in f:
                    if line.endswith("\n"):
                        show(json.loads(line))
                        position += len(line.encode())
                    else:
                        break
        if finished:
            return


def run_project_sim(build_cfg, sim="verilator", *, out, args=None, thread_params=(),
                    limit_ms=1000.0, stall_ms=10.0, memory_mb=DEFAULT_MEMORY_MB, seed=None,
                    build_dir=None, quiet=True, waves=False, progress=None, log=None, ros2=None,
                    record=None, trace=None, play=None, cxx_opt=None, status=None,
                    status_seconds=STATUS_SECONDS):
    """Export, build and run the project's system under ``sim``; return the nodes' results.

    Parameters
    ----------
    build_cfg : path
    sim : str
        ``"icarus"`` or ``"verilator"``.
    out : path
        Folder of the nodes' files, ``sim_results.json`` and the simulator's log.
    args : dict
        ``ctx.args`` of the nodes.
    thread_params : list of str
        ``THREAD.NAME=VALUE`` settings over the build.cfg's thread ``Parameters``.
    limit_ms, stall_ms : float
        Simulated time after which the run ends unfinished; simulated time without any
        activity after which it ends as stalled.
    memory_mb : int
        MiB of physical memory behind the system's AXI4 port (``--memory-mb``).
    build_dir : path or None
        Where the Verilog and the simulator build go (default: the per-user cache).
    quiet : bool
        Send the simulator's output to ``<out>/sim.log`` instead of this process's output.
    progress : callable or None
        ``progress(stage, text)`` for the build's progress.
    log : callable or None
        ``log(cycle, text)`` for each line the nodes log while the simulation runs.
    status : callable or None
        ``status(dict)`` every :data:`STATUS_SECONDS` of wall time while the simulation runs:
        ``seconds`` (wall, since the nodes started), ``cycle``, ``ms`` (simulated),
        ``messages``, ``memory_in_use``, ``memory_size`` (bytes) and, when a node reports it
        (:meth:`SimContext.progress`), ``done``, ``total``, ``unit``.
    status_seconds : float
        Wall seconds between two ``status`` calls.
    ros2 : dict or None
        Join a DDS domain instead of running to the nodes' end (``rosgate sim --ros2``):
        ``domain`` (int), ``nodes`` (bool: run ``sim.py``'s nodes too), ``service_queue``
        (int: calls of one service the bridge holds for the hardware; more are refused) and
        ``clock`` (``"zero"``: ``/clock`` and stamps are simulated time from zero, ``"wall"``:
        from the wall time at the start, ``"none"``: no ``/clock``). The run has no
        simulated-time limit; SIGINT or SIGTERM to this process ends it cleanly.
    record, trace : path or None
        Write every message on the project's topics to a rosbag2 (MCAP) at ``record`` (a new
        folder), and one line per message to the text file ``trace``.
    play : dict or None
        Play a rosbag2 into the system's topics (``rosgate sim --play``): ``path``, ``topics``
        (bag topics to play; default every one the system subscribes), ``remaps``
        (``FROM:=TO``), ``pace`` (``"bag"`` or ``"fast"``), ``rate`` (bag pace), ``delay``
        (wall seconds before the first message). The bag is
        read and checked before the build (:func:`host.ros2.player.plan_playback`). Without
        ``--ros2`` the run ends once the bag is played and the system is idle, or when
        ``sim.py``'s ``PLAY_NODES`` end.
    cxx_opt : str or None
        The C++ optimisation of a Verilator model (:func:`host.simulator.run_top`); a build
        folder is built with one. ``None``: :func:`host.simulator.project_cxx_opt` (``-O3``
        unless ``ROSGATE_CXX_OPT`` says otherwise).

    Raises
    ------
    ProjectError
        ``sim.py`` refused the arguments, raised, or the run stalled or timed out.
    SimulationFailed
        The simulation failed for another reason (see the log).
    """
    from gen.config import apply_parameters, load_project
    from gen.system import build_system, thread_code

    build_cfg = Path(build_cfg).resolve()
    if sim == "verilator" and cxx_opt is None:
        cxx_opt = project_cxx_opt()
    project = apply_parameters(load_project(build_cfg), thread_params)
    out = Path(out).resolve()
    module = load_sim_module(project)
    from gen.system import thread_module_path
    if not any(thread_module_path(project, t).is_file() or t.gateway is not None
               for t in project.threads):
        raise ProjectError(f"{project.name} has no Amaranth thread: every slot is an external "
                           f"core (an HLS or VHDL thread; its ports are ports of the system "
                           f"top), so there is no hardware to simulate; `rosgate export-hw` "
                           f"writes the system for Vivado")
    if module is None and ros2 is None and play is None:
        raise ProjectError(f"{project.name} has no sim.py ({project.dir / 'sim.py'}): nothing "
                           f"would drive its system, and the run would end at once; write "
                           f"one (docs/simulation.md), join a ROS 2 graph with --ros2 or "
                           f"play a bag with --play")
    try:
        args = check_args(module, dict(args or {}), project.name)
    except ArgumentError as exc:
        raise ProjectError(str(exc)) from None
    plan = None
    if play is not None:
        from gen.config import project_library

        from .ros2.graph import ros_interfaces
        from .ros2.player import PlaybackError, plan_playback
        try:
            plan = plan_playback(play["path"], ros_interfaces(project),
                                 project_library(project), topics=play.get("topics", ()),
                                 remaps=play.get("remaps", ()), pace=play.get("pace", "bag"),
                                 rate=play.get("rate", 1.0), delay=play.get("delay", 0.0))
        except PlaybackError as exc:
            raise ProjectError(str(exc)) from None
    _check_output("--record", record, "new folder")
    _check_output("--trace", trace, "file")
    _check_output("-o", out, "folder")
    system = build_system(project)
    build_dir = Path(build_dir) if build_dir else \
        project_build_dir(project, thread_params, sim, cxx_opt)
    # the Verilog first (seconds): the threads' parameters are final, and check() may read
    # them before minutes go into the simulator build
    with thread_code(project):
        vfile = export_top(system, TOP, build_dir, icarus=sim == "icarus",
                           key=_system_key(project, thread_params))
    if module is not None and hasattr(module, "check"):
        try:
            module.check(CheckContext(project, args, thread_components(project, system)))
        except Exception as exc:
            raise ProjectError(_located(exc, project.dir / "sim.py")) from exc
    params = {"build_cfg": str(build_cfg), "arch": project.arch,
              "threads": [s.name for s in sorted(project.slots, key=lambda s: s.id)],
              "async_slots": [s.id for s in project.slots
                              if s.clock is not project.system_clock],
              "clock_ns": _period_ns(project.system_clock.freq),
              "slot_clock_ns": {str(s.id): _period_ns(s.clock.freq) for s in project.slots},
              "args": args, "thread_params": list(thread_params), "out": str(out),
              "limit_ms": float(limit_ms), "memory_mb": int(memory_mb),
              "stall_ms": float(stall_ms), "status_seconds": float(status_seconds)}
    if record is not None:
        params["record"] = str(Path(record).resolve())
    if trace is not None:
        params["trace"] = str(Path(trace).resolve())
    if plan is not None:
        params["play"] = plan.to_json()
    if ros2 is not None:
        params["ros2"] = {"domain": int(ros2["domain"]), "nodes": bool(ros2.get("nodes")),
                          "stop_file": str(out / STOP),
                          "service_queue": int(ros2.get("service_queue", SERVICE_QUEUE)),
                          "clock": ros2.get("clock", "zero"), "clock_start_ns": time.time_ns(),
                          "goal_policy": ros2.get("goal_policy", "queue")}
    inputs = [name for name, flow in top_ports(system).items()
              if name.startswith("slot") and flow == "in" and not name.endswith("_clk")]
    out.mkdir(parents=True, exist_ok=True)
    for name in (RESULTS, ERROR, PROGRESS, STOP, WAVES):
        if (out / name).exists():
            (out / name).unlink()
    stop = threading.Event()
    follower = None
    joined = threading.Event()       # the bridge is on DDS: a stop request ends it cleanly
    if log is not None or status is not None or ros2 is not None:
        def show(event):
            if "status" in event:
                if status is not None:
                    status(event["status"])
                return
            if event["text"].startswith(JOINED):
                joined.set()
            if log is not None:
                log(event["cycle"], event["text"])
        follower = threading.Thread(target=_follow, daemon=True,
                                    args=(out / PROGRESS, show, stop))
        follower.start()
    handlers = _forward_stop(out / STOP, joined) if ros2 is not None else {}
    try:
        run_top(__name__, TOP, system, sim, build_dir, params=params, seed=seed,
                extra_env={"ROSGATE_EXTERNAL_INPUTS": " ".join(inputs)},
                log_file=out / LOG if quiet else None, waves=waves, progress=progress,
                exported=vfile, harness=memory_harness(), cxx_opt=cxx_opt)
    except SimulationFailed as exc:
        if (out / ERROR).is_file():
            raise ProjectError(json.loads((out / ERROR).read_text())["error"]) from None
        reason = _logged_exception(out / LOG, project.dir) if quiet else None
        raise SimulationFailed(f"{reason or exc}; simulator log: {out / LOG}" if quiet
                               else str(exc),
                               failed=exc.failed, total=exc.total,
                               results=exc.results) from None
    finally:
        if waves and (build_dir / f"{TOP}.fst").is_file():
            # the waveform goes with the run's other files, out of the build cache
            os.replace(build_dir / f"{TOP}.fst", out / WAVES)
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
        (out / STOP).unlink(missing_ok=True)
        stop.set()
        if follower is not None:
            follower.join()
    return json.loads((out / RESULTS).read_text())


_LOG_EVENT = re.compile(r"^\s*[\d.]+[munpf]?s\s+[A-Z]+\s|^\s*\*\*")
_FRAME = re.compile(r'^File "(?P<file>[^"]+)", line (?P<line>\d+)')


def _logged_exception(log, project_dir):
    """``file:line: Type: message`` of the last Python exception in the simulator's ``log``
    (the deepest frame in ``project_dir`` if any, else the last), ``None`` without one: a
    failure outside the nodes' own code (a task a node started, the simulator) still names
    its reason on the terminal."""
    try:
        lines = Path(log).read_text(errors="replace").splitlines()
    except OSError:
        return None
    starts = [n for n, line in enumerate(lines) if line.strip() ==
              "Traceback (most recent call last):"]
    if not starts:
        return None
    frames, message, code_line = [], None, False
    for line in lines[starts[-1] + 1:]:
        if _LOG_EVENT.match(line):
            break
        text = line.strip()
        mo = _FRAME.match(text)
        if mo:
            frames.append((mo["file"], int(mo["line"])))
            code_line = True        # the frame's source line follows
        elif code_line:
            code_line = False
        elif text and set(text) - set("^~ "):
            message = text
    if message is None:
        return None
    mine = [f for f in frames if Path(f[0]).resolve().is_relative_to(Path(project_dir).resolve())]
    file, line = (mine or frames)[-1]
    return f"{file}:{line}: {message}"


def _check_output(option, path, kind):
    """Refuse, before anything is built, an output ``path`` that cannot be written: its
    parent folder is created (as the run would) or the error names the option. ``kind``:
    ``"file"``, ``"folder"``, or ``"new folder"`` (rosbag2 refuses an existing one)."""
    if path is None:
        return
    path = Path(path)
    if kind == "new folder" and path.exists():
        raise ProjectError(f"{option} {path}: the folder exists; rosbag2 writes a new one")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ProjectError(f"{option} {path}: cannot create {path.parent}: "
                           f"{exc.strerror}") from None
    if not os.access(path.parent, os.W_OK):
        raise ProjectError(f"{option} {path}: cannot write into {path.parent}")
    if path.exists() and path.is_dir() != (kind != "file"):
        found = "a folder, not a file" if kind == "file" else "a file, not a folder"
        raise ProjectError(f"{option} {path}: {found}")


def project_build_dir(project, thread_params, sim, cxx_opt=None):
    """The folder of the per-user cache a project's system is built in for ``sim`` (and, for
    Verilator, at C++ optimisation ``cxx_opt``, ``None`` for :func:`project_cxx_opt`: make
    does not rebuild for another)."""
    digest = hashlib.sha1(f"{Path(project.path).resolve()} {sorted(thread_params)}"
                          .encode()).hexdigest()[:8]
    if sim == "verilator" and cxx_opt is None:
        cxx_opt = project_cxx_opt()
    opt = f"{cxx_opt.lstrip('-')}-" if sim == "verilator" and cxx_opt else ""
    return cache_dir() / "sim" / f"{project.name.lower()}-{digest}-{opt}{sim}"


def _system_key(project, thread_params):
    """A fingerprint of the project's system Verilog: rosgate's hardware and generators, the
    project's folder (build.cfg, messages, threads) and the thread parameters."""
    import gen
    import hdl
    package = Path(hdl.__file__).resolve().parent.parent
    return source_digest(Path(hdl.__file__).parent, Path(gen.__file__).parent, project.dir,
                         extra=json.dumps(sorted(thread_params)).encode(),
                         root=package)[:32]


def _has_joined(progress):
    try:
        return JOINED in progress.read_text()
    except OSError:
        return False


def _forward_stop(stop_file, joined):
    """While a ``--ros2`` run is on DDS (``joined`` set): SIGINT and SIGTERM to this process
    write ``stop_file``, which the simulation reads to end cleanly (the simulator, in the same
    process group, also gets a terminal's SIGINT itself). Before that (building, starting), or
    at a second signal, they raise :class:`~host.console.Interrupted`: the build or the
    simulator is stopped and the command ends at once. Returns the handlers to restore."""
    def request_stop(signum, frame):
        if not joined.is_set() and _has_joined(Path(stop_file).with_name(PROGRESS)):
            joined.set()            # the follower had not read it yet
        if not joined.is_set() or Path(stop_file).exists():
            raise Interrupted(signum)
        Path(stop_file).write_text(signal.Signals(signum).name)
    return {signum: signal.signal(signum, request_stop)
            for signum in (signal.SIGINT, signal.SIGTERM)}


def thread_components(project, system):
    """Thread name -> the Amaranth component of its first slot in ``system`` (``None`` for
    a thread without Amaranth source)."""
    threads = {}
    for s, component in zip(sorted(project.slots, key=lambda s: s.id), system.threads):
        if s.thread is not None and s.thread.name not in threads:
            threads[s.thread.name] = component
    return threads


def _period_ns(freq):
    """The clock period in ns, rounded to an even number of picoseconds (cocotb's clock
    needs equal high and low halves at the 1 ps precision)."""
    return round(1e12 / freq / 2) * 2 / 1000


def top_ports(component):
    """Ports of ``component`` as exported: name -> ``"in"`` or ``"out"``."""
    from amaranth.lib import wiring
    from gen.export.verilog import exported_ports
    return {name: "in" if flow == wiring.In else "out"
            for name, (_, flow) in exported_ports(component).items()}
