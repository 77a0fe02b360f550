"""``rosgate tap``: a simulated design on a TAP device in a network namespace the command
creates and removes (docs/simulation.md "On a TAP device"), and ``rosgate export finemb``."""

import os
import shlex
import signal
import sys
import threading
import time
from pathlib import Path

from .console import Console
from .tap import KERNEL_IP, TAP_NAME

__all__ = ["add_tap_commands", "add_export_finemb"]

PROG = "rosgate"
#: node k of a line answers at this host number + k (host/finemb/master.py)
ENGINE_IP = "198.18.0.16"


def _stop_on_signals(event):
    """SIGINT and SIGTERM set ``event`` (the command then stops the simulation, removes the
    namespace and prints what ran)."""
    def handler(signum, frame):
        event.set()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, handler)


def _wait(event, duration_s, tick, every_s=1.0):
    """Call ``tick()`` every ``every_s`` until ``event`` or ``duration_s`` (0: no limit)."""
    end = time.monotonic() + duration_s if duration_s else None
    while not event.wait(every_s):
        if end is not None and time.monotonic() >= end:
            return
        tick()


def _sim_line(status):
    if not status:
        return "starting"
    ms = status["cycles"] * 8e-6
    return (f"{ms:.3f} ms simulated in {status['wall_s']:.0f} s, frames "
            f"{status['bridge']['to_design']} in, {status['bridge']['from_design']} out")


def _add_common(p):
    p.add_argument("--kernel-ip", default=KERNEL_IP,
                   help=f"the kernel's address on {TAP_NAME} (default {KERNEL_IP}/24)")
    p.add_argument("--duration", type=float, default=0.0,
                   help="stop after this many seconds (default: run until Ctrl-C)")
    p.add_argument("--build-dir", type=Path, default=None,
                   help="simulator build folder (default: the per-user cache)")


def _build_dir(args, name):
    from .toolchain import cache_dir
    return args.build_dir or cache_dir() / "tap" / name


def add_tap_commands(commands):
    tap = commands.add_parser(
        "tap", help="run a simulated design on a TAP device in a network namespace",
        description="Build a design for Verilator and run it with its Ethernet port on a TAP "
                    "device in a network namespace this command creates (needs root). "
                    "Anything run with the printed `ip netns exec` prefix (ping, tcpdump, "
                    "sitcpy, your own sockets) reaches the simulated hardware through the "
                    "Linux network stack. Ctrl-C stops it and removes the namespace.")
    designs = tap.add_subparsers(dest="design", metavar="DESIGN", required=True)
    p = designs.add_parser(
        "engine", help="the TCP/IP engine: RBCP registers and TCP echo sessions",
        description="The TCP/IP engine (hdl.net.echo.EchoEngine): ARP, ICMP echo, RBCP "
                    "(SiTCP's UDP register protocol) on a register RAM, and TCP sessions "
                    "that listen on the TCP port and send back what they receive.")
    p.add_argument("--ip", default=ENGINE_IP, help=f"the engine's address (default {ENGINE_IP})")
    p.add_argument("--sessions", type=int, default=2, help="TCP sessions, 1..8 (default 2)")
    p.add_argument("--registers", type=int, default=256,
                   help="bytes of RBCP register RAM, a power of two (default 256)")
    _add_common(p)
    p.set_defaults(func=_run_tap_engine, parser=p,
                   options={"sessions": "--sessions", "registers": "--registers",
                            "ip": "--ip"})
    p = designs.add_parser(
        "finemb", help="a line of FinEmbP PID nodes, with the Python master",
        description="A line of FinEmbP PID nodes (docs/finemb.md) on the TAP device, and the "
                    "FinEmbP master of host/finemb over UDP sockets in the namespace: it finds "
                    "and initialises the nodes and runs cycles against a plant model while "
                    "the nodes' states and the cycle rate are shown.")
    p.add_argument("--nodes", type=int, default=2, help="nodes in the line, 1..32 (default 2)")
    p.add_argument("--io", type=Path, default=None,
                   help="the nodes' IO description (default: the PID benchmark's)")
    p.add_argument("--cycles", type=int, default=0,
                   help="stop after this many cycles (default: run until Ctrl-C)")
    p.add_argument("--period-ms", type=float, default=0.0,
                   help="the shortest cycle period (default 0: as fast as the simulation)")
    p.add_argument("--no-master", action="store_true",
                   help="bring the line up and wait for your own master (FINROC's, or one "
                        "you wrote): prints the namespace, the kernel's address and the "
                        "nodes' MACs, then shows the nodes' states until Ctrl-C")
    _add_common(p)
    p.set_defaults(func=_run_tap_finemb, parser=p, options={"nodes": "--nodes"})
    from .board import DESIGNS
    p = designs.add_parser(
        "board", help="a board design's top as the bitstream has it, its PHY simulated",
        description="A board design of `rosgate board build` (docs/boards.md), the same top "
                    "with only the ECP5 primitives (PLL, DDR registers, delays, I/O buffers) "
                    "replaced by simulation models, its first RGMII port driven by an RGMII "
                    "PHY model bridged to the TAP device.")
    p.add_argument("board_design", metavar="design", choices=sorted(DESIGNS),
                   help="; ".join(f"{name}: {what}" for name, what in DESIGNS.items()))
    p.add_argument("--board", required=True, help="a board of `rosgate board list`")
    p.add_argument("--ip", default=ENGINE_IP,
                   help=f"the engine's address (engine, tcpros; default {ENGINE_IP})")
    p.add_argument("--boards", type=int, default=2,
                   help="finemb: boards in the line, 2..4 (default 2; the board needs two "
                        "RGMII ports), each node on its own board and oscillator")
    p.add_argument("--cycles", type=int, default=0,
                   help="finemb: stop after this many master cycles (default: until Ctrl-C)")
    p.add_argument("--period-ms", type=float, default=0.0,
                   help="finemb: the shortest cycle period (default 0)")
    _add_common(p)
    p.set_defaults(func=_run_tap_board, parser=p, options={"ip": "--ip"}, no_master=False)


