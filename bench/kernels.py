"""Streaming kernels benchmark (issue: kernels; docs/kernels.md, docs/reconos.md,
docs/kernels.md): cycles per 640x480 frame or per item under Verilator at 100 MHz beside the papers'
numbers and the issue's targets; yosys synth_xilinx resources of each kernel."""

import json

from bench.report import component_resources, resource_table, write_report
from gen.export.resources import YOSYS_COMMAND
from gen.tops import build_kernel
from tb.harness import SIM_BUILD, run_bench

CLOCK_MHZ = 100


def _k(kind, **params):
    return dict(kind=kind, max_width=640, max_height=480, **params)


#: kernel -> (spec, label, paper reference (label, ms) or None, target ms or None)
IMAGE = {
    "sobel_p1": (_k("sobel", pixels_per_beat=1), "Sobel opencv, bgr8, 1 px/clk",
                 ("ReconROS Sobel raw HW", 22.28), 3.1),
    "sobel_p4": (_k("sobel", pixels_per_beat=4), "Sobel opencv, bgr8, 4 px/clk",
                 ("ReconROS Sobel raw HW", 22.28), 0.8),
    "sobel_rr": (dict(kind="sobel", mode="reconros", channels=4, pixels_per_beat=1,
                      max_width=480, max_height=480),
                 "Sobel reconros (480 words x 480 rows), 1 word/clk",
                 ("ReconROS Sobel raw HW", 22.28), None),
    "gauss3_p1": (_k("gaussian", ksize=3), "Gaussian 3x3, bgr8, 1 px/clk", None, 3.1),
    "gauss5_p1": (_k("gaussian", ksize=5), "Gaussian 5x5, bgr8, 1 px/clk", None, 3.1),
    "gauss5_p4": (_k("gaussian", ksize=5, pixels_per_beat=4), "Gaussian 5x5, bgr8, 4 px/clk",
                  None, 0.8),
    "gray_p1": (_k("gray"), "BGR to GRAY, 1 px/clk", None, 3.1),
    "hsv_p1": (_k("hsv"), "BGR to HSV, 1 px/clk", None, 3.1),
    "hsv_p4": (_k("hsv", pixels_per_beat=4), "BGR to HSV, 4 px/clk", None, 0.8),
    "inrange_p1": (_k("inrange"), "inRange, 1 px/clk", None, 3.1),
    "traffic_p1": (_k("traffic_light"), "traffic lights (HSV + 3 inRange + counts), 1 px/clk",
                   None, 3.1),
    "equalize_p1": (_k("equalize"), "equalizeHist (frame buffer, 1 frame latency), 1 px/clk",
                    None, 3.1),
}
CONTROL = {
    "sort": (dict(kind="sort", block_size=2048), "sort 2048 x uint32 (per block)",
             ("ReconROS sorting raw HW", 35.11), 0.25),
    "pid": (dict(kind="pid"), "PID update (per update)",
            ("FINROC PID on Nios II at 25 kHz", 0.04), 0.00001),
    "ik": (dict(kind="inverse_kinematics", lanes=16), "inverse kinematics (per solution)",
           ("ReconROS inverse kinematics raw HW", 0.19), 0.002),
    "ball": (dict(kind="ball_control"),
             "ball-on-plate Kalman + PD, touch sample to the 6th leg word (per sample)",
             ("ReconROS ball-on-plate sampling period", 20.0), 0.02),
}
MNIST = {
    "mnist": (dict(kind="mnist", pixels_per_beat=4),
              "MNIST CNN (4-bit weights), 28x28 digit in to result out (latency)",
              ("ReconROS MNIST raw HW", 30.74), 0.005),
}


def measure(log=print):
    records = {}
    # one top per image kernel: a simulation of many kernels pays every port's driver each
    # cycle
    runs = [(f"bench_{name}", {name: spec}) for name, (spec, *_) in IMAGE.items()]
    runs.append(("bench_control", {name: spec for name, (spec, *_) in CONTROL.items()}))
    runs.append(("bench_mnist", {"cnn": MNIST["mnist"][0]}))
    for config, kernels in runs:
        out = SIM_BUILD / f"bench-kernels-{config}.json"
        log(f"  simulating {', '.join(kernels)} (Verilator)...")
        run_bench("bench.kernels_bench", "kernels", config, {"kernels": kernels}, "verilator",
                  quiet=True, optimise=True, extra_env={"ROSGATE_BENCH_OUT": str(out)})
        records.update(json.loads(out.read_text()))
    rows = []
    for name, (spec, label, paper, target) in {**IMAGE, **CONTROL, **MNIST}.items():
        rec = records[name]
        if name in IMAGE:
            cycles = rec["period"]
            row = {"kernel": name, "label": label, "cycles": cycles,
                   "first_frame_cycles": rec["first_frame"],
                   "size": f"{rec['width']}x{rec['height']}"}
        else:
            cycles = rec["cycles"] / rec["items"]
            row = {"kernel": name, "label": label, "cycles": cycles}
        row.update(ms=cycles / (CLOCK_MHZ * 1e3), paper=paper, target_ms=target)
        rows.append(row)
    return {"clock_mhz": CLOCK_MHZ, "rows": rows}


