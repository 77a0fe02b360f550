"""The ``rosgate`` command line.

Exit codes: 0 success, 1 a runtime failure (I/O, tool), 2 bad usage or a bad parameter (the
message names the option and the allowed values).
"""

import argparse
import sys
import threading
import time
from pathlib import Path

from gen.config import ConfigError
from gen.finemb import IoDescriptionError
from gen.msg.model import MessageDefinitionError
from hdl.dds import MAX_ENDPOINTS, QOS_POLICIES
from hdl.params import ParameterError

from .compiled import DEFAULT_MEMORY_MB, MEMORY_OPTION
from .ros2.bridge import GOAL_POLICIES, SERVICE_QUEUE
from .ros2.player import PACES as PLAY_PACES
from .board_cli import add_board_commands
from .tap_cli import add_export_finemb, add_tap_commands

__all__ = ["main"]

PROG = "rosgate"


def _version():
    try:
        from importlib.metadata import version
        return version("rosgate")
    except Exception:  # not installed (running from a checkout)
        return "unknown"


def _cannot_write(command, path, exc):
    print(f"{PROG} {command}: error: cannot write {path}: {exc.strerror}", file=sys.stderr)
    return 1


# export topic ------------------------------------------------------------------------------

#: component parameter -> command-line option, so errors name what the user typed
TOPIC_OPTIONS = {
    "pubs": "--pubs", "subs": "--subs", "data_width": "--width", "fifo_depth": "--fifo-depth",
    "qos": "--qos", "history": "--history", "counter_width": "--counter-width",
    "user_width": "--user-width", "id_width": "--id-width", "dest_width": "--dest-width",
}


def _add_export_topic(sub):
    p = sub.add_parser(
        "topic", help="a hardware-mapped topic (N publishers, M subscribers)",
        description="Export a hardware-mapped topic (fpgaDDS) as Verilog module `topic` with "
                    "ports aclk, aresetn, s<i>_axis_t* (publisher i), m<j>_axis_t* "
                    "(subscriber j) and monitor_* counters, plus a JSON manifest.")
    p.add_argument("--pubs", type=int, required=True,
                   help=f"publishers, 1..{MAX_ENDPOINTS}")
    p.add_argument("--subs", type=int, required=True,
                   help=f"subscribers, 1..{MAX_ENDPOINTS}")
    p.add_argument("--width", type=int, required=True,
                   help="tdata bits, a multiple of 8 in 8..1024")
    p.add_argument("--fifo-depth", type=int, default=0,
                   help="beats of FIFO per subscriber: 0 (none, default) or a power of two "
                        "in 2..65536")
    p.add_argument("--qos", default="keep_all",
                   help=f"subscriber QoS: {', '.join(QOS_POLICIES)} (default keep_all)")
    p.add_argument("--history", type=int, default=None,
                   help="keep_last only: messages kept per subscriber (power of two, "
                        "default 4)")
    p.add_argument("--user-width", type=int, default=0, help="tuser bits (default 0: none)")
    p.add_argument("--id-width", type=int, default=0, help="tid bits (default 0: none)")
    p.add_argument("--dest-width", type=int, default=0, help="tdest bits (default 0: none)")
    p.add_argument("--no-monitor", action="store_true", help="omit the monitor counters")
    p.add_argument("--counter-width", type=int, default=32,
                   help="monitor counter bits (default 32)")
    p.add_argument("--no-register", action="store_true",
                   help="omit the register slice (purely combinational topic)")
    p.add_argument("-o", "--output", required=True, type=Path,
                   help="output folder (created); writes topic.v and topic.json")
    p.set_defaults(func=_run_export_topic, options=TOPIC_OPTIONS, parser=p)


def _run_export_topic(args):
    from gen.export.verilog import export_verilog, write_if_changed, write_manifest
    from gen.tops import build_top

    params = dict(pubs=args.pubs, subs=args.subs, data_width=args.width,
                  fifo_depth=args.fifo_depth, qos=args.qos, history=args.history,
                  user_width=args.user_width, id_width=args.id_width,
                  dest_width=args.dest_width, monitor=not args.no_monitor,
                  counter_width=args.counter_width, register=not args.no_register)
    component = build_top("topic", **params)
    start = time.monotonic()
    text, top = export_verilog(component, "topic")
    out = args.output
    try:
        out.mkdir(parents=True, exist_ok=True)
        write_if_changed(out / "topic.v", text)
        write_manifest(out / "topic.json", module="topic", component=component, top=top,
                       extra={"latency_cycles": component.latency})
    except OSError as exc:
        return _cannot_write("export topic", out, exc)
    print(f"wrote {out / 'topic.v'} (module topic, {len(top.ports) + 2} ports, "
          f"{component.pubs}:{component.subs} at {args.width} bits, qos {args.qos}, "
          f"latency {component.latency} cycles) and {out / 'topic.json'} "
          f"in {time.monotonic() - start:.1f} s")
    return 0


