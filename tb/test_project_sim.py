"""``rosgate sim`` of the example projects: the paper's Sobel/DIP application bit-exact with
OpenCV on photographs and a random image, and the sort service demo with two slots on their
own clock serving one service (both simulators)."""

import json

import numpy as np
import cv2
import pytest

from gen.cli import main as rosgate

from .project_sim import run_project_sim
from .test_project_config import ROOT

SIMS = ("icarus", "verilator")


@pytest.mark.parametrize("sim", SIMS)
def test_sobel_dip(sim, tmp_path):
    """Two photographs and a random image through camera -> DIP (HW) -> Sobel service (HW)
    -> viewer, through ``rosgate sim``; each result equals OpenCV's and is written as PNG."""
    noise = np.random.default_rng(7).integers(0, 256, (24, 32, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "noise.png"), noise)
    images = f"coffee_80x60.png,{tmp_path / 'noise.png'},chelsea_96x72.png"
    out = tmp_path / "out"
    assert rosgate(["sim", str(ROOT / "examples/sobel_dip/build.cfg"), "--sim", sim,
                    "--arg", f"images={images}", "--limit-ms", "50", "-o", str(out)]) == 0
    got = json.loads((out / "sim_results.json").read_text())["images"]
    assert [r["image"] for r in got] == ["coffee_80x60.png", "noise.png", "chelsea_96x72.png"]
    for r in got:
        assert r["bit_exact"] and r["header_ok"], r
        assert r["cycles"] > r["width"] * r["height"] * 3 // 8, r   # one word per cycle at most
        assert cv2.imread(r["filtered_png"]).shape == (r["height"], r["width"], 3)


#: in test-full (make test: the sort service node runs in tb/test_reconos_apps.py, clock-crossing
#: slots in the reconos system benches)
SORT_SIMS = [pytest.param(s, marks=pytest.mark.full) for s in ("icarus", "verilator")]


@pytest.mark.parametrize("sim", SORT_SIMS)
def test_sort_service_two_slots(sim, tmp_path):
    """Both slots of ``SortDemo(*)`` (120 MHz, clock-crossing FIFOs) serve "srv"; six
    concurrent calls of 300 values each come back sorted."""
    results = run_project_sim(ROOT / "examples/sort_service/build.cfg", sim,
                              out=tmp_path / "out", args={"requests": "3", "size": "300"},
                              limit_ms=20, quiet=True)
    assert results["slots_running"] == [0, 1]
    assert len(results["calls"]) == 6 and results["all_sorted"], results
