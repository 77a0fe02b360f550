"""The pace of a cocotb bench run, for ``bench/cosim.py``: simulated cycles of one clock per
CPU-second of the simulator process (model and Python together), written as JSON to the file
``ROSGATE_BENCH_PACE`` names (nothing when it is unset)."""

import json
import os
import time
from pathlib import Path

from cocotb.utils import get_sim_time

__all__ = ["PaceMeter"]


class PaceMeter:
    """Started when made; :meth:`write` records the cycles of a ``period_ns`` clock and the
    process's CPU seconds since then."""

    def __init__(self, period_ns):
        self.period_ns = period_ns
        self.cpu_start = time.process_time()
        self.ns_start = get_sim_time("ns")

    def write(self):
        path = os.environ.get("ROSGATE_BENCH_PACE")
        if not path:
            return
        cycles = round((get_sim_time("ns") - self.ns_start) / self.period_ns)
        Path(path).write_text(json.dumps({
            "cycles": cycles, "cpu_seconds": round(time.process_time() - self.cpu_start, 3)}))
