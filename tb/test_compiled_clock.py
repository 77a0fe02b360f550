"""The compiled clocks of rosgate's Verilator main (``host/compiled/verilator_main.cpp``)
against cocotb's GPI clock, on ``two_clock_counters.v``: two clocks of unrelated periods
(8 ns and 7.998 ns, the GMII clock and one 250 ppm fast), started at different times,
counters on both edges. The same cocotb test runs with either clock implementation in one
build: the times of every rising edge it sees, the values it reads at each edge and at timers
between edges, and what a ``clock_cycles`` wait returns must be the same.

A second test checks that Python threads run while the model does: the main loop lets the
interpreter's lock go between callbacks."""

import json
import sys
import threading
import time

import cocotb
from cocotb.triggers import FallingEdge, RisingEdge, Timer

import host.simulator as simulator
from host.simulator import QUICK_CXX_OPT, clock_cycles, run_top, start_clock, top_params

from .harness import ROOT, SIM_BUILD

TOP = ROOT / "tb" / "two_clock_counters.v"


async def _edges(clock, values, count, out):
    for _ in range(count):
        await RisingEdge(clock)
        out.append((cocotb.utils.get_sim_time("ps"), *(int(v.value) for v in values)))


@cocotb.test()
async def clocks_and_what_a_test_sees(dut):
    p = top_params()
    if p["gpi"]:
        simulator._compiled_clocks.cache_clear()
        simulator._compiled_clocks = lambda: None
    seen = {"compiled": simulator._compiled_clocks() is not None}
    values = (dut.count_a, dut.count_b, dut.fall_copy)
    start_clock(dut.clk_a, 8)
    await Timer(3, "ns")
    start_clock(dut.clk_b, 7.998)
    edges_a, edges_b = [], []
    cocotb.start_soon(_edges(dut.clk_a, values, 300, edges_a))
    cocotb.start_soon(_edges(dut.clk_b, values, 300, edges_b))
    timers = []
    for step in (1, 7, 13, 4001, 2, 999):
        await Timer(step, "ps")
        timers.append((cocotb.utils.get_sim_time("ps"), *(int(v.value) for v in values)))
    await FallingEdge(dut.clk_a)
    timers.append((cocotb.utils.get_sim_time("ps"), *(int(v.value) for v in values)))
    await clock_cycles(dut.clk_b, 200)
    timers.append((cocotb.utils.get_sim_time("ps"), *(int(v.value) for v in values)))
    await Timer(3000, "ns")
    seen.update(edges_a=edges_a, edges_b=edges_b, timers=timers)
    with open(p["out"], "w") as f:
        json.dump(seen, f)


@cocotb.test()
async def python_threads_run_while_the_model_runs(dut):
    """With a switch interval of an hour, a thread that wants the interpreter's lock gets it
    only when the holder lets it go: if the simulator kept it while the model runs (cocotb's
    own main does), the thread could not run during one long timer of pure model time (a
    million cycles, tenths of a second of wall time, long enough for the operating system
    to schedule the thread on a loaded machine)."""
    p = top_params()
    start_clock(dut.clk_a, 8)
    go, ran = threading.Event(), threading.Event()

    def thread():
        go.wait()                   # lock released while it waits, wanted back when go is set
        sum(range(1000))
        ran.set()

    saved = sys.getswitchinterval()
    sys.setswitchinterval(3600)
    try:
        worker = threading.Thread(target=thread, daemon=True)
        worker.start()
        go.set()
        started = time.monotonic()
        await Timer(p["cycles"] * 8, "ns")      # nothing in Python until it ends
        after_timer = ran.is_set()
        wall = time.monotonic() - started
    finally:
        sys.setswitchinterval(saved)
    worker.join(timeout=10)
    with open(p["out"], "w") as f:
        json.dump({"ran_during_timer": after_timer, "timer_wall_s": wall}, f)


def _run(gpi, tmp_path):
    out = tmp_path / f"{'gpi' if gpi else 'compiled'}.json"
    run_top(__name__, TOP.stem, None, "verilator", SIM_BUILD / "compiled_clock",
            params={"gpi": gpi, "out": str(out)}, extra_env={"PYTHONPATH": str(ROOT)},
            lint=False, cxx_opt=QUICK_CXX_OPT, exported=TOP, run_name="gpi" if gpi else None,
            testcase=["clocks_and_what_a_test_sees"])
    return json.loads(out.read_text())


def test_compiled_clocks_give_the_gpi_clocks_edges_and_values(tmp_path):
    compiled, gpi = _run(False, tmp_path), _run(True, tmp_path)
    assert compiled.pop("compiled") and not gpi.pop("compiled")
    assert len(compiled["edges_a"]) == len(compiled["edges_b"]) == 300
    # the edges come where the periods say: clock a every 8,000 ps from 4,000
    assert [e[0] for e in compiled["edges_a"]][:3] == [4000, 12000, 20000]
    assert compiled == gpi


def test_python_threads_run_while_the_model_runs(tmp_path):
    out = tmp_path / "threads.json"
    run_top(__name__, TOP.stem, None, "verilator", SIM_BUILD / "compiled_clock",
            params={"out": str(out), "cycles": 1_000_000}, extra_env={"PYTHONPATH": str(ROOT)},
            lint=False, cxx_opt=QUICK_CXX_OPT, exported=TOP, run_name="threads",
            testcase=["python_threads_run_while_the_model_runs"])
    seen = json.loads(out.read_text())
    assert seen["ran_during_timer"], \
        f"a Python thread did not run during {seen['timer_wall_s']:.3f} s of model time"
