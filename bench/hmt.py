"""Hardware-mapped topic benchmark (issue: foundation §6; docs/topics.md).

All numbers are simulated clock cycles of the real :class:`hdl.dds.Topic` RTL under Verilator
(generator and checker in :mod:`tb.topic_traffic`), converted to time at 100 MHz, the clock of
the fpgaDDS evaluation. Resources come from Debian's Yosys ``synth_xilinx -flatten -family xc7``.
"""

import json
import math

from bench.report import component_resources, resource_table, write_report
from gen.export.resources import YOSYS_COMMAND
from gen.tops import build_top
from tb.harness import SIM_BUILD, run_bench
from tb.topic_traffic import TOPOLOGIES, WIDTHS, build_topic_bench_top

CLOCK_MHZ = 100

#: fpgaDDS Table I (docs/topics.md): message bytes -> (CycloneDDS ms, fpgaDDS ms); the sizes are
#: square RGB images 32^2..1024^2 x 3 bytes.
PAPER_TABLE_I = {
    3 * 32 ** 2: ("3 kB", 0.06, "<0.01"),
    3 * 64 ** 2: ("12 kB", 0.07, 0.02),
    3 * 128 ** 2: ("50 kB", 0.19, 0.06),
    3 * 256 ** 2: ("196 kB", 0.63, 0.24),
    3 * 512 ** 2: ("786 kB", 2.34, 0.98),
    3 * 1024 ** 2: ("3146 kB", 9.24, 3.93),
}

#: Target of the foundation issue, from verilog-axis axis_arb_mux + axis_broadcast (4:4, 64 b).
RESOURCE_TARGET = {"LUT": 287, "FF": 608}