# export av_chain --------------------------------------------------------------------------

def _add_export_av_chain(sub):
    p = sub.add_parser(
        "av_chain", help="the lane-following chain joined by hardware topics (fpgaDDS)",
        description="Export the lane-following chain of examples/av_chain as one Verilog "
                    "module `av_chain`: seven kernels joined by hardware topics, the camera "
                    "stream in, the drive command out, taps of topics A-F (docs/av_chain.md), "
                    "plus a JSON manifest.")
    p.add_argument("--scale", type=float, default=1.0,
                   help="image scale in (0, 1]: 1 is the 640x480 camera and the 1000x600 "
                        "bird's-eye view (default 1)")
    p.add_argument("--pixels-per-beat", type=int, default=4, choices=(1, 2, 4, 8),
                   help="pixels per stream beat (default 4)")
    p.add_argument("-o", "--output", required=True, type=Path,
                   help="output folder (created); writes av_chain.v and av_chain.json")
    p.set_defaults(func=_run_export_av_chain, options={}, parser=p)


def _run_export_av_chain(args):
    from gen.av_chain import scaled_params
    from gen.export.verilog import export_verilog, write_if_changed, write_manifest
    from gen.tops import build_top

    if not 0 < args.scale <= 1:
        args.parser.error(f"--scale must be in (0, 1], not {args.scale!r}")
    params = scaled_params(args.scale, args.pixels_per_beat)
    start = time.monotonic()
    component = build_top("av_chain", **params)
    text, top = export_verilog(component, "av_chain")
    out = args.output
    try:
        write_if_changed(out / "av_chain.v", text)
        write_manifest(out / "av_chain.json", module="av_chain", component=component, top=top,
                       extra={"scale": args.scale, "pixels_per_beat": args.pixels_per_beat,
                              "camera": list(component.config.camera),
                              "bev": list(component.config.bev)})
    except OSError as exc:
        return _cannot_write("export av_chain", out, exc)
    c = component.config
    print(f"wrote {out / 'av_chain.v'} (module av_chain, {len(top.ports) + 2} ports; camera "
          f"{c.camera[0]}x{c.camera[1]}, bird's-eye view {c.bev[0]}x{c.bev[1]}, "
          f"{c.pixels_per_beat} px/beat) and {out / 'av_chain.json'} in "
          f"{time.monotonic() - start:.1f} s")
    return 0


# msg -------------------------------------------------------------------------------------

def _add_msg(commands):
    msg = commands.add_parser("msg", help="ROS message definitions and their C layouts",
                              description="Inspect message types: ROS 2 standard interfaces "
                                          "(rosbags ros2_humble store) and the .msg/.srv/.action "
                                          "files under --msg-dir.")
    sub = msg.add_subparsers(dest="msg_command", metavar="ACTION", required=True)
    for name, helptext, func in (
            ("show", "print a type's fields and constants", _run_msg_show),
            ("layout", "print the rosidl C layout (offsets for OFFSETOF)", _run_msg_layout),
            ("export-c", "write a C header with rosidl structs and offset constants",
             _run_msg_export_c),
            ("plan", "print the stream plan: what a hardware (de)serializer moves, in order",
             _run_msg_plan)):
        p = sub.add_parser(name, help=helptext, description=helptext)
        p.add_argument("type", help="message type, e.g. sensor_msgs/Image or "
                                    "sorter_msgs/srv/Sort_Request")
        p.add_argument("--msg-dir", action="append", type=Path, default=[],
                       help="folder with project .msg/.srv/.action files (repeatable)")
        if name == "layout":
            p.add_argument("--arch", default="arm64", choices=["arm32", "arm64", "x86_64"],
                           help="ABI: arm32 (ILP32, Zynq-7000) or arm64/x86_64 (LP64); "
                                "default arm64")
        if name == "plan":
            p.add_argument("--framing", default="cdr", choices=["cdr", "ros1", "reconros"],
                           help="cdr (ROS 2 XCDR1, default), ros1 (TCPROS message; ROS 1 types"
                                ", Header with seq) or reconros (ReconROS hardware topics)")
        if name == "export-c":
            p.add_argument("-o", "--output", type=Path, help="header file (default: stdout)")
        p.set_defaults(func=func, options={}, parser=p)


def _definition(args, store="ros2_humble"):
    """The message library of ``--msg-dir`` and the definition of ``args.type`` in it."""
    from gen.msg import MessageLibrary
    for folder in args.msg_dir:
        if not folder.is_dir():
            args.parser.error(f"--msg-dir {folder}: "
                              f"{'a file, not a folder' if folder.exists() else 'no such folder'}")
    library = MessageLibrary(args.msg_dir, store=store)
    if args.type not in library:
        args.parser.error(f"unknown message type {args.type!r} (standard interfaces and "
                          f"--msg-dir {', '.join(map(str, args.msg_dir)) or '(none)'})")
    return library, library[args.type]


