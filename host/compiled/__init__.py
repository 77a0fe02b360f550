"""Models compiled into a Verilator co-simulation, so that nothing in Python runs per cycle.

A system top's AXI4 master port reads and writes the process memory on most cycles of a
ReconROS run; cocotbext-axi's ``AxiRam`` does that in Python coroutines woken at every clock
edge with traffic. :func:`cosim_wrapper` writes a simulation top around the exported system
that connects that port to ``rosgate_axi_ram`` (``axi_ram.sv``), a Verilog slave with
``AxiRam``'s handshake timing whose bytes live in C++ (``axi_ram.cpp``, called through DPI-C),
and registers the system's reset so that the model's input logic stays small.
:class:`CompiledAxiRam` is the Python view of those bytes, read and written in place through
``ctypes``: Python code that used ``AxiRam.read``/``AxiRam.write`` works unchanged.

Icarus Verilog has no DPI-C: there, the co-simulation keeps the Python bus models.
"""

import ctypes
import re
from pathlib import Path

__all__ = ["DEFAULT_MEMORY_MB", "MEMORY_OPTION", "SOURCES", "LINK_ARGS", "CompiledAxiRam",
           "attach_memory", "cosim_wrapper", "memory_harness", "verilog_ports", "wrapper_head"]

#: MiB of physical memory behind a system's AXI4 port in ``rosgate sim`` unless
#: :data:`MEMORY_OPTION` says otherwise (only what is written is backed by the host's memory)
DEFAULT_MEMORY_MB = 256
#: the ``rosgate sim`` option that sets it
MEMORY_OPTION = "--memory-mb"

HERE = Path(__file__).resolve().parent
#: the files a Verilator build with the compiled memory adds to the exported Verilog
SOURCES = (HERE / "axi_ram.sv", HERE / "axi_ram.cpp")
#: Verilator options that let Python find the memory's functions in the simulator
LINK_ARGS = ("-LDFLAGS", "-Wl,--export-dynamic-symbol=rosgate_axi_ram_*")
#: the AXI4 signals the memory model takes from a master port, by their suffix
_MEMORY_SIGNALS = ("awid", "awaddr", "awlen", "awsize", "awburst", "awvalid", "awready",
                   "wdata", "wstrb", "wlast", "wvalid", "wready", "bid", "bresp", "bvalid",
                   "bready", "arid", "araddr", "arlen", "arsize", "arburst", "arvalid",
                   "arready", "rid", "rdata", "rresp", "rlast", "rvalid", "rready")


class CompiledAxiRam:
    """The bytes of the compiled AXI4 memory, inside the simulator process.

    Parameters
    ----------
    size : int
        Bytes of memory; an access at or above ``size`` is answered SLVERR by the slave and
        raises :class:`IndexError` here.

    The interface is cocotbext-axi's ``Memory``: :meth:`read` and :meth:`write` of bytes at
    physical addresses, used by :class:`host.reconos.memory.ProcessMemory`.
    """

    def __init__(self, size):
        if not isinstance(size, int) or size <= 0 or size % 4096:
            raise ValueError(f"memory size {size!r}: expected a positive multiple of 4096 bytes")
        try:
            program = ctypes.CDLL(None)
            attach = program.rosgate_axi_ram_attach
        except (OSError, AttributeError) as exc:
            raise RuntimeError("the simulator was not built with the compiled AXI memory "
                               "(host.compiled.SOURCES and LINK_ARGS)") from exc
        attach.restype = ctypes.c_void_p
        attach.argtypes = [ctypes.c_uint64]
        base = attach(size)
        if not base:
            raise MemoryError(f"could not map {size} bytes for the compiled AXI memory")
        self._accesses = program.rosgate_axi_ram_accesses
        self._accesses.restype = ctypes.c_uint64
        self.size = size
        self.mem = memoryview((ctypes.c_ubyte * size).from_address(base)).cast("B")

    @property
    def accesses(self):
        """Bus reads and writes of the memory so far."""
        return int(self._accesses())

    def _check(self, address, length):
        if address < 0 or length < 0 or address + length > self.size:
            raise IndexError(f"no memory at 0x{address:x}..0x{address + length:x} "
                             f"({self.size} bytes)")

    def read(self, address, length):
        self._check(address, length)
        return bytes(self.mem[address:address + length])

    def write(self, address, data):
        data = bytes(data)
        self._check(address, len(data))
        self.mem[address:address + len(data)] = data


