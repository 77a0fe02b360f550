"""The fpgaDDS lane-following chain benchmark (docs/av_chain.md): chain alpha over 100 scene
frames for the hardware-topic (fpgaDDS) variant at 1 and 4 pixels per clock under Verilator,
over the scene's 100 frames at full size and at a fifth of the size for the ReconROS variant
(examples/av_chain: the same nodes as ReconOS threads, topics through memory and the broker)
at 1 and 4 pixels per clock (``python -m bench.av_chain --reconros`` re-measures only those,
``--fpgadds`` the hardware-topic rows),
and the software variant (the OpenCV nodes of host/autorace.py on this machine), beside the fpgaDDS paper's Table III; the whole chain's
Yosys resources beside its Table II. Writes ``bench/results/av_chain.json`` with the
``chain_alpha`` list (and ``reconros_scaled``, ``resources``), the Markdown tables and the
plots (latency per frame, the lane overlay of one frame)."""

import json
import os
import statistics
import sys
import time
from concurrent.futures import ThreadPoolExecutor

from bench.av_chain_bench import HARNESS
from bench.report import component_resources, resource_table, write_report
from gen.av_chain import NODES, chain_node, chain_topics, scaled_config, scaled_params
from host.project_sim import run_project_sim
from tb.harness import ROOT, SIM_BUILD, run_bench

sys.path.insert(0, str(ROOT / "examples" / "av_chain"))
import scene  # noqa: E402

#: scene frames per variant (``ROSGATE_AV_FRAMES`` for a shorter trial)
FRAMES = int(os.environ.get("ROSGATE_AV_FRAMES", 100))
#: full-size frames of the ReconROS variant per px/clk (``ROSGATE_AV_RECONROS_FRAMES``): the
#: scene's 100, 1.4 million cycles each at 4 px/clk, 2.7 million at 1 px/clk
RECONROS_FRAMES = int(os.environ.get("ROSGATE_AV_RECONROS_FRAMES", 100))
#: the ReconROS variant's frames and frame scale for the spread over the scene: 100 frames at
#: a fifth of the size (128x96 camera, 200x120 view), 16 to 19 min each, side by side
RECONROS_SCALED = (int(os.environ.get("ROSGATE_AV_RECONROS_SCALED_FRAMES", 100)), 0.2)
PROJECT = ROOT / "examples" / "av_chain" / "build.cfg"
CLOCK_MHZ = 100
#: fpgaDDS Table III: chain alpha, mean (sd) in ms
PAPER = {"software": (274.44, 14.96), "reconros": (110.72, 7.73), "fpgadds": (20.58, 0.13)}
#: fpgaDDS Table II: LUTs of the whole hardware chain with fpgaDDS
PAPER_LUT = 44939
#: fpgaDDS Table II, the same row: block RAM (36 Kb), UltraRAM and DSP of the chain on the ZCU104
PAPER_MEMORY = {"BRAM36": 255.0, "URAM": 91, "DSP": 230}
#: the ZCU104's XCZU7EV: CLB LUTs, flip-flops, 36 Kb block RAMs, UltraRAMs, DSP slices
XCZU7EV = {"LUT": 230400, "FF": 460800, "BRAM36": 312, "URAM": 96, "DSP": 1728}


def _stats(values):
    return statistics.fmean(values), (statistics.pstdev(values) if len(values) > 1 else 0.0)


def _software(frames, log):
    """The OpenCV chain on this machine: wall-clock ms per frame (compensation to command)."""
    from host.autorace import SoftwareChain
    chain = SoftwareChain(scaled_config())
    times, errors = [], []
    for f in frames:
        start = time.perf_counter()
        step = chain.step(f.image)
        times.append((time.perf_counter() - start) * 1e3)
        errors.append(abs(step.lane[0] - f.centre))
    log(f"  software chain: {statistics.fmean(times):.1f} ms per frame on this machine")
    return times, errors


