"""Plots of ``make bench``'s results beside the papers' figures (matplotlib PNG in
bench/results/), drawn from the JSON each bench writes: ``python bench/plots.py`` redraws
them all without simulating anything."""

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"

#: fpgaDDS Table I: message bytes -> (CycloneDDS ms, fpgaDDS ms); "<0.01" drawn at 0.01
FPGADDS_TABLE_I = {3 * 32 ** 2: (0.06, 0.01), 3 * 64 ** 2: (0.07, 0.02),
                   3 * 128 ** 2: (0.19, 0.06), 3 * 256 ** 2: (0.63, 0.24),
                   3 * 512 ** 2: (2.34, 0.98), 3 * 1024 ** 2: (9.24, 3.93)}
#: the SiTCP ROS component paper, 6 MB sensor_msgs/Image through the FPGA (ms): Fig. 12 round
#: trip, Fig. 13 FPGA receiving (PC sends), Fig. 14 FPGA sending
SITCP_6MB = {"round trip": 175, "FPGA receives": 57, "FPGA sends": 116}
#: ReconROS paper Table 4, raw copy by a hardware thread (ms) at 100 MHz
RECONROS_COPY_HW = {4: 0.01, 8192: 0.13, 1 << 20: 12.81, 6 << 20: 76.35, 10 << 20: 127.19}


def _save(fig, name):
    path = RESULTS / f"{name}.png"
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _load(name):
    path = RESULTS / f"{name}.json"
    return json.loads(path.read_text()) if path.is_file() else None


def plot_topics(data):
    """Topic transfer time vs message size: rosgate's topic (1:1, one message) at 64 and
    512 bits beside fpgaDDS and CycloneDDS (fpgaDDS Table I)."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    sizes = sorted(FPGADDS_TABLE_I)
    ax.plot(sizes, [FPGADDS_TABLE_I[s][0] for s in sizes], "s--", color="tab:gray",
            label="CycloneDDS via MEMIF (fpgaDDS Table I)")
    ax.plot(sizes, [FPGADDS_TABLE_I[s][1] for s in sizes], "o--", color="tab:orange",
            label="fpgaDDS (Table I)")
    clock = data["clock_mhz"]
    for width, colour in ((64, "tab:blue"), (512, "tab:green")):
        runs = sorted((r for r in data["runs"] if r["pubs"] == 1 and r["subs"] == 1 and
                       r["width"] == width and r["kind"] == "one"), key=lambda r: r["size"])
        if runs:
            ax.plot([r["size"] for r in runs], [r["time_ms"] for r in runs], "o-",
                    color=colour, label=f"rosgate topic 1:1, {width} bit at {clock} MHz")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("message size (bytes)")
    ax.set_ylabel("transfer time (ms)")
    ax.set_title("Hardware-mapped topic: one message, publisher to subscriber")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, "hmt_transfer_time")


def plot_network(data):
    """TCP image transfers (1, 2, 6 MB sensor_msgs/Image) through the TCPROS node beside the
    SiTCP paper's 6 MB bars, and goodput of the two buffer configurations."""
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5))
    images = data["image"]
    labels = list(images)
    mb = [images[k]["bytes"] / 1e6 for k in labels]
    for key, name, style in (("receive_ms", "FPGA receives", "o-"),
                             ("send_ms", "FPGA sends", "s-"),
                             ("round_trip_ms", "round trip", "^-")):
        ax.plot(mb, [images[k][key] for k in labels], style, label=f"rosgate: {name}")
    for (name, ms), marker in zip(SITCP_6MB.items(), ("^", "o", "s")):
        ax.plot([6.22], [ms], marker, markersize=10, markerfacecolor="none",
                label=f"SiTCP paper, 6 MB: {name} {ms} ms")
    ax.set_xlabel("message size (MB)")
    ax.set_ylabel("latency (ms)")
    ax.set_title(f"sensor_msgs/Image over TCPROS at {data['clock_mhz']} MHz GMII")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    cases = data["tcp"]
    names = list(cases)
    x = range(len(names))
    bx.bar([i - 0.2 for i in x], [cases[n]["engine_to_peer"]["mbps"] for n in names], 0.4,
           label="engine to peer")
    bx.bar([i + 0.2 for i in x], [cases[n]["peer_to_engine"]["mbps"] for n in names], 0.4,
           label="peer to engine")
    bx.axhline(949.3, color="k", linestyle="--", linewidth=1, label="TCP ceiling 949.3 Mb/s")
    bx.axhline(436, color="tab:red", linestyle=":", linewidth=1,
               label="SiTCP capture, FPGA to PC (436 Mb/s)")
    bx.set_xticks(list(x), [cases[n]["label"].split(";")[0] for n in names], fontsize=7)
    bx.set_ylabel("goodput (Mb/s)")
    bx.set_title("TCP goodput, 1 session")
    bx.legend(fontsize=7, loc="lower right")
    return _save(fig, "net_image_latency")


