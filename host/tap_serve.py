"""The cocotb side of :class:`host.tapsim.TapSimulation`: clocks and resets the design, bridges
its GMII port to the TAP device, writes a status file every few thousand cycles (simulated
time, and whatever the design reports), and ends when the stop file appears. Runs inside the
simulator; :class:`~host.tapsim.TapSimulation` starts it."""

import json
import os
import time
from pathlib import Path

import cocotb
from cocotb.triggers import ClockCycles

from host.compiled.gmii_tap import CompiledTapPort
from host.simulator import clock_cycles, start_gmii_clocks, top_params
from host.tap import TapBridge

#: cycles between looks at the stop file and status updates
POLL_CYCLES = 4096


@cocotb.test()
async def serve(dut):
    """Run the design on the TAP device until the stop file appears. Its GMII port is on the
    compiled TAP port (the wrapper of :func:`host.compiled.gmii_tap.gmii_tap_harness`)."""
    params = top_params()
    start_gmii_clocks(dut, params["port"])
    dut.aresetn.value = 0
    await ClockCycles(dut.aclk, 4)
    dut.aresetn.value = 1
    await ClockCycles(dut.aclk, 2)
    port = CompiledTapPort(TapBridge.open_tap(params["tap"]),
                           poll_cycles=params.get("poll_cycles", 64))
    await serve_until_stopped(dut, dut.aclk, [port], params)


async def serve_until_stopped(dut, clock, bridges, params):
    """Count ``clock``'s cycles and write the status file until the stop file appears."""
    stop = Path(params["stop_file"])
    status = Path(params["status_file"])
    watch = params.get("watch", [])
    cycles = 0
    started, cpu_started = time.monotonic(), time.process_time()
    while not stop.exists():
        await clock_cycles(clock, POLL_CYCLES)
        cycles += POLL_CYCLES
        stats = {key: sum(b.stats[key] for b in bridges) for key in bridges[0].stats}
        report = {"cycles": cycles, "wall_s": time.monotonic() - started,
                  "cpu_seconds": time.process_time() - cpu_started,
                  "bridge": stats,
                  "signals": {name: int(getattr(dut, name).value) for name in watch}}
        tmp = status.with_suffix(".tmp")
        tmp.write_text(json.dumps(report))
        os.replace(tmp, status)
