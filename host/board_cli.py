"""``rosgate board list`` and ``rosgate board build`` (docs/boards.md)."""

from pathlib import Path

__all__ = ["add_board_commands"]

PROG = "rosgate"


def add_board_commands(commands):
    from .board import DESIGNS
    p = commands.add_parser(
        "board", help="bitstreams of the network designs for ECP5 boards with RGMII PHYs",
        description="Build rosgate's network designs for ECP5 boards with Gigabit RGMII PHYs "
                    "through the open flow (Yosys, nextpnr-ecp5, ecppack from PyPI): pins from "
                    "amaranth-boards, RGMII through the FPGA's DDR registers, clocks from the "
                    "board's oscillator through a PLL (docs/boards.md).")
    sub = p.add_subparsers(dest="board_command", metavar="COMMAND", required=True)
    q = sub.add_parser("list", help="the supported boards: FPGA, PHYs, RGMII delays")
    q.set_defaults(func=_run_list, parser=q, options={})
    q = sub.add_parser(
        "build", help="build a design for a board: top, constraints, bitstream, timing",
        description="Write into the output folder the design as Yosys read it, the LPF "
                    "constraints, the bitstream (top.bit, top.svf), nextpnr's log and report "
                    "per seed and board.json (every clock's worst Fmax of the seeds against "
                    "its target times 1.05, the resources).")
    q.add_argument("design", choices=sorted(DESIGNS), help="; ".join(
        f"{name}: {what}" for name, what in DESIGNS.items()))
    q.add_argument("--board", required=True, help="a board of `rosgate board list`")
    q.add_argument("-o", "--output", type=Path, default=None,
                   help="output folder (default build/board/<design>-<board>)")
    q.add_argument("--ip", default="192.168.10.16",
                   help="the engine's IPv4 address (engine, tcpros; default 192.168.10.16)")
    q.add_argument("--mac", default=None,
                   help="the design's MAC address (default 02:00:c0:a8:0a:10; finemb: "
                        "02:00:00:00:46:01)")
    q.add_argument("--sessions", type=int, default=2, help="TCP echo sessions, 1..8 (engine)")
    q.add_argument("--io", type=Path, default=None,
                   help="the FinEmbP node's IO description (finemb; default "
                        "examples/finemb/pid_node.toml)")
    q.add_argument("--serial", type=int, default=1,
                   help="the FinEmbP node's serial number (finemb; default 1)")
    q.add_argument("--seeds", type=int, default=3,
                   help="place-and-route seeds (1, 2, ...; default 3): each clock's worst")
    q.set_defaults(func=_run_build, parser=q, options={})


def _run_list(args):
    from gen.boards import BOARDS, board_platform, rgmii_ports
    print(f"{'board':<24} {'FPGA':<20} {'RGMII ports and PHYs':<44} delays rx/tx")
    for b in BOARDS.values():
        ports = rgmii_ports(board_platform(b))
        phys = ", ".join(f"{k}: {phy}" for k, phy in zip(ports, b.phys))
        print(f"{b.name:<24} {b.fpga():<20} {phys:<44} "
              f"{b.rx_delay_ns:g}/{b.tx_delay_ns:g} ns")
    return 0


def _run_build(args):
    from gen.boards import BoardError
    from gen.finemb import IoDescriptionError
    from hdl.params import ParameterError

    from .board import build_board
    from .console import Console
    console = Console(f"{PROG} board build")
    if args.seeds < 1:
        console.error(f"--seeds {args.seeds}: expected 1 or more")
        return 2
    out = args.output or Path("build") / "board" / f"{args.design}-{args.board}"

    def progress(text):
        if console.out.is_terminal:
            console.progress("board", text)
        else:
            console.print(f"   {text}")
    try:
        with console.step(f"building {args.design} for {args.board}"):
            result = build_board(args.design, args.board, out, seeds=tuple(
                range(1, args.seeds + 1)), options={"ip": args.ip, "mac": args.mac,
                                                    "sessions": args.sessions,
                                                    "io": args.io, "serial": args.serial},
                progress=progress)
    except ParameterError as exc:
        option = {"sessions": "--sessions", "ip": "--ip", "mac": "--mac",
                  "serial": "--serial"}.get(exc.name, exc.name)
        console.error(f"{option} must be {exc.allowed}, not {exc.value!r}")
        return 2
    except (BoardError, IoDescriptionError) as exc:
        console.error(exc)
        return 2
    except RuntimeError as exc:
        console.error(exc)
        return 1
    for name, clock in sorted(result["clocks"].items()):
        seeds = " / ".join(f"{v:.1f}" for v in clock["seeds"].values())
        console.print(f"clock {name}: {clock['worst_mhz']:.1f} MHz worst of {seeds}, needs "
                      f"{clock['needed_mhz']:g} ({clock['target_mhz']:g} x 1.05): "
                      f"{'PASS' if clock['pass'] else 'FAIL'}")
    used = result["utilisation"]
    shown = ", ".join(f"{cell} {u}/{a}" for cell, (u, a) in used.items()
                      if u and cell in ("TRELLIS_COMB", "TRELLIS_FF", "DP16KD", "MULT18X18D",
                                        "TRELLIS_IO", "EHXPLLL", "DELAYG", "IOLOGIC"))
    console.print(f"resources: {shown}")
    console.done(f"bitstream {out / 'top.bit'} and {out / 'top.svf'} (seed "
                 f"{result['bitstream_seed']}); timing and resources in {out / 'board.json'}")
    return 0 if result["passed"] else 1
