"""``rosgate sim``: co-simulate a ReconROS project's system top with the software model.

The cocotb test of this module resets the exported ``rosgate_system``, starts the ReconOS
runtime model (:mod:`tb.models.reconos_sw`), creates every Amaranth hardware thread of the
project in its slots with the resources of its ``build.cfg`` groups (handles in build.cfg
order), and runs the project's software nodes.

Software nodes live in ``<project>/sim.py``:

``NODES``
    A list of ``async def node(ctx)`` callables, run concurrently; the simulation ends when
    all of them have returned (or at the time limit).
``setup(ctx)`` (optional)
    Called after the threads are created and before the nodes start, as a ReconROS
    application's ``main()`` prepares messages after ``reconos_app_init``.

``ctx`` is a :class:`SimContext`.
"""

import hashlib
import importlib.util
import json
import os
import sys
from pathlib import Path

import cocotb
from cocotb.triggers import ClockCycles, Combine, with_timeout

from .harness import bench_params, run_bench
from .models.reconos_sw import Resource
from .reconos_tb import ReconosTB

__all__ = ["SimContext", "model_resources", "run_project_sim", "top_ports"]

TOP = "rosgate_system"


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
    return out


class SimContext:
    """What a project's software nodes get.

    Attributes
    ----------
    project : gen.config.Project
    broker : tb.models.reconos_sw.Broker
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
    """

    def __init__(self, tb, project, args, out):
        self.tb = tb
        self.project = project
        self.broker = tb.broker
        self.runtime = tb.runtime
        self.messages = tb.messages
        self.memory = tb.memory
        self.args = args
        self.out = Path(out)
        self.results = {}
        self.clock_mhz = project.clock_mhz
        self._resources = {}
        self._start = cocotb.utils.get_sim_time("ns")

    def now(self):
        """System clock cycles since the nodes started."""
        return round((cocotb.utils.get_sim_time("ns") - self._start) * self.clock_mhz / 1000)

    async def cycles(self, n):
        await ClockCycles(self.tb.dut.aclk, n)

    def resource(self, thread, name, slot=None):
        """The model object of resource ``name`` of ``thread`` (in its first slot by default):
        ``.ptr`` is the message's address for message resources."""
        t = next(t for t in self.project.threads if t.name == thread)
        slot = t.slots[0].id if slot is None else slot
        return self._resources[slot][t.handle(name)]

    def log(self, text):
        self.tb.dut._log.info(text)


def _load_nodes(project):
    path = project.dir / "sim.py"
    if not path.is_file():
        return None
    spec = importlib.util.spec_from_file_location(f"rosgate_sim_{project.name.lower()}", path)
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(project.dir))
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(project.dir))
    return module


@cocotb.test()
async def run_project(dut):
    """Create the project's threads and run its software nodes to completion."""
    from gen.config import load_project, project_library
    from gen.system import thread_module_path

    p = bench_params()
    project = load_project(p["build_cfg"])
    tb = ReconosTB(dut, ram_size=p.get("ram_size", 1 << 25))
    for name in os.environ.get("ROSGATE_EXTERNAL_INPUTS", "").split():
        getattr(dut, name).value = 0     # ports of slots without a thread: idle
    await tb.reset()
    await tb.start_runtime(project_library(project))
    ctx = SimContext(tb, project, p.get("args", {}), p["out"])
    module = _load_nodes(project)
    created = []
    for thread in project.threads:
        if not thread_module_path(project, thread).is_file():
            continue
        for slot in thread.slots:
            res = model_resources(thread)
            ctx._resources[slot.id] = res
            await tb.runtime.create_thread(slot.id, res)
            created.append(slot.id)
    if module is not None and hasattr(module, "setup"):
        module.setup(ctx)
    nodes = list(getattr(module, "NODES", [])) if module is not None else []
    ctx._start = cocotb.utils.get_sim_time("ns")
    tasks = [cocotb.start_soon(node(ctx)) for node in nodes]
    limit_us = float(p.get("limit_ms", 1000)) * 1000
    if tasks:
        try:
            await with_timeout(Combine(*tasks), limit_us, "us")
        except Exception as exc:
            if type(exc).__name__ != "SimTimeoutError":
                raise
            raise AssertionError(f"the software nodes did not finish within "
                                 f"{limit_us / 1000:g} ms of simulated time; delegate logs "
                                 f"{dict(tb.runtime.log)}, errors {tb.runtime.errors}") from None
        for t in tasks:
            t.result()
    assert not tb.runtime.errors, f"protocol errors: {tb.runtime.errors}"
    ctx.results.setdefault("cycles", ctx.now())
    ctx.results.setdefault("slots_running", created)
    Path(p["out"]).mkdir(parents=True, exist_ok=True)
    (Path(p["out"]) / "sim_results.json").write_text(json.dumps(ctx.results, indent=2) + "\n")


def run_project_sim(build_cfg, sim="verilator", *, out, args=None, limit_ms=1000, seed=None,
                    quiet=False):
    """Export, build and run the project's system under ``sim``; return the nodes' results."""
    from gen.config import load_project
    from gen.system import build_system

    build_cfg = Path(build_cfg).resolve()
    project = load_project(build_cfg)
    out = Path(out).resolve()
    params = {"build_cfg": str(build_cfg), "arch": project.arch,
              "threads": [s.name for s in sorted(project.slots, key=lambda s: s.id)],
              "async_slots": [s.id for s in project.slots
                              if s.clock is not project.system_clock],
              "clock_ns": _period_ns(project.system_clock.freq),
              "slot_clock_ns": {str(s.id): _period_ns(s.clock.freq) for s in project.slots},
              "args": dict(args or {}), "out": str(out), "limit_ms": limit_ms}
    system = build_system(project)
    inputs = [name for name, (_, _, flow) in top_ports(system).items()
              if name.startswith("slot") and flow == "in" and not name.endswith("_clk")]
    digest = hashlib.sha1(str(build_cfg).encode()).hexdigest()[:8]
    config_id = f"{project.name.lower()}-{digest}"
    results = out / "sim_results.json"
    if results.exists():
        results.unlink()
    run_bench(__name__, TOP, config_id, params, sim, seed=seed, quiet=quiet,
              build=lambda **_: system,
              extra_env={"ROSGATE_EXTERNAL_INPUTS": " ".join(inputs)})
    return json.loads(results.read_text())


def _period_ns(freq):
    """The clock period in ns, rounded to an even number of picoseconds (cocotb's clock
    needs equal high and low halves at the 1 ps precision)."""
    return round(1e12 / freq / 2) * 2 / 1000


def top_ports(component):
    """Ports of ``component`` as exported: name -> (top signal, inner value, "in"|"out")."""
    from amaranth.lib import wiring
    from gen.export.verilog import VivadoTop
    return {name: (top, value, "in" if flow == wiring.In else "out")
            for name, (top, value, flow) in VivadoTop(component).ports.items()}