def _run_msg_show(args):
    library, definition = _definition(args)
    print(f"{definition.name}  ({definition.source})")
    for const in definition.constants:
        print(f"  {const.type} {const.name}={const.value!r}")
    for field in definition.fields:
        default = f" {field.default!r}" if field.default is not None else ""
        print(f"  {field.type} {field.name}{default}")
    return 0


def _run_msg_layout(args):
    from gen.msg.layout import CLayout
    library, definition = _definition(args)
    layout = CLayout(library, args.arch)
    struct = layout.struct(definition.name)
    print(f"{definition.name} on {args.arch}: sizeof {struct.size}, align {struct.align}")
    print(f"  {'offset':>6}  {'size':>4}  {'C type':<28} field")
    for path, offset, size, ctype in layout.flat(definition.name):
        print(f"  {offset:>6}  {size:>4}  {ctype:<28} {path}")
    return 0


def _run_msg_export_c(args):
    from gen.export.verilog import write_atomically
    from gen.msg.cheader import c_header
    library, definition = _definition(args)
    text = c_header(library, definition.name)
    if args.output is None:
        sys.stdout.write(text)
        return 0
    try:
        write_atomically(args.output, text)
    except OSError as exc:
        return _cannot_write("msg export-c", args.output, exc)
    print(f"wrote {args.output} (rosidl structs of {definition.name} and its members, offsets "
          "for arm32, arm64, x86_64)")
    return 0


def _run_msg_plan(args):
    from gen.msg.plan import stream_plan
    from gen.msg.ros1 import md5sum, message_definition, ros1_name
    store = "ros1_noetic" if args.framing == "ros1" else "ros2_humble"
    library, definition = _definition(args, store)
    plan = stream_plan(library, definition.name, args.framing)
    print(plan.describe())
    if args.framing == "ros1":
        print(f"TCPROS type {ros1_name(definition.name)}, md5sum "
              f"{md5sum(library, definition.name)}; message_definition:")
        print("  " + message_definition(library, definition.name).replace("\n", "\n  "))
    return 0


# projects ----------------------------------------------------------------------------------

def _project(args):
    from gen.config import apply_parameters, load_project
    project = load_project(args.build_cfg)
    try:
        return apply_parameters(project, args.param)
    except ValueError as exc:
        args.parser.error(str(exc))


