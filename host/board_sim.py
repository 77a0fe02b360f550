"""A board top in simulation (docs/boards.md "Simulating a board top"): the design exactly as
``rosgate board build`` elaborates it, with only the ECP5 primitives replaced by the
cycle-level models of ``host/compiled/ecp5_primitives.v``; or the netlist Yosys synthesised
for the bitstream, with Yosys' own ECP5 cell models."""

import json
from pathlib import Path

from gen.boards import board, board_platform

from .board import board_top

__all__ = ["PRIMITIVES", "board_sim_verilog"]

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
