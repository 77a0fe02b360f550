"""The co-simulation's pace beside the bare model's, in simulated cycles per CPU-second.

For each run, side by side:

* the **bare model**: the run's Verilator model (the same Verilog, wrapper, public ports and
  options) driven by a C++ main that only toggles the clocks, reset released, every other
  input idle (``bench/cosim_bare_main.cpp``);
* the **co-simulation** doing its real work: cycles simulated over the simulator process's
  CPU time (model and Python together) while it ran.

The runs: the two project systems under ``rosgate sim`` (``cpu_seconds`` of
``sim_results.json``); the 4:4 64-bit topic bench (every case of ``bench/hmt.py``); the network
engine with the Python TCP peer moving 1 MiB each way (``bench/net.py``'s ``seed_16k`` case);
a line of 4 FinEmbP nodes on the TAP device driven by the Python master over UDP sockets for
1,000 cycles (the simulator's CPU time from its status file; the master and the kernel run in
other processes and set the pace of the wall clock). Cycles are those of the run's first
clock: ``aclk`` for the systems, the topic and the FinEmbP line, the GMII clock for the engine.

The figures before were measured once and are kept here as measured: the project systems on
commit 7822329 (cocotbext-axi's ``AxiRam`` in Python, ``ClockCycles`` waits, the model at
-O1; none at 1 px/clk), the topic and the engine on 1297819 (cocotb's GPI clock, the engine's
peer waiting with ``ClockCycles``), each with the same CPU-time measure. None for the FinEmbP
line: its TAP port was Python's then, at 87 FinEmbP cycles per second with 2 nodes.
"""

import json
import subprocess
from pathlib import Path

from bench.hmt import PAPER_TABLE_I, run_topology, single_cases, stream_cases
from bench.report import write_report
from gen.config import apply_parameters, load_project
from host.compiled import SOURCES as AXI_RAM_SOURCES
from host.compiled.gmii_tap import GMII_TAP_LINK_ARGS, GMII_TAP_SOURCES
from host.project_sim import project_build_dir, run_project_sim
from host.simulator import (CORE_NS, DEFAULT_CXX_OPT, GMII_NS, gmii_clocks, project_cxx_opt,
                            VERILATOR_BENCH_ARGS, VERILATOR_TOP_ARGS, verilator_make_env)
from host.toolchain import put_verilator_on_path
from tb.harness import ROOT, SIM_BUILD

BARE_MAIN = Path(__file__).resolve().parent / "cosim_bare_main.cpp"

#: name -> (build.cfg, --arg values, --param values, bare-model cycles to run)
SYSTEMS = {
    "sobel_dip": ("examples/sobel_dip/build.cfg",
                  {"images": "coffee_640x480.png,chelsea_96x72.png,coffee_80x60.png"}, [],
                  2_000_000),
    "av_chain_p4": ("examples/av_chain/build.cfg", {"frames": "1"}, ["*.pixels_per_beat=4"],
                    500_000),
    "av_chain_p1": ("examples/av_chain/build.cfg", {"frames": "1"}, ["*.pixels_per_beat=1"],
                    500_000),
}
#: before: the systems measured on 7822329 (cycles and the simulator's CPU seconds while the
#: nodes ran); the topic and the engine on 1297819, before the compiled clocks (cocotb's GPI
#: clock; the engine's peer waiting with cocotb's ClockCycles), with the same PaceMeter
BEFORE = {"sobel_dip": {"cycles": 877204, "cpu_seconds": 24.036},
          "av_chain_p4": {"cycles": 1407326, "cpu_seconds": 95.41},
          "av_chain_p1": {"cycles": None, "cpu_seconds": None},
          "topic_4x4_w64": {"cycles": 2699286, "cpu_seconds": 3.054},
          "net_tcp_1mib": {"cycles": 3641901, "cpu_seconds": 27.132}}
#: the issue's goals: the co-simulation at this share of the bare model's pace
GOAL = 0.5
NETWORK_GOAL = 0.25
#: the topic bench's configuration and the engine's case of bench/net.py (1 MiB each way)
TOPIC = (4, 4, 64)
NET_CASE = "seed_16k"


