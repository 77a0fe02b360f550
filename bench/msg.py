"""Message (de)serializer benchmark (issue: ROS messages in hardware §6; docs/messages.md,
docs/topics.md).

Simulated cycles of the generated :class:`hdl.msg.Serializer` / :class:`hdl.msg.Deserializer`
RTL (and of the ReconROS framing's beat-at-a-time pair, :class:`hdl.msg.ReconrosSerializer` /
:class:`hdl.msg.ReconrosDeserializer`, as the gateway uses it) under Verilator at full rate
(no idle, no backpressure), each output checked against rosbags (or the ReconROS model),
converted to time at 100 MHz. Resources come from Debian's Yosys
``synth_xilinx -flatten -family xc7``.
"""

import json
from pathlib import Path

from bench.report import component_resources, resource_table, write_report
from gen.export.resources import YOSYS_COMMAND
from gen.tops import message_plan
from hdl.msg import Deserializer, ReconrosDeserializer, ReconrosSerializer, Serializer
from tb.harness import SIM_BUILD, run_bench

CLOCK_MHZ = 100
IMAGE = "sensor_msgs/msg/Image"
SORTDATA = "sorter_msgs/msg/Sortdata"
POSES = "geometry_msgs/msg/PoseArray"
DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
DIRS = {IMAGE: ["examples/messages/rosgate_test_msgs"],
        SORTDATA: ["examples/messages/sorter_msgs"],
        POSES: [], DIAGNOSTICS: []}
IMAGE_640 = {"height": 480, "width": 640, "step": 1920, "encoding": "bgr8",
             "header.frame_id": "cam", "data": {"bytes": 640 * 480 * 3}}
SEQ_2048 = {"sortdata": {"elements": 2048}}
POSES_1000 = {"poses": {"elements": 1000}}
#: 32 statuses of 4 key/value pairs: strings inside a sequence inside a sequence
STATUS_32 = {"status": {"elements": 32, "values": 4}}

#: (label, type, framing, width, field values[, the beat-at-a-time pair])
CASES = [
    ("Image 640x480 bgr8", IMAGE, "cdr", 64, IMAGE_640),
    ("Image 640x480 bgr8", IMAGE, "cdr", 512, IMAGE_640),
    ("Image 640x480 bgr8", IMAGE, "reconros", 64, IMAGE_640),
    ("Image 640x480 bgr8", IMAGE, "reconros", 64, IMAGE_640, True),
    ("uint32[2048]", SORTDATA, "cdr", 64, SEQ_2048),
    ("uint32[2048]", SORTDATA, "cdr", 512, SEQ_2048),
    ("uint32[2048]", SORTDATA, "reconros", 64, SEQ_2048),
    ("uint32[2048]", SORTDATA, "reconros", 64, SEQ_2048, True),
    ("PoseArray 1000 poses", POSES, "cdr", 64, POSES_1000),
    ("DiagnosticArray 32x4", DIAGNOSTICS, "cdr", 64, STATUS_32),
]

#: docs/topics.md [derived]: ReconROS 640x480 bgr8 Image = 115 217 beats = 1.152 ms at 100 MHz
RECONROS_IMAGE_BEATS = 115217


def run_case(label, typename, framing, width, values, beats=False, *, sim="verilator"):
    config_id = (f"bench-{typename.split('/')[-1].lower()}_{framing}{'_beats' if beats else ''}"
                 f"_w{width}")
    out = SIM_BUILD / f"msg_codec-{config_id}-{sim}" / "record.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    params = dict(type=typename, framing=framing, data_width=width, msg_dirs=DIRS[typename],
                  max_count=1 << 21, beats=beats)
    run_bench("bench.msg_bench", "msg_codec", config_id, params, sim,
              extra_env={"ROSGATE_BENCH_CASE": json.dumps({"set": values}),
                         "ROSGATE_BENCH_OUT": str(out)}, quiet=True, optimise=True)
    record = json.loads(out.read_text())
    limit = width // 8
    record.update(
        label=label, type=typename, framing=framing, beats=beats, width=width,
        limit_bytes_per_cycle=limit,
        serialize_bytes_per_cycle=record["wire_bytes"] / record["serialize_cycles"],
        deserialize_bytes_per_cycle=record["wire_bytes"] / record["deserialize_cycles"],
        payload_bytes_per_cycle=record["payload_bytes"] / record["payload_cycles"],
        serialize_ms=record["serialize_cycles"] / (CLOCK_MHZ * 1e3),
        deserialize_ms=record["deserialize_cycles"] / (CLOCK_MHZ * 1e3))
    return record


