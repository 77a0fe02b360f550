import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))

# what the tests run through ``rosgate`` builds under sim_build/, not in the user's cache, and
# at -O1: their runs are short, so the build is most of their time (the product's -O3 is for
# long runs; the benches and make demo keep it)
os.environ.setdefault("ROSGATE_CACHE", str(ROOT / "sim_build" / "cache"))
os.environ.setdefault("ROSGATE_CXX_OPT", "-O1")

from host.toolchain import put_verilator_on_path  # noqa: E402

put_verilator_on_path()


def pytest_configure(config):
    config.addinivalue_line("markers", "full: part of the long matrix (make test-full)")
    config.addinivalue_line("markers", "formal: runs a formal proof (needs yowasp-sby)")