def bare_model(build_dir, toplevel, sources, args, clocks, cycles, cxx_opt, log, *,
               axi_ram=False):
    """Build the bare model of ``toplevel`` beside its co-simulation build (``sources`` and
    Verilator ``args`` as that build has them, its control file when there is one) and run it
    for ``cycles`` cycles of the first of ``clocks`` (name -> period in ns); return its cycles
    and CPU seconds."""
    build_dir = Path(build_dir)
    exe_dir = build_dir / "bare"
    exe_dir.mkdir(parents=True, exist_ok=True)
    # the template with this top's clocks and reset defined in front (a forced include would
    # come before the model's precompiled header and make the compiler refuse it)
    lines = ["#define BARE_CLOCKS " + " ".join(
        f"X({name}, {round(period * 500)})" for name, period in clocks.items()),
        "#define BARE_RESET_N aresetn"]
    if axi_ram:
        lines.append("#define BARE_AXI_RAM 1")
    main = exe_dir / "bare_main.cpp"
    main.write_text("\n".join(lines) + "\n" + BARE_MAIN.read_text())
    control = build_dir / f"{toplevel}.vlt"
    verilator = put_verilator_on_path()
    command = [verilator, "-cc", "--exe", "--build", "-j", "2", "-Mdir", str(exe_dir),
               "--top-module", toplevel, "--prefix", "Vtop", "-o", "bare", *args,
               "--timescale", "1ns/1ps", *([str(control)] if control.exists() else []),
               str(main), *map(str, sources)]
    log(f"    building the bare model in {exe_dir}")
    with verilator_make_env("verilator", cxx_opt):
        subprocess.run(command, check=True, capture_output=True, text=True)
    run = subprocess.run([str(exe_dir / "bare"), str(cycles)], check=True, capture_output=True,
                         text=True)
    return json.loads(run.stdout.strip().splitlines()[-1])


def _rate(r):
    return r["cycles"] / r["cpu_seconds"] if r and r.get("cpu_seconds") else None


def _row(name, kind, bare, after, before, goal, log):
    row = {"system": name, "kind": kind, "bare": bare, "cosim": after, "cosim_before": before,
           "goal": goal}
    for key, r in (("bare", bare), ("cosim", after), ("cosim_before", before)):
        row[f"{key}_cycles_per_cpu_s"] = round(_rate(r)) if _rate(r) else None
    row["ratio"] = round(_rate(after) / _rate(bare), 3)
    row["ratio_before"] = round(_rate(before) / _rate(bare), 3) if _rate(before) else None
    log(f"    bare {row['bare_cycles_per_cpu_s']:,} cycles/CPU-s, co-simulation "
        f"{row['cosim_cycles_per_cpu_s']:,} ({row['ratio']:.0%} of bare)")
    return row


def measure_systems(log):
    rows = []
    for name, (cfg, args, params, bare_cycles) in SYSTEMS.items():
        build_cfg = ROOT / cfg
        log(f"  {name}: rosgate sim {cfg}")
        sim = run_project_sim(build_cfg, "verilator", out=SIM_BUILD / f"bench-cosim-{name}",
                              args=args, thread_params=params, limit_ms=1000)
        after = {"cycles": sim["cycles"], "cpu_seconds": sim["cpu_seconds"]}
        project = apply_parameters(load_project(build_cfg), params)
        build_dir = Path(project_build_dir(project, params, "verilator"))
        bare = bare_model(build_dir, "rosgate_system_cosim",
                          [build_dir / "rosgate_system.v", build_dir / "rosgate_system_cosim.v",
                           *AXI_RAM_SOURCES], VERILATOR_TOP_ARGS, {"aclk": 10}, bare_cycles,
                          project_cxx_opt(), log, axi_ram=True)
        rows.append(_row(name, "system", bare, after, BEFORE[name], GOAL, log))
    return rows


def measure_topic(log):
    pubs, subs, width = TOPIC
    name = f"topic_{pubs}x{subs}_w{width}"
    log(f"  {name}: the topic bench's cases (bench/hmt.py)")
    pace = SIM_BUILD / f"bench-cosim-{name}.json"
    run_topology(pubs, subs, width,
                 single_cases(pubs, width, tuple(PAPER_TABLE_I)) + stream_cases(pubs, width),
                 pace=pace)
    after = json.loads(pace.read_text())
    build_dir = SIM_BUILD / f"topic_bench-{pubs}x{subs}_w{width}-verilator-opt"
    bare = bare_model(build_dir, "topic_bench", [build_dir / "topic_bench.v"],
                      VERILATOR_BENCH_ARGS, {"aclk": 10}, 5_000_000, None, log)
    return _row(name, "topic", bare, after, BEFORE[name], None, log)


def measure_net(log):
    from bench.net import TCP_CASES, run_tcp_case
    name = "net_tcp_1mib"
    log(f"  {name}: the engine with the Python TCP peer, {NET_CASE} case of bench/net.py "
        f"({TCP_CASES[NET_CASE][3]:,} bytes each way)")
    pace = SIM_BUILD / f"bench-cosim-{name}.json"
    run_tcp_case(NET_CASE, SIM_BUILD / f"bench-cosim-{name}-out.json", pace=pace)
    after = json.loads(pace.read_text())
    build_dir = SIM_BUILD / f"net_bench-{NET_CASE}-verilator-opt"
    bare = bare_model(build_dir, "net_bench", [build_dir / "net_bench.v"],
                      VERILATOR_BENCH_ARGS, {"gmii_clk": GMII_NS, "aclk": CORE_NS}, 2_000_000,
                      None, log)
    return _row(name, "network", bare, after, BEFORE[name], NETWORK_GOAL, log)