def measure(log=print):
    runs = []
    for case in CASES:
        pair = " (beat-at-a-time pair)" if case[5:] and case[5] else ""
        log(f"  simulating {case[0]} {case[2]}{pair} at {case[3]} bits (Verilator)...")
        runs.append(run_case(*case))
    return {"clock_mhz": CLOCK_MHZ, "runs": runs}


FRAMING_NAMES = {"cdr": "CDR", "reconros": "ReconROS"}

#: the (de)serializers whose resources and timing are measured: (class, framing, width)
BLOCKS = [(Deserializer, "cdr", 64), (Serializer, "cdr", 64), (Deserializer, "cdr", 512),
          (ReconrosDeserializer, "reconros", 64), (ReconrosSerializer, "reconros", 64)]

#: blocks over the timing flow's placement budget (bench/timing.py), and the narrower widths
#: placed instead, largest first
TIMING_FALLBACKS = {"image_deserializer_w512": (256, 128)}


def _block(cls, framing, width):
    """``(name, label, build)`` of ``cls`` for the Image in ``framing`` at ``width`` bits."""
    return (f"image_{cls.__name__.lower()}_w{width}",
            f"sensor_msgs/Image {cls.__name__}, {FRAMING_NAMES[framing]}, {width} bit",
            lambda: cls(message_plan(IMAGE, framing, DIRS[IMAGE]), width))


def resource_blocks():
    """(name, label, build) of the (de)serializers whose resources and timing are measured."""
    return [_block(*block) for block in BLOCKS]


def timing_fallbacks(name):
    """``(label, build)`` of the configurations bench/timing.py places when block ``name`` is
    too large for its flow."""
    cls, framing, _ = next(b for b in BLOCKS if _block(*b)[0] == name)
    return [_block(cls, framing, width)[1:] for width in TIMING_FALLBACKS.get(name, ())]


def measure_resources(log=print):
    rows = []
    for name, label, build in resource_blocks():
        log(f"  yosys {YOSYS_COMMAND}: {label}...")
        rows.append({"config": label, **component_resources(
            build(), "msg_block", name.replace("image_", "image-").replace("_w", "-w"))})
    return rows


def pct(record, what):
    return f"{100 * record[f'{what}_bytes_per_cycle'] / record['limit_bytes_per_cycle']:.2f} %"


def timing_core(name):
    """The timing flow's core name (bench/timing.py) of block ``name``."""
    return f"msg_{name}"


