"""Verilog export of Amaranth components as Vivado-facing tops.

The exported module has an ``aclk`` clock and an active-low synchronous ``aresetn`` (AMBA
convention) and flat ports with single-underscore AMBA names (``s0_axis_tdata``) so that Vivado's
interface inference and cocotbext-axi recognise them (docs/testing.md pitfalls 5 and 7). The text
is stable: no source locations, no internal attributes, no host paths (pitfall 8). Yosys'
``always @*`` trigger registers are initialised in an ``initial`` block so that Icarus evaluates
combinational logic at t=0 (pitfall 3).
"""

import json
import os
import re
from pathlib import Path

from amaranth.back import verilog
from amaranth.hdl import (
    ClockDomain,
    ClockSignal,
    Elaboratable,
    Module,
    ResetSignal,
    Signal,
    ValueCastable,
)
from amaranth.lib import wiring

from .comb_cycles import faster_comb_cycle_check

__all__ = ["VivadoTop", "convert_top", "exported_ports", "export_verilog", "manifest_data",
           "port_name", "write_if_changed", "write_manifest", "without_zero_memory_init",
           "fix_icarus_t0"]


def port_name(path):
    """Flat port name for a signature member path.

    Names are joined with ``_``; an array index is appended to the name before it, and for a
    stream member named ``<x>_axis`` goes before the ``_axis`` suffix (Xilinx ``s0_axis``).

    >>> port_name(("s_axis", 2, "tdata"))
    's2_axis_tdata'
    >>> port_name(("monitor", "pub", 0, "beats"))
    'monitor_pub0_beats'
    """
    parts = []
    for item in path:
        if isinstance(item, int):
            if parts and parts[-1].endswith("_axis"):
                parts[-1] = f"{parts[-1][:-len('_axis')]}{item}_axis"
            elif parts:
                parts[-1] = f"{parts[-1]}{item}"
            else:
                parts.append(str(item))
        else:
            parts.append(str(item))
    return "_".join(parts)


def exported_ports(component, *, clock="aclk", reset="aresetn"):
    """The top-level ports of ``component`` as :class:`VivadoTop` exports it: name -> (inner
    value, flow), clock and reset not included."""
    ports = {}
    for path, member, value in component.signature.flatten(component):
        if isinstance(value, ValueCastable):
            value = value.as_value()
        name = port_name(path)
        if name in ports or name in (clock, reset):
            raise ValueError(f"port name {name!r} of member {path} is not unique")
        ports[name] = (value, member.flow)
    return ports


class VivadoTop(Elaboratable):
    """Wraps a component whose logic runs in the ``sync`` domain as a flat AXI-style top.

    Parameters
    ----------
    component : wiring.Component
        The design; every member of its signature becomes a top-level port named by
        :func:`port_name`.
    clock, reset : str
        Names of the clock and the active-low synchronous reset ports.
    """

    def __init__(self, component, *, clock="aclk", reset="aresetn"):
        self.component = component
        self.clock = Signal(name=clock)
        self.reset_n = Signal(name=reset, init=1)
        #: name -> (top signal, inner value, flow)
        self.ports = {name: (Signal(len(value), name=name), value, flow) for name, (value, flow)
                      in exported_ports(component, clock=clock, reset=reset).items()}

    def elaborate(self, platform):
        m = Module()
        m.domains.sync = ClockDomain("sync")
        m.d.comb += [ClockSignal("sync").eq(self.clock), ResetSignal("sync").eq(~self.reset_n)]
        m.submodules.core = self.component
        for top, value, flow in self.ports.values():
            if flow == wiring.In:
                m.d.comb += value.eq(top)
            else:
                m.d.comb += top.eq(value)
        return m

    def port_list(self):
        """Ports for :func:`amaranth.back.verilog.convert`, clock and reset first."""
        return [self.clock, self.reset_n] + [top for top, _, _ in self.ports.values()]

    def manifest_ports(self):
        """Port descriptions for a JSON manifest: name, direction, width."""
        ports = [{"name": self.clock.name, "direction": "input", "width": 1, "role": "clock"},
                 {"name": self.reset_n.name, "direction": "input", "width": 1,
                  "role": "reset_active_low"}]
        for name, (top, _, flow) in self.ports.items():
            ports.append({"name": name, "direction": "input" if flow == wiring.In else "output",
                          "width": len(top)})
        return ports


_AUTO_REG = re.compile(r"^(\s*)reg (\\\$auto\$\S+)\s+= (\S+);$", re.MULTILINE)


def fix_icarus_t0(text, *, delay=False):
    """Move Yosys' ``reg \\$auto... = 0;`` initialisers into ``initial`` blocks (pitfall 3).

    With ``delay`` (Icarus simulation only) the assignment waits ``#0``: an ``always @*`` block
    that has not reached its event control when the ``initial`` runs would miss the event and
    keep X until one of its inputs changes, which for a register that never leaves its reset
    value is never (seen on an idle TCP session's acknowledgement number)."""
    wait = "#0 " if delay else ""
    text = _AUTO_REG.sub(lambda mo: (f"{mo.group(1)}reg {mo.group(2)} ;\n"
                                     f"{mo.group(1)}initial {wait}{mo.group(2)} = "
                                     f"{mo.group(3)};"),
                         text)
    if delay:
        text = _trigger_single_statement_blocks(text)
    return text


