"""The cycle figures the documentation quotes for the examples are the measured ones of
``bench/results/`` (``make bench`` writes them; ``bench/examples.py`` runs the examples as a
user does), not numbers typed by hand."""

import json
import re

from .harness import ROOT

RESULTS = ROOT / "bench" / "results"
DOCS = ROOT / "docs"


def examples():
    return json.loads((RESULTS / "examples.json").read_text())["examples"]


def test_sobel_dip_figures_of_the_simulation_page():
    text = (DOCS / "simulation.md").read_text()
    cycles = examples()["sobel_dip"]["cycles"]
    quoted = 0
    for image, n in cycles.items():
        for mo in re.finditer(rf"viewer: {re.escape(image)} \(\d+x\d+\) filtered in (\d+) "
                              rf"cycles = ([0-9.]+) ms", text):
            assert int(mo.group(1)) == n and float(mo.group(2)) == round(n / 1e5, 3), mo[0]
            quoted += 1
        for mo in re.finditer(rf"^{re.escape(image)}\s+\d+x\d+\s+(\d+)\s+([0-9.]+)\s", text,
                              re.MULTILINE):
            assert int(mo.group(1)) == n and float(mo.group(2)) == round(n / 1e5, 3), mo[0]
            quoted += 1
    assert quoted >= 2, "docs/simulation.md no longer quotes the Sobel/DIP example"


def test_inverse_kinematics_figures_of_the_howto():
    text = (DOCS / "howto.md").read_text()
    mo = re.search(r"\((\d+) cycles from publish to answer on average, (\d+) of them the "
                   r"kernel's search", text)
    assert mo, "docs/howto.md no longer quotes the inverse kinematics example"
    assert int(mo.group(1)) == examples()["inverse_kinematics"]["cycles"]["mean"]
    kernels = json.loads((RESULTS / "kernels.json").read_text())["rows"]
    ik = next(r for r in kernels if r["label"] == "inverse kinematics (per solution)")
    assert int(mo.group(2)) == round(ik["cycles"])


def test_howto_shows_the_example_thread_as_it_is():
    """docs/howto.md's complete FSM thread is examples/image_invert's, character for
    character (the example runs in tb/test_project_sim.py)."""
    text = (DOCS / "howto.md").read_text()
    code = (ROOT / "examples/image_invert/src/rt_invert/amaranth/thread.py").read_text()
    assert f"```python\n{code}```" in text


def test_service_figures_of_the_services_page():
    text = (DOCS / "services.md").read_text()
    rows = json.loads((RESULTS / "services.json").read_text())["sort"]
    for row in rows:
        label = "0 (transport only)" if row["values"] == 0 else str(row["values"])
        unit = " cycles" if row["values"] == 0 else ""
        line = (f"| {label} | {row['hw_topics_cycles']:,}{unit} | "
                f"{row['memory_cycles']:,}{unit} |")
        assert line in text, line