def _reconros(ppcs, log, frames=RECONROS_FRAMES, scale=1.0):
    """The ReconROS variant under ``rosgate sim``, the px/clk settings side by side: its
    results per px/clk."""
    def simulate(p):
        start = time.monotonic()
        results = run_project_sim(PROJECT, "verilator",
                                  out=SIM_BUILD / f"bench-av_chain-p{p}-s{scale}",
                                  args={"frames": str(frames)},
                                  thread_params=[f"*.pixels_per_beat={p}"] +
                                  ([f"*.scale={scale}"] if scale != 1 else []),
                                  limit_ms=100 * frames)
        results["wall_s"] = round(time.monotonic() - start, 1)
        return p, results
    size = "full-size" if scale == 1 else f"{scale:g}-scale"
    log(f"  simulating the ReconROS variant (examples/av_chain) at {' and '.join(map(str, ppcs))}"
        f" px/clk over {frames} {size} frames each, side by side (Verilator)...")
    with ThreadPoolExecutor(len(ppcs)) as pool:
        return dict(pool.map(simulate, ppcs))


def reconros_entries(runs, scale=1.0):
    """The ``chain_alpha`` entries and the per-frame ms of the ReconROS runs (px/clk ->
    ``rosgate sim`` results) at frame ``scale``."""
    entries, per_frame = [], {}
    for p, rec in sorted(runs.items(), reverse=True):
        ms = [f["cycles"] / (CLOCK_MHZ * 1e3) for f in rec["frames"]]
        mean, sd = _stats(ms)
        assert rec["events_equal"], (rec["stops"], rec["starts"])
        entries.append({"variant": "reconros", "ppc": p, "clock_mhz": CLOCK_MHZ,
                        "frames": len(ms), "mean_ms": round(mean, 4), "sd_ms": round(sd, 4),
                        "lane_centre_max_error_px": round(rec["lane_centre_max_error_px"], 3),
                        "stages_bit_exact": rec["stages_bit_exact"],
                        "cycles": round(rec["mean_cycles"]),
                        "stops": rec["stops"], "starts": rec["starts"],
                        "simulation": {"wall_s": rec["wall_s"],
                                       "cpu_seconds": rec["cpu_seconds"],
                                       "cycles": rec["cycles"]},
                        "note": "the broker and the delegate threads in software take no "
                                "simulated time: a lower bound"})
        if scale != 1:
            entries[-1]["scale"] = scale
        per_frame[f"reconros_p{p}" + (f"_scale{scale:g}" if scale != 1 else "")] = ms
    return entries, per_frame


def measure(log=print):
    log(f"  generating {FRAMES} scene frames...")
    frames = list(scene.frames(FRAMES))
    results = measure_fpgadds({"chain_alpha": [], "per_frame_ms": {}}, log)
    measure_reconros(results, log)
    entries, per_frame = results["chain_alpha"], results["per_frame_ms"]
    times, errors = _software(frames, log)
    mean, sd = _stats(times)
    entries.append({"variant": "software", "ppc": None, "clock_mhz": None,
                    "frames": len(times), "mean_ms": round(mean, 3), "sd_ms": round(sd, 3),
                    "lane_centre_max_error_px": round(max(errors), 3),
                    "stages_bit_exact": True, "note": "wall-clock on this machine"})
    per_frame["software"] = times
    return {**results, "paper": PAPER, "paper_lut": PAPER_LUT, "overlay_frame": 50}


