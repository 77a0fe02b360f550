"""The examples as a user runs them: ``rosgate sim`` of each example project under Verilator
with the arguments its documentation shows, and the cycle figures the documentation quotes
(docs/simulation.md, docs/howto.md, docs/ros2.md), so the documents cite measured numbers
(tb/test_docs_figures.py holds them to this file)."""

from bench.report import write_report
from host.project_sim import run_project_sim
from tb.harness import ROOT, SIM_BUILD

CLOCK_MHZ = 100
#: example -> (``--arg`` values, what the figure is)
RUNS = {
    "sobel_dip": ({"images": "coffee_80x60.png,chelsea_96x72.png"},
                  "publish to the filtered image on /image_filtered, per photograph"),
    "inverse_kinematics": ({}, "publish on /angle to the answer on /legangle, mean of the "
                               "answered requests"),
    "sort_service": ({}, "request to response of each call, two clients at once (2048 "
                         "values each)"),
    "image_echo": ({}, "publish on /image_in to the echo on /image_out, per image"),
}


def _figures(name, results):
    if name == "sobel_dip":
        return {i["image"]: i["cycles"] for i in results["images"]}
    if name == "inverse_kinematics":
        return {"mean": round(results["mean_cycles"]), "answered": results["answered"]}
    if name == "sort_service":
        return {f"client {c['client']} call {c['call']}": c["cycles"]
                for c in results["calls"]}
    if name == "image_echo":
        return {i["image"]: i["cycles"] for i in results["images"]}
    raise KeyError(name)


def measure(log=print):
    out = {}
    for name, (args, what) in RUNS.items():
        log(f"  rosgate sim examples/{name}/build.cfg "
            f"{' '.join(f'--arg {k}={v}' for k, v in args.items())} (Verilator)...")
        results = run_project_sim(ROOT / "examples" / name / "build.cfg", "verilator",
                                  out=SIM_BUILD / f"bench-examples-{name}", args=args,
                                  limit_ms=100)
        out[name] = {"args": args, "what": what, "cycles": _figures(name, results),
                     "total_cycles": results["cycles"]}
    return {"clock_mhz": CLOCK_MHZ, "examples": out}


def measure_resources(log=print):
    return {}


def markdown(r):
    lines = ["# The examples as rosgate sim runs them", "",
             f"Verilator, system clock {r['clock_mhz']} MHz; cycles of the system clock. The "
             "documentation's figures for the examples come from this table.", "",
             "| example | arguments | figure | cycles |", "|---|---|---|---|"]
    for name, e in r["examples"].items():
        args = " ".join(f"`--arg {k}={v}`" for k, v in e["args"].items()) or "(defaults)"
        for key, cycles in e["cycles"].items():
            lines.append(f"| {name} | {args} | {e['what']}: {key} | {cycles:,} |")
    return "\n".join(lines) + "\n"


def write_results(results, resources, folder):
    return write_report(folder, "examples", results, markdown(results))


if __name__ == "__main__":
    from pathlib import Path
    print(write_results(measure(), {}, Path(__file__).resolve().parent / "results"))