_MODULE_HEADER = re.compile(r"^(module [^;]*;\n)", re.MULTILINE)
_SINGLE_ALWAYS = re.compile(r"^(\s*)always @\*\n(\s*)(?!begin\b)([^\n]*;)$", re.MULTILINE)


def _trigger_single_statement_blocks(text):
    """Give every one-statement ``always @*`` block (Yosys writes ``x[7:0] = y;`` that way,
    without its t=0 trigger) a trigger of its own module, so Icarus evaluates it at t=0 even
    if ``y`` never changes (an idle session's acknowledgement number stayed X)."""
    out = []
    parts = _MODULE_HEADER.split(text)
    out.append(parts[0])
    for k in range(1, len(parts), 2):
        header, body = parts[k], parts[k + 1]
        if _SINGLE_ALWAYS.search(body):
            trigger = f"\\$rosgate_t0$trigger_{k} "
            body = (f"  reg {trigger};\n  initial #0 {trigger}= 0;\n" +
                    _SINGLE_ALWAYS.sub(lambda mo: (f"{mo.group(1)}always @* begin\n"
                                                   f"{mo.group(2)}if ({trigger}) begin end\n"
                                                   f"{mo.group(2)}{mo.group(3)}\n"
                                                   f"{mo.group(1)}end"), body))
        out.append(header + body)
    return "".join(out)


def convert_top(top, name):
    """The Verilog text of :class:`VivadoTop` ``top`` as module ``name``, as Yosys writes it
    (before :func:`fix_icarus_t0`)."""
    with faster_comb_cycle_check():
        return verilog.convert(top, name=name, ports=top.port_list(), emit_src=False,
                               strip_internal_attrs=True)


def export_verilog(component, name, *, clock="aclk", reset="aresetn", icarus=False):
    """Return ``(verilog_text, top)`` for ``component`` wrapped in a :class:`VivadoTop`;
    ``icarus`` prepares the text for Icarus simulation (see :func:`fix_icarus_t0`)."""
    top = VivadoTop(component, clock=clock, reset=reset)
    return fix_icarus_t0(convert_top(top, name), delay=icarus), top


_ZERO_MEMORY_INIT = re.compile(r"^\s*initial begin\n(?:\s*[\w\\$.]+\[\d+\] = \d+'[hbd]0+;\n)+"
                               r"\s*end\n", re.M)


def without_zero_memory_init(text):
    """``text`` without the ``initial`` blocks that set every word of a memory to 0, for
    synthesis only: block and distributed RAM start at 0 on the FPGAs rosgate targets
    anyway, and a frame store's 76,800 init statements keep Yosys' front end busy for tens
    of minutes. Simulation keeps them (Verilator and Icarus start from them)."""
    return _ZERO_MEMORY_INIT.sub("", text)


_ESCAPED_NAME = re.compile(r"\\(\S+)(?=\s)")
_PLAIN_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_$]*")


def without_bracketed_names(text):
    """``text`` with every escaped identifier that holds a bracket renamed without it, for
    synthesis only: ``\\weights[9]`` (Amaranth's name for an element of an array port)
    becomes ``\\weights__9``, the same new name wherever the old one occurs, made unique
    against every other identifier of ``text``.

    Yosys 0.70 (the YoWASP build of the timing flow) can read such a name, when it comes
    back from ABC, as bit 9 of a wire ``weights`` and fail an assertion
    (``GetSize(conn.first) == GetSize(conn.second)`` in ``abc_ops_reintegrate``); whether
    it does depends on which names survive optimisation."""
    taken = set(_PLAIN_NAME.findall(text)) | set(_ESCAPED_NAME.findall(text))
    renamed = {}

    def rename(match):
        name = match.group(1)
        if "[" not in name and "]" not in name:
            return match.group(0)
        if name not in renamed:
            new = name.replace("[", "__").replace("]", "")
            while new in taken:
                new += "_"
            taken.add(new)
            renamed[name] = new
        return "\\" + renamed[name]

    return _ESCAPED_NAME.sub(rename, text)


def write_if_changed(path, text):
    """Write ``text`` to ``path`` unless it already holds exactly that; return whether written.

    Keeping the timestamp of an unchanged file lets incremental Verilator builds skip work.
    """
    path = Path(path)
    if path.is_file() and path.read_text() == text:
        return False
    write_atomically(path, text)
    return True


def write_atomically(path, text):
    """Write ``text`` to ``path`` through a temporary file in the same folder and a rename: a
    write that fails (a full disk, a killed process) leaves the old file or none, never a
    truncated one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(temporary, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def manifest_data(*, module, component, top, extra=None):
    """The manifest describing an exported top (a JSON-able dict), see :func:`write_manifest`."""
    data = {
        "module": module,
        "component": f"{type(component).__module__}.{type(component).__qualname__}",
        "clock": top.clock.name,
        "reset": top.reset_n.name,
        "parameters": getattr(component, "parameters", {}),
        "ports": top.manifest_ports(),
    }
    if extra:
        data.update(extra)
    return data


def write_manifest(path, *, module, component, top, extra=None):
    """Write a JSON manifest describing an exported top; return it."""
    data = manifest_data(module=module, component=component, top=top, extra=extra)
    write_if_changed(path, json.dumps(data, indent=2) + "\n")
    return data
