"""ReconROS demo nodes benchmark (issue: ReconOS infrastructure §3; docs/reconos.md):
cycles of the sort service, sort action, mailbox sort, Sobel service and DIP + Sobel round
trip as hardware threads under Verilator, beside P-RR Table 6; yosys resources of the
threads beside P-RR Table 5."""

import json

from bench.report import component_resources, resource_table, write_report
from gen.export.resources import YOSYS_COMMAND
from gen.tops import build_thread
from tb.harness import SIM_BUILD, run_bench
from tb.reconos_tb import apps_configs

CLOCK_MHZ = 100
#: P-RR Table 6 (ms): raw HW (the hardware node), pp HW (ping-pong through ROS 2)
PAPER = {"sort_service": ("Sorting, raw HW", 35.11), "sort_action": None,
         "mbox_sort": None, "sobel_service": ("Sobel, raw HW", 22.28),
         "sobel_pair": ("Sobel, pp HW", 68.54)}
LABELS = {
    "sort_service": "sort service call, 2048 x uint32 (take, read, sort, set size, write, respond)",
    "sort_action": "sort action goal, 2048 x uint32 (goal, accept, result request, sort with feedback, result)",
    "mbox_sort": "mailbox sort, 2048 x uint32 in place (ReconOS sort demo)",
    "sobel_service": "Sobel service call, 640x480 bgr8 (read, filter, write 900 KiB)",
    "sobel_pair": "DIP + Sobel round trip, 640x480 bgr8 (take, copy in, service, copy back, publish)",
}
#: P-RR Table 5 (Zynq-7100): Slice LUTs, BRAM
PAPER_RESOURCES = {"sort_service": "10396 LUT, 2 BRAM", "sobel_server": "13625 LUT, 10 BRAM"}


def measure(log=print):
    rows = []
    for arch, params in (("r64", apps_configs()["apps_r64"]), ("r32", apps_configs()["apps_r32"])):
        out = SIM_BUILD / f"bench-reconos-apps-{arch}.json"
        log(f"  simulating the demo nodes on {arch} (Verilator)...")
        run_bench("bench.reconos_apps_bench", "reconos", f"apps_{arch}", params, "verilator",
                  quiet=True, optimise=True, extra_env={"ROSGATE_BENCH_OUT": str(out)})
        rec = json.loads(out.read_text())
        for key, label in LABELS.items():
            rows.append({"arch": arch, "case": key, "label": label, "cycles": rec[key],
                         "ms": rec[key] / (CLOCK_MHZ * 1e3),
                         "paper": PAPER[key]})
        rows.append({"arch": arch, "case": "sort_action_feedbacks",
                     "feedbacks": rec["sort_action_feedbacks"]})
    return {"clock_mhz": CLOCK_MHZ, "rows": rows}


def measure_resources(log=print):
    rows = []
    params = apps_configs()["apps_r64"]
    for spec in params["threads"]:
        # the counter and the call sequencer are test fixtures, not demo nodes
        if spec["kind"] in ("counter", "calls") or any(r["thread"] == spec["kind"] for r in rows):
            continue
        log(f"  yosys {YOSYS_COMMAND}: {spec['kind']} thread (r64)...")
        res = component_resources(build_thread("r64", spec), f"thread_{spec['kind']}",
                                  f"thread-{spec['kind']}")
        rows.append({"thread": spec["kind"], **res,
                     "paper": PAPER_RESOURCES.get(spec["kind"], "-")})
    return rows


def markdown(results, resources):
    lines = ["# ReconROS demo nodes benchmark", "",
             f"Hardware threads of the `apps` system (tb/reconos_tb.py) under Verilator at "
             f"{CLOCK_MHZ} MHz with the software model answering OS calls through the OSIF "
             "AXI-Lite registers and a zero-wait AxiRam; every result checked (sorted() / the "
             "spec's Sobel golden model). Cycles from the Python call (service request, goal, "
             "mailbox put, image publish) to its answer, so OSIF handshakes are included. "
             "Paper: P-RR Table 6 (Zynq-7100, HLS threads not optimised, 100 MHz).", "",
             "| arch | operation | cycles | ms | paper ms |", "|---|---|---|---|---|"]
    for r in results["rows"]:
        if "cycles" not in r:
            continue
        paper = f"{r['paper'][1]} ({r['paper'][0]})" if r["paper"] else "-"
        lines.append(f"| {r['arch']} | {r['label']} | {r['cycles']} | {r['ms']:.3f} | {paper} |")
    fb = [r for r in results["rows"] if r["case"] == "sort_action_feedbacks"]
    lines += ["", "Sort action feedback messages per goal: " +
              ", ".join(f"{r['arch']} {r['feedbacks']}" for r in fb) + ".", "",
              ]
    lines += resource_table(resources, "thread", "thread", extra=(("paper (Table 5)", "paper"),),
                            detail="; thread alone, r64, without the slot FIFOs and "
                                   "infrastructure")
    lines.append("")
    return "\n".join(lines)


def write_results(results, resources, folder):
    return write_report(folder, "reconos_apps", dict(results, resources=resources),
                        markdown(results, resources))
