"""ROS 2 bridge benchmark (docs/ros2.md): what ``rosgate sim --ros2`` adds to a message's
way between a DDS participant and the simulated hardware, in wall time on this machine.

``examples/image_echo`` (one hardware thread that takes each image from /image_in and
publishes the same message on /image_out) runs under Verilator on a loopback DDS domain. A
participant in this process writes ``sensor_msgs/msg/Image`` samples of about 3 kB
(32x32 bgr8) and 1 MB (1024x1024 mono8) as raw CDR and takes the echoes. The bridge's
timeline (wall-clock ``CLOCK_MONOTONIC`` times, comparable across processes) splits each trip:

* ingress: the participant's write -> the bridge hands the message to the simulated system;
* egress: the hardware publishes it -> the participant has the sample.

In the same run, the same bytes make a Cyclone loopback round trip (this process -> an echo
participant in another process -> back, raw in both directions); each overhead is also given
as a ratio to that round trip's median. These are wall times of a Python bridge on a loaded
2-core machine, not properties of the hardware; the simulated time between ingress and egress
is not part of them."""

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from bench.report import write_report
from host.ros2.cosim import POLL_CYCLES
from tb.harness import ROOT, SIM_BUILD
from tb.models import ros2_peer as peer

ECHO = ROOT / "examples" / "image_echo" / "build.cfg"
SIZES = {"3 kB": ((32, 32, 3), "bgr8", 40), "1 MB": ((1024, 1024), "mono8", 10)}

_ECHO_PEER = """
import sys
from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.util import duration
from tb.models import ros2_peer as peer
p = peer.Peer(int(sys.argv[1]))
reader = p.reader("rt/loop_out", peer.Image)
writer = p.writer("rt/loop_back", peer.Image)
waitset = WaitSet(p.participant)
waitset.attach(ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any))
print("ready", flush=True)
while True:
    waitset.wait(duration(seconds=1))
    got = ddspy_take(reader._ref, SampleState.Any | ViewState.Any | InstanceState.Any, 16)
    for data, info in got:
        if info.valid_data:
            ddspy_write(writer._ref, bytes(data))
"""


def _sample(shape, encoding, sec):
    pixels = np.random.default_rng(sec).integers(0, 256, shape, np.uint8)
    height, width = shape[:2]
    step = width * (3 if encoding == "bgr8" else 1)
    return peer.Image(peer.Header(peer.Time(sec, 0), "bench"), height, width, encoding, 0,
                      step, list(pixels.tobytes())).serialize()


def _round_trips(domain, out_topic, back_topic, samples):
    """(write_ns, receive_ns) of each sample written raw on ``out_topic`` and taken back on
    ``back_topic``; each echo must equal the sample."""
    p = peer.Peer(domain)
    writer = p.writer(out_topic, peer.Image)
    reader = p.reader(back_topic, peer.Image)
    p.wait_matched(writer, reader)
    trips = []
    for data in samples:
        start = time.monotonic_ns()
        p.write_raw(writer, data)
        got = p.take_raw(reader)
        trips.append((start, time.monotonic_ns()))
        assert got[4:len(data)] == data[4:], f"the echo on {back_topic} differs from the sample"
    return trips


def _loopback_rtt(domain, samples):
    """Median round trip (ns) of each sample through an echo participant in another
    process."""
    env = peer.loopback_environment()
    echo = subprocess.Popen([sys.executable, "-c", _ECHO_PEER, str(domain)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert echo.stdout.readline().strip() == "ready"
        trips = _round_trips(domain, "rt/loop_out", "rt/loop_back", samples)
        return statistics.median(end - start for start, end in trips)
    finally:
        echo.kill()
        echo.wait()


def _bridge_trips(domain, samples, out):
    """(write_ns, receive_ns) per sample through the bridge and the echo thread, and the
    bridge's timeline."""
    with peer.ros2_sim(ECHO, "verilator", out, domain) as process:
        trips = _round_trips(domain, "rt/image_in", "rt/image_out", samples)
    assert process.returncode == 0
    return trips, peer.results(out)["ros2"]["timeline"]


def measure(log=print):
    rows = []
    base = peer.unique_domain()
    for k, (label, (shape, encoding, count)) in enumerate(SIZES.items()):
        samples = [_sample(shape, encoding, i) for i in range(count)]
        log(f"  {label}: {count} images through rosgate sim --ros2 (image_echo, Verilator) "
            f"and a Cyclone loopback echo...")
        out = SIM_BUILD / f"bench-ros2-{k}"
        trips, timeline = _bridge_trips(base + 2 * k, samples, out)
        ins = [e for e in timeline if e["direction"] == "in"][-count:]
        outs = [e for e in timeline if e["direction"] == "out"][-count:]
        ingress = [e["ingress_ns"] - start for e, (start, _) in zip(ins, trips)]
        egress = [end - e["published_ns"] for e, (_, end) in zip(outs, trips)]
        rtt = _loopback_rtt(base + 2 * k + 1, samples)
        rows.append({
            "message": label, "type": "sensor_msgs/msg/Image", "encoding": encoding,
            "width": shape[1], "height": shape[0], "cdr_bytes": len(samples[0]),
            "messages": count,
            "ingress_ms_median": statistics.median(ingress) / 1e6,
            "egress_ms_median": statistics.median(egress) / 1e6,
            "ingress_ms_max": max(ingress) / 1e6, "egress_ms_max": max(egress) / 1e6,
            "loopback_rtt_ms_median": rtt / 1e6,
            "ingress_per_rtt": statistics.median(ingress) / rtt,
            "egress_per_rtt": statistics.median(egress) / rtt})
    return {"machine": f"{os.cpu_count()} cores", "rows": rows}


def measure_resources(log=print):
    return {}


def markdown(results):
    lines = ["# ROS 2 bridge: overhead per message (wall time, this machine)", "",
             "`rosgate sim examples/image_echo/build.cfg --ros2` under Verilator; a participant "
             "in the bench process writes raw CDR and takes the echo. Ingress: its write -> the "
             "bridge hands the message to the simulated system. Egress: the hardware "
             "publishes -> the participant has the sample. Loopback: the same bytes to an echo "
             "participant in another process and back, in the same run.", "",
             "| message | CDR bytes | n | ingress median (max) ms | egress median (max) ms | "
             "Cyclone loopback RTT ms | ingress / RTT | egress / RTT |",
             "|---|---|---|---|---|---|---|---|"]
    for r in results["rows"]:
        lines.append(f"| {r['message']} ({r['width']}x{r['height']} {r['encoding']}) | "
                     f"{r['cdr_bytes']:,} | {r['messages']} | {r['ingress_ms_median']:.2f} "
                     f"({r['ingress_ms_max']:.2f}) | {r['egress_ms_median']:.2f} "
                     f"({r['egress_ms_max']:.2f}) | {r['loopback_rtt_ms_median']:.2f} | "
                     f"{r['ingress_per_rtt']:.2f} | {r['egress_per_rtt']:.2f} |")
    lines += ["", "Wall times of a Python bridge in the simulator's process: they include "
              "decoding and checking each sample (ingress), encoding it (egress) and the wait "
              f"for the bridge's next poll (every {POLL_CYCLES:,} simulated cycles); they say "
              "nothing "
              "about the hardware, whose timing is in simulated cycles.", ""]
    return "\n".join(lines)


def write_results(results, resources, folder):
    return write_report(folder, "ros2", results, markdown(results))


if __name__ == "__main__":
    data = measure()
    print(write_results(data, {}, Path(__file__).resolve().parent / "results"))
    print(json.dumps(data["rows"], indent=1))
