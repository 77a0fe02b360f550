"""Lint exported Verilog with ``verilator --lint-only -Wall``.

Waived, each for a reason that belongs to the generator rather than the design:
DECLFILENAME (Amaranth names submodules ``top.sub`` in one file), UNUSEDSIGNAL (unused bits of
Amaranth temporaries), PROCASSINIT (Yosys initialises registers at declaration for simulation),
WIDTHEXPAND / WIDTHTRUNC (Yosys arithmetic temporaries), CASEINCOMPLETE (Yosys ``casez`` with
a default assignment before it), UNSIGNED (``x >= 0`` comparisons from range checks),
SYNCASYNCNET (an ``amaranth.lib.fifo.AsyncFIFO`` between clock domains resets its read side
through an asynchronous reset synchronizer fed by the write side's synchronous reset: the
standard way to take a reset across clocks).
"""

import argparse
import subprocess
import sys
from pathlib import Path

from host.toolchain import put_verilator_on_path

__all__ = ["WAIVERS", "LINT_ARGS", "lint_verilog", "main"]

WAIVERS = ("DECLFILENAME", "UNUSEDSIGNAL", "PROCASSINIT", "WIDTHEXPAND", "WIDTHTRUNC",
           "CASEINCOMPLETE", "UNSIGNED", "SYNCASYNCNET")

#: Verilator's lint options: every warning but the waived ones (a build with them fails on
#: a warning, as ``--lint-only`` reports it)
LINT_ARGS = ("-Wall", *(f"-Wno-{w}" for w in WAIVERS))


def _verilator():
    exe = put_verilator_on_path()
    if exe is None:
        raise RuntimeError("verilator not found: install the project (make setup)")
    return exe


def lint_verilog(path, top):
    """Return verilator's warnings for module ``top`` in ``path`` ('' when clean)."""
    cmd = [_verilator(), "--lint-only", *LINT_ARGS, "--top-module", top]
    cmd.append(str(path))
    result = subprocess.run(cmd, capture_output=True, text=True)
    return (result.stdout + result.stderr).strip() if result.returncode else ""


def main(argv=None):
    parser = argparse.ArgumentParser(description="verilator --lint-only every given top")
    parser.add_argument("files", nargs="+", type=Path, help="Verilog files; module = file stem")
    args = parser.parse_args(argv)
    failed = 0
    for path in args.files:
        report = lint_verilog(path, path.stem)
        print(f"lint {path}: {'clean' if not report else 'WARNINGS'}")
        if report:
            print(report)
            failed += 1
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
