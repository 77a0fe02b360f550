"""Bus interfaces of an exported top, found from its Amaranth signature.

One description serves the Vivado IP packaging script, the JSON manifest and the tests that
check both against the Verilog: an interface has a Vivado bus type, a mode and a map from
logical port names to the physical ports :func:`~gen.export.verilog.port_name` gives.
"""

from dataclasses import dataclass, field

from amaranth.hdl import Shape
from amaranth.lib import wiring

from hdl.bus import AXI4LiteSignature, AXI4Signature
from hdl.reconos.fifo import FifoReadSignature, FifoWriteSignature
from hdl.stream import AXIStreamSignature

from .verilog import port_name

__all__ = ["BusInterface", "bus_interfaces", "AXIMM", "AXIS", "INTERRUPT", "CLOCK", "RESET",
           "reconos_fifo_bus"]

AXIMM = ("xilinx.com:interface:aximm:1.0", "xilinx.com:interface:aximm_rtl:1.0")
AXIS = ("xilinx.com:interface:axis:1.0", "xilinx.com:interface:axis_rtl:1.0")
INTERRUPT = ("xilinx.com:signal:interrupt:1.0", "xilinx.com:signal:interrupt_rtl:1.0")
CLOCK = ("xilinx.com:signal:clock:1.0", "xilinx.com:signal:clock_rtl:1.0")
RESET = ("xilinx.com:signal:reset:1.0", "xilinx.com:signal:reset_rtl:1.0")


def reconos_fifo_bus(kind, width):
    """ReconOS' FIFO bus definition (docs/reconos.md): ``FIFO_M``/``FIFO64_M`` for the write
    side, ``FIFO_S``/``FIFO64_S`` for the read side; VLNV ``cs.upb.de:reconos:<name>:1.0``."""
    name = f"FIFO{'64' if width == 64 else ''}_{kind}"
    return name, (f"cs.upb.de:reconos:{name}:1.0", f"cs.upb.de:reconos:{name}_rtl:1.0")


@dataclass
class BusInterface:
    """``name`` (the port prefix), ``bus`` (bus type and abstraction VLNVs), ``mode``
    (``master``/``slave``), ``ports`` logical -> physical, ``parameters`` for Vivado."""
    name: str
    kind: str
    bus: tuple
    mode: str
    ports: dict
    parameters: dict = field(default_factory=dict)


def _flow(flow, flipped):
    if not flipped:
        return flow
    return wiring.In if flow == wiring.Out else wiring.Out


def _walk(signature, path, flipped, out):
    for name, member in signature.members.items():
        p = (*path, name)
        flow = _flow(member.flow, flipped)
        if not member.is_signature:
            prefix = port_name(p)
            if prefix.startswith("irq") and flow == wiring.Out:
                out.append(BusInterface(prefix, "interrupt", INTERRUPT, "master",
                                        {"INTERRUPT": prefix}, {"SENSITIVITY": "LEVEL_HIGH"}))
            elif prefix.endswith("_clk") and flow == wiring.In:
                out.append(BusInterface(prefix, "clock", CLOCK, "slave", {"CLK": prefix}))
            elif prefix.endswith("_rst") and flow == wiring.Out:
                out.append(BusInterface(prefix, "reset", RESET, "master", {"RST": prefix},
                                        {"POLARITY": "ACTIVE_HIGH"}))
            continue
        sig = member.signature
        inner_flipped = flipped ^ (member.flow == wiring.In)
        prefix = port_name(p)
        mode = "slave" if flow == wiring.In else "master"
        names = {m: f"{prefix}_{m}" for m in sig.members}
        if isinstance(sig, (AXI4LiteSignature, AXI4Signature)):
            params = {"PROTOCOL": "AXI4LITE" if isinstance(sig, AXI4LiteSignature) else "AXI4"}
            out.append(BusInterface(prefix, "aximm", AXIMM, mode,
                                    {m.upper(): n for m, n in names.items()}, params))
        elif isinstance(sig, AXIStreamSignature):
            out.append(BusInterface(prefix, "axis", AXIS, mode,
                                    {m.upper(): n for m, n in names.items()}))
        elif isinstance(sig, (FifoReadSignature, FifoWriteSignature)):
            kind = "S" if isinstance(sig, FifoReadSignature) else "M"
            width = Shape.cast(sig.members["data"].shape).width
            bus_name, vlnv = reconos_fifo_bus(kind, width)
            logical = {"data": "Data", "empty": "Empty", "re": "RE", "full": "Full", "we": "WE"}
            out.append(BusInterface(prefix, "fifo", vlnv, mode,
                                    {f"{bus_name}_{logical[m]}": n for m, n in names.items()}))
        else:
            _walk(sig, p, inner_flipped, out)


def bus_interfaces(component, *, clock="aclk", reset="aresetn"):
    """Interfaces of ``component`` exported with :func:`~gen.export.verilog.export_verilog`:
    its clock and active-low reset first, then one per bus member, in signature order."""
    out = []
    _walk(component.signature, (), False, out)
    buses = [i.name for i in out if i.kind in ("aximm", "axis", "fifo")]
    clk = BusInterface(clock, "clock", CLOCK, "slave", {"CLK": clock},
                       {"ASSOCIATED_BUSIF": ":".join(buses), "ASSOCIATED_RESET": reset})
    rst = BusInterface(reset, "reset", RESET, "slave", {"RST": reset},
                       {"POLARITY": "ACTIVE_LOW"})
    return [clk, rst, *out]