def _add_project_commands(commands):
    def add(name, helptext, func, description=None):
        p = commands.add_parser(name, help=helptext, description=description or helptext)
        p.add_argument("build_cfg", type=Path, help="the ReconROS project file (build.cfg)")
        p.add_argument("--param", action="append", default=[], metavar="THREAD.NAME=VALUE",
                       help="set a thread parameter over the build.cfg's Parameters "
                            "(repeatable), e.g. Sobel.mode=reconros; *.NAME=VALUE sets "
                            "it for every thread")
        p.set_defaults(func=func, options={}, parser=p)
        return p

    add("info", "print a project's clocks, slots, resources with handles, threads and topics",
        _run_info)
    p = add("export-hw", "write the project's hardware: Verilog, Vivado TCL, FuseSoC cores, "
                         "manifest", _run_export_hw,
            "Write the system top and every Amaranth thread as Verilog (hdl/), FuseSoC cores "
            "(hdl/*.core), Vivado IP packaging (ip/), the block design (bd/design_1.tcl), "
            "build.tcl and manifest.json (which lists every file written, relative to the "
            "folder). Files are written whole (a temporary file and a rename); re-exporting "
            "into an earlier export's folder removes what the new export no longer writes.")
    p.add_argument("-o", "--output", type=Path, required=True, help="output folder (created)")
    p.add_argument("--force", action="store_true",
                   help="write into a non-empty folder that is not an earlier export")
    p = add("export-msg", "write C offset headers for the project's messages",
            _run_export_msg,
            "Write one C header per message type the project uses (rosidl structs and "
            "OFFSETOF constants for arm32, arm64 and x86_64).")
    p.add_argument("-o", "--output", type=Path, required=True, help="output folder (created)")
    p = add("sim", "co-simulate the system with the ReconOS software model",
            _run_sim,
            "Export and simulate the system top; the ReconOS runtime model runs the "
            "delegate threads, the project's sim.py the software nodes. Prints the nodes' "
            "results (also in <output>/sim_results.json).")
    p.add_argument("--sim", default="verilator", choices=["icarus", "verilator"],
                   help="simulator (default verilator)")
    p.add_argument("--waves", action="store_true",
                   help="record every signal of the system as an FST waveform into the output "
                        "folder (rosgate_system.fst)")
    p.add_argument("--arg", action="append", default=[], metavar="KEY=VALUE",
                   help="passed to the software nodes as ctx.args (repeatable)")
    p.add_argument("--help-args", action="store_true",
                   help="list the --arg keys the project's sim.py takes, and exit")
    p.add_argument("--limit-ms", type=_positive_ms, default=1000.0,
                   help="simulated-time limit in ms (default 1000)")
    p.add_argument("--stall-ms", type=_positive_ms, default=10.0,
                   help="end the run when nothing happens (no OS call, memory access or "
                        "message) for this long in simulated time (default 10 ms)")
    p.add_argument(MEMORY_OPTION, type=_memory_mb, default=DEFAULT_MEMORY_MB,
                   help="physical memory behind the system's AXI4 port, in MiB (default "
                        f"{DEFAULT_MEMORY_MB})")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="folder for the nodes' files (default build/<name>/sim)")
    p.add_argument("--ros2", action="store_true",
                   help="join a ROS 2 (Cyclone DDS) domain: the build.cfg's topics and "
                        "services appear on it; runs until SIGINT/SIGTERM (docs/ros2.md)")
    p.add_argument("--domain", type=int, default=None,
                   help="DDS domain id with --ros2 (default: ROS_DOMAIN_ID, else 0)")
    p.add_argument("--service-queue", type=_positive_int, default=None, metavar="N",
                   help="with --ros2, calls of one hardware service the bridge holds while the "
                        "hardware serves earlier ones; a call beyond them is refused with the "
                        f"empty response, counted and logged (default {SERVICE_QUEUE})")
    p.add_argument("--clock", choices=("zero", "wall", "none"), default=None,
                   help="with --ros2, /clock (rosgraph_msgs/msg/Clock, for nodes with "
                        "use_sim_time) and the stamps of goals and recordings: simulated time "
                        "from zero (default), from the wall time at the start, or no /clock")
    p.add_argument("--goal-policy", choices=GOAL_POLICIES, default=None,
                   help="with --ros2, an action goal that arrives while the hardware serves "
                        "others: accepted at once and queued (default), or refused at once")
    p.add_argument("--with-nodes", action="store_true",
                   help="with --ros2, also run sim.py's nodes (by default the ROS 2 graph "
                        "stands in for them)")
    p.add_argument("--record", type=Path, default=None, metavar="DIR",
                   help="write every message on the project's topics to a rosbag2 (MCAP) in "
                        "the new folder DIR, stamped with simulated time")
    p.add_argument("--trace", type=Path, default=None, metavar="FILE",
                   help="write one readable line per message (time, topic, fields) to FILE")
    p.add_argument("--play", type=Path, default=None, metavar="BAG",
                   help="play a rosbag2 (MCAP or sqlite3: a bag folder or a .mcap/.db3 file) "
                        "into the system's topics; without --ros2 the run ends when the bag "
                        "is played and the system is idle (docs/simulation.md)")
    p.add_argument("--play-topic", action="append", default=[], metavar="TOPIC",
                   help="with --play, play this bag topic (repeatable; default: every bag "
                        "topic that a thread of the system subscribes)")
    p.add_argument("--remap", action="append", default=[], metavar="FROM:=TO",
                   help="with --play, play bag topic FROM into the system's topic TO "
                        "(repeatable)")
    p.add_argument("--play-pace", choices=PLAY_PACES, default=None,
                   help="with --play: each message at its time in the bag, mapped to "
                        "simulated time from the start (bag, the default), or each as soon "
                        "as every subscriber took the one before (fast)")
    p.add_argument("--play-delay", type=_seconds, default=None, metavar="S",
                   help="with --play, wait S seconds of wall time before the first message "
                        "(with --ros2: time for DDS peers to discover the bridge)")
    p.add_argument("--play-rate", type=_positive_rate, default=None, metavar="R",
                   help="with --play and pace bag, play R times as fast as recorded "
                        "(default 1)")
    p = add("report", "resources per core (yosys synth_xilinx) and the last simulation's "
                      "numbers", _run_report)
    p.add_argument("--sim-results", type=Path, default=None,
                   help="sim_results.json to include (default build/<name>/sim/...)")
    p.add_argument("--timing", action="store_true",
                   help="also place and route each core out of context on a Lattice "
                        "LFE5UM5G-85F-8 (yosys synth_ecp5, nextpnr-ecp5) at the system clock "
                        "over 3 seeds: worst Fmax, LUT4/FF/DP16KD/MULT18, critical path")


