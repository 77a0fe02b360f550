"""``make bench``: every benchmark, results to bench/results/ (JSON, Markdown, PNG plots and,
for the network engine, pcap captures).

``--resources-only`` (``make bench-resources``) keeps the cycle results of the last run and
re-measures only the yosys resource estimates; bench names (``hmt``, ``net``, ...) select
some of them."""

import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import (av_chain, ball_on_plate, cosim, examples, finemb, hmt,  # noqa: E402
                   kernels, msg, net, reconos, reconos_apps, ros2, services, timing)
from bench.plots import write_plots  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"


#: (title, module): each module has measure(), measure_resources() and write_results()
BENCHES = [
    ("hardware-mapped topics", hmt),
    ("message serializers and deserializers", msg),
    ("ReconOS infrastructure (MEMIF copies, OS calls, resources)", reconos),
    ("ReconROS demo nodes (sort, Sobel) as hardware threads", reconos_apps),
    ("streaming kernels (Sobel, Gaussian, colour, equalization, sort, PID, inverse "
     "kinematics)", kernels),
    ("network engine and TCPROS (goodput, seed paper's image transfers, resources)", net),
    ("FinEmbP lines of 1 to 16 PID nodes, the Python master through TAP, resources", finemb),
    ("ROS 2 bridge: overhead per message against a Cyclone loopback round trip", ros2),
    ("ball-on-plate control loop: four hardware threads closed through a plant model",
     ball_on_plate),
    ("the fpgaDDS lane-following chain: chain alpha over 100 scene frames", av_chain),
    ("services and actions over hardware topics against ReconROS' memory-based services",
     services),
    ("co-simulation pace: rosgate sim against the bare Verilator model", cosim),
    ("the examples as rosgate sim runs them: the figures the documentation quotes", examples),
    ("timing: every core placed and routed on ECP5 (LFE5UM5G-85F-8), 3 seeds", timing),
]


def main(argv=None):
    args = sys.argv[1:] if argv is None else argv
    resources_only = "--resources-only" in args
    only = [a for a in args if not a.startswith("--")]
    names = [module.__name__.rsplit(".", 1)[-1] for _, module in BENCHES]
    unknown = [a for a in only + [a for a in args if a.startswith("--")]
               if a not in names and a != "--resources-only"]
    if unknown:
        raise SystemExit(f"bench/run.py: unknown argument {unknown[0]!r}; benches: "
                         f"{', '.join(names)}; option: --resources-only")
    for title, module in BENCHES:
        start = time.monotonic()
        name = module.__name__.rsplit(".", 1)[-1]
        if only and name not in only:
            continue
        print(f"rosgate bench: {title}", flush=True)
        if resources_only:
            # the cycle results of the last full run, with fresh yosys estimates
            saved = json.loads((RESULTS / f"{name}.json").read_text())
            results = {k: v for k, v in saved.items() if k != "resources"}
        else:
            results = module.measure()
        resources = module.measure_resources()
        print(module.write_results(results, resources, RESULTS))
        plots = write_plots([name], log=lambda _: None)
        print(f"wrote {RESULTS / (name + '.json')}, {RESULTS / (name + '.md')}"
              f"{''.join(', ' + str(p) for p in plots)} ({time.monotonic() - start:.0f} s)",
              flush=True)
    return 0

if __name__ == "__main__":
    sys.exit(main())
