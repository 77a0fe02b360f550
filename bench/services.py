"""Services and actions over hardware topics against ReconROS' memory-based services
(docs/services.md): round-trip cycles of the sort service called by a hardware client over
the service's hardware topics (``examples/hw_services``) and by a client of the ReconROS
service through the OSIF, MEMIF and the software broker (``examples/sort_service``, whose
server is ReconROS' sort node), for the same request sizes and the same merge sorter; and the
Fibonacci action's goal-to-result cycles over hardware topics. Both under Verilator, one
client at a time, nothing else running."""

from bench.report import write_report
from host.project_sim import run_project_sim
from tb.harness import ROOT, SIM_BUILD

HW_SERVICES = ROOT / "examples" / "hw_services" / "build.cfg"
MEMORY_SERVICE = ROOT / "examples" / "sort_service" / "build.cfg"
SIZES = [0, 1, 256, 2048]
ORDERS = [0, 10, 46]
#: cycles between two Fibonacci values in the bench (the server's work per step)
STEP_CYCLES = 0
CLOCK_MHZ = 100


def same_clock_copy(build_cfg, folder):
    """A copy of the project of ``build_cfg`` in ``folder`` whose slots run on the system
    clock (the sort service demo's slots run at 120 MHz): the comparison is then cycle for
    cycle at 100 MHz."""
    import re
    import shutil
    if folder.exists():
        shutil.rmtree(folder)
    shutil.copytree(build_cfg.parent, folder)
    text = (folder / "build.cfg").read_text()
    text = re.sub(r"(?m)^Clock = (?!System).*$", "Clock = System", text)
    (folder / "build.cfg").write_text(text)
    return folder / "build.cfg"


def measure(log=print):
    log("  sort service over hardware topics, SortClientA alone (Verilator)...")
    hw = run_project_sim(HW_SERVICES, "verilator", out=SIM_BUILD / "bench-hw_services",
                         args={"sort_sizes": ",".join(map(str, SIZES)),
                               "fib_orders": ",".join(map(str, ORDERS))},
                         thread_params=[f"FibServer.step_cycles={STEP_CYCLES}"], limit_ms=50)
    rows = []
    for call in hw["sort_calls"]:
        assert call["sorted"], call
        rows.append({"values": call["values"], "hw_topics_cycles": call["cycles"]})
    memory_service = same_clock_copy(MEMORY_SERVICE, SIM_BUILD / "bench-sort_service-100mhz")
    for row in rows:
        log(f"  ReconROS memory-based sort service, {row['values']} values (Verilator)...")
        mem = run_project_sim(memory_service, "verilator",
                              out=SIM_BUILD / f"bench-sort_service-{row['values']}",
                              args={"clients": "1", "requests": "1",
                                    "size": str(row["values"])}, limit_ms=50)
        call = mem["calls"][0]
        assert call["sorted"], call
        row["memory_cycles"] = call["cycles"]
    goals = [{"order": g["order"], "feedbacks": g["feedbacks"], "cycles": g["cycles"]}
             for g in hw["fibonacci_goals"] if g["status"] == 0]
    return {"sort": rows, "fibonacci": goals, "step_cycles": STEP_CYCLES,
            "clock_mhz": CLOCK_MHZ}


def measure_resources(log=print):
    return {}


def markdown(r):
    lines = ["# Services and actions over hardware topics", "",
             "Round trip of one sort call, from the client's request to its last reply value "
             "read, one client at a time, the same merge sorter (block of 2048) in both "
             "servers. Over hardware topics the client is a hardware thread "
             "(`examples/hw_services`); ReconROS' memory-based service "
             "(`examples/sort_service`) is called by a software client through the broker, "
             "whose own work counts zero cycles here, so that column is a lower bound for "
             "ReconROS; its slots run on the 100 MHz system clock for this comparison (the "
             "demo's own 120 MHz slot clock removed), so both columns count the same "
             "clock and the same sorter, and their difference is the transport's.", "",
             "| values | hardware topics (cycles) | memory-based (cycles) | difference |",
             "|---|---|---|---|"]
    for row in r["sort"]:
        lines.append(f"| {row['values']} | {row['hw_topics_cycles']:,} | "
                     f"{row['memory_cycles']:,} | "
                     f"{row['memory_cycles'] - row['hw_topics_cycles']:,} |")
    lines += ["", f"Fibonacci action over hardware topics, goal to the result's last value "
              f"({r['step_cycles']} cycles of work per value):", "",
              "| order | feedbacks | cycles | us at 100 MHz |", "|---|---|---|---|"]
    for g in r["fibonacci"]:
        lines.append(f"| {g['order']} | {g['feedbacks']} | {g['cycles']:,} | "
                     f"{g['cycles'] / r['clock_mhz']:.2f} |")
    return "\n".join(lines + ["", "![round trips](services.png)", ""])


def plot(r, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax_sort, ax_fib) = plt.subplots(1, 2, figsize=(11, 4))
    labels = [str(row["values"]) for row in r["sort"]]
    x = range(len(labels))
    ax_sort.bar([i - 0.2 for i in x], [row["hw_topics_cycles"] for row in r["sort"]], 0.4,
                label="hardware topics")
    ax_sort.bar([i + 0.2 for i in x], [row["memory_cycles"] for row in r["sort"]], 0.4,
                label="ReconROS memory-based")
    ax_sort.set(xticks=list(x), xticklabels=labels, yscale="log", xlabel="values sorted",
                ylabel="round trip (cycles at 100 MHz)", title="sort service")
    ax_sort.legend()
    ax_fib.plot([g["order"] for g in r["fibonacci"]], [g["cycles"] for g in r["fibonacci"]],
                "o-")
    ax_fib.set(xlabel="goal order", ylabel="goal to result (cycles)",
               title=f"Fibonacci action, {r['step_cycles']} cycles of work per value")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_results(results, resources, folder):
    plot(results, folder / "services.png")
    return write_report(folder, "services", results, markdown(results))
