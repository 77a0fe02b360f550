"""Ball-on-plate control loop benchmark (docs/ball_on_plate.md): ``examples/ball_on_plate``
under Verilator for 300 servo periods (6 s of plant time at the paper's 20 ms period), the
ball dropped 108 mm off centre. Writes the ball's path, the servo arm angles, the settling
time and the loop latency in cycles (touch sample to the sixth leg angle, and to the PWM
update), with a plot."""

import math

from bench.report import write_report
from host.project_sim import run_project_sim
from tb.harness import ROOT, SIM_BUILD

BUILD_CFG = ROOT / "examples" / "ball_on_plate" / "build.cfg"
PERIODS = 300
CLOCK_MHZ = 100
PAPER_PERIOD_MS = 20.0
#: the ball counts as settled once it stays within this radius
RADIUS_MM = 3.0


def measure(log=print):
    log(f"  simulating examples/ball_on_plate for {PERIODS} servo periods (Verilator)...")
    results = run_project_sim(BUILD_CFG, "verilator", out=SIM_BUILD / "bench-ball_on_plate",
                              args={"periods": str(PERIODS)}, limit_ms=200)
    periods = results["periods"]
    radius = [math.hypot(p["x"], p["y"]) for p in periods]
    outside = [p["t"] for p, r in zip(periods, radius) if r > RADIUS_MM]
    settled = outside[-1] + 0.02 if outside else 0.0
    lat = results["latencies"]
    period_cycles = 20_000 * results["pwm_clock_hz"] // 1_000_000
    return {"periods": periods, "radius_mm": RADIUS_MM, "settled_s": round(settled, 3),
            "final_radius_mm": results["final_radius_mm"],
            "chain_cycles_mean": sum(lat) / len(lat), "chain_cycles_max": max(lat),
            "pwm_period_cycles": period_cycles, "pwm_clock_hz": results["pwm_clock_hz"],
            "clock_mhz": CLOCK_MHZ, "paper_period_ms": PAPER_PERIOD_MS}


def measure_resources(log=print):
    return {}


def markdown(r):
    mean, worst = r["chain_cycles_mean"], r["chain_cycles_max"]
    return "\n".join([
        "# Ball-on-plate control loop", "",
        f"`examples/ball_on_plate` under Verilator: Touch, Control (Kalman + PD), Inverse "
        f"(six legs) and Servo as hardware threads at {r['clock_mhz']} MHz, closed through the "
        f"ball and Stewart-platform model of its `sim.py`, {len(r['periods'])} servo periods of "
        f"{r['paper_period_ms']:g} ms. The ball starts at (90, -60) mm.", "",
        "| figure | value |", "|---|---|",
        f"| settled within {r['radius_mm']:g} mm after | {r['settled_s']:.2f} s |",
        f"| distance from the centre at the end | {r['final_radius_mm']:.2f} mm |",
        f"| touch sample to the sixth leg angle, mean (max) | {mean:.0f} ({worst}) cycles = "
        f"{mean / r['clock_mhz']:.1f} us |",
        f"| touch sample to the PWM update (the next period start) | at most one period: "
        f"{r['paper_period_ms']:g} ms |",
        f"| the paper's sampling period | {r['paper_period_ms']:g} ms = "
        f"{r['paper_period_ms'] * r['clock_mhz'] * 1000:,.0f} cycles |", "",
        f"Time scale of the simulation: the PWM counts at {r['pwm_clock_hz']:,} Hz, so one "
        f"{r['paper_period_ms']:g} ms period takes {r['pwm_period_cycles']:,} cycles of the "
        "100 MHz slots; the chain runs at its real speed.", "",
        "![ball path and servo angles](ball_on_plate.png)", ""])


def plot(r, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    periods = r["periods"]
    t = [p["t"] for p in periods]
    fig, (ax_path, ax_t, ax_servo) = plt.subplots(1, 3, figsize=(15, 4.2))
    ax_path.plot([p["x"] for p in periods], [p["y"] for p in periods], ".-", ms=3)
    ax_path.plot([0], [0], "r+", ms=12)
    ax_path.set(xlabel="x (mm)", ylabel="y (mm)", title="ball on the plate",
                aspect="equal")
    ax_t.plot(t, [p["x"] for p in periods], label="x")
    ax_t.plot(t, [p["y"] for p in periods], label="y")
    ax_t.plot(t, [math.hypot(p["x"], p["y"]) for p in periods], label="distance")
    ax_t.axhline(r["radius_mm"], color="grey", ls=":")
    ax_t.set(xlabel="time (s)", ylabel="mm", title="position")
    ax_t.legend()
    scale = 1e6 / r["pwm_clock_hz"]
    for leg in range(6):
        ax_servo.plot(t, [((p["widths"][leg] * scale) - 500) * 180 / 2000 if p["widths"][leg]
                          else float("nan") for p in periods], label=f"leg {leg}")
    ax_servo.set(xlabel="time (s)", ylabel="arm angle (degrees)",
                 title="servo angles from the measured PWM")
    ax_servo.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_results(results, resources, folder):
    plot(results, folder / "ball_on_plate.png")
    return write_report(folder, "ball_on_plate", results, markdown(results))