def measure_fpgadds(results, log=print, ppcs=(4, 1)):
    """Measure the hardware-topic (fpgaDDS) variant's rows into ``results`` (a ``measure()``
    result), replacing the ones it has: ``FRAMES`` full-size frames per px/clk, side by side,
    the camera and the image taps on compiled stream ports."""
    outs = {p: SIM_BUILD / f"bench-av_chain-p{p}.json" for p in ppcs}

    def simulate(p):
        run_bench("bench.av_chain_bench", "av_chain", f"bench_p{p}", scaled_params(1.0, p),
                  "verilator", quiet=True, optimise=True, harness=lambda params: HARNESS,
                  extra_env={"ROSGATE_BENCH_OUT": str(outs[p]), "ROSGATE_AV_FRAMES": str(FRAMES)})
    log(f"  simulating the hardware-topic chain at {' and '.join(map(str, ppcs))} px/clk over "
        f"{FRAMES} frames each, side by side (Verilator)...")
    with ThreadPoolExecutor(len(ppcs)) as pool:
        list(pool.map(simulate, ppcs))
    entries, per_frame = [], {}
    for p in ppcs:
        rec = json.loads(outs[p].read_text())
        ms = [c / (CLOCK_MHZ * 1e3) for c in rec["latencies"]]
        mean, sd = _stats(ms)
        error = max(abs(r["centre"] - r["truth"]) for r in rec["frames"])
        entries.append({"variant": "fpgadds", "ppc": p, "clock_mhz": CLOCK_MHZ,
                        "frames": len(ms), "mean_ms": round(mean, 4), "sd_ms": round(sd, 4),
                        "lane_centre_max_error_px": round(error, 3),
                        "stages_bit_exact": True,
                        "cycles": rec["latencies"][0],
                        "off_by_one_pixels_per_checked_frame": statistics.fmean(
                            r["off_by_one"] for r in rec["frames"] if "off_by_one" in r),
                        "stops": rec["stops"], "starts": rec["starts"]})
        per_frame[f"fpgadds_p{p}"] = ms
    rows = [e for e in results["chain_alpha"] if e["variant"] != "fpgadds"]
    results["chain_alpha"] = entries + rows
    results["per_frame_ms"] = per_frame | {k: v for k, v in results["per_frame_ms"].items()
                                           if not k.startswith("fpgadds")}
    return results


def measure_reconros(results, log=print, ppcs=(4, 1)):
    """Measure the ReconROS variant's rows (full size and at a fifth of the size) into
    ``results`` (a ``measure()`` result), replacing the ones it has."""
    full, full_ms = reconros_entries(_reconros(ppcs, log))
    frames_scaled, scale = RECONROS_SCALED
    scaled, scaled_ms = reconros_entries(_reconros(ppcs, log, frames_scaled, scale), scale)
    rows = [e for e in results["chain_alpha"] if e["variant"] != "reconros"]
    at = next((i for i, e in enumerate(rows) if e["variant"] == "software"), len(rows))
    results["chain_alpha"] = rows[:at] + full + rows[at:]
    results["reconros_scaled"] = scaled
    results["per_frame_ms"] = {k: v for k, v in results["per_frame_ms"].items()
                               if not k.startswith("reconros")} | full_ms | scaled_ms
    return results


def _add(rows, label):
    """The sum of the estimates ``rows`` as one row labelled ``label``."""
    keys = [k for k, v in rows[0].items() if isinstance(v, (int, float)) and k != "ppc"]
    return {"part": label, **{k: sum(r[k] for r in rows) for k in keys}}


def project_part():
    """The part of the example project (its build.cfg's ``TargetPart``) and its Yosys family."""
    from gen.config import load_project
    from gen.export.resources import xilinx_family
    part = load_project(PROJECT).part
    return part, xilinx_family(part)


def _node_resources(config, name, log, family):
    """The estimate of node ``name`` at ``config``'s size for ``family``: the projection
    without its coordinate dividers plus one divider's estimate per instance (the ``P``
    identical dividers, each mapped on its own by Yosys, are most of the time of the whole
    projection)."""
    node = chain_node(config, name, events=True)
    stem = f"av-{name}-p{config.pixels_per_beat}-{family}"
    if name != "projection":
        return component_resources(node, f"av_{name}", stem, family=family)
    rest = component_resources(node, f"av_{name}", stem, blackbox=node.DIVIDER_SUBMODULES,
                               family=family)
    divider = component_resources(node.coordinate_divider(), "av_projection_divider",
                                  f"av-projection-divider-p{config.pixels_per_beat}-{family}",
                                  family=family)
    count = node.coordinate_divider_count
    log(f"    projection: {rest['LUT']} LUT without its {count} coordinate dividers, "
        f"{divider['LUT']} LUT each")
    return _add([rest] + [divider] * count, name)