def timing_note(results, timing):
    """The rows of the blocks in :data:`TIMING_FALLBACKS` beside what the timing flow
    (``timing``: bench/results/timing.json) showed of them: their largest placed
    configuration and the clock it reached."""
    cores = {r["core"]: r for r in timing.get("cores", ())}
    blocks = {_block(*b)[0]: b for b in BLOCKS}
    narrow = [cores.get(timing_core(name)) for name, (_, _, width) in blocks.items()
              if width == 64]
    closed = (f"the 64-bit blocks close {CLOCK_MHZ} MHz on the open ECP5 flow (all "
              f"{min(r['fmax_mhz'] for r in narrow)} MHz or more); "
              if narrow and all(r and r["pass"] for r in narrow) else "")
    lines = []
    for name in TIMING_FALLBACKS:
        cls, framing, width = blocks[name]
        row = cores.get(timing_core(name))
        run = next((r for r in results["runs"] if r["type"] == IMAGE
                    and r["framing"] == framing and r["width"] == width), None)
        if row is None or run is None or not row.get("fmax_mhz"):
            continue
        why = row.get("full_does_not_fit")
        side = "deserialize" if issubclass(cls, Deserializer) else "serialize"
        cycles, ms = run[f"{side}_cycles"], run[f"{side}_ms"]
        if row.get("pass") and not row.get("placed_config"):
            lines += ["", f"Timing (bench/results/timing.json, docs/timing.md): {closed}the "
                      f"{width}-bit {cls.__name__.lower()} places ({row['lut4']} LUT4+carry) "
                      f"and reaches {row['fmax_mhz']} MHz (worst of {len(row['seeds'])} seeds), "
                      f"so its rows' times hold at {CLOCK_MHZ} MHz on this device: the "
                      f"640x480 Image {side}s in {ms:.4f} ms."]
            continue
        placed = (f"is not placed{f' ({why})' if why else ''}, and its largest placed "
                  f"configuration, {row['placed_config']}, reaches {row['fmax_mhz']} MHz"
                  if row.get("placed_config") else
                  f"places ({row['lut4']} LUT4+carry) and reaches {row['fmax_mhz']} MHz")
        lines += ["", f"Timing (bench/results/timing.json, docs/timing.md): {closed}the "
                  f"{width}-bit {cls.__name__.lower()} {placed}. "
                  f"So the {width}-bit rows' times are not shown to hold at {CLOCK_MHZ} MHz "
                  f"on this device: at {row['fmax_mhz']} MHz the 640x480 Image {side}s in "
                  f"{cycles / (row['fmax_mhz'] * 1e3):.4f} ms, not {ms:.4f}."]
    return lines


def markdown(results, resources, timing=None):
    lines = ["# Message (de)serializer benchmark", "",
             f"Simulated cycles of the generated RTL (Verilator), time at {CLOCK_MHZ} MHz, full "
             "rate (no idle, no backpressure), every output checked against rosbags or the "
             "ReconROS model. Serialize: first cycle the fields are offered to the last output "
             "beat. Deserialize: first input beat to the last payload beat. Payload: the "
             "largest field's packet, first to last beat.", "",
             "| message | framing | width | wire bytes | serialize cycles (ms) | B/cycle | "
             "deserialize cycles (ms) | B/cycle | payload B/cycle | W/8 |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results["runs"]:
        lines.append(
            f"| {r['label']} | {r['framing']}{' (beats)' if r.get('beats') else ''} | "
            f"{r['width']} | {r['wire_bytes']} | "
            f"{r['serialize_cycles']} ({r['serialize_ms']:.4f}) | "
            f"{r['serialize_bytes_per_cycle']:.3f} ({pct(r, 'serialize')}) | "
            f"{r['deserialize_cycles']} ({r['deserialize_ms']:.4f}) | "
            f"{r['deserialize_bytes_per_cycle']:.3f} ({pct(r, 'deserialize')}) | "
            f"{r['payload_bytes_per_cycle']:.3f} | {r['limit_bytes_per_cycle']} |")
    poses = next(r for r in results["runs"] if r["type"] == POSES)
    lines += ["", f"Sequences of messages (docs/messages.md): {POSES_1000['poses']['elements']} "
              f"poses of 56 bytes take {poses['deserialize_cycles'] / 1000:.2f} cycles each to "
              "deserialize at 64 bits (7 for the bytes, 1 for the loop step); strings inside "
              "elements add a few steps each (count read and written packed, NUL, alignment), "
              "which is what the DiagnosticArray row shows."]
    lines += ["", f"ReconROS framing (one 64-bit beat per primitive, docs/topics.md): the spec "
              f"derives {RECONROS_IMAGE_BEATS} beats = "
              f"{RECONROS_IMAGE_BEATS / (CLOCK_MHZ * 1e3):.3f} ms for the 640x480 bgr8 Image. "
              "The rows marked (beats) are the framing's beat-at-a-time pair "
              "(`ReconrosSerializer`, `ReconrosDeserializer`), which the ROS gateway uses.",
              ]
    lines += timing_note(results, timing or {})
    lines += resource_table(resources, "config", "block")
    lines.append("")
    return "\n".join(lines)


def write_results(results, resources, folder):
    data = dict(results, resources=resources, reconros_image_beats=RECONROS_IMAGE_BEATS)
    timing = Path(folder) / "timing.json"
    timing = json.loads(timing.read_text()) if timing.exists() else None
    return write_report(folder, "msg", data, markdown(results, resources, timing))
