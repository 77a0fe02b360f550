"""Helpers every ``make bench`` module shares: yosys estimates of a component, and writing
one benchmark's JSON and Markdown into ``bench/results``."""

import json
from pathlib import Path

from gen.export.resources import estimate_resources
from gen.export.verilog import export_verilog, write_if_changed
from tb.toolchain import SIM_BUILD

__all__ = ["component_resources", "write_report"]


def component_resources(component, top, file_stem):
    """Export ``component`` as Verilog module ``top`` (to ``sim_build/bench-resources/
    <file_stem>.v``, rewritten only when it changed) and return its yosys estimate without
    the per-cell list."""
    text, _ = export_verilog(component, top)
    vfile = SIM_BUILD / "bench-resources" / f"{file_stem}.v"
    write_if_changed(vfile, text)
    return {k: v for k, v in estimate_resources(vfile, top).items() if k != "cells"}


def write_report(folder, name, data, text):
    """Write ``<name>.json`` (``data``) and ``<name>.md`` (``text``) into ``folder``; return
    ``text``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.json").write_text(json.dumps(data, indent=1) + "\n")
    (folder / f"{name}.md").write_text(text)
    return text