def plot_memif(data):
    """MEMIF copy throughput vs transfer size beside ReconROS' hardware copy (Table 4), and
    the throughput of single requests vs their burst length."""
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5))
    clock = data["clock_mhz"]
    for arch, colour in (("r64", "tab:blue"), ("r32", "tab:green")):
        rows = sorted((r for r in data["copies"] if r["arch"] == arch),
                      key=lambda r: r["nominal"])
        ax.plot([r["bytes"] for r in rows],
                [2 * r["bytes"] / r["op_cycles"] * clock for r in rows], "o-", color=colour,
                label=f"rosgate {arch} copy (read + write), whole operation")
    sizes = sorted(RECONROS_COPY_HW)
    ax.plot(sizes, [2 * s / (RECONROS_COPY_HW[s] * 1e3) for s in sizes], "s--",
            color="tab:gray", label="ReconROS HW copy (Table 4)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("copy size (bytes)")
    ax.set_ylabel("bytes moved per microsecond (MB/s)")
    ax.set_title(f"MEMIF copies at {clock} MHz")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    for arch, colour in (("r64", "tab:blue"), ("r32", "tab:green")):
        rows = sorted((r for r in data.get("bursts", []) if r["arch"] == arch),
                      key=lambda r: r["length"])
        if rows:
            bx.plot([r["length"] for r in rows],
                    [r["length"] / r["bus_cycles"] * clock for r in rows], "o-",
                    color=colour, label=f"{arch}: one read request")
            bx.axhline(rows[0]["word_bytes"] * clock, color=colour, linestyle=":",
                       linewidth=1, label=f"{arch}: one word per cycle")
    bx.set_xscale("log", base=2)
    bx.set_xlabel("request (burst) length in bytes")
    bx.set_ylabel("MB/s (first address to last data)")
    bx.set_title("MEMIF read throughput vs burst length")
    bx.grid(True, which="both", alpha=0.3)
    bx.legend(fontsize=7)
    return _save(fig, "memif_throughput")


def plot_kernels(kernels, apps):
    """Kernel time per item beside the ReconROS paper's raw hardware times (Table 6)."""
    rows = [r for r in kernels["rows"] if r.get("paper")]
    if apps:
        rows += [r for r in apps["rows"] if r.get("paper") and r["arch"] == "r64"]
    fig, ax = plt.subplots(figsize=(9, 0.45 * len(rows) + 1.5))
    y = range(len(rows))
    ax.barh([i + 0.2 for i in y], [r["ms"] for r in rows], 0.4, label="rosgate (simulated)")
    ax.barh([i - 0.2 for i in y], [r["paper"][1] for r in rows], 0.4, color="tab:gray",
            label="paper")
    ax.set_yticks(list(y), [f"{r['label'][:60]}\nvs {r['paper'][0]}" for r in rows],
                  fontsize=6)
    ax.set_xscale("log")
    ax.set_xlabel("ms per item (log)")
    ax.set_title(f"Kernels and demo nodes at {kernels['clock_mhz']} MHz vs ReconROS Table 6")
    ax.grid(True, axis="x", which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, "kernels_vs_reconros")


#: P-FIN's PID loop on a Nios II soft core (FINROC), cycles per second
PFIN_PID_HZ = 25_000


def plot_finemb(data):
    """FinEmbP cycle rate vs line length, sequential and pipelined, beside the wire limit of
    the same frames, the goals and P-FIN's soft core."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for polling, colour in (("sequential", "tab:blue"), ("pipelined", "tab:green")):
        rows = sorted((r for r in data["line"] if r["polling"] == polling),
                      key=lambda r: r["nodes"])
        ax.plot([r["nodes"] for r in rows], [r["cycle_rate_hz"] / 1e3 for r in rows], "o-",
                color=colour, label=f"rosgate, {polling} polling")
        if polling == "pipelined":
            ax.plot([r["nodes"] for r in rows], [r["wire_limit_hz"] / 1e3 for r in rows],
                    ":", color="tab:gray", label="wire limit of the same frames (1 Gbit/s)")
    goals = [(r["nodes"], r["goal_hz"]) for r in data["line"] if r["goal_hz"]]
    ax.plot([n for n, _ in goals], [g / 1e3 for _, g in goals], "v", color="tab:red",
            markersize=9, label="goal")
    ax.axhline(PFIN_PID_HZ / 1e3, color="tab:orange", linestyle="--",
               label="P-FIN: PID on a Nios II (25 kHz)")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("nodes in the line")
    ax.set_ylabel("cycle rate (kHz)")
    ax.set_title("FinEmbP: PID cycles per second, every node answered every cycle")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, "finemb_cycle_rate")


def write_plots(names=None, log=print):
    """Redraw the plots of the given benches (default: every bench with results)."""
    written = []
    wanted = set(names or ("hmt", "net", "reconos", "kernels", "reconos_apps", "finemb"))
    if "hmt" in wanted and (data := _load("hmt")):
        written.append(plot_topics(data))
    if "net" in wanted and (data := _load("net")):
        written.append(plot_network(data))
    if "reconos" in wanted and (data := _load("reconos")):
        written.append(plot_memif(data))
    if wanted & {"kernels", "reconos_apps"} and (data := _load("kernels")):
        written.append(plot_kernels(data, _load("reconos_apps")))
    if "finemb" in wanted and (data := _load("finemb")):
        written.append(plot_finemb(data))
    for path in written:
        log(f"wrote {path}")
    return written


if __name__ == "__main__":
    write_plots(sys.argv[1:] or None)
    sys.exit(0)
