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
import functools
import hashlib
import json
import os
import sys
from pathlib import Path

import pytest

from gen.export.verilog import write_if_changed
from gen.tops import build_top
from host.simulator import (
    DEFAULT_CXX_OPT,
    QUICK_CXX_OPT,
    SIMULATORS,
    SimulationFailed,
    environment_seed,
    export_top,
    failed_seeds,
    run_top,
    source_digest,
    top_manifest,
    top_params,
)

__all__ = ["SIMULATORS", "ROOT", "SIM_BUILD", "amount", "cocotb_bench", "run_bench",
           "run_rosgate", "bench_params", "bench_manifest", "export_bench_top", "environment_seed",
           "failed_seeds", "verilog_key"]

#: the repository, and its simulator output folder
ROOT = Path(__file__).resolve().parents[1]
SIM_BUILD = ROOT / "sim_build"

#: ``make test-full`` sets ``ROSGATE_FULL=1``: the benches that draw random inputs draw the long
#: matrix's amounts of them (messages, photographs at full size, servo periods); ``make test``
#: and a bare pytest run the same cases with fewer draws
_FULL = os.environ.get("ROSGATE_FULL", "0") not in ("", "0")


def run_rosgate(*args, cwd=None, env=None, timeout=600):
    """``rosgate <args>`` as a user runs it: its own process (``python -m host.cli``), in
    ``cwd`` (default: the repository); the completed process, output captured as text."""
    import subprocess
    env = dict(os.environ if env is None else env, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "host.cli", *map(str, args)],
                          cwd=cwd or ROOT, env=env, capture_output=True, text=True,
                          timeout=timeout)


def amount(quick, full):
    """``full`` in the long matrix (``ROSGATE_FULL=1``, ``make test-full``), else ``quick``.

    The simulators inherit the environment, so a cocotb test module and the pytest test that
    runs it agree."""
    return full if _FULL else quick


#: Tops whose tests simulate long enough to repay an optimised C++ build: the
#: network stack's tests exchange megabytes with Linux and peer models (test_net[stack-verilator]
#: 74 s built at -Os, 225 s at -O0)
OPTIMISED_TOPS = frozenset({"net"})

bench_params = top_params
bench_manifest = top_manifest


def _waves():
    return os.environ.get("WAVES", "0") not in ("", "0")


#: what a bench top's Verilog can depend on besides its parameters: every file of these
#: folders (the hardware, its generators and message definitions, the bench tops), and the
#: Python of these
_DESIGN_FOLDERS, _PYTHON_FOLDERS = ("hdl", "gen"), ("tb", "bench", "host")


@functools.cache
def _design_digest():
    return source_digest(*(ROOT / folder for folder in _DESIGN_FOLDERS),
                         *(p for folder in _PYTHON_FOLDERS for p in (ROOT / folder).rglob("*.py")),
                         root=ROOT)


def _named_files(value):
    """Files named by string values anywhere in ``value`` (message folders, I/O descriptions),
    relative to the repository or absolute."""
    if isinstance(value, dict):
        value = list(value.values())
    if isinstance(value, (list, tuple)):
        return [f for v in value for f in _named_files(v)]
    if isinstance(value, str) and value and len(value) < 4096 and "\n" not in value:
        path = ROOT / value
        if path.is_file():
            return [path]
        if path.is_dir() and path != ROOT:
            return sorted(p for p in path.rglob("*") if p.is_file())
    return []


def verilog_key(top, params, build=None):
    """A fingerprint of the Verilog of ``top`` built with ``params`` (by ``build``, default the
    :data:`gen.tops.TOPS` builder): the sources it can depend on, the parameters and the files
    they name. ``None`` when ``build`` may hold state the fingerprint does not see (a lambda
    or a closure): that top is converted every time."""
    if build is not None and (build.__name__ == "<lambda>" or build.__closure__
                              or "<locals>" in build.__qualname__):
        return None
    digest = hashlib.sha256(_design_digest().encode())
    if build is not None:
        digest.update(f"{build.__module__}.{build.__qualname__}".encode())
    digest.update(json.dumps([top, params], sort_keys=True).encode())
    for path in _named_files(params):
        digest.update(str(path).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:32]


def _maker(top, params, build):
    """A function of no arguments that makes ``top`` with ``params`` (by ``build``, default the
    :data:`gen.tops.TOPS` builder): called only when its conversion is not cached."""
    return lambda: (build or functools.partial(build_top, top))(**params)


