"""The ``rosgate`` command line.

Exit codes: 0 success, 1 a runtime failure (I/O, tool), 2 bad usage or a bad parameter (the
message names the option and the allowed values).
"""

import argparse
import sys
import time
from pathlib import Path

from hdl.dds import MAX_ENDPOINTS, QOS_POLICIES
from gen.msg.model import MessageDefinitionError
from hdl.params import ParameterError

__all__ = ["main"]

PROG = "rosgate"


def _version():
    try:
        from importlib.metadata import version
        return version("rosgate")
    except Exception:  # not installed (running from a checkout)
        return "unknown"


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
        print(f"{PROG} export topic: error: cannot write {out}: {exc.strerror}",
              file=sys.stderr)
        return 1
    print(f"wrote {out / 'topic.v'} (module topic, {len(top.ports) + 2} ports, "
          f"{component.pubs}:{component.subs} at {args.width} bits, qos {args.qos}, "
          f"latency {component.latency} cycles) and {out / 'topic.json'} "
          f"in {time.monotonic() - start:.1f} s")
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
    from gen.msg.cheader import c_header
    library, definition = _definition(args)
    text = c_header(library, definition.name)
    if args.output is None:
        sys.stdout.write(text)
        return 0
    try:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.write_text(text)
    except OSError as exc:
        print(f"{PROG} msg export-c: error: cannot write {args.output}: {exc.strerror}",
              file=sys.stderr)
        return 1
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
    _add_msg(commands)
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ParameterError as exc:
        option = args.options.get(exc.name, exc.name)
        args.parser.error(f"{option} must be {exc.allowed}, not {exc.value!r}")
    except (MessageDefinitionError, KeyError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
