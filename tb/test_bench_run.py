"""``bench/run.py`` arguments: a misspelt bench name or option is refused by name before
anything runs (run as the command a user types)."""

import subprocess
import sys

import pytest

from .harness import ROOT


@pytest.mark.parametrize("args,bad", [(["--resources-only", "nett"], "nett"),
                                      (["--resorces-only"], "--resorces-only")])
def test_unknown_argument_is_named(args, bad):
    result = subprocess.run([sys.executable, str(ROOT / "bench" / "run.py"), *args],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode != 0
    assert f"unknown argument '{bad}'" in result.stderr and "benches: hmt" in result.stderr, \
        result.stderr

