"""``host.simulator.run_top`` on Verilator: the model shows the cocotb side the exported top
module's signals only (its ports), so Verilator may optimise the component below them;
``internals=True`` shows every signal. Both models compute the same thing. The cocotb test
below runs only when the pytest tests of this module start it."""

import json
import os
import time
from pathlib import Path

import cocotb
import pytest
from amaranth import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out
from cocotb.triggers import ClockCycles, RisingEdge

from host.simulator import (QUICK_CXX_OPT, VERILOG_CACHE_DAYS, clock_cycles, export_top,
                            run_top, start_clock)


class _Accumulator(wiring.Component):
    """Adds ``amount`` into ``total`` on every clock with ``add`` high."""

    add: In(1)
    amount: In(8)
    total: Out(16)

    def elaborate(self, platform):
        m = Module()
        with m.If(self.add):
            m.d.sync += self.total.eq(self.total + self.amount)
        return m


class _Top(wiring.Component):
    """An accumulator in a submodule, its sum on ``total``; ``seen`` is a wire of this
    component (inside the exported top's ``core``)."""

    add: In(1)
    amount: In(8)
    total: Out(16)

    def elaborate(self, platform):
        m = Module()
        m.submodules.inner = inner = _Accumulator()
        seen = Signal(8, name="seen")
        m.d.comb += [inner.add.eq(self.add), inner.amount.eq(self.amount),
                     self.total.eq(inner.total), seen.eq(self.amount)]
        return m


@cocotb.test()
async def sums_and_reports_what_it_sees(dut):
    """Adds 1..10 through the ports; writes the sum and which handles exist to
    ``ROSGATE_SEEN``."""
    start_clock(dut.aclk, 10)
    dut.aresetn.value = 0
    dut.add.value = 0
    await ClockCycles(dut.aclk, 2)
    dut.aresetn.value = 1
    for n in range(1, 11):
        dut.add.value, dut.amount.value = 1, n
        await RisingEdge(dut.aclk)
    dut.add.value = 0
    await ClockCycles(dut.aclk, 2)

    def visible(*path):
        handle = dut
        try:
            for name in path:
                handle = getattr(handle, name)
            return True
        except AttributeError:
            return False
    Path(os.environ["ROSGATE_SEEN"]).write_text(json.dumps({
        "total": int(dut.total.value), "port": visible("amount"),
        "seen": visible("core", "seen"), "inner": visible("core", "inner", "total")}))


@cocotb.test()
async def clock_cycles_ends_where_clockcycles_ends(dut):
    """``clock_cycles(clk, n)`` and cocotb's ``ClockCycles(clk, n)``, started at the same
    instant (on an edge, or at a random point of a cycle), return at the same simulated time,
    for short and long waits; writes the mismatches to ``ROSGATE_SEEN``."""
    import random

    from cocotb.triggers import Timer
    from cocotb.utils import get_sim_time

    start_clock(dut.aclk, 10)
    mismatches, checked = [], 0

    async def reference(n, ends):
        await ClockCycles(dut.aclk, n)
        ends.append(get_sim_time("ps"))
    for n in [1, 2, 3, 4, 5, 7, 64, 1000, 20_000] + [random.randrange(1, 300) for _ in range(20)]:
        if random.random() < 0.5:
            await Timer(random.randrange(1, 10_000), unit="ps")
        else:
            await RisingEdge(dut.aclk)
        ends = []
        task = cocotb.start_soon(reference(n, ends))
        await clock_cycles(dut.aclk, n)
        mine = get_sim_time("ps")
        await task
        checked += 1
        if ends[0] != mine:
            mismatches.append([n, ends[0], mine])
    Path(os.environ["ROSGATE_SEEN"]).write_text(json.dumps({"checked": checked,
                                                             "mismatches": mismatches}))


@pytest.mark.parametrize("sim", ["icarus", "verilator"])
def test_clock_cycles_equals_clockcycles(tmp_path, sim):
    seen = tmp_path / "seen.json"
    run_top(__name__, "accumulator_top", _Top(), sim, tmp_path / "build",
            extra_env={"ROSGATE_SEEN": str(seen)}, lint=False, cxx_opt=QUICK_CXX_OPT,
            log_file=tmp_path / "sim.log", testcase=["clock_cycles_ends_where_clockcycles_ends"])
    report = json.loads(seen.read_text())
    assert report["checked"] == 29 and report["mismatches"] == []


@pytest.mark.parametrize("internals", [False, True], ids=["top_only", "internals"])
def test_verilator_model_shows_the_top_module(tmp_path, internals):
    seen = tmp_path / "seen.json"
    run_top(__name__, "accumulator_top", _Top(), "verilator", tmp_path / "build",
            extra_env={"ROSGATE_SEEN": str(seen)}, lint=False, cxx_opt=QUICK_CXX_OPT,
            log_file=tmp_path / "sim.log", internals=internals,
            testcase=["sums_and_reports_what_it_sees"])
    report = json.loads(seen.read_text())
    assert report["total"] == sum(range(1, 11))
    assert report["port"] is True
    assert report["seen"] is internals and report["inner"] is internals
    assert (tmp_path / "build" / "accumulator_top.vlt").exists() is not internals


def test_conversion_is_cached_by_key_for_both_simulators(tmp_path, monkeypatch):
    """``export_top`` with a key converts once: a second export with the same key, for the
    other simulator, reads the cache without making the component; its Verilog differs from
    an uncached export only by the simulator's fixes, and its manifest is the same; another
    key converts again."""
    monkeypatch.setenv("ROSGATE_CACHE", str(tmp_path / "cache"))
    made = []

    def make():
        made.append(1)
        return _Top()

    first = export_top(make, "accumulator_top", tmp_path / "v", key="k1")
    second = export_top(make, "accumulator_top", tmp_path / "i", icarus=True, key="k1")
    assert len(made) == 1
    plain = export_top(_Top(), "accumulator_top", tmp_path / "p", icarus=True)
    assert second.read_text() == plain.read_text()
    assert first.read_text() == export_top(_Top(), "accumulator_top", tmp_path / "q").read_text()
    assert first.read_text() != second.read_text()          # Icarus' t=0 fix
    for folder in ("i", "p"):
        manifest = json.loads((tmp_path / folder / "accumulator_top.json").read_text())
        assert manifest == json.loads((tmp_path / "v" / "accumulator_top.json").read_text())
    export_top(make, "accumulator_top", tmp_path / "v2", key="k2")
    assert len(made) == 2
    assert sorted(p.name for p in (tmp_path / "cache" / "verilog").glob("*.v")) == [
        "accumulator_top-k1.v", "accumulator_top-k2.v"]


def test_cache_forgets_conversions_unused_for_a_week(tmp_path, monkeypatch):
    monkeypatch.setenv("ROSGATE_CACHE", str(tmp_path / "cache"))
    export_top(_Top, "accumulator_top", tmp_path / "a", key="old")
    old = tmp_path / "cache" / "verilog" / "accumulator_top-old.v"
    week = time.time() - (VERILOG_CACHE_DAYS + 1) * 86400
    os.utime(old, (week, week))
    export_top(_Top, "accumulator_top", tmp_path / "b", key="new")
    assert sorted(p.name for p in old.parent.iterdir()) == [
        "accumulator_top-new.json", "accumulator_top-new.lock", "accumulator_top-new.v"]
