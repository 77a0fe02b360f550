"""The software side attached to a simulated ReconOS system top: clocks, reset, the three
AXI4-Lite masters of the CPU, the process memory behind the AXI4 port, and the runtime."""

import logging

from cocotb.triggers import ClockCycles
from cocotbext.axi import AxiLiteBus, AxiLiteMaster

from hdl.reconos.protocol import arch as get_arch
from host.compiled import attach_memory
from host.simulator import start_clock

from .broker import Broker
from .memory import ProcessMemory
from .messages import MessageMemory
from .runtime import ReconosRuntime

__all__ = ["ReconosCosim", "RAM_SIZE"]

#: bytes of physical memory behind the system's AXI4 port, by default
RAM_SIZE = 1 << 25


class ReconosCosim:
    """The CPU side of a system top with ReconOS ports (``aclk``, ``aresetn``,
    ``s_axi_osif``, ``s_axi_intc``, ``s_axi_proc``, ``m_axi_mem``, ``irq_osif``,
    ``irq_pgf``), inside a cocotb test.

    Parameters
    ----------
    dut : cocotb handle
        The system top.
    arch : str
        ``"r32"`` or ``"r64"``.
    num_hwts : int
        Hardware thread slots.
    clock_ns : float
        System clock period.
    slot_clocks : dict
        Slot index -> clock period in ns, for slots on their own clock (port
        ``slot<i>_clk``).
    ram_size : int
        Bytes of physical memory.
    """

    def __init__(self, dut, *, arch, num_hwts, clock_ns=10, slot_clocks=None,
                 ram_size=RAM_SIZE):
        self.dut = dut
        self.arch = get_arch(arch)
        self.num_hwts = num_hwts
        start_clock(dut.aclk, clock_ns)
        for i, period in (slot_clocks or {}).items():
            start_clock(getattr(dut, f"slot{i}_clk"), period)
        self.osif, self.intc, self.proc = (
            AxiLiteMaster(AxiLiteBus.from_prefix(dut, f"s_axi_{name}"), dut.aclk, dut.aresetn,
                          reset_active_level=False) for name in ("osif", "intc", "proc"))
        #: the compiled memory of a Verilator harness, or cocotbext-axi's AxiRam on the port
        self.ram = attach_memory(dut, ram_size)
        for m in (self.osif, self.intc, self.proc):
            for part in ("write_if", "read_if"):
                if hasattr(m, part):
                    getattr(m, part).log.setLevel(logging.WARNING)
            if hasattr(m, "log"):
                m.log.setLevel(logging.WARNING)
        self.ram_size = ram_size
        self.memory = ProcessMemory(self.arch, self.ram, ram_size)
        self.broker = Broker()
        self.messages = None
        self.runtime = None

    @property
    def memory_accesses(self):
        """Memory accesses of the hardware so far (a measure of progress)."""
        return self.ram.accesses

    async def reset(self):
        self.dut.aresetn.value = 0
        await ClockCycles(self.dut.aclk, 5)
        self.dut.aresetn.value = 1
        await ClockCycles(self.dut.aclk, 2)

    async def start_runtime(self, library=None):
        """Start the ReconOS runtime with the message types of ``library`` (default: the
        ROS 2 standard interfaces only); return it."""
        from gen.msg import MessageLibrary
        library = library or MessageLibrary([], store="ros2_humble")
        self.messages = MessageMemory(self.memory, library)
        self.runtime = ReconosRuntime(
            self.arch, osif=self.osif, intc=self.intc, proc=self.proc,
            irq_osif=self.dut.irq_osif, irq_pgf=self.dut.irq_pgf, clock=self.dut.aclk,
            memory=self.memory, messages=self.messages, broker=self.broker,
            num_hwts=self.num_hwts)
        await self.runtime.start()
        return self.runtime