def _run_info(args):
    from gen.system import thread_sources
    p = _project(args)
    print(f"project {p.name} ({p.path}): {p.board} {p.part}, {p.target_os} ({p.arch}), "
          f"reference design {p.reference_design}")
    print("clocks:")
    for c in p.clocks:
        sysmark = "  (system)" if c is p.system_clock else ""
        print(f"  {c.id} {c.name}: {c.freq / 1e6:g} MHz, {c.source}{sysmark}")
    print("slots:")
    for s in sorted(p.slots, key=lambda s: s.id):
        print(f"  {s.id} {s.name}: clock {s.clock.name}, thread "
              f"{s.thread.name if s.thread else '(none)'}")
    sources = thread_sources(p)
    print("threads:")
    for t in p.threads:
        print(f"  {t.id} {t.name} -> slots {', '.join(s.name for s in t.slots)}; "
              f"{sources[t.name]}")
        for h, r in enumerate(t.resources):
            extra = f" {r.msgtype}" if r.msgtype else ""
            print(f"      handle {h:2d} = {r.c_name:<34} {r.type:<22} (global {r.id}){extra} "
                  f"[{', '.join(r.args)}]")
        for e in t.endpoints:
            fifo = f", FIFO {e.depth}" if e.depth else ""
            print(f"      hw {e.direction} {e.topic} (port {e.port}{fifo})")
    print("hardware topics:" if p.topics else "hardware topics: none")
    for name, t in p.topics.items():
        print(f"  {name}: {t.msgtype}, {t.topology}, publishers "
              f"{', '.join(f'{e.thread.name}.{e.port}' for e in t.pubs)}; subscribers "
              f"{', '.join(f'{e.thread.name}.{e.port}' for e in t.subs)}")
    for w in p.warnings:
        print(f"warning: {w}")
    return 0


