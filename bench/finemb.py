"""FinEmbP benchmark (docs/finemb.md): lines of 1, 2, 4, 8 and 16 PID nodes under Verilator at
125 MHz (GMII, 1 Gbit/s) with the cycle-accurate master, polled sequentially and pipelined:
the cycle rate at the fastest fixed period, what the master link could carry for the same
frames, the hop latency and the cycle jitter at the far end; the Python socket master
through a TAP device against 2 nodes; yosys resources of a node beside the TCP engine's."""

import json
from pathlib import Path

from bench.report import component_resources, resource_table, write_report
from gen.export.resources import YOSYS_COMMAND
from gen.finemb import load_io_description
from hdl.finemb import NODE_CLOCKS_HZ
from tb.finemb_line_top import build_finemb_line_bench_top
from tb.finemb_tb import CLOCK_NS, PID_IO
from tb.harness import SIM_BUILD, run_bench

LINES = (1, 2, 4, 8, 16)
#: P-FIN's PID loop on a Nios II soft core (FINROC framework), and the goals of the issue
PFIN_HZ = 25_000
GOALS = {1: 250_000, 16: 40_000}
#: the nodes' core clock (the benches' cycles are the GMII clock's)
CORE_MHZ = NODE_CLOCKS_HZ["aclk"] / 1e6
HOP_GOAL_NS = 200
SOCKET_NODES = 4
SOCKET_CYCLES = 1000
#: lines this long are compiled optimised: the simulation, not the build, dominates
OPTIMISE_FROM = 8


def measure_lines(log=print):
    rows = []
    for n in LINES:
        out = SIM_BUILD / f"bench-finemb-n{n}.json"
        log(f"  simulating a line of {n} node{'s' * (n > 1)} (Verilator)...")
        run_bench("bench.finemb_bench", "finemb_line", f"bench_n{n}",
                  {"io": PID_IO, "nodes": n}, "verilator", build=build_finemb_line_bench_top,
                  quiet=True, optimise=n >= OPTIMISE_FROM,
                  extra_env={"ROSGATE_BENCH_OUT": str(out), "ROSGATE_FINEMB_NODES": str(n)})
        rec = json.loads(out.read_text())
        for polling, mode in rec["modes"].items():
            period_ns = mode["period_cycles"] * CLOCK_NS
            rows.append({
                "nodes": n, "polling": polling,
                "cycle_rate_hz": round(1e9 / period_ns),
                "period_cycles": mode["period_cycles"],
                "wire_limit_hz": round(1e9 / max(mode["tx_ns"], mode["rx_ns"])),
                "hop_latency_ns": rec["hop_latency_ns"],
                "jitter_ns": mode["jitter_ns"],
                "late": mode["late"],
                "frames_tx_bytes": mode["frames_tx"], "frames_rx_bytes": mode["frames_rx"],
                "goal_hz": GOALS.get(n),
            })
    return rows


def measure_socket_master(log=print):
    """The Python master over UDP sockets through a TAP device against a simulated line;
    ``simulation``: the simulator's own cycles (``aclk``), wall and CPU seconds."""
    from host.finemb.run import run_line_with_master
    from host.tap import namespace_unavailable
    why = namespace_unavailable()
    if why:
        log(f"  Python socket master skipped: {why}")
        return {"nodes": SOCKET_NODES, "skipped": why}
    log(f"  the Python socket master through TAP against {SOCKET_NODES} nodes "
        f"({SOCKET_CYCLES} cycles)...")
    stats = run_line_with_master(load_io_description(PID_IO), SOCKET_NODES,
                                 cycles=SOCKET_CYCLES,
                                 build_dir=SIM_BUILD / f"tap-finemb-n{SOCKET_NODES}")
    simulation = stats["simulation"]
    return {"nodes": SOCKET_NODES, "polling": "pipelined", "cycles": stats["cycles"],
            "cycle_rate_hz": round(stats["cycle_rate_hz"], 1), "late": stats["late"],
            "states": stats["states"],
            "simulation": {"cycles": simulation["cycles"],
                           "wall_s": round(simulation["wall_s"], 3),
                           "cpu_seconds": round(simulation["cpu_seconds"], 3)},
            "note": "wall-clock rate of this machine against the simulated line (the "
                    "simulator runs far slower than the hardware): not comparable with the "
                    "simulated rows"}


