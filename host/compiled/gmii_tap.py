"""A design's GMII port on a TAP device in compiled code: ``rosgate_gmii_tap``
(``gmii_tap.sv`` and ``gmii_tap.cpp``, DPI-C) moves the frames byte by byte inside the
simulator, where cocotbext-eth's ``GmiiSource`` and ``GmiiSink`` wake Python on every byte of
a frame. :func:`gmii_tap_harness` wraps an exported top with it for
:func:`host.simulator.run_top` (Verilator); :class:`CompiledTapPort` attaches the TAP device
and reads the counters from the cocotb side."""

import ctypes
from pathlib import Path

from hdl.net.crc import CRC32_POLY_REFLECTED
from hdl.net.frames import ETHERTYPE_IPV6, IFG, MIN_FRAME, PREAMBLE, PREAMBLE_BYTE, SFD

from ..simulator import gmii_clocks
from . import verilog_ports, wrapper_head

__all__ = ["GMII_TAP_SOURCES", "GMII_TAP_LINK_ARGS", "CompiledTapPort", "gmii_tap_harness",
           "gmii_tap_wrapper"]

HERE = Path(__file__).resolve().parent
GMII_TAP_SOURCES = (HERE / "gmii_tap.sv", HERE / "gmii_tap.cpp")
#: Verilator options of a build with the pump: its framing from hdl.net (defined once there),
#: and its functions visible to Python
GMII_TAP_LINK_ARGS = (
    "-CFLAGS", " ".join(f"-DROSGATE_GMII_{name}={value}" for name, value in (
        ("PREAMBLE", PREAMBLE), ("PREAMBLE_BYTE", PREAMBLE_BYTE), ("SFD", SFD), ("IFG", IFG),
        ("MIN_FRAME", MIN_FRAME), ("CRC32_POLY_REFLECTED", f"{CRC32_POLY_REFLECTED:#x}u"),
        ("ETHERTYPE_IPV6", ETHERTYPE_IPV6))),
    "-LDFLAGS", "-Wl,--export-dynamic-symbol=rosgate_gmii_tap_*")
#: the port's pins the wrapper takes (by suffix), each to the pump's port of that name
_PINS = ("rxd", "rx_dv", "rx_er", "txd", "tx_en", "tx_er")
#: the counters of ``rosgate_gmii_tap_stat``, in its order
STATS = ("to_design", "from_design", "dropped", "ipv6", "bad_fcs")


def gmii_tap_wrapper(text, top, port):
    """Verilog of module ``<top>_tap``: ``top`` (in Verilog ``text``) with its GMII port
    ``port`` on ``rosgate_gmii_tap``; every other port of ``top`` is a port of the wrapper
    with the same name. Return ``(name, verilog)``."""
    ports = verilog_ports(text, top)
    pins = {f"{port}_{pin}": pin for pin in _PINS}
    missing = [p for p in pins if p not in ports]
    if missing:
        raise ValueError(f"module {top!r} has no GMII port {port!r} (no {missing[0]})")
    _, (rx_clk, tx_clk) = gmii_clocks(ports, port)
    name = f"{top}_tap"
    lines = wrapper_head(name, ports, list(pins), f"{top} with its GMII port {port} on "
                                                  f"rosgate_gmii_tap")
    lines += [f"    {top} dut ("]
    lines.append(",\n".join(f"        .{p}({p})" for p in ports))
    lines += ["    );",
              f"    rosgate_gmii_tap #(.PORT(0)) tap (.rx_clk({rx_clk}), .tx_clk({tx_clk}),"]
    lines.append(",\n".join(f"        .{pump}({pin})" for pin, pump in pins.items()) + ");")
    lines.append("endmodule")
    return name, "\n".join(lines) + "\n"


def gmii_tap_harness(port):
    """A ``harness`` for :func:`host.simulator.run_top`: the exported top inside
    :func:`gmii_tap_wrapper`, only the wrapper's ports visible to the cocotb side."""
    from gen.export.verilog import write_if_changed

    def make(vfile, build_dir):
        vfile = Path(vfile)
        name, verilog = gmii_tap_wrapper(vfile.read_text(), vfile.stem, port)
        wrapper = Path(build_dir) / f"{name}.v"
        write_if_changed(wrapper, verilog)
        return (name, [wrapper, GMII_TAP_SOURCES[0]],
                [str(GMII_TAP_SOURCES[1]), *GMII_TAP_LINK_ARGS],
                list(verilog_ports(verilog, name)))
    return make


class CompiledTapPort:
    """The compiled GMII port of a :func:`gmii_tap_harness` top, attached to TAP file
    descriptor ``fd`` (non-blocking), polled every ``poll_cycles`` receive clock cycles while
    no frame is on its way to the design. ``stats`` has the keys of
    :class:`host.tap.TapBridge`'s (impairments are the Python bridge's only)."""

    def __init__(self, fd, poll_cycles=64):
        try:
            program = ctypes.CDLL(None)
            attach, self._stat = program.rosgate_gmii_tap_attach, program.rosgate_gmii_tap_stat
        except (OSError, AttributeError) as exc:
            raise RuntimeError("the simulator was not built with the compiled GMII port "
                               "(host.compiled.gmii_tap.gmii_tap_harness)") from exc
        attach.restype = ctypes.c_int
        attach.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int]
        self._stat.restype = ctypes.c_uint64
        self._stat.argtypes = [ctypes.c_int, ctypes.c_int]
        if attach(0, fd, poll_cycles) != 0:
            raise ValueError(f"poll_cycles {poll_cycles!r}: expected a positive count")

    @property
    def stats(self):
        return {**{name: int(self._stat(0, k)) for k, name in enumerate(STATS)},
                "duplicated": 0, "reordered": 0}
