"""A faster combinational cycle check for Amaranth 0.5's netlists.

Amaranth checks every netlist for combinational cycles before it writes Verilog or RTLIL
(``Netlist.check_comb_cycles``). In 0.5 that check walks the netlist bit by bit, and an
arithmetic, comparison or shift cell lists all its input bits as the source of each of its
output bits: a cell with ``n`` output and ``m`` input bits costs ``n * m`` steps. A 512-bit
message deserializer spends about three quarters of its export time there (33 of 46 s).

Such a cell's output bits all have the same sources, so a walk that reached one of them has
covered all of them. :func:`check_comb_cycles` walks each such cell once, holding all its
output bits on the path while it does (a path back to any of them is a cycle through it),
and every other cell bit by bit as Amaranth does; it finds the same cycles and reports them
in Amaranth's words. Amaranth's development branch does the same since
amaranth-lang/amaranth#1632 (not in a 0.5 release); :func:`faster_comb_cycle_check` uses
this check only for an Amaranth without it.
"""

import contextlib

from amaranth.hdl import _ast, _nir

__all__ = ["check_comb_cycles", "faster_comb_cycle_check"]

#: cells whose every output bit has the sources of all the others (``comb_edges_to`` does
#: not look at the bit); any other cell, also one this module does not know, is walked bit
#: by bit
_SAME_SOURCES_FOR_EVERY_BIT = (_nir.Top, _nir.Part, _nir.Matches, _nir.FlipFlop,
                               _nir.AsyncReadPort, _nir.SyncReadPort, _nir.Initial,
                               _nir.AnyValue, _nir.Instance)


def _same_sources_for_every_bit(cell):
    if isinstance(cell, _nir.Operator):
        bitwise = ((len(cell.inputs) == 1 and cell.operator == "~") or
                   (len(cell.inputs) == 2 and cell.operator in ("&", "|", "^")) or
                   len(cell.inputs) == 3)
        return not bitwise
    return type(cell) in _SAME_SOURCES_FOR_EVERY_BIT


def _describe(step):
    obj, bit, src_loc = step
    if isinstance(obj, _ast.Signal):
        obj = f"signal {obj.name}"
    elif isinstance(obj, _nir.Operator):
        obj = f"operator {obj.operator}"
    else:
        obj = f"cell {obj.__class__.__qualname__}"
    src_loc = "<unknown>:0" if src_loc is None else f"{src_loc[0]}:{src_loc[1]}"
    return f"  {src_loc}: {obj} bit {bit}\n"


def check_comb_cycles(netlist):
    """Raise :class:`amaranth.hdl.CombinationalCycle`, naming the cycle's path as Amaranth
    does, when ``netlist`` (an ``amaranth.hdl._nir.Netlist``) has a combinational cycle."""
    checked, on_path = set(), set()
    groups = {}           # cell index -> its output nets, for cells walked once

    def enter(net):
        """A frame for ``net``: [net, nets it puts on the path, its sources, step taken]."""
        if net.is_const:
            sources, group = iter(()), (net,)
        elif net.is_late:
            sources, group = iter(((netlist.connections[net], None),)), (net,)
        else:
            cell = netlist.cells[net.cell]
            if _same_sources_for_every_bit(cell):
                if net.cell not in groups:
                    groups[net.cell] = tuple(cell.output_nets(net.cell))
                group = groups[net.cell]
            else:
                group = (net,)
            sources = iter(cell.comb_edges_to(net.bit))
        on_path.update(group)
        return [net, group, sources, None]

    def step_of(frame):
        net, _, _, src_loc = frame
        if net.is_late:
            signal, bit = netlist.late_to_signal[net]
            return (signal, bit, signal.src_loc)
        return (netlist.cells[net.cell], net.bit, src_loc)

    def walk(start):
        if start in checked:
            return
        path = [enter(start)]
        while path:
            frame = path[-1]
            for source, src_loc in frame[2]:
                if source in checked:
                    continue
                frame[3] = src_loc
                if source in on_path:
                    first = next(i for i, f in enumerate(path) if source in f[1])
                    raise _nir.CombinationalCycle("".join(
                        ["Combinational cycle detected, path:\n"] +
                        [_describe(step_of(f)) for f in path[first:]]))
                path.append(enter(source))
                break
            else:
                path.pop()
                on_path.difference_update(frame[1])
                checked.update(frame[1])

    for cell_idx, cell in enumerate(netlist.cells):
        for net in cell.output_nets(cell_idx):
            walk(net)
    for value in netlist.signals.values():
        for net in value:
            walk(net)


@contextlib.contextmanager
def faster_comb_cycle_check():
    """Within this context, Amaranth's netlists are checked by :func:`check_comb_cycles`
    (unless this Amaranth already walks such cells once)."""
    if hasattr(_nir.Cell, "comb_edges_is_per_bit"):
        yield
        return
    original = _nir.Netlist.check_comb_cycles
    _nir.Netlist.check_comb_cycles = check_comb_cycles
    try:
        yield
    finally:
        _nir.Netlist.check_comb_cycles = original
