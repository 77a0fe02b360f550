"""Helpers every ``make bench`` module shares: yosys estimates of a component, and writing
one benchmark's JSON and Markdown into ``bench/results``."""

import json
from pathlib import Path

from gen.export.resources import estimate_resources
from gen.export.verilog import export_verilog, write_if_changed
from tb.harness import SIM_BUILD

__all__ = ["component_resources", "resource_table", "write_report"]

#: Columns of every resource table: (heading, key of an estimate)
RESOURCE_COLUMNS = (("LUT", "LUT"), ("INV", "INV"), ("FF", "FF"), ("LUTRAM", "LUTRAM"),
                    ("BRAM18 eq.", "BRAM18_equiv"), ("DSP", "DSP"), ("CARRY4", "CARRY4"))


def component_resources(component, top, file_stem, *, blackbox=None, family="xc7"):
    """Export ``component`` as Verilog module ``top`` (to ``sim_build/bench-resources/
    <file_stem>.v``, rewritten only when it changed) and return its yosys estimate for
    ``family`` without the per-cell list (``blackbox``, ``family``:
    :func:`~gen.export.resources.estimate_resources`)."""
    text, _ = export_verilog(component, top)
    vfile = SIM_BUILD / "bench-resources" / f"{file_stem}.v"
    write_if_changed(vfile, text)
    return {k: v for k, v in estimate_resources(vfile, top, blackbox=blackbox,
                                                family=family).items() if k != "cells"}


#: Columns of a resource table for UltraScale+ (``xcup``): block RAM and UltraRAM apart, the
#: carry chains are CARRY8 cells
ULTRASCALE_PLUS_COLUMNS = (("LUT", "LUT"), ("INV", "INV"), ("FF", "FF"), ("LUTRAM", "LUTRAM"),
                           ("BRAM36", "BRAM36"), ("BRAM18", "BRAM18"), ("URAM", "URAM"),
                           ("DSP", "DSP"), ("CARRY8", "CARRY4"))


def resource_table(rows, label, title, *, detail="", extra=(), family="xc7"):
    """Markdown lines of a resource section: a heading naming the yosys flow for ``family``
    and how LUTs are counted (``detail`` adds to it), then one row per estimate in ``rows``,
    labelled by ``row[label]`` under the column ``title``; ``extra`` is (heading, key) of
    further columns."""
    from gen.export.resources import yosys_command
    columns = (ULTRASCALE_PLUS_COLUMNS if family == "xcup" else RESOURCE_COLUMNS) + tuple(extra)
    lines = ["", f"## Resources (Debian Yosys `{yosys_command(family)}`{detail}; LUT = LUT1..LUT6 "
             "as in docs/network.md, INV cells apart: see gen/export/resources.py)", "",
             "| " + " | ".join([title] + [c for c, _ in columns]) + " |",
             "|" + "---|" * (len(columns) + 1)]
    for r in rows:
        lines.append("| " + " | ".join([str(r[label])] + [str(r.get(k, "-"))
                                                          for _, k in columns]) + " |")
    return lines


def write_report(folder, name, data, text):
    """Write ``<name>.json`` (``data``) and ``<name>.md`` (``text``) into ``folder``; return
    ``text``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.json").write_text(json.dumps(data, indent=1) + "\n")
    (folder / f"{name}.md").write_text(text)
    return text