def export_bench_top(top, params, build_dir, *, build=None, icarus=False):
    """Export ``top`` with ``params`` into ``build_dir``; return the Verilog path.

    ``build`` makes the component (default: the :data:`gen.tops.TOPS` builder of ``top``).
    """
    return export_top(_maker(top, params, build), top, build_dir, icarus=icarus,
                      key=verilog_key(top, params, build))


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
              extra_env=None, quiet=False, run_name=None, optimise=False, harness=None,
              ecp5_models=False):
    """Export, build and run the cocotb tests of ``module`` against ``top`` in
    ``sim_build/<top>-<config_id>-<sim>/``; raise on failure, naming each failed test's seed
    and the command that repeats the pytest item with it.

    ``build`` and ``extra_env`` serve benchmark tops that are not in :data:`gen.tops.TOPS`
    (built without lint); ``quiet`` sends the simulator's log to ``sim-<module>.log`` in the
    build folder; ``run_name`` keeps the results and log of one case of a parametrised test
    apart from the module's other cases in the same build. ``seed`` (default: ``SEED`` in the
    environment, else a new one) seeds cocotb. ``harness(params)``, if given, returns the
    Verilator harness of :func:`host.simulator.run_top` (compiled models around the top) for
    the configuration. ``ecp5_models`` runs a top that instantiates ECP5 primitives (such as
    the MNIST CNN with ``multipliers="ecp5"``) with their cycle-level models
    (:data:`host.board_sim.PRIMITIVES`) in the same Verilog file.

    A Verilator model is compiled without optimisation (``OPT_FAST=-O0``): cocotb's Python
    side sets the pace of a test's simulation, so the C++ build is most of a bench's time
    (topic 4x4_w512, ReconOS r64 calls and the ros1_w64 codec: 101 s built at Verilator's
    default -Os, 58 s at -O0, on 2 cores), except for :data:`OPTIMISED_TOPS`, compiled at
    :data:`host.simulator.DEFAULT_CXX_OPT`. ``optimise`` keeps Verilator's own -Os, in a
    build folder of its own, for runs long enough to repay it (``make bench``).
    """
    cxx_opt = None if optimise else DEFAULT_CXX_OPT if top in OPTIMISED_TOPS else QUICK_CXX_OPT
    build_dir = SIM_BUILD / f"{top}-{config_id}-{sim}{'-opt' if optimise else ''}"
    short = module.rsplit(".", 1)[-1] + (f"-{run_name}" if run_name else "")
    env = {
        "ROSGATE_CONFIG": config_id,
        # the test modules import tb (not installed); relative paths in the parameters
        # (message folders) are relative to the repository
        "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
        "ROSGATE_ROOT": str(ROOT),
        **(extra_env or {}),
    }
    exported = None
    if ecp5_models:
        from host.board_sim import PRIMITIVES
        build_dir = build_dir.with_name(build_dir.name + "-ecp5")
        vfile = export_bench_top(top, params, build_dir, build=build, icarus=sim == "icarus")
        exported = build_dir / f"{top}_with_ecp5_models.v"
        write_if_changed(exported, PRIMITIVES.read_text() + vfile.read_text())
    try:
        return run_top(module, top, _maker(top, params, build), sim, build_dir, params=params,
                       testcase=testcase, seed=seed, extra_env=env, exported=exported,
                       log_file=build_dir / f"sim-{short}.log" if quiet else None,
                       run_name=run_name, lint=build is None and not ecp5_models,
                       cxx_opt=cxx_opt,
                       waves=_waves(), verilog_key=verilog_key(top, params, build),
                       harness=harness(params) if harness else None)
    except SimulationFailed as exc:
        seeds = sorted({s for s in exc.failed.values() if s is not None})
        again = "".join(f"; again with: {rerun_hint(s)}" for s in seeds)
        if not exc.failed:
            raise AssertionError(f"{top} [{config_id}, {sim}]: {exc}") from None
        raise AssertionError(f"{top} [{config_id}, {sim}]: {len(exc.failed)} of {exc.total} "
                             f"cocotb tests failed: {', '.join(exc.failed)} (seed "
                             f"{', '.join(map(str, seeds)) or 'not recorded'}{again}; log "
                             f"above, results in {exc.results})") from None


def config_params(value):
    """``(params, marks)`` of a configuration value, plain or wrapped in ``pytest.param``."""
    if isinstance(value, dict):
        return value, ()
    return value.values[0], value.marks


def cocotb_bench(top, configs, *, module=None, simulators=SIMULATORS, long=(), testcases=None,
                 harness=None):
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
        short on a fresh 2-core machine; each such configuration still runs on the other
        simulator in ``make test``.
    testcases : list of str or None
        Run only these cocotb tests of the module (for configurations that exist for one
        behaviour); default: all.
    harness : callable or None
        ``harness(params)``: the Verilator harness of a configuration (see :func:`run_bench`),
        such as :func:`host.compiled.streams.stream_harness` for its stream ports.
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
        run_bench(module, top, config_id, params, sim, testcase=testcases, harness=harness)

    bench.__name__ = f"test_{top}"
    return bench
