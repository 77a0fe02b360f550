"""LiteEth's standalone UDP core as the timing flow's peer (docs/timing.md).

``python -m liteeth.gen`` (PyPI liteeth, the setup's ``bench`` extra) generates the core from a
YAML description: GMII PHY, Lattice, ``core: udp`` with one UDP streamer port, 8- or 32-bit
datapath. For placement out of context the PHY's I/O primitives become pass-through modules:
``BUFG`` (clock buffers), ``ODDRX1F`` (the forwarded transmit clock) and ``TRELLIS_IO`` (MDIO)
are pads, not protocol logic.
"""

import re
import subprocess
import sys
from pathlib import Path

__all__ = ["CONFIGS", "LiteEthError", "liteeth_verilog"]

#: ``{core: (datapath bits, sys clock MHz)}``: LiteEth closes 1 Gbit/s with the byte-wide GMII
#: side at 125 MHz and, on the 32-bit datapath, the protocol logic at 62.5 MHz
CONFIGS = {"liteeth_udp8": (8, 125.0), "liteeth_udp32": (32, 62.5)}
#: the GMII receive clock (the PHY's transmit clock is derived from it at 1 Gbit/s)
GMII_CLOCK = ("gmii_clocks_rx", 125.0)

_PASS_THROUGH = """
module rosgate_pt_bufg (input I, output O);
  assign O = I;
endmodule
module rosgate_pt_oddr (input D0, input D1, input SCLK, output Q);
  assign Q = D0;
endmodule
module rosgate_pt_io #(parameter DIR = "INPUT") (input B, input I, input T, output O);
  assign O = B;
endmodule
"""
_PRIMITIVES = {"BUFG": "rosgate_pt_bufg", "ODDRX1F": "rosgate_pt_oddr",
               "TRELLIS_IO": "rosgate_pt_io"}


class LiteEthError(RuntimeError):
    """LiteEth's generator is missing or failed."""


def _yaml(width, sys_mhz):
    return (f"phy: LiteEthPHYGMII\nvendor: lattice\ndevice: LFE5UM5G-85F-8BG381C\n"
            f"toolchain: trellis\nclk_freq: {sys_mhz * 1e6:.0f}\ncore: udp\n"
            f"data_width: {width}\nmac_address: 0x10e2d5000000\nip_address: 192.168.1.50\n"
            f"udp_ports:\n  udp0:\n    udp_port: 4660\n    ip_address: 192.168.1.100\n"
            f"    data_width: {width}\n    tx_fifo_depth: 64\n    rx_fifo_depth: 64\n")


def liteeth_verilog(core, folder):
    """Generate ``core`` (a key of :data:`CONFIGS`) into ``folder``; returns (Verilog text with
    the I/O primitives as pass-through modules, ``{clock net: MHz}``)."""
    if core not in CONFIGS:
        raise LiteEthError(f"unknown LiteEth configuration {core!r}; known: {sorted(CONFIGS)}")
    width, sys_mhz = CONFIGS[core]
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    config = folder / f"{core}.yml"
    config.write_text(_yaml(width, sys_mhz))
    log = folder / "liteeth_gen.log"
    with open(log, "w") as out:
        done = subprocess.run([sys.executable, "-m", "liteeth.gen", config.name, "--name", core,
                               "--output-dir", "liteeth_build"], cwd=folder, stdout=out,
                              stderr=subprocess.STDOUT, check=False)
    if done.returncode:
        tail = log.read_text()[-1200:]
        hint = " (pip install '.[bench]' installs it)" if "No module named" in tail else ""
        raise LiteEthError(f"LiteEth generator failed for {core}{hint}; log {log}:\n{tail}")
    text = (folder / "liteeth_build" / "gateware" / f"{core}.v").read_text()
    for primitive, module in _PRIMITIVES.items():
        text, count = re.subn(rf"^{primitive}(\s)", rf"{module}\1", text, flags=re.M)
        if not count:
            raise LiteEthError(f"{core}: LiteEth's Verilog has no {primitive} instance to "
                               f"pass through; its PHY changed")
    return text + _PASS_THROUGH, {"sys_clock": sys_mhz, GMII_CLOCK[0]: GMII_CLOCK[1]}
