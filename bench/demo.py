"""``make demo``: the Sobel/DIP application of the ReconROS paper (Fig. 5, Listing 1).

1. ``rosgate export-hw examples/sobel_dip/build.cfg -o build/sobel_dip``: Verilog, Vivado TCL,
   FuseSoC cores and the manifest of the two-slot system.
2. ``rosgate sim`` under Verilator: a camera node publishes three photographs as
   ``sensor_msgs/Image``; the DIP hardware node takes each, calls the Sobel hardware service
   (OpenCV's Sobel edge image), publishes the result; a viewer node writes it as PNG beside
   OpenCV's result and a montage, and prints the latency and the speedup over the paper.
"""

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from host.cli import main as rosgate  # noqa: E402

PROJECT = ROOT / "examples" / "sobel_dip" / "build.cfg"
OUT = ROOT / "build" / "sobel_dip"
IMAGES = ["coffee_640x480.png", "chelsea_96x72.png", "coffee_80x60.png"]


def main():
    print("== rosgate demo: the Sobel/DIP application of the ReconROS paper (Fig. 5)",
          flush=True)
    project = PROJECT.relative_to(ROOT)
    print(f"$ rosgate export-hw {project} -o {OUT.relative_to(ROOT)}", flush=True)
    if rosgate(["export-hw", str(PROJECT), "-o", str(OUT)]):
        return 1
    images = ",".join(IMAGES)
    print(f"\n$ rosgate sim {project} --arg images={images} -o {(OUT / 'sim').relative_to(ROOT)}",
          flush=True)
    if rosgate(["sim", str(PROJECT), "--arg", f"images={images}", "--limit-ms", "100",
                "-o", str(OUT / "sim")]):
        return 1
    results = json.loads((OUT / "sim" / "sim_results.json").read_text())["images"]
    exact = sum(r["bit_exact"] for r in results)
    print(f"\ndemo: {exact} of {len(results)} images equal to OpenCV's Sobel edge image; open "
          f"{(OUT / 'sim').relative_to(ROOT)}/*_montage.png (input | rosgate | OpenCV); the "
          f"Vivado project is in {OUT.relative_to(ROOT)}/ (vivado -mode batch -source "
          f"build.tcl)")
    return 0 if exact == len(results) else 1


if __name__ == "__main__":
    sys.exit(main())
