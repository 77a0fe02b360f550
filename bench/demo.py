"""``make demo``: the Sobel/DIP application of the ReconROS paper (Fig. 5, Listing 1).

1. ``rosgate export-hw examples/sobel_dip/build.cfg -o build/sobel_dip``: Verilog, Vivado TCL,
   FuseSoC cores and the manifest of the two-slot system.
2. ``rosgate sim`` under Verilator: a camera node publishes real photographs as
   ``sensor_msgs/Image``; the DIP hardware node takes each, calls the Sobel hardware service,
   publishes the result; a viewer node writes it as PNG next to OpenCV's result.
3. A table of what the simulation measured, beside the paper's Table 6 Sobel row.
"""

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gen.cli import main as rosgate  # noqa: E402
from tb.project_sim import run_project_sim  # noqa: E402

PROJECT = ROOT / "examples" / "sobel_dip" / "build.cfg"
OUT = ROOT / "build" / "sobel_dip"
IMAGES = ["coffee_640x480.png", "chelsea_96x72.png", "coffee_80x60.png"]
CLOCK_MHZ = 100
#: ReconROS paper Table 6, Sobel row (640x480 bgr8, Zynq-7100 at 100 MHz), ms
PAPER = {"raw SW": 37.53, "raw HW": 22.28, "pp SW": 83.39, "pp HW": 68.54}


def main():
    start = time.monotonic()
    print("== rosgate demo: the Sobel/DIP application of the ReconROS paper (Fig. 5)")
    print(f"-- rosgate export-hw {PROJECT.relative_to(ROOT)} -o {OUT.relative_to(ROOT)}",
          flush=True)
    t = time.monotonic()
    if rosgate(["export-hw", str(PROJECT), "-o", str(OUT)]):
        return 1
    export_s = time.monotonic() - t
    print(f"-- rosgate sim {PROJECT.relative_to(ROOT)} --sim verilator --arg images="
          f"{','.join(IMAGES)}  (camera -> DIP (HW) -> Sobel service (HW) -> viewer)",
          flush=True)
    results = run_project_sim(PROJECT, "verilator", out=OUT / "sim",
                              args={"images": ",".join(IMAGES)}, limit_ms=100, quiet=True)
    rows = results["images"]
    print()
    print(f"| image | cycles (publish to filtered image received) | ms at {CLOCK_MHZ} MHz | "
          "frames/s | bit-exact with OpenCV |")
    print("|---|---|---|---|---|")
    for r in rows:
        ms = r["cycles"] / (CLOCK_MHZ * 1000)
        print(f"| {r['image']} ({r['width']}x{r['height']}) | {r['cycles']} | {ms:.3f} | "
              f"{1000 / ms:.1f} | {'yes' if r['bit_exact'] and r['header_ok'] else 'NO'} |")
    big = next(r for r in rows if (r["width"], r["height"]) == (640, 480))
    ms = big["cycles"] / (CLOCK_MHZ * 1000)
    exact = sum(r["bit_exact"] and r["header_ok"] for r in rows)
    print()
    print(f"images processed: {len(rows)}, bit-exact with the OpenCV golden result: "
          f"{exact} of {len(rows)}")
    print(f"640x480 bgr8: {big['cycles']} cycles = {ms:.2f} ms at {CLOCK_MHZ} MHz = "
          f"{1000 / ms:.1f} frames/s (DIP takes the image, copies it into the request, the "
          "Sobel server filters it, DIP copies the result back and publishes it; the software "
          "side is the ReconOS runtime model, whose ROS overhead is not simulated)")
    print(f"paper Table 6, Sobel: raw HW {PAPER['raw HW']} ms (Sobel node alone), pp HW "
          f"{PAPER['pp HW']} ms (ping-pong through ROS 2); speedup of this round trip: "
          f"{PAPER['raw HW'] / ms:.1f}x vs raw HW, {PAPER['pp HW'] / ms:.1f}x vs pp HW, "
          f"{PAPER['raw SW'] / ms:.1f}x vs raw SW")
    print(f"filtered images and OpenCV's: {OUT / 'sim'}/*_filtered.png, *_opencv.png")
    print(f"Vivado export: {OUT} (build.tcl, bd/design_1.tcl, ip/, hdl/, manifest.json), "
          f"written in {export_s:.1f} s")
    print(f"demo done in {time.monotonic() - start:.0f} s")
    return 0 if exact == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
