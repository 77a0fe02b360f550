"""``make bench``: every benchmark, results to bench/results/ (JSON + Markdown)."""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import hmt, kernels, msg, net, reconos, reconos_apps  # noqa: E402

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
]


def main():
    for title, module in BENCHES:
        start = time.monotonic()
        print(f"rosgate bench: {title}")
        results = module.measure()
        resources = module.measure_resources()
        print(module.write_results(results, resources, RESULTS))
        name = module.__name__.rsplit(".", 1)[-1]
        print(f"wrote {RESULTS / (name + '.json')} and {RESULTS / (name + '.md')} "
              f"({time.monotonic() - start:.0f} s)")
    return 0

if __name__ == "__main__":
    sys.exit(main())