def _run_tap_engine(args):
    from hdl.net.echo import EchoEngine
    from hdl.net.frames import DEFAULT_RBCP_PORT, DEFAULT_TCP_PORT

    from .tapsim import TapSimulation
    con = Console(f"{PROG} tap engine")
    engine = EchoEngine(ip=args.ip, sessions=args.sessions, registers=args.registers)
    stop = threading.Event()
    _stop_on_signals(stop)
    start = time.monotonic()
    with con.step(f"building the TCP/IP engine ({args.sessions} TCP sessions) for Verilator"):
        sim = TapSimulation(engine, "echo_engine", _build_dir(args, "engine"), port="gmii",
                            kernel_ip=args.kernel_ip, progress=con.progress).__enter__()
    ns = f"ip netns exec {sim.namespace}"
    lines = [f"the engine is up at {args.ip}; the kernel is {args.kernel_ip}/24 on {TAP_NAME} "
             f"in namespace {sim.namespace}",
             f"  ping       {ns} ping {args.ip}",
             f"  RBCP       {ns} {shlex.quote(sys.executable)} -c \"import sitcpy.rbcp as r; "
             f"print(r.Rbcp('{args.ip}', {DEFAULT_RBCP_PORT}).read(0, 16))\"  "
             f"({args.registers} registers at 0)",
             f"  TCP echo   {ns} nc {args.ip} {DEFAULT_TCP_PORT}",
             f"  capture    {ns} tcpdump -i {TAP_NAME} -w engine.pcap"]
    return _serve(con, args, sim, stop, start, lines, "tap engine")


def _serve(con, args, sim, stop, start, lines, command):
    """Print ``lines`` (how to reach the design), report the simulation every 10 s until
    Ctrl-C, ``--duration`` or its end, stop it and print what ran."""
    try:
        for line in lines + ["Ctrl-C stops the simulation and removes the namespace."]:
            con.print(line)
        last = [0.0]

        def tick():
            if not sim.alive():
                stop.set()
            elif time.monotonic() - last[0] >= 10:
                last[0] = time.monotonic()
                con.print(f"   [{_sim_line(sim.status)}]")
        _wait(stop, args.duration, tick)
        status = sim.status
    finally:
        sim.stop()
    con.print(f"{PROG} {command}: stopped after {_sim_line(status)}; namespace "
              f"{sim.namespace} removed ({time.monotonic() - start:.0f} s)")
    return 0