def measure(log=print):
    return {"clock_mhz": 1000 // CLOCK_NS, "line": measure_lines(log),
            "socket_master": measure_socket_master(log)}


def measure_resources(log=print):
    from hdl.finemb import FinembPidNode
    io = load_io_description(PID_IO)
    rows = []
    log(f"  yosys {YOSYS_COMMAND}: FinEmbP PID node...")
    rows.append({"design": "FinEmbP PID node (2 ports, forwarding, client, page buffer, PID)",
                 **component_resources(FinembPidNode(io), "finemb_node", "finemb-node")})
    # the engine as the network bench measured it, by the same flow
    net = json.loads((Path(__file__).resolve().parent / "results" / "net.json").read_text())
    engine = next(r for r in net["resources"] if r["block"].startswith("engine"))
    rows.append({**engine, "design": f"TCP/IP engine (bench/results/net.json): "
                                     f"{engine['block']}"})
    return rows


def markdown(results, resources):
    lines = ["# FinEmbP benchmark", "",
             f"Lines of PID nodes under Verilator, cycles of the {results['clock_mhz']} MHz "
             f"GMII clock (1 Gbit/s; the nodes' protocol side and application on a "
             f"{CORE_MHZ} MHz core clock), the cycle-accurate master of tb/finemb_tb.py on node "
             "0's port 0. A cycle is the "
             "SoC and one ISEND_REQ per node, each answered by an ISEND_RES with the node's "
             "PID output for that cycle (checked against the AVR221 model). *sequential*: the "
             "master asks the next node after the previous answer; *pipelined*: all requests "
             "back to back. The rate is the fastest fixed period at which every answer came "
             "in time (40 cycles, none late; periods are tried upwards from the longest "
             "free-running cycle); *wire limit* what the master link could carry "
             "for the same frames (full duplex: the busier direction, 672 ns per minimum "
             "frame); *hop* the first byte into node 0 to the first byte out of its far port "
             "for a frame it forwards; *jitter* the spread of SoC periods at the last node's "
             "SoC event, which is on its core clock: a SoC reaches the wire of every node at "
             "the same cycle of every period (forwarding stays on the GMII clock), and a node "
             "sees it a core cycle earlier or later with the core clock's phase. "
             f"P-FIN: the PID loop at {PFIN_HZ // 1000} kHz on a Nios II soft core.", "",
             "| nodes | polling | cycle rate kHz | period cycles | wire limit kHz | hop ns | "
             "jitter ns | late | goal kHz | vs P-FIN |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results["line"]:
        goal = f">= {r['goal_hz'] / 1000:.0f}" if r["goal_hz"] else "-"
        lines.append(f"| {r['nodes']} | {r['polling']} | {r['cycle_rate_hz'] / 1000:.1f} | "
                     f"{r['period_cycles']} | {r['wire_limit_hz'] / 1000:.1f} | "
                     f"{r['hop_latency_ns']:.0f} | {r['jitter_ns']} | {r['late']} | {goal} | "
                     f"{r['cycle_rate_hz'] / PFIN_HZ:.1f}x |")
    s = results["socket_master"]
    lines += ["", "## The Python socket master through TAP", ""]
    if "skipped" in s:
        lines.append(f"Skipped: {s['skipped']}.")
    else:
        lines.append(f"`rosgate tap finemb --nodes {s['nodes']}`'s master (host/finemb/master.py, "
                     "UDP sockets in a network namespace, the kernel's stack, a TAP device "
                     f"bridged to the simulated line): {s['cycles']} cycles at "
                     f"{s['cycle_rate_hz']} Hz, {s['late']} late answers, final states "
                     f"{s['states']}. {s['note']}.")
    lines += resource_table(resources, "design", "design")
    lines += ["", "![plot](finemb_cycle_rate.png)"]
    return "\n".join(lines) + "\n"


def write_results(results, resources, folder):
    return write_report(folder, "finemb", {**results, "resources": resources},
                        markdown(results, resources))
