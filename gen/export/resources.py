"""FPGA resource estimates with Debian's Yosys: ``synth_xilinx -flatten -family <family>``.

Estimates for trends and comparisons, not Vivado's numbers (docs/testing.md, Vivado-free checks).
The family follows the part (:func:`xilinx_family`): 7-series for the benches' fixed
comparisons, UltraScale+ (with UltraRAM) for a project on a Zynq UltraScale+ board.
"""

import hashlib
import json
import re
import shutil
import subprocess
from pathlib import Path

__all__ = ["estimate_resources", "yosys_command", "xilinx_family", "FAMILY_NAMES",
           "YOSYS_COMMAND"]

#: Yosys' Xilinx families: name
FAMILY_NAMES = {"xc7": "7-series", "xcu": "UltraScale", "xcup": "UltraScale+"}


def xilinx_family(part):
    """The ``synth_xilinx`` family of a Xilinx part name: ``xcup`` for Zynq UltraScale+
    (``xczu...``) and the ``...p`` Kintex/Virtex UltraScale+ parts, ``xcu`` for the other
    Kintex/Virtex UltraScale parts, ``xc7`` for 7-series (``xc7...``, Zynq-7000)."""
    name = str(part).strip().lower()
    if name.startswith("xczu"):
        return "xcup"
    mo = re.match(r"xc(ku|vu)(\d+)(p?)", name)
    if mo:
        return "xcup" if mo.group(3) else "xcu"
    if name.startswith("xc7"):
        return "xc7"
    raise ValueError(f"part {part!r}: not a Xilinx 7-series or UltraScale(+) part yosys "
                     f"maps (xc7..., xczu..., xcku..., xcvu...)")


def yosys_command(family="xc7"):
    """The synthesis command for ``family`` (UltraRAM inferred where the family has it)."""
    if family not in FAMILY_NAMES:
        raise ValueError(f"family {family!r}: expected one of {', '.join(FAMILY_NAMES)}")
    return f"synth_xilinx -flatten -family {family}" + (" -uram" if family == "xcup" else "")


#: the benches' fixed comparison (the papers' and LiteEth's figures are 7-series)
YOSYS_COMMAND = yosys_command("xc7")


def _run_yosys(yosys, script, verilog, progress):
    """Yosys' log of ``script``; ``progress(pass_name)`` for each pass it starts."""
    import tempfile
    with tempfile.TemporaryFile("w+") as errors:
        proc = subprocess.Popen([yosys, "-q", "-p", script, "-l", "/dev/stdout"],
                                stdout=subprocess.PIPE, stderr=errors, text=True)
        lines = []
        for line in proc.stdout:
            lines.append(line)
            mo = _PASS.match(line)
            if mo and progress is not None and "frontend" not in mo.group(1):
                progress(mo.group(1))
        if proc.wait():
            errors.seek(0)
            raise RuntimeError(f"yosys failed on {verilog}:\n{errors.read()[-2000:]}")
    return "".join(lines)


#: a line of yosys' log that starts a pass: ``2.3. Executing ABC pass (technology mapping).``
_PASS = re.compile(r"^\d+(?:\.\d+)*\. Executing (.+?)(?: \(.*\))?\.?$")


def estimate_resources(verilog, top, *, blackbox=None, progress=None, family="xc7"):
    """Return ``{"LUT", "INV", "FF", "LUTRAM", "BRAM36", "BRAM18", "DSP", "CARRY4", "cells"}``
    for ``top``.

    ``blackbox`` (a regular expression) leaves the modules whose names it matches in full out
    of the estimate: a caller adds their own estimates times ``cells[name]``, the instance
    count (for cores with many copies of one large block, which Yosys would map copy by
    copy). An estimate is kept beside the Verilog and reused while the Verilog, the command
    and this Yosys stay the same.

    LUT counts LUT1..LUT6, as the anchors of docs/network.md were measured. INV cells are
    counted apart: ``synth_xilinx`` leaves one per flip-flop for the exported active-low
    ``aresetn`` (its flip-flop map inverts the reset inside every cell), where Vivado drives
    all reset pins from one inverter, so adding them would count the reset once per
    flip-flop. FF counts every FD* flip-flop, LUTRAM the RAM*/SRL* cells, BRAM18 and BRAM36
    the block RAM primitives (an RAMB36 counts as two BRAM18 in ``BRAM18_equiv``).
    ``progress(pass_name)`` is called as Yosys starts each pass. ``family`` is the
    ``synth_xilinx`` family (:func:`xilinx_family`); URAM counts UltraRAM (URAM288) blocks.
    """
    yosys = shutil.which("yosys")
    if yosys is None:
        raise RuntimeError("yosys not found: install Debian's yosys (make setup does)")
    from .verilog import without_zero_memory_init, write_if_changed
    source = Path(verilog).with_suffix(".synth.v")
    write_if_changed(source, without_zero_memory_init(Path(verilog).read_text()))
    text = source.read_text()
    boxed = []
    if blackbox is not None:
        boxed = [n for n in re.findall(r"^module \\?(\S+)", text, re.M)
                 if re.search(blackbox, n)]
        if not boxed:
            raise ValueError(f"blackbox {blackbox!r} matches no module of {verilog}")
    box = f"hierarchy -top {top}; blackbox {' '.join(_escaped(n) for n in boxed)}; " \
        if boxed else ""
    script = f"read_verilog -sv {source}; {box}{yosys_command(family)} -top {top}; stat"
    version = subprocess.run([yosys, "-V"], capture_output=True, text=True).stdout
    key = hashlib.sha1(f"{version}\n{script}\n{text}".encode()).hexdigest()
    cached = source.with_suffix(".resources.json")
    if cached.exists():
        saved = json.loads(cached.read_text())
        if saved.get("key") == key:
            return saved["estimate"]
    text = _run_yosys(yosys, script, verilog, progress)
    stat = text[text.rindex("Printing statistics"):] if "Printing statistics" in text else text
    cells = {name: int(n) for name, n in re.findall(r"^\s+(\S+)\s+(\d+)\s*$", stat, re.M)}
    total = lambda pred: sum(n for name, n in cells.items() if pred(name))  # noqa: E731
    res = {
        "LUT": total(lambda c: re.fullmatch(r"LUT[1-6]", c) is not None),
        "INV": total(lambda c: c == "INV"),
        "FF": total(lambda c: c.startswith("FD")),
        "LUTRAM": total(lambda c: c.startswith("RAM") and not c.startswith("RAMB")
                        or c.startswith("SRL")),
        "BRAM36": total(lambda c: c.startswith("RAMB36")),
        "BRAM18": total(lambda c: c.startswith("RAMB18")),
        "URAM": total(lambda c: c.startswith("URAM")),
        "DSP": total(lambda c: c.startswith("DSP")),
        "CARRY4": total(lambda c: c.startswith("CARRY")),
        "cells": cells,
    }
    res["BRAM18_equiv"] = res["BRAM18"] + 2 * res["BRAM36"]
    cached.write_text(json.dumps({"key": key, "estimate": res}))
    return res


def _escaped(name):
    """A module name as a Yosys command names it (``\\a.b`` for a name with dots)."""
    return name if re.fullmatch(r"[A-Za-z_]\w*", name) else "\\" + name