def beats_of(size, width):
    return math.ceil(size / (width // 8))


def single_cases(pubs, width, sizes):
    """One message from publisher 0 alone, then one from every publisher at once."""
    cases = []
    for size in sizes:
        beats = beats_of(size, width)
        cases.append({"name": f"one-{size}", "kind": "one", "size": size,
                      "beats": [beats] * pubs, "count": [1] + [0] * (pubs - 1)})
        if pubs > 1:
            cases.append({"name": f"all-{size}", "kind": "all", "size": size,
                          "beats": [beats] * pubs, "count": [1] * pubs})
    return cases


def stream_cases(pubs, width):
    """Back-to-back messages from every publisher: efficiency and gaps."""
    cases = []
    for size, count in ((3 * 32 ** 2, 16), (width // 8, 256), (3 * width // 8 + 1, 64)):
        beats = beats_of(size, width)
        cases.append({"name": f"stream-{size}", "kind": "stream", "size": size,
                      "beats": [beats] * pubs, "count": [count] * pubs})
    return cases


def run_topology(pubs, subs, width, cases, *, sim="verilator", pace=None):
    """Run ``cases`` on the ``pubs``:``subs`` topic of ``width`` bits; return their records.
    ``pace``: a file for the run's cycles and CPU seconds (:class:`bench.pace.PaceMeter`)."""
    config_id = f"{pubs}x{subs}_w{width}"
    out = SIM_BUILD / f"bench-{config_id}-{sim}" / "records.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    run_bench("bench.hmt_bench", "topic_bench", config_id,
              {"pubs": pubs, "subs": subs, "data_width": width}, sim,
              build=build_topic_bench_top, optimise=True,
              extra_env={"ROSGATE_BENCH_CASES": json.dumps(cases),
                         "ROSGATE_BENCH_OUT": str(out),
                         **({"ROSGATE_BENCH_PACE": str(pace)} if pace else {})}, quiet=True)
    return json.loads(out.read_text())


def summarise(record):
    """Cycles of a record: first beat in to last beat out (all subscribers), latency, gaps."""
    first_in = min(f for f, c in zip(record["pub_first"], record["count"]) if c)
    last_out = max(record["sub_last"])
    beats = record["sub_beats"][0]
    span0 = record["sub_last"][0] - record["sub_first"][0] + 1
    return {
        "cycles": last_out - first_in + 1,
        "latency": min(record["sub_first"]) - first_in,
        "beats": beats,
        "idle_cycles": span0 - beats,
        "efficiency": beats / span0,
        "messages": record["sub_messages"][0],
    }


def measure(widths=WIDTHS, sizes=tuple(PAPER_TABLE_I), topologies=TOPOLOGIES, log=print):
    results = {"clock_mhz": CLOCK_MHZ, "runs": []}
    for width in widths:
        for pubs, subs in topologies:
            log(f"  simulating {pubs}:{subs} topic at {width} bits (Verilator)...")
            cases = single_cases(pubs, width, sizes) + stream_cases(pubs, width)
            for record in run_topology(pubs, subs, width, cases):
                entry = {"pubs": pubs, "subs": subs, "width": width, "kind": record["kind"],
                         "size": record["size"], "beats_per_message": record["beats"][0],
                         **summarise(record)}
                entry["time_ms"] = entry["cycles"] / (CLOCK_MHZ * 1e3)
                results["runs"].append(entry)
    return results


#: (name, label, parameters) of the topic configurations whose resources and timing are measured
RESOURCE_CONFIGS = (
    ("4x4_w64", "4:4 64 b, no FIFO, no monitor", dict(fifo_depth=0, monitor=False)),
    ("4x4_w64_mon", "4:4 64 b, no FIFO, monitor counters", dict(fifo_depth=0, monitor=True)),
    ("4x4_w64_fifo", "4:4 64 b, 512-deep FIFOs, no monitor", dict(fifo_depth=512, monitor=False)),
    ("4x4_w64_fifo_mon", "4:4 64 b, 512-deep FIFOs, monitor counters",
     dict(fifo_depth=512, monitor=True)),
    ("4x4_w512", "4:4 512 b, no FIFO, no monitor",
     dict(fifo_depth=0, monitor=False, data_width=512)))


def resource_configs():
    """(name, {"label", "build"}) of each configuration of :data:`RESOURCE_CONFIGS`."""
    return [(name, {"label": label,
                    "build": lambda p=params: build_top("topic", pubs=4, subs=4,
                                                        **{"data_width": 64, **p})})
            for name, label, params in RESOURCE_CONFIGS]


def measure_resources(log=print):
    rows = []
    for _, config in resource_configs():
        log(f"  yosys {YOSYS_COMMAND}: {config['label']}...")
        rows.append({"config": config["label"],
                     **component_resources(config["build"](), "topic", f"topic-{len(rows)}")})
    return rows


def fmt_ms(ms):
    return f"{ms:.4f}" if ms < 0.1 else f"{ms:.3f}"


def markdown(results, resources):
    runs = results["runs"]
    lines = ["# Hardware-mapped topic benchmark", "",
             f"Simulated cycles of the `Topic` RTL (Verilator), time at {CLOCK_MHZ} MHz. "
             "Cycles count from the first beat a publisher hands over to the last beat the last "
             "subscriber takes; subscribers always ready.", ""]
    for width in sorted({r["width"] for r in runs}):
        lines += [f"## One message, {width}-bit topic, beside fpgaDDS Table I", "",
                  "| message | beats | 1:1 cycles | 1:1 ms | 1:4 ms | 4:1 ms | 4:4 ms | "
                  "4:4 all pubs ms / msg | paper CycloneDDS ms | paper fpgaDDS ms |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for size, (label, cyclone, fpgadds) in PAPER_TABLE_I.items():
            row = {(r["pubs"], r["subs"]): r for r in runs
                   if r["width"] == width and r["size"] == size and r["kind"] == "one"}
            if (1, 1) not in row:
                continue
            allp = [r for r in runs if r["width"] == width and r["size"] == size and
                    r["kind"] == "all" and (r["pubs"], r["subs"]) == (4, 4)]
            per_msg = fmt_ms(allp[0]["time_ms"] / 4) if allp else "-"
            lines.append(
                f"| {label} ({size} B) | {row[(1, 1)]['beats']} | {row[(1, 1)]['cycles']} | "
                + " | ".join(fmt_ms(row[t]["time_ms"]) if t in row else "-"
                             for t in TOPOLOGIES)
                + f" | {per_msg} | {cyclone} | {fpgadds} |")
        lines.append("")
    lines += ["## Back-to-back messages from every publisher (subscriber 0)", "",
              "| topic | width | message bytes | messages | beats | idle cycles between "
              "messages | efficiency | latency (cycles) |", "|---|---|---|---|---|---|---|---|"]
    for r in runs:
        if r["kind"] == "stream":
            lines.append(f"| {r['pubs']}:{r['subs']} | {r['width']} | {r['size']} | "
                         f"{r['messages']} | {r['beats']} | {r['idle_cycles']} | "
                         f"{100 * r['efficiency']:.3f} % | {r['latency']} |")
    lines += resource_table(resources, "config", "configuration")
    lines.append(f"| target: verilog-axis axis_arb_mux + axis_broadcast, 4:4 64 b (issue) | "
                 f"{RESOURCE_TARGET['LUT']} | - | {RESOURCE_TARGET['FF']} | - | 0 | - | - |")
    lines.append("")
    lines += ["", "![plot](hmt_transfer_time.png)", ""]
    return "\n".join(lines)


def write_results(results, resources, folder):
    data = dict(results, resources=resources, resource_target=RESOURCE_TARGET,
                paper_table_i={str(k): v for k, v in PAPER_TABLE_I.items()})
    return write_report(folder, "hmt", data, markdown(results, resources))