def _run_tap_board(args):
    from gen.boards import BoardError
    from hdl.net.frames import DEFAULT_RBCP_PORT, DEFAULT_TCP_PORT

    from .board_sim import TOP, board_line_sim_verilog, board_sim_verilog
    from .tapsim import TapSimulation
    con = Console(f"{PROG} tap board")
    design = args.board_design
    stop = threading.Event()
    _stop_on_signals(stop)
    start = time.monotonic()
    folder = _build_dir(args, f"board-{design}-{args.board}")
    top = TOP
    try:
        with con.step(f"elaborating {design} for {args.board} with the primitives' models"):
            if design == "finemb":
                verilog, pins = board_line_sim_verilog(args.board, folder, boards=args.boards)
                top = "board_line"
            else:
                verilog, pins = board_sim_verilog(design, args.board, folder, {"ip": args.ip})
    except (BoardError, ValueError) as exc:
        con.error(exc)
        return 2
    what = (f"a line of {args.boards} {args.board} boards of finemb" if design == "finemb"
            else f"the board top of {design}")
    with con.step(f"building {what} for Verilator"):
        sim = TapSimulation(None, top, folder, exported=verilog, module="host.tap_board_serve",
                            params={"pins": pins}, kernel_ip=args.kernel_ip,
                            progress=con.progress).__enter__()
    if design == "finemb":
        con.print(f"board k's port 1 is wired to board k+1's port 0; board 0's port 0 is on "
                  f"{TAP_NAME}; the oscillators are {', '.join(map(str, pins['ppm']))} ppm "
                  f"off 125 MHz")
        return _drive_line(con, args, sim, stop, start, args.boards, "tap board finemb")
    ns = f"ip netns exec {sim.namespace}"
    lines = [f"{design} on {args.board} (simulated) is up; the kernel is {args.kernel_ip}/24 "
             f"on {TAP_NAME} in namespace {sim.namespace}, on the board's RGMII port 0",
             f"  ping       {ns} ping {args.ip}",
             f"  RBCP       {ns} {shlex.quote(sys.executable)} -c \"import sitcpy.rbcp as r; "
             f"print(r.Rbcp('{args.ip}', {DEFAULT_RBCP_PORT}).read(0, 16))\""]
    if design == "engine":
        lines.append(f"  TCP echo   {ns} nc {args.ip} {DEFAULT_TCP_PORT}")
    lines.append(f"  capture    {ns} tcpdump -i {TAP_NAME} -w {design}.pcap")
    return _serve(con, args, sim, stop, start, lines, "tap board")


def _node_table(master, rate, terminal):
    """The nodes' states as a table (a terminal) or one line (a log)."""
    inputs = {k: " ".join(f"{name}={value}" for name, value in (n.inputs or {}).items())
              for k, n in master.nodes.items()}
    if not terminal:
        return f"   cycle {master.cycle_no} ({rate:.1f}/s): " + "; ".join(
            f"node {k} {n.state.name} {n.answered} answered {n.late} late {inputs[k]}"
            for k, n in sorted(master.nodes.items()))
    from rich.table import Table
    table = Table(title=f"FinEmbP cycle {master.cycle_no}: {rate:.1f} cycles/s")
    for col in ("node", "MAC", "IP", "state", "answered", "late", "REINIT seen", "reinits",
                "inputs"):
        table.add_column(col, no_wrap=True)
    for k, n in sorted(master.nodes.items()):
        table.add_row(str(k), n.mac_text, n.ip, n.state.name, str(n.answered), str(n.late),
                      str(n.reinit_answers), str(n.reinits), inputs[k])
    return table


def _run_tap_finemb(args):
    from gen.finemb import load_io_description
    from hdl.params import check_int

    from .finemb.run import line_simulation
    con = Console(f"{PROG} tap finemb")
    check_int("nodes", args.nodes, 1, 32)
    if args.no_master and (args.cycles or args.period_ms):
        args.parser.error("--cycles and --period-ms set rosgate's master; --no-master runs none")
    io_path = args.io or Path(__file__).resolve().parents[1] / "examples" / "finemb" / \
        "pid_node.toml"
    descriptor = load_io_description(io_path)
    stop = threading.Event()
    _stop_on_signals(stop)
    start = time.monotonic()
    with con.step(f"building a line of {args.nodes} FinEmbP nodes for Verilator"):
        sim = line_simulation(descriptor, args.nodes, _build_dir(args, f"finemb-{args.nodes}"),
                              kernel_ip=args.kernel_ip, progress=con.progress).__enter__()
    if args.no_master:
        return _serve_line(con, args, sim, stop, start)
    return _drive_line(con, args, sim, stop, start, args.nodes, "tap finemb")