def _run_export_hw(args):
    from gen.export.hw import ExportFolderError, export_hw
    p = _project(args)
    start = time.monotonic()
    try:
        manifest = export_hw(p, args.output, log=lambda s: print(f"-- {s}", flush=True),
                             force=args.force)
    except ExportFolderError as exc:
        print(f"{PROG} export-hw: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        return _cannot_write("export-hw", args.output, exc)
    print(f"wrote {args.output}: {len(manifest['cores'])} cores "
          f"({', '.join(manifest['cores'])}), build.tcl, bd/design_1.tcl, manifest.json in "
          f"{time.monotonic() - start:.1f} s")
    return 0


def _run_export_msg(args):
    from gen.config import project_library
    from gen.export.verilog import write_atomically
    from gen.msg.cheader import c_header
    p = _project(args)
    library = project_library(p)
    types = sorted({r.msgtype for r in p.resources if r.msgtype})
    try:
        args.output.mkdir(parents=True, exist_ok=True)
        for t in types:
            name = t.replace("/", "__").lower() + ".h"
            write_atomically(args.output / name, c_header(library, t))
            print(f"wrote {args.output / name}")
    except OSError as exc:
        return _cannot_write("export-msg", args.output, exc)
    print(f"wrote {len(types)} C headers ({', '.join(types)}) to {args.output}")
    return 0


def _number_option(kind, expected, ok):
    """An argparse ``type``: the text read as ``kind`` and accepted by ``ok``, else an error
    naming the text and what was ``expected``."""
    def read(text):
        try:
            value = kind(text)
        except ValueError:
            value = None
        if value is None or not ok(value):
            raise argparse.ArgumentTypeError(f"{text!r}: expected {expected}")
        return value
    return read


#: ``--memory-mb``: the r32 bus addresses 4 GiB
_memory_mb = _number_option(int, "a whole number of MiB from 1 to 4095",
                            lambda v: 1 <= v <= 4095)
_positive_int = _number_option(int, "a whole number above 0", lambda v: v >= 1)
_positive_rate = _number_option(float, "a number above 0", lambda v: 0 < v < float("inf"))
_seconds = _number_option(float, "seconds, 0 or more", lambda v: 0 <= v < float("inf"))
#: ``--limit-ms``, ``--stall-ms`` (NaN and infinity refused)
_positive_ms = _number_option(float, "a number of milliseconds above 0",
                              lambda v: 0 < v < float("inf"))


def _key_values(items, option):
    out = {}
    for item in items:
        if "=" not in item:
            raise ParameterError(option, item, "KEY=VALUE")
        k, v = item.split("=", 1)
        out[k] = v
    return out


def _default_out(p, leaf):
    return Path("build") / p.dir.resolve().name / leaf


def _run_sim(args):
    from host.console import Console
    from host.project_sim import ProjectError, load_sim_module, run_project_sim
    from host.simulator import SimulationFailed
    console = Console(f"{PROG} sim")
    p = _project(args)
    if args.help_args:
        from host.sim_args import describe_args
        try:
            module = load_sim_module(p)
        except ProjectError as exc:
            console.error(exc)
            return 2
        for line in describe_args(module, p.name):
            print(line)
        return 0
    out = args.output or _default_out(p, "sim")
    started = time.time()
    ros2 = None
    if args.ros2:
        from host.ros2.bridge import DOMAIN_IDS, default_domain
        domain = default_domain() if args.domain is None else args.domain
        if domain not in DOMAIN_IDS:
            console.error(f"--domain {domain}: expected a DDS domain id 0..{DOMAIN_IDS[-1]}")
            return 2
        ros2 = {"domain": domain, "nodes": args.with_nodes,
                "service_queue": args.service_queue or SERVICE_QUEUE,
                "clock": args.clock or "zero", "goal_policy": args.goal_policy or "queue"}
    elif args.domain is not None or args.with_nodes or args.service_queue is not None or \
            args.clock is not None or args.goal_policy is not None:
        console.error("--domain, --with-nodes, --service-queue, --clock and --goal-policy "
                      "need --ros2")
        return 2
    play = None
    if args.play is not None:
        play = {"path": str(args.play.resolve()), "topics": args.play_topic,
                "remaps": args.remap, "pace": args.play_pace or "bag",
                "rate": args.play_rate or 1.0, "delay": args.play_delay or 0.0}
        if play["pace"] == "fast" and args.play_rate is not None:
            console.error("--play-rate applies to --play-pace bag; fast plays each message "
                          "as soon as the one before was taken")
            return 2
    elif args.play_topic or args.remap or args.play_pace or args.play_rate is not None or \
            args.play_delay is not None:
        console.error("--play-topic, --remap, --play-pace, --play-rate and --play-delay need "
                      "--play")
        return 2
    try:
        with console.step(f"exporting and building {p.name} ({len(p.threads)} threads) for "
                          f"{args.sim}, then simulating"
                          + (f" on DDS domain {ros2['domain']} until SIGINT/SIGTERM"
                             if ros2 else "")):
            results = run_project_sim(
                p.path, args.sim, out=out, args=_key_values(args.arg, "--arg"),
                thread_params=args.param, limit_ms=args.limit_ms, stall_ms=args.stall_ms,
                memory_mb=args.memory_mb, waves=args.waves, progress=console.progress, ros2=ros2,
                record=args.record, trace=args.trace, play=play,
                status=_SimStatus(console),
                log=lambda cycle, text: console.print(f"   [{cycle:>10} cycles] {text}"))
    except ProjectError as exc:
        console.error(exc)
        _failed_waves(console, args, out)
        return 2
    except SimulationFailed as exc:
        console.error(f"simulation failed: {exc}")
        _failed_waves(console, args, out)
        return 1
    module = load_sim_module(p)
    if "play" in results:
        _print_play(console, results["play"])
    if ros2 is not None:
        _print_bridge(console, results["ros2"])
    elif play is not None and not hasattr(module, "PLAY_NODES"):
        pass                    # sim.py's nodes did not run: its summary has nothing to say
    elif module is not None and hasattr(module, "summary"):
        for line in module.summary(results, p.clock_mhz):
            console.print(line)
    else:
        import json
        console.print(json.dumps(results, indent=2))
    if args.waves:
        from host.project_sim import WAVES
        console.print(f"waveform (every signal of the system, FST): {Path(out) / WAVES}; open "
                      f"it with gtkwave or surfer")
    for path, counts in results.get("recorded", {}).items():
        console.print(f"recorded {sum(counts.values())} messages on {len(counts)} topics to "
                      f"{path}")
    written = sorted(f.name for f in Path(out).iterdir()
                     if f.is_file() and f.stat().st_mtime >= started)
    console.done(f"{len(written)} files to {out}/ ({', '.join(written[:6])}"
                 f"{', ...' if len(written) > 6 else ''})")
    return 0


def _failed_waves(console, args, out):
    from host.project_sim import WAVES
    if args.waves and (Path(out) / WAVES).is_file():
        console.error(f"the waveform up to the failure: {Path(out) / WAVES}")


class _SimStatus:
    """The running simulation's status: on a terminal the step's status line, off it one
    line every :attr:`LOG_SECONDS` (a log shows a long run is alive and how far it is)."""

    LOG_SECONDS = 10.0

    def __init__(self, console):
        self.console = console
        self.printed = None

    @staticmethod
    def describe(s):
        parts = [f"{s['cycle']:,} cycles ({s['ms']:g} ms simulated)"]
        if "done" in s:
            parts.append(f"{s['done']} of {s['total']} {s['unit']}")
            if s["done"] > 0 and s["total"] > s["done"]:
                left = s["seconds"] * (s["total"] - s["done"]) / s["done"]
                parts.append(f"about {_duration(left)} left")
        parts.append(f"{s['messages']:,} messages")
        parts.append(f"memory {s['memory_in_use'] / 2**20:.1f} of "
                     f"{s['memory_size'] / 2**20:.0f} MiB in use")
        parts.append(f"{_duration(s['seconds'])} running")
        return ", ".join(parts)

    def __call__(self, status):
        text = self.describe(status)
        if self.console.out.is_terminal:
            self.console.progress("simulation", text)
        elif status["seconds"] >= self.LOG_SECONDS and (
                self.printed is None or time.monotonic() - self.printed >= self.LOG_SECONDS):
            self.printed = time.monotonic()
            self.console.print(f"   [status] {text}")


def _duration(seconds):
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds} s"
    if seconds < 3600:
        return f"{seconds // 60} min {seconds % 60:02d} s"
    return f"{seconds // 3600} h {seconds // 60 % 60:02d} min"


