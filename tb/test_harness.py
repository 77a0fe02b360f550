"""The harness's seeds (tb/harness.py): ``SEED`` repeats a run's random numbers exactly, a
failed bench names its seed and the command that repeats it, and a bad ``SEED`` is refused by
name. The cocotb tests below run on the smallest topic top (Icarus); only the pytest tests of
this module start them, each by name.
"""

import os
import random
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import cocotb
import pytest
from cocotb.triggers import Timer

from gen.tops import build_top
from tb.harness import environment_seed, run_bench, verilog_key
from tb.topic_tb import CONFIGS

CONFIG_ID = "1x1_w8"


@cocotb.test()
async def draws_random_numbers(dut):
    """Writes the first numbers of Python's random module to ``ROSGATE_DRAWS``."""
    await Timer(1, "ns")
    Path(os.environ["ROSGATE_DRAWS"]).write_text(" ".join(
        str(random.getrandbits(32)) for _ in range(4)))


@cocotb.test()
async def fails_on_purpose(dut):
    """Fails, for the failure message's test."""
    await Timer(1, "ns")
    raise AssertionError("failing on purpose")


def run(tmp_path, testcase, run_name):
    draws = tmp_path / f"{run_name}.txt"
    results = run_bench(__name__, "topic", CONFIG_ID, CONFIGS[CONFIG_ID], "icarus",
                        testcase=[testcase], quiet=True, run_name=run_name,
                        extra_env={"ROSGATE_DRAWS": str(draws)})
    return draws.read_text(), results


def recorded_seed(results):
    [seed] = {p.get("value") for p in ET.parse(results).iter("property")
              if p.get("name") == "random_seed"}
    return int(seed)


def test_seed_repeats_the_random_numbers(tmp_path, monkeypatch):
    monkeypatch.setenv("SEED", "12345")
    first, results = run(tmp_path, "draws_random_numbers", "seed-a")
    assert recorded_seed(results) == 12345
    again, _ = run(tmp_path, "draws_random_numbers", "seed-b")
    assert again == first
    monkeypatch.setenv("SEED", "12346")
    other, results = run(tmp_path, "draws_random_numbers", "seed-c")
    assert recorded_seed(results) == 12346
    assert other != first
    monkeypatch.delenv("SEED")
    fresh, results = run(tmp_path, "draws_random_numbers", "seed-d")
    assert recorded_seed(results) not in (12345, 12346) and fresh != first


def test_failure_names_seed_and_command(tmp_path, monkeypatch):
    monkeypatch.setenv("SEED", "777")
    with pytest.raises(AssertionError) as info:
        run(tmp_path, "fails_on_purpose", "seed-fail")
    message = str(info.value)
    assert "1 of 1 cocotb tests failed: fails_on_purpose (seed 777;" in message, message
    nodeid = "tb/test_harness.py::test_failure_names_seed_and_command"
    assert re.search(rf"again with: SEED=777 \S*python\S* -m pytest -p no:xdist '{nodeid}';",
                     message), message
    monkeypatch.delenv("PYTEST_CURRENT_TEST")
    with pytest.raises(AssertionError, match="again with: SEED=777 in the environment;"):
        run(tmp_path, "fails_on_purpose", "seed-fail")


@pytest.mark.parametrize("value", ["abc", "-3", "1.5"])
def test_bad_seed_is_refused_by_name(monkeypatch, value):
    monkeypatch.setenv("SEED", value)
    with pytest.raises(ValueError, match=f"SEED='{value}' in the environment: expected a "
                                         f"non-negative integer"):
        environment_seed()


@pytest.mark.parametrize("value,seed", [("", None), ("0", 0), ("42", 42), ("0x10", 16)])
def test_seed_values(monkeypatch, value, seed):
    monkeypatch.setenv("SEED", value)
    assert environment_seed() == seed


def test_verilog_key_follows_parameters_named_files_and_builder(tmp_path):
    """The fingerprint a bench top's conversion is cached under changes with its parameters,
    with the content of a file they name, and with the builder; a builder that may hold state
    the fingerprint cannot see (a lambda, a closure) gets none."""
    params = dict(CONFIGS["1x1_w8"])
    key = verilog_key("topic", params)
    assert key == verilog_key("topic", dict(params))
    assert key != verilog_key("topic", dict(params, data_width=16))
    assert key != verilog_key("topic", params, build=build_top)
    named = tmp_path / "io.txt"
    named.write_text("a")
    with_file = verilog_key("topic", dict(params, io=str(named)))
    named.write_text("b")
    assert with_file != verilog_key("topic", dict(params, io=str(named)))
    assert verilog_key("topic", params, build=lambda **p: build_top("topic", **p)) is None
    stop = 3

    def closure(**p):
        return stop
    assert verilog_key("topic", params, build=closure) is None