def measure_finemb(log):
    from bench.finemb import SOCKET_NODES, measure_socket_master
    name = f"finemb_tap_line{SOCKET_NODES}"
    socket = measure_socket_master(log)
    if "skipped" in socket:
        return None
    after = dict(socket["simulation"], finemb_cycle_rate_hz=socket["cycle_rate_hz"])
    build_dir = SIM_BUILD / f"tap-finemb-n{SOCKET_NODES}"
    clocks, _ = gmii_clocks(["gmii_clk"])
    bare = bare_model(build_dir, "finemb_line_tap",
                      [build_dir / "finemb_line.v", build_dir / "finemb_line_tap.v",
                       *GMII_TAP_SOURCES],
                      [*VERILATOR_TOP_ARGS, *GMII_TAP_LINK_ARGS], clocks, 1_000_000,
                      DEFAULT_CXX_OPT, log)
    return _row(name, "network (TAP)", bare, after, None, NETWORK_GOAL, log)


def measure(log=print):
    runs = measure_systems(log)
    runs += [row for row in (measure_topic(log), measure_net(log), measure_finemb(log)) if row]
    return {"runs": runs, "goal_ratio": GOAL, "network_goal_ratio": NETWORK_GOAL}


def measure_resources(log=print):
    return []


def markdown(r):
    lines = ["# Co-simulation pace against the bare model", "",
             "Simulated cycles per CPU-second of the simulator process (`python bench/run.py "
             "cosim`). The bare model is the same Verilator model with a C++ main that only "
             "toggles the clocks; the co-simulation is the run doing its real work: "
             "`rosgate sim` for the systems, the cocotb bench for the topic and the engine, "
             "the TAP simulation under the Python FinEmbP master for the line. Before: the "
             "systems on commit 7822329 (the process memory in cocotbext-axi's `AxiRam`, "
             "`ClockCycles` waits), the topic and the engine on 1297819 (cocotb's GPI clock, "
             "the engine's peer waiting with `ClockCycles`).",
             "", "| run | kind | bare | co-simulation before | co-simulation now | "
             "before / bare | now / bare | goal |", "|---|---|---|---|---|---|---|---|"]
    for row in r["runs"]:
        def fmt(v):
            return f"{v:,}" if v else "-"
        before = f"{row['ratio_before']:.1%}" if row["ratio_before"] else "-"
        goal = row.get("goal", r["goal_ratio"] if row.get("kind", "system") == "system" else None)
        lines.append(f"| {row['system']} | {row.get('kind', 'system')} | "
                     f"{fmt(row['bare_cycles_per_cpu_s'])} | "
                     f"{fmt(row['cosim_before_cycles_per_cpu_s'])} | "
                     f"{fmt(row['cosim_cycles_per_cpu_s'])} | {before} | {row['ratio']:.1%} | "
                     f"{f'>= {goal:.0%}' if goal else '-'} |")
    finemb = [row for row in r["runs"] if "finemb_cycle_rate_hz" in row["cosim"]]
    for row in finemb:
        lines += ["", f"{row['system']}: {row['cosim']['finemb_cycle_rate_hz']} FinEmbP cycles "
                      f"per second of wall time, {row['cosim']['cycles']:,} simulated cycles "
                      f"in {row['cosim']['wall_s']} s wall, {row['cosim']['cpu_seconds']} s of "
                      f"the simulator's CPU (the master and the kernel set the pace)."]
    return "\n".join(lines) + "\n"


def plot(r, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = [row["system"] for row in r["runs"]]
    series = [("bare model", "bare_cycles_per_cpu_s"),
              ("co-simulation before", "cosim_before_cycles_per_cpu_s"),
              ("co-simulation now", "cosim_cycles_per_cpu_s")]
    fig, ax = plt.subplots(figsize=(7, 3.5))
    width = 0.27
    for i, (label, key) in enumerate(series):
        values = [(row[key] or 0) / 1000 for row in r["runs"]]
        ax.bar([x + (i - 1) * width for x in range(len(names))], values, width, label=label)
    ax.set_xticks(range(len(names)), names)
    ax.set_ylabel("k cycles per CPU-second")
    ax.legend()
    ax.set_title("rosgate sim against its bare Verilator model")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_results(results, resources, folder):
    plot(results, Path(folder) / "cosim.png")
    return write_report(folder, "cosim", results, markdown(results))