def _print_bridge(console, summary):
    console.print(f"DDS domain {summary['domain']}: per interface, samples received from DDS "
                  f"/ delivered / rejected, and written to DDS")
    for name, c in sorted(summary["counts"].items()):
        console.print(f"  {name:<32} {c['received']:>6} {c['delivered']:>6} {c['rejected']:>6} "
                      f"{c['sent']:>6}")


def _print_play(console, play):
    played = sum(play["played"].values())
    pace = f"bag time x{play['rate']:g}" if play["pace"] == "bag" else "as fast as taken"
    into = ", ".join(f"{source} -> {target} {play['played'][target]}"
                     for source, target in sorted(play["mapping"].items()))
    console.print(f"played {played} of {play['messages']} messages from {play['bag']} "
                  f"({pace}): {into}" + ("" if play["finished"] else "; the run ended first"))
    for skip in play["skipped"][:5]:
        console.print(f"  skipped message {skip['index']} of {skip['topic']}: {skip['reason']}")
    if len(play["skipped"]) > 5:
        console.print(f"  ... {len(play['skipped'])} skipped in all (sim_results.json)")
    for topic, why in sorted(play["ignored"].items()):
        console.print(f"  not played: {topic} ({why})")
    answered = ", ".join(f"{t} {n}" for t, n in play["published_by_system"].items())
    console.print(f"the system published meanwhile: {answered or 'nothing'}")


def _run_report(args):
    import json

    from gen.export.resources import (FAMILY_NAMES, estimate_resources, xilinx_family,
                                      yosys_command)
    from gen.export.verilog import export_verilog, write_if_changed
    from gen.system import build_system, thread_code
    p = _project(args)
    try:
        family = xilinx_family(p.part)
    except ValueError as exc:
        raise ConfigError(p.part_at, str(exc)) from None
    system = build_system(p)
    rows = [("rosgate_system", "system", system)]
    seen = set()
    for s, c in zip(sorted(p.slots, key=lambda s: s.id), system.threads):
        if c is not None and s.thread.core_name not in seen:
            seen.add(s.thread.core_name)
            rows.append((s.thread.core_name, f"thread {s.thread.name}", c))
    folder = _default_out(p, "report")
    command = yosys_command(family)
    print(f"{p.name}: resources per core for {p.part} ({FAMILY_NAMES[family]}, from the "
          f"build.cfg's TargetPart) from yosys `{command}` (estimates)", flush=True)
    print("| core | what | LUT | FF | LUTRAM | BRAM36 | BRAM18 | URAM | DSP |\n"
          "|---|---|---|---|---|---|---|---|---|")
    vfiles = []
    for name, what, component in rows:
        with thread_code(p):
            text, _ = export_verilog(component, name)
        vfile = folder / f"{name}.v"
        write_if_changed(vfile, text)
        vfiles.append(vfile)
        with _PassProgress(f"yosys synth_xilinx ({family}) on {name}") as progress:
            r = estimate_resources(vfile, name, progress=progress, family=family)
        print(f"| {name} | {what} | {r['LUT']} | {r['FF']} | {r['LUTRAM']} | {r['BRAM36']} | "
              f"{r['BRAM18']} | {r.get('URAM', 0)} | {r['DSP']} |", flush=True)
    if args.timing:
        _report_timing(p, rows, vfiles, folder)
    path = args.sim_results or _default_out(p, "sim") / "sim_results.json"
    if path.is_file():
        print(f"last simulation ({path}):")
        print(json.dumps(json.loads(path.read_text()), indent=2))
    else:
        print(f"no simulation results at {path} (run `rosgate sim {args.build_cfg}`)")
    print(f"wrote the Verilog of {len(rows)} cores to {folder} (what yosys read)")
    return 0


