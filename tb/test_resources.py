"""Yosys resource estimates (gen/export/resources.py): a block left out as a black box and
counted per instance gives the whole core's estimate; a black box that names nothing is an
error; an unchanged core's estimate is reused."""

import pytest
from amaranth.hdl import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from gen.export.resources import estimate_resources
from gen.export.verilog import export_verilog


class RegisteredAdder(wiring.Component):
    """``s = a + b``, registered: a block that stays the same across a hierarchy boundary."""

    a: In(16)
    b: In(16)
    s: Out(17)

    def elaborate(self, platform):
        m = Module()
        m.d.sync += self.s.eq(self.a + self.b)
        return m


class TwoAdders(wiring.Component):
    """Two :class:`RegisteredAdder` copies on separate inputs and a register of the XOR of
    their sums."""

    a: In(16)
    b: In(16)
    c: In(16)
    d: In(16)
    x: Out(17)

    def elaborate(self, platform):
        m = Module()
        m.submodules.add0 = add0 = RegisteredAdder()
        m.submodules.add1 = add1 = RegisteredAdder()
        m.d.comb += [add0.a.eq(self.a), add0.b.eq(self.b), add1.a.eq(self.c),
                     add1.b.eq(self.d)]
        out = Signal(17)
        m.d.sync += out.eq(add0.s ^ add1.s)
        m.d.comb += self.x.eq(out)
        return m


def _write(tmp_path, component, top):
    path = tmp_path / f"{top}.v"
    path.write_text(export_verilog(component, top)[0])
    return path



def test_black_box_counted_per_instance(tmp_path):
    whole = estimate_resources(_write(tmp_path, TwoAdders(), "two_adders"), "two_adders")
    rest = estimate_resources(tmp_path / "two_adders.v", "two_adders", blackbox=r"\.add\d$")
    adder = estimate_resources(_write(tmp_path, RegisteredAdder(), "adder"), "adder")
    boxes = [n for n in rest["cells"] if n.endswith((".add0", ".add1"))]
    assert sorted(boxes) == ["two_adders.core.add0", "two_adders.core.add1"]
    assert all(rest["cells"][n] == 1 for n in boxes)
    assert adder["FF"] == 17 and adder["CARRY4"] > 0
    assert rest["FF"] == whole["FF"] - 2 * 17
    # the adders' flip-flops and carries are in the whole estimate, not in the rest
    for key in ("FF", "CARRY4"):
        assert rest[key] + 2 * adder[key] == whole[key], key


def test_black_box_matching_nothing(tmp_path):
    path = _write(tmp_path, RegisteredAdder(), "adder")
    with pytest.raises(ValueError, match=r"blackbox '\\\\.nothing' matches no module"):
        estimate_resources(path, "adder", blackbox=r"\.nothing")


def test_estimate_reused_while_unchanged(tmp_path, monkeypatch):
    path = _write(tmp_path, RegisteredAdder(), "adder")
    first = estimate_resources(path, "adder")
    import gen.export.resources as resources
    calls = []
    real_run, real_popen = resources.subprocess.run, resources.subprocess.Popen

    def run(args, **kwargs):
        calls.append(args)
        return real_run(args, **kwargs)

    def popen(args, **kwargs):
        calls.append(args)
        return real_popen(args, **kwargs)
    monkeypatch.setattr(resources.subprocess, "run", run)
    monkeypatch.setattr(resources.subprocess, "Popen", popen)
    assert estimate_resources(path, "adder") == first
    assert all("-V" in a for a in calls), calls       # only the version was asked
    path.write_text(path.read_text().replace("adder", "adder2"))
    passes = []
    estimate_resources(path, "adder2", progress=passes.append)
    assert any("-p" in a for a in calls)
    assert passes[0] == "SYNTH_XILINX pass" and "ABC" in passes, passes


class LargeStore(wiring.Component):
    """A 32K x 64 synchronous store (2 Mibit): block RAM on 7-series, UltraRAM on
    UltraScale+."""

    waddr: In(15)
    wdata: In(64)
    we: In(1)
    raddr: In(15)
    rdata: Out(64)

    def elaborate(self, platform):
        from amaranth.lib.memory import Memory
        m = Module()
        m.submodules.store = store = Memory(shape=64, depth=1 << 15, init=[])
        w, r = store.write_port(), store.read_port()
        m.d.comb += [w.addr.eq(self.waddr), w.data.eq(self.wdata), w.en.eq(self.we),
                     r.addr.eq(self.raddr), self.rdata.eq(r.data)]
        return m


@pytest.mark.parametrize("part, family", [
    ("xczu7ev-ffvc1156-2-e", "xcup"), ("xczu3eg-sbva484-1-e", "xcup"),
    ("xc7z020clg484-1", "xc7"), ("xc7z100ffg900-2", "xc7"), ("xc7a35ticsg324-1L", "xc7"),
    ("xcku040-ffva1156-2-e", "xcu"), ("xcvu9p-flga2104-2L-e", "xcup")])
def test_family_follows_the_part(part, family):
    from gen.export.resources import xilinx_family
    assert xilinx_family(part) == family


def test_unknown_part_is_refused():
    from gen.export.resources import xilinx_family
    with pytest.raises(ValueError, match="part 'xc6slx9': not a Xilinx 7-series"):
        xilinx_family("xc6slx9")


def test_ultrascale_plus_maps_a_large_store_to_ultraram(tmp_path):
    path = _write(tmp_path, LargeStore(), "large_store")
    xcup = estimate_resources(path, "large_store", family="xcup")
    xc7 = estimate_resources(path, "large_store", family="xc7")
    # 2 Mibit: 8 URAM288 (288 Kibit each) on UltraScale+, 64 RAMB36 (36 Kibit) on 7-series
    assert xcup["URAM"] == 8 and xcup["BRAM36"] == 0, xcup
    assert xc7["URAM"] == 0 and xc7["BRAM18_equiv"] >= 114, xc7
