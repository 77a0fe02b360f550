"""gen.export.comb_cycles: the faster combinational cycle check finds exactly the cycles
Amaranth's own check finds, names them, and leaves the exported Verilog as it was."""

import contextlib
import random

import pytest
from amaranth.back import rtlil
from amaranth.hdl import Cat, CombinationalCycle, Module, Mux, Signal, _nir

import gen.export.verilog as verilog_export
from gen.export.comb_cycles import check_comb_cycles, faster_comb_cycle_check
from gen.export.verilog import export_verilog
from hdl.dds.topic import Topic

AMARANTH_CHECK = _nir.Netlist.check_comb_cycles


def verdict(design, ports, check):
    """None when ``design`` converts under ``check``, else the cycle's message."""
    original = _nir.Netlist.check_comb_cycles
    _nir.Netlist.check_comb_cycles = check
    try:
        rtlil.convert(design, ports=ports)
        return None
    except CombinationalCycle as error:
        return str(error)
    finally:
        _nir.Netlist.check_comb_cycles = original


def random_design(rng):
    """A module of random combinational and registered assignments between a few signals,
    with whole-signal and single-bit assignments, bitwise, arithmetic, comparison, shift,
    slice and multiplexer cells (some with cycles, some not)."""
    m = Module()
    inputs = [Signal(rng.randrange(1, 9), name=f"i{k}") for k in range(3)]
    nodes = [Signal(rng.randrange(1, 9), name=f"s{k}") for k in range(rng.randrange(3, 7))]
    sources = inputs + nodes

    def operand():
        value = rng.choice(sources)
        if len(value) > 1 and rng.random() < 0.3:
            lo = rng.randrange(len(value))
            value = value[lo:rng.randrange(lo + 1, len(value) + 1)]
        return value

    def expression():
        a, b = operand(), operand()
        return rng.choice([
            lambda: a + b, lambda: a - b, lambda: a & b, lambda: a | b, lambda: a ^ b,
            lambda: ~a, lambda: a == b, lambda: a < b, lambda: a >> b[:2], lambda: a << 1,
            lambda: Mux(b[0], a, operand()), lambda: Cat(a, b), lambda: a.any(),
            lambda: a.bit_select(b[:2], 1), lambda: a,
        ])()

    registered = rng.sample(range(len(nodes)), rng.randrange(0, 3))
    for index, node in enumerate(nodes):
        domain = m.d.sync if index in registered else m.d.comb
        if len(node) > 1 and rng.random() < 0.4:
            for bit in range(len(node)):        # bit by bit: bit-level paths matter
                domain += node[bit].eq(expression())
        else:
            domain += node.eq(expression())
    return m, inputs + nodes


def test_same_verdict_as_amaranth_on_random_designs():
    rng = random.Random(20261128)
    cyclic = acyclic = 0
    for _ in range(400):
        design, ports = random_design(rng)
        theirs = verdict(design, ports, AMARANTH_CHECK)
        ours = verdict(design, ports, check_comb_cycles)
        assert (ours is None) == (theirs is None), (theirs, ours)
        cyclic += ours is not None
        acyclic += ours is None
    assert cyclic > 50 and acyclic > 50, (cyclic, acyclic)


def test_cycle_through_another_bit_of_a_wide_cell_is_found():
    """An adder's bit 3 feeds back into its operand's bit 0: the walk enters the adder by
    its bit 0 and reaches bit 3, which the walk holds on its path as well."""
    m = Module()
    x, total = Signal(8), Signal(8)
    m.d.comb += [total.eq(x + 1), x[1:].eq(5), x[0].eq(total[3])]
    message = verdict(m, [total], check_comb_cycles)
    assert message is not None and message.startswith("Combinational cycle detected")
    assert "operator +" in message and "signal" in message
    assert verdict(m, [total], AMARANTH_CHECK) is not None


def test_bit_level_paths_are_not_cycles():
    """Bits of one signal that feed each other without a loop (a ripple through an
    assignment list and a bitwise cell) are not a cycle, as in Amaranth."""
    m = Module()
    a, chain = Signal(8), Signal(8)
    m.d.comb += chain[0].eq(a[0])
    for k in range(1, 8):
        m.d.comb += chain[k].eq(chain[k - 1] ^ a[k])
    assert verdict(m, [a, chain], check_comb_cycles) is None
    assert verdict(m, [a, chain], AMARANTH_CHECK) is None


def test_context_restores_amaranth_check():
    with faster_comb_cycle_check():
        inside = _nir.Netlist.check_comb_cycles
    assert _nir.Netlist.check_comb_cycles is AMARANTH_CHECK
    assert inside in (check_comb_cycles, AMARANTH_CHECK)


def test_exported_verilog_unchanged(monkeypatch):
    """A top exported with the faster check is the text Amaranth's own check lets through."""
    fast, _ = export_verilog(Topic(3, 3, data_width=64), "topic")
    monkeypatch.setattr(verilog_export, "faster_comb_cycle_check", contextlib.nullcontext)
    plain, _ = export_verilog(Topic(3, 3, data_width=64), "topic")
    assert plain == fast


@pytest.mark.parametrize("width", [64, 512])
def test_wide_cells_walked_once(width):
    """The number of steps does not grow with an adder's width times its inputs' width."""
    m = Module()
    a, b, total = Signal(width), Signal(width), Signal(width)
    m.d.comb += total.eq(a + b)
    steps = []
    original = _nir.Operator.comb_edges_to

    def counted(self, bit):
        for edge in original(self, bit):
            steps.append(bit)
            yield edge
    _nir.Operator.comb_edges_to = counted
    try:
        assert verdict(m, [a, b, total], check_comb_cycles) is None
    finally:
        _nir.Operator.comb_edges_to = original
    assert len(steps) <= 2 * width + 2, len(steps)