class _PassProgress:
    """Progress of a long tool run on standard error (the report's table stays on standard
    output): on a terminal one line, rewritten each second, with the tool's current pass and
    the time; off it one such line every :attr:`LOG_SECONDS`."""

    LOG_SECONDS = 30.0

    def __init__(self, what):
        self.what = what
        self.tty = sys.stderr.isatty()
        self.step = "starting"
        self.stop = threading.Event()

    def __enter__(self):
        self.start = time.monotonic()
        self.ticker = threading.Thread(target=self._tick, daemon=True)
        self.ticker.start()
        return self

    def __call__(self, step):
        self.step = step

    def _tick(self):
        while not self.stop.wait(1.0 if self.tty else self.LOG_SECONDS):
            line = f"  {self.what}: {self.step} ({time.monotonic() - self.start:.0f} s)"
            if self.tty:
                sys.stderr.write("\r\033[K" + line[:150])
                sys.stderr.flush()
            else:
                print(line, file=sys.stderr, flush=True)

    def __exit__(self, *exc):
        self.stop.set()
        self.ticker.join()
        if self.tty:
            sys.stderr.write("\r\033[K")
            sys.stderr.flush()


def _report_timing(project, rows, vfiles, folder):
    import json

    from host.timing import DEVICE, MARGIN, SEEDS, TimingError, time_verilog
    mhz = project.clock_mhz
    print(f"timing: {DEVICE}, out of context at {mhz:g} MHz, seeds "
          f"{', '.join(map(str, SEEDS))} (PASS: worst Fmax >= {MARGIN} x {mhz:g} MHz)",
          flush=True)
    print("| core | Fmax MHz (worst seed) | LUT4+carry | FF | DP16KD | MULT18 | critical path | "
          "|\n|---|---|---|---|---|---|---|---|")
    results = {}
    for (name, _, _), vfile in zip(rows, vfiles):
        print(f"  placing and routing {name}...", flush=True)
        try:
            r = time_verilog(vfile, name, {"clk": mhz}, folder / "timing" / name)
        except TimingError as exc:
            print(f"| {name} | not placed: {str(exc).splitlines()[0]} | | | | | | FAIL |")
            results[name] = {"error": str(exc)}
            continue
        results[name] = r
        path = r["critical_path"] or {}
        print(f"| {name} | {r['fmax_mhz']} | {r['lut4']} | {r['ff']} | {r['bram']} | "
              f"{r['dsp']} | `{path.get('from', '-')}` -> `{path.get('to', '-')}` | "
              f"{'PASS' if r['pass'] else 'FAIL'} |", flush=True)
    out = folder / "timing.json"
    out.write_text(json.dumps({"device": DEVICE, "clock_mhz": mhz, "cores": results},
                              indent=1) + "\n")
    print(f"wrote the timing of {len(results)} cores to {out}")


# main --------------------------------------------------------------------------------------

def build_parser():
    parser = argparse.ArgumentParser(
        prog=PROG, description="rosgate: ROS 2 nodes and their communication in FPGA logic.")
    parser.add_argument("--version", action="version", version=f"{PROG} {_version()}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    export = commands.add_parser("export", help="export one core as Verilog + manifest",
                                 description="Export one core as Verilog and a JSON manifest.")
    cores = export.add_subparsers(dest="core", metavar="CORE", required=True)
    _add_export_topic(cores)
    add_export_finemb(cores)
    _add_export_av_chain(cores)
    _add_msg(commands)
    _add_project_commands(commands)
    add_tap_commands(commands)
    add_board_commands(commands)
    return parser


def main(argv=None):
    from host.console import discard_stdout, stop_on_signals
    parser = build_parser()
    args = parser.parse_args(argv)
    status = 1
    if argv is None:
        # the command line's own process: Ctrl-C and SIGTERM stop it cleanly at any moment
        stop_on_signals()
    try:
        status = _dispatch(args)
        return status
    except BrokenPipeError:
        # the reader went away (`rosgate ... | head`): end quietly, as a SIGPIPE would
        discard_stdout()
        status = 141
        return status
    finally:
        if status != 0:
            _quiet_unused_elaboratables()


def _quiet_unused_elaboratables():
    """A run that failed half-way leaves Amaranth components never elaborated, and Amaranth
    warns about each when it is collected: noise after the error that matters."""
    import warnings

    from amaranth.hdl import UnusedElaboratable
    warnings.filterwarnings("ignore", category=UnusedElaboratable)


def _dispatch(args):
    try:
        return args.func(args)
    except ParameterError as exc:
        option = args.options.get(exc.name, exc.name)
        args.parser.error(f"{option} must be {exc.allowed}, not {exc.value!r}")
    except (ConfigError, IoDescriptionError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except (MessageDefinitionError, KeyError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:
        # a tool failed (a simulator build, yosys): its own message says which and where
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        from host.console import Interrupted
        if isinstance(exc, Interrupted):
            print(f"{PROG} {args.command}: stopped by {exc.name}", file=sys.stderr)
            return 128 + exc.signum
        print(f"{PROG} {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
