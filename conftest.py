import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from tb.toolchain import put_verilator_on_path  # noqa: E402

put_verilator_on_path()


def pytest_configure(config):
    config.addinivalue_line("markers", "full: part of the long matrix (make test-full)")
    config.addinivalue_line("markers", "formal: runs a formal proof (needs yowasp-sby)")
