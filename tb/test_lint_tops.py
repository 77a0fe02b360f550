"""``make lint`` in the long matrix: every bench top and every example project's system is
lint-clean (``verilator --lint-only -Wall`` with the waivers of :mod:`host.lint`)."""

import pytest

from tb import lint_tops


@pytest.mark.full
def test_every_top_is_lint_clean(capsys):
    failed = lint_tops.main()
    assert failed == 0, capsys.readouterr().out[-5000:]
