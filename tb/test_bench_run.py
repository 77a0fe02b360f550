"""``bench/run.py`` arguments: a misspelt bench name or option is refused by name before
anything runs."""

import pytest

from bench.run import main


@pytest.mark.parametrize("args,bad", [(["--resources-only", "nett"], "nett"),
                                      (["--resorces-only"], "--resorces-only")])
def test_unknown_argument_is_named(args, bad):
    with pytest.raises(SystemExit, match=f"unknown argument '{bad}'.*benches: hmt"):
        main(args)