#: kernels whose resource estimate uses a smaller maximum frame: Yosys does not finish
#: mapping a 640x480 frame buffer (2.4 Mbit, about 67 RAMB36) in reasonable time
RESOURCE_SPECS = {"equalize_p1": (dict(kind="equalize", max_width=128, max_height=128),
                                  "equalizeHist, 128x128 frame buffer (640x480: + ~63 RAMB36)")}


#: kernels too large for the timing device (bench/timing.py), or that it does not route in
#: the flow's time, and the smaller configurations placed instead, largest first:
#: (parameter, value). The MNIST CNN has none: at 1 pixel per clock it gathers four pixels
#: into the same first layer and multiplier array, so it is no smaller to place
TIMING_FALLBACKS = {"ik": (("lanes", 8),)}

#: parameters a kernel is placed with on the timing bench's ECP5 only: the MNIST CNN's
#: multipliers as MULT18X18D with their own registers (Yosys does not move registers into
#: them; Vivado does into its DSP48, so the exported kernel keeps inferred ones)
TIMING_PARAMS = {"mnist": {"multipliers": "ecp5"}}


def measure_resources(log=print):
    rows = []
    for name, (spec, label, *_) in {**IMAGE, **CONTROL, **MNIST}.items():
        spec, label = RESOURCE_SPECS.get(name, (spec, label))
        log(f"  yosys {YOSYS_COMMAND}: {name}...")
        rows.append({"kernel": name, "label": label,
                     **component_resources(build_kernel(spec), f"kernel_{name}",
                                           f"kernel-{name}")})
    return rows


def markdown(results, resources):
    lines = ["# Streaming kernels benchmark", "",
             f"Each kernel alone under Verilator at {CLOCK_MHZ} MHz, no idle and no "
             "backpressure, every output checked against its golden model (OpenCV, the "
             "AVR221 model, the ap_fixed inverse-kinematics model, `sorted`). Image kernels: "
             "the 640x480 photograph `examples/images/coffee_640x480.png` twice back to back; "
             "*cycles* is the frame period (last pixel of frame 1 to last pixel of frame 2), "
             "*first frame* the cycles from the first pixel in to the last pixel out. Paper: "
             "ReconROS Table 6 (non-optimised HLS at 100 MHz); FINROC: PID loop on a Nios II "
             "soft core at 25 kHz.", "",
             "| kernel | cycles | first frame | ms | target ms | paper ms |",
             "|---|---|---|---|---|---|"]
    for r in results["rows"]:
        paper = f"{r['paper'][1]} ({r['paper'][0]})" if r["paper"] else "-"
        target = f"<= {r['target_ms']}" if r["target_ms"] else "-"
        cycles = f"{r['cycles']:.1f}" if isinstance(r["cycles"], float) else str(r["cycles"])
        lines.append(f"| {r['label']} | {cycles} | {r.get('first_frame_cycles', '-')} | "
                     f"{r['ms']:.5f} | {target} | {paper} |")
    lines += resource_table(resources, "label", "kernel", detail=", 640x480 maximum frame")
    lines += ["", "Anchors (docs/kernels.md): Vitis Vision xFSobel 3x3 1 px/clk 616 LUT, 609 FF, "
              "3 BRAM18; 8 px/clk 1892 LUT; ReconROS Sobel thread 13 625 LUT, 10 BRAM "
              "(Table 5). MNIST: FINN SFC-max (binarized, fully connected; ZC706) 0.31 us, "
              "95.8 %, 91,131 LUT, 4.5 BRAM36; ReconROS MNIST thread (LeNet-5, ap_fixed<8,3>) "
              "26,071 LUT, 18 DSP, 57.5 BRAM (Table 5), 30.74 ms.", ""]
    return "\n".join(lines)


def write_results(results, resources, folder):
    return write_report(folder, "kernels", dict(results, resources=resources),
                        markdown(results, resources))