def measure_resources(log=print):
    """Yosys estimates of the whole hardware chain (the fpgaDDS variant's seven nodes and six
    topic fabrics, at the camera's 640x480) at 4 and 1 px/clk for the example project's part
    (UltraRAM included), beside fpgaDDS Table II."""
    from gen.export.resources import FAMILY_NAMES
    part, family = project_part()
    rows = []
    for p in (4, 1):
        config = scaled_config(1.0, p)
        log(f"  yosys estimates of the chain's nodes and topics at {p} px/clk for {part} "
            f"({FAMILY_NAMES[family]}; minutes per node the first time)...")
        parts = []
        for name in NODES:
            parts.append({"part": name, **_node_resources(config, name, log, family)})
            log(f"    {name}: {parts[-1]['LUT']} LUT, {parts[-1]['FF']} FF, "
                f"{parts[-1]['BRAM36']} BRAM36, {parts[-1]['BRAM18']} BRAM18, "
                f"{parts[-1]['URAM']} URAM, {parts[-1]['DSP']} DSP")
        topics = [component_resources(t, f"av_topic_{k}", f"av-topic-{k}-p{p}-{family}",
                                      family=family)
                  for k, t in chain_topics(config).items()]
        parts.append(_add(topics, "topic fabrics A-F"))
        total = _add(parts, "whole chain")
        rows += [dict(r, ppc=p, part_name=part, family=family) for r in parts + [total]]
    return rows


def resource_lines(resources):
    """The Markdown of the chain's resources beside fpgaDDS Table II and the device."""
    if not resources:
        return []
    from gen.export.resources import FAMILY_NAMES
    family, part = resources[0]["family"], resources[0]["part_name"]
    lines = resource_table([dict(r, label=f"{r['part']} ({r['ppc']})") for r in resources],
                           "label", "part (px/clk)", family=family,
                           detail=f" for {part}, {FAMILY_NAMES[family]}; 640x480 camera, "
                                  "1000x600 bird's-eye view")
    paper, dev = PAPER_MEMORY, XCZU7EV

    def share(value, total):
        return f"{value:,g} ({100 * value / total:.0f} %)"

    lines += ["", "The whole chain beside fpgaDDS Table II (its chain on the ZCU104's XCZU7EV) "
              "and the device (share of the device in parentheses; a chain fits with 20 % to "
              "spare at 80 % or less of each):", "",
              "| chain | LUT | BRAM36 eq. | UltraRAM | DSP |", "|---|---|---|---|---|",
              f"| fpgaDDS paper (Vivado) | {share(PAPER_LUT, dev['LUT'])} | "
              f"{share(paper['BRAM36'], dev['BRAM36'])} | {share(paper['URAM'], dev['URAM'])} "
              f"| {share(paper['DSP'], dev['DSP'])} |"]
    for r in resources:
        if r["part"] == "whole chain":
            bram36 = r["BRAM18_equiv"] / 2
            lines.append(f"| rosgate, {r['ppc']} px/clk (Yosys) | {share(r['LUT'], dev['LUT'])} "
                         f"| {share(bram36, dev['BRAM36'])} | "
                         f"{share(r.get('URAM', 0), dev['URAM'])} | "
                         f"{share(r['DSP'], dev['DSP'])} |")
    lines += ["", f"The XCZU7EV: {dev['LUT']:,} LUTs, {dev['BRAM36']} BRAM36, {dev['URAM']} "
              f"UltraRAMs (288 Kb each), {dev['DSP']:,} DSPs. BRAM36 eq. counts a BRAM18 as "
              "half. The projection's coordinate dividers are estimated once and counted per "
              "instance (one per px/clk, for a pixel's x and y)."]
    return lines