def attach_memory(dut, size, *, prefix="m_axi_mem", clock="aclk", reset="aresetn"):
    """Inside a cocotb test: the memory behind ``dut``'s AXI4 master port ``prefix``, ``size``
    bytes: the :class:`CompiledAxiRam` when a :func:`memory_harness` wrapper took the port
    (Verilator), else cocotbext-axi's ``AxiRam`` on it (Icarus). Either answers an access at
    or above ``size`` with SLVERR, has ``read``, ``write``, ``size`` and ``accesses`` (bus
    reads and writes so far), and takes the same cycles."""
    if not hasattr(dut, f"{prefix}_arvalid"):
        return CompiledAxiRam(size)
    import logging

    from cocotbext.axi import AxiBus, AxiRam

    ram = AxiRam(AxiBus.from_prefix(dut, prefix), getattr(dut, clock), getattr(dut, reset),
                 reset_active_level=False, size=size)
    for part in (ram.write_if, ram.read_if):
        part.log.setLevel(logging.WARNING)
    ram.accesses = 0
    # AxiRam wraps addresses modulo its size; an interconnect answers an access with nothing
    # behind it with an error: raising here makes cocotbext-axi answer SLVERR
    for port, name in ((ram.read_if, "_read"), (ram.write_if, "_write")):
        inner = getattr(port, name)

        async def checked(address, arg, _inner=inner):
            if address >= size:
                raise IndexError(f"no memory at 0x{address:x}")
            ram.accesses += 1
            return await _inner(address, arg)
        setattr(port, name, checked)
    return ram


_PORT = re.compile(r"^\s*(input|output)\s+(?:wire\s+|reg\s+|logic\s+)?(?:\[(\d+):(\d+)\]\s*)?"
                   r"\\?([A-Za-z_][\w$]*)\s*;", re.M)


def verilog_ports(text, top):
    """Ports of module ``top`` in Verilog ``text`` as Yosys writes it: name -> (direction,
    width)."""
    start = re.search(rf"^module\s+\\?{re.escape(top)}\s*\(", text, re.M)
    if start is None:
        raise ValueError(f"no module {top!r} in the Verilog")
    body = text[start.end():text.index("endmodule", start.end())]
    return {m.group(4): (m.group(1), int(m.group(2)) - int(m.group(3)) + 1 if m.group(2) else 1)
            for m in _PORT.finditer(body)}


def wrapper_head(name, ports, inner, what):
    """The first lines of a simulation wrapper module ``name`` around a top with ``ports``
    (:func:`verilog_ports`): a comment saying ``what`` it is, the module header and the
    declarations of every port but ``inner``, which become wires."""
    def decl(kind, port):
        width = ports[port][1]
        return f"    {kind} {'[%d:0] ' % (width - 1) if width > 1 else ''}{port};"
    outer = [p for p in ports if p not in inner]
    return ([f"// {name}: {what} (simulation only)", f"module {name}({', '.join(outer)});"]
            + [decl(ports[p][0], p) for p in outer] + [decl("wire", p) for p in inner])


def cosim_wrapper(text, top, *, memory="m_axi_mem", clock="aclk", reset="aresetn"):
    """Verilog of module ``<top>_cosim``: ``top`` (in Verilog ``text``) with its AXI4 master
    port ``memory`` connected to ``rosgate_axi_ram`` and its reset ``reset`` registered once
    on ``clock``; every other port of ``top`` is a port of the wrapper with the same name.
    Return ``(name, verilog)``."""
    ports = verilog_ports(text, top)
    for sig in _MEMORY_SIGNALS:
        if f"{memory}_{sig}" not in ports:
            raise ValueError(f"module {top!r} has no port {memory}_{sig}: not an AXI4 "
                             f"master port {memory!r}")
    for name in (clock, reset):
        if name not in ports or ports[name][0] != "input":
            raise ValueError(f"module {top!r} has no input {name!r}")
    name = f"{top}_cosim"
    lines = wrapper_head(name, ports, [p for p in ports if p.startswith(memory + "_")],
                         f"{top} with its AXI4 port {memory} on rosgate_axi_ram")
    lines += [f"    reg {reset}_q = 1'b0;",
              f"    always @(posedge {clock}) {reset}_q <= {reset};",
              f"    {top} dut ("]
    lines.append(",\n".join(f"        .{p}({reset + '_q' if p == reset else p})" for p in ports))
    lines += ["    );",
              "    rosgate_axi_ram #(",
              f"        .ADDR_W({ports[memory + '_araddr'][1]}),",
              f"        .DATA_W({ports[memory + '_rdata'][1]}),",
              f"        .ID_W({ports[memory + '_arid'][1]})",
              f"    ) memory (.aclk({clock}), .aresetn({reset}),"]
    lines.append(",\n".join(f"        .{sig}({memory}_{sig})" for sig in _MEMORY_SIGNALS) + ");")
    lines.append("endmodule")
    return name, "\n".join(lines) + "\n"


def memory_harness(memory="m_axi_mem"):
    """A ``harness`` for :func:`host.simulator.run_top`: the exported top inside
    :func:`cosim_wrapper`, built with the compiled memory, only the wrapper's ports visible to
    the cocotb side."""
    from gen.export.verilog import write_if_changed

    def make(vfile, build_dir):
        vfile = Path(vfile)
        text = vfile.read_text()
        name, verilog = cosim_wrapper(text, vfile.stem, memory=memory)
        wrapper = Path(build_dir) / f"{name}.v"
        write_if_changed(wrapper, verilog)
        return (name, [wrapper, SOURCES[0]], [str(SOURCES[1]), *LINK_ARGS],
                list(verilog_ports(verilog, name)))
    return make
