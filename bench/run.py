"""``make bench``: every benchmark, results to bench/results/ (JSON + Markdown)."""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import hmt, msg, reconos  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"


def main():
    start = time.monotonic()
    print("rosgate bench: hardware-mapped topics")
    results = hmt.measure()
    resources = hmt.measure_resources()
    text = hmt.write_results(results, resources, RESULTS)
    print(text)
    print(f"wrote {RESULTS / 'hmt.json'} and {RESULTS / 'hmt.md'} "
          f"({time.monotonic() - start:.0f} s)")
    start = time.monotonic()
    print("rosgate bench: message serializers and deserializers")
    results = msg.measure()
    resources = msg.measure_resources()
    print(msg.write_results(results, resources, RESULTS))
    print(f"wrote {RESULTS / 'msg.json'} and {RESULTS / 'msg.md'} "
          f"({time.monotonic() - start:.0f} s)")
    start = time.monotonic()
    print("rosgate bench: ReconOS infrastructure (MEMIF copies, OS calls, resources)")
    results = reconos.measure()
    resources = reconos.measure_resources()
    print(reconos.write_results(results, resources, RESULTS))
    print(f"wrote {RESULTS / 'reconos.json'} and {RESULTS / 'reconos.md'} "
          f"({time.monotonic() - start:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