def markdown(r, resources=()):
    lines = ["# The fpgaDDS lane-following chain", "",
             "Chain alpha (the frame's last beat into Image Compensation to Lane Control's "
             "command for it) over the scene's frames, beside fpgaDDS Table III.", "",
             "| variant | px/clk | frames | mean (ms) | sd (ms) | lane centre max error (px) | "
             "stages bit-exact | paper mean (sd) ms |", "|---|---|---|---|---|---|---|---|"]
    for e in r["chain_alpha"]:
        paper = r["paper"].get(e["variant"])
        paper_text = f"{paper[0]} ({paper[1]})" if paper else "-"
        lines.append(f"| {e['variant']} | {e['ppc'] or '-'} | {e['frames']} | "
                     f"{e['mean_ms']} | {e['sd_ms']} | {e['lane_centre_max_error_px']} | "
                     f"{'yes' if e['stages_bit_exact'] else 'no'} | {paper_text} |")
    for e in r.get("reconros_scaled", []):
        lines.append(f"| reconros at {e['scale']:g} scale | {e['ppc']} | {e['frames']} | "
                     f"{e['mean_ms']} | {e['sd_ms']} | {e['lane_centre_max_error_px']} | "
                     f"{'yes' if e['stages_bit_exact'] else 'no'} | - |")
    lines += ["", "The projection is within 1 of OpenCV's float32 result where the value lies "
              "within float32's error of a half (docs/kernels.md); every other stage is "
              "bit-exact. The software row is wall-clock on this machine, not simulated.", "",
              "The ReconROS rows are the same hardware nodes as ReconOS threads with their "
              "topics through memory and the software broker (examples/av_chain): each node "
              "takes a whole frame from memory and writes its result back before the next "
              "node starts, through one 64-bit memory port. The software side (broker, "
              "delegate threads) takes no simulated time there, so they are a lower bound; "
              f"they cover {RECONROS_FRAMES} full-size frames per px/clk; the rows at a "
              "fifth of the size (128x96 camera, 200x120 view) cover the scene's 100 frames "
              "too and show the spread over it. At that size the lane centre is further from the scene's truth in its "
              "200-pixel view, in the software chain as in hardware: every frame's lane "
              "result equals the software chain's.", "",
              "![chain alpha per frame](av_chain.png)", ""]
    lines += resource_lines(resources)
    return "\n".join(lines)


def plot(r, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 4))
    for name, ms in r["per_frame_ms"].items():
        if not name.startswith("software"):
            ax.plot(range(len(ms)), ms, ".-", label=name.replace("_", ", "))
    ax.axhline(r["paper"]["fpgadds"][0], color="grey", ls=":", label="fpgaDDS paper")
    ax.axhline(r["paper"]["reconros"][0], color="grey", ls="--",
               label="HW + Cyclone DDS, fpgaDDS paper")
    ax.set(xlabel="frame", ylabel="chain alpha (ms at 100 MHz)", yscale="log",
           title="chain alpha per frame")
    ax.legend(loc="center right", fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def overlay(r, path):
    """The lane found in the bird's-eye view of one frame, over that view."""
    import cv2
    from host import autorace
    f = list(scene.frames(r["overlay_frame"] + 1))[-1]
    g = scene.Geometry()
    a, _, _ = autorace.compensate(f.image)
    bev = autorace.project(autorace.blur(a), g.homography())
    centre, left, right = autorace.lane_centre(bev)
    out = bev.copy()
    h = out.shape[0]
    cv2.line(out, (0, g.band_top), (out.shape[1], g.band_top), (255, 255, 0), 1)
    for x, colour in ((left, (0, 255, 255)), (right, (255, 255, 255)), (centre, (0, 0, 255))):
        if x is not None:
            cv2.line(out, (int(x), g.band_top), (int(x), h - 1), colour, 3)
    cv2.circle(out, (int(round(f.centre)), h - 20), 8, (0, 255, 0), 2)
    cv2.imwrite(str(path), out)


def write_results(results, resources, folder):
    plot(results, folder / "av_chain.png")
    overlay(results, folder / "av_chain_overlay.png")
    return write_report(folder, "av_chain", {**results, "resources": resources},
                        markdown(results, resources))


def main(argv=None):
    """``python -m bench.av_chain --fpgadds --reconros`` (either or both): measure only those
    rows again, into the saved results (the other rows and the resources are kept)."""
    args = sys.argv[1:] if argv is None else argv
    parts = {"--fpgadds": measure_fpgadds, "--reconros": measure_reconros}
    if not args or any(a not in parts for a in args):
        raise SystemExit("usage: python -m bench.av_chain [--fpgadds] [--reconros] (all rows: "
                         "python bench/run.py av_chain)")
    folder = ROOT / "bench" / "results"
    saved = json.loads((folder / "av_chain.json").read_text())
    resources = saved.pop("resources")
    for name, part in parts.items():
        if name in args:
            saved = part(saved)
    print(write_results(saved, resources, folder))
    print(f"wrote {folder / 'av_chain.json'}, {folder / 'av_chain.md'} and the plots")
    return 0


if __name__ == "__main__":
    sys.exit(main())
