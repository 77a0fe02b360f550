"""``make soak`` (tb/soak.py): each run gets its own SEED, the failed seeds are reported and
repeatable, an empty selection and bad counts are refused. The runs here are of a small pytest
file written for the test, whose outcome depends on SEED alone."""

import sys

import pytest

from tb.soak import main, soak

SEED_TEST = '''
import os


def test_even_seed():
    assert int(os.environ["SEED"]) % 2 == 0, os.environ["SEED"]
'''


@pytest.fixture
def seed_test(tmp_path):
    path = tmp_path / "test_seed_parity.py"
    path.write_text(SEED_TEST)
    return path


def test_failed_seeds_are_returned(seed_test):
    lines = []
    assert soak([str(seed_test)], [10, 11, 12, 13], log=lines.append) == [11, 13]
    runs = [line for line in lines if line.startswith("run ")]
    assert [r.split(":")[0] for r in runs] == [f"run {n}/4 SEED={s}" for n, s in
                                                zip(range(1, 5), range(10, 14))]
    assert ["FAIL" in r for r in runs] == [False, True, False, True]
    assert any("AssertionError: 11" in line or "FAILED" in line for line in lines)


def test_parallel_runs(seed_test):
    assert soak([str(seed_test)], [2, 3], jobs=2, log=lambda line: None) == [3]


def test_main_repeats_from_first_seed(seed_test, capsys):
    assert main([str(seed_test), "--runs", "3", "--first-seed", "20"]) == 1
    out = capsys.readouterr().out
    assert "seeds 20..22" in out and "2 of 3 runs passed" in out
    assert f"failed with SEED=21: SEED=21 {sys.executable} -m pytest {seed_test}" in out
    assert main([str(seed_test), "--runs", "1", "--first-seed", "4"]) == 0


def test_empty_selection_is_refused(seed_test):
    with pytest.raises(ValueError, match="no test selected"):
        soak([str(seed_test), "-k", "no_such_test"], [1], log=lambda line: None)


@pytest.mark.parametrize("args,bad", [(["--runs", "0"], "--runs 0"),
                                      (["--jobs", "0"], "--jobs 0"),
                                      (["--first-seed", "-1"], "--first-seed -1"),
                                      ([], "no pytest selection")])
def test_bad_arguments_are_named(seed_test, capsys, args, bad):
    argv = args + ([str(seed_test)] if args else [])
    with pytest.raises(SystemExit):
        main(argv)
    assert bad in capsys.readouterr().err