def _drive_line(con, args, sim, stop, start, nodes, command):
    """rosgate's FinEmbP master against the simulated line ``sim`` of ``nodes`` nodes: find
    and initialise them, run ``args.cycles`` cycles (or until Ctrl-C) against a plant model,
    show the nodes' states, stop the simulation and print a summary line."""
    from .finemb import FinembMaster
    from .finemb.run import PlantModel
    plant = PlantModel()
    try:
        con.print(f"the line is up on {TAP_NAME} in namespace {sim.namespace}; the master runs "
                  f"at {args.kernel_ip} (capture: ip netns exec {sim.namespace} tcpdump -i "
                  f"{TAP_NAME}); Ctrl-C stops it")
        with FinembMaster(args.kernel_ip, interface=TAP_NAME, timeout_s=5.0) as master:
            with con.step("finding and initialising the nodes"):
                master.init(expected=nodes)
            for k, n in sorted(master.nodes.items()):
                con.print(f"  node {k}: {n.mac_text} at {n.ip}, serial {n.serial}, "
                          f"{len(n.descriptor.ports)} ports ({n.descriptor.name})")
            live = _live(con)
            last = 0.0
            while not stop.is_set() and (not args.cycles or master.cycles_run < args.cycles):
                t0 = time.monotonic()
                inputs = master.cycle(plant.outputs(master.cycle_no, sorted(master.nodes)),
                                      t0 + 5.0)
                plant.update(inputs)
                if time.monotonic() - last >= 1.0 or master.cycles_run == args.cycles:
                    last = time.monotonic()
                    live(_node_table(master, master.cycle_rate_hz(), con.out.is_terminal))
                if args.duration and time.monotonic() - start >= args.duration:
                    break
                stop.wait(max(0.0, t0 + args.period_ms / 1000 - time.monotonic()))
            states = ", ".join(f"{k} {n.state.name}" for k, n in sorted(master.nodes.items()))
            summary = (f"{master.cycles_run} cycles at {master.cycle_rate_hz():.1f} cycles/s, "
                       f"{sum(n.late for n in master.nodes.values())} late answers, nodes "
                       f"{states}")
            live(None)
    finally:
        sim.stop()
    con.print(f"{PROG} {command}: {summary}; namespace {sim.namespace} removed "
              f"({time.monotonic() - start:.0f} s)")
    return 0


def _serve_line(con, args, sim, stop, start):
    """``rosgate tap finemb --no-master``: the line waits for a master the user runs in the
    namespace; the nodes' states are shown as they change."""
    from hdl.finemb.line import line_mac
    from hdl.finemb.protocol import FINEMB_PORT, NodeState
    ns = f"ip netns exec {sim.namespace}"
    try:
        for line in (
                f"the line of {args.nodes} nodes is up on {TAP_NAME} in namespace "
                f"{sim.namespace}; the kernel is {args.kernel_ip}/24 there. Run your FinEmbP "
                f"master in the namespace (UDP port {FINEMB_PORT}, broadcasts and the SoC out "
                f"of {TAP_NAME}):",
                f"  master     {ns} <your master>",
                f"  capture    {ns} tcpdump -i {TAP_NAME} -w finemb.pcap",
                "nodes, from the TAP side along the line (none has an address yet):",
                *(f"  node {k}: MAC {line_mac(k)}, serial {k + 1}" for k in range(args.nodes)),
                "Ctrl-C stops the simulation and removes the namespace."):
            con.print(line)
        shown = None
        while not stop.wait(0.5):
            status = sim.status
            if status is not None:
                states = [NodeState(int(status["signals"][f"state{k}"])).name
                          for k in range(args.nodes)]
                if states != shown:
                    shown = states
                    con.print(f"   [{_sim_line(status)}] nodes: "
                              + ", ".join(f"{k} {s}" for k, s in enumerate(states)))
            if args.duration and time.monotonic() - start >= args.duration:
                break
        status = sim.status
    finally:
        sim.stop()
    con.print(f"{PROG} tap finemb: stopped after {_sim_line(status) if status else 'no status'}"
              f"; namespace {sim.namespace} removed ({time.monotonic() - start:.0f} s)")
    return 0


def _live(con):
    """``show(table)`` refreshes a live table on a terminal, prints it otherwise;
    ``show(None)`` ends it."""
    if not con.out.is_terminal:
        def show(line):
            if line is not None:
                con.print(line)
        return show
    from rich.live import Live
    live = Live(console=con.out, auto_refresh=False)
    live.start()

    def show(table):
        if table is None:
            live.stop()
        else:
            live.update(table, refresh=True)
    return show


# export finemb ---------------------------------------------------------------------------

def add_export_finemb(cores):
    p = cores.add_parser(
        "finemb", help="a FinEmbP node for an IO description",
        description="Export a FinEmbP node (docs/finemb.md) for the IO description file: "
                    "hdl/finemb_node.v, the manifest finemb_node.json (ports, page layout, "
                    "IO descriptor bytes, clocks), constraints/finemb_node_clocks.xdc (its two "
                    "clocks, asynchronous) and ip/package_finemb_node.tcl (Vivado IP). With "
                    "--app page the application's side of the page buffer is a port of the "
                    "core; with --app pid the PID benchmark application is inside.")
    p.add_argument("--io", type=Path, required=True, help="the IO description (TOML)")
    p.add_argument("--app", choices=("page", "pid"), default="page",
                   help="page: expose the page buffer (default); pid: the PID application")
    p.add_argument("--mac", default="02:00:00:00:46:01", help="the node's MAC address")
    p.add_argument("--serial", type=int, default=1, help="serial number in ID_RES")
    p.add_argument("--part", default="xc7z020clg400-1", help="FPGA part of the Vivado TCL")
    p.add_argument("-o", "--output", type=Path, required=True, help="output folder (created)")
    p.set_defaults(func=_run_export_finemb, parser=p,
                   options={"mac": "--mac", "serial": "--serial", "descriptor": "--io"})


def _run_export_finemb(args):
    from gen.export.interfaces import bus_interfaces
    from gen.export.verilog import export_verilog, write_if_changed, write_manifest
    from gen.export.vivado import clock_constraints, package_tcl
    from gen.finemb import load_io_description
    from hdl.finemb import NODE_CLOCKS_HZ, FinembNode, FinembPidNode

    start = time.monotonic()
    descriptor = load_io_description(args.io)
    cls = FinembPidNode if args.app == "pid" else FinembNode
    node = cls(descriptor, mac=args.mac, serial=args.serial)
    name = "finemb_node"
    text, top = export_verilog(node, name)
    description = (f"FinEmbP node '{descriptor.name}' ({len(descriptor.ports)} ports; "
                   f"{'PID application' if args.app == 'pid' else 'page buffer port'})")
    out = args.output
    try:
        write_if_changed(out / "hdl" / f"{name}.v", text)
        write_if_changed(out / "constraints" / f"{name}_clocks.xdc",
                         clock_constraints(NODE_CLOCKS_HZ))
        (out / "ip" / "busdefs").mkdir(parents=True, exist_ok=True)
        write_if_changed(out / "ip" / f"package_{name}.tcl",
                         package_tcl(name, args.part, bus_interfaces(node),
                                     description=description))
        ports = [{"port_id": p.port_id, "name": p.name, "direction": p.direction.name.lower(),
                  "type": p.type.name.lower(), "offset": p.offset, "size": p.size}
                 for p in descriptor.ports]
        write_manifest(out / f"{name}.json", module=name, component=node, top=top, extra={
            # relative to the manifest's folder, as every path of an export's manifest
            "io_description": os.path.relpath(args.io.resolve(), out.resolve()),
            "application": args.app, "mac": args.mac,
            "serial": args.serial, "page_out_bytes": descriptor.page_out_bytes,
            "page_in_bytes": descriptor.page_in_bytes, "io_ports": ports,
            "io_descriptor_hex": descriptor.encode().hex(),
            "clocks_mhz": {port: hz / 1e6 for port, hz in NODE_CLOCKS_HZ.items()}})
    except OSError as exc:
        print(f"{PROG} export finemb: error: cannot write {out}: {exc.strerror}")
        return 1
    print(f"wrote {out / 'hdl' / (name + '.v')} (module {name}, {len(top.ports) + 2} ports, "
          f"pages out {descriptor.page_out_bytes} B / in {descriptor.page_in_bytes} B), "
          f"{out / (name + '.json')}, {out / 'constraints' / (name + '_clocks.xdc')} and "
          f"{out / 'ip' / ('package_' + name + '.tcl')} in "
          f"{time.monotonic() - start:.1f} s")
    return 0
