"""The software-visible ReconOS control blocks: reconos_osif, reconos_osif_intc and
reconos_proc_control (docs/reconos.md), each an AXI4-Lite subordinate."""

from amaranth.hdl import Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..bus import AXI4LiteSignature, AXI4LiteTarget
from ..params import check_int
from .fifo import FifoReadSignature, FifoWriteSignature
from .protocol import (MemStatus, OsifRegister, ProcControlRegister, arch as get_arch,
                       proc_control_offset)

__all__ = ["ReconosOsif", "OsifIntc", "ProcControl", "CONTROL_ADDR_WIDTH", "MAX_HWTS",
           "SYS_RESET_CYCLES"]

#: Each block decodes a 64 KiB window.
CONTROL_ADDR_WIDTH = 16
MAX_HWTS = 32
#: Length of the ``PROC_Sys_Rst`` pulse after a write to SYS_RESET.
SYS_RESET_CYCLES = 16


def _check_hwts(num_hwts):
    return check_int("num_hwts", num_hwts, 1, MAX_HWTS)


class ReconosOsif(wiring.Component):
    """reconos_osif: four registers per hardware thread between the CPU and the slot's OSIF
    FIFOs (docs/reconos.md; register ``4*i + k`` at byte offset ``(4*i + k) * W``).

    ======  =========  ================================================================
    k       access     function
    ======  =========  ================================================================
    0       R          head of hw2sw; the read pops it (a read of an empty FIFO returns 0
                       and pops nothing)
    1       W          push the written word into sw2hw (dropped if sw2hw is full)
    2       R          MSB = hw2sw empty; bits 15..0 = hw2sw fill (rosgate)
    3       R          MSB = sw2hw full; bits 15..0 = sw2hw free entries (rosgate)
    ======  =========  ================================================================

    Reads of other registers return 0 with OKAY, writes to read-only ones are ignored, as in
    ReconOS; offsets beyond thread ``num_hwts - 1`` answer SLVERR.

    Parameters
    ----------
    arch : str
        ``"r32"`` (32-bit registers) or ``"r64"`` (64-bit).
    num_hwts : int
        Hardware threads (slots), 1..32.

    Members
    -------
    bus : In(AXI4LiteSignature(16, W*8))
    hw2sw : Out(FifoReadSignature(W*8)).array(num_hwts)
        Read side of each slot's hw2sw FIFO.
    hw2sw_fill : In(16).array(num_hwts)
    sw2hw : Out(FifoWriteSignature(W*8)).array(num_hwts)
        Write side of each slot's sw2hw FIFO.
    sw2hw_free : In(16).array(num_hwts)
    """

    def __init__(self, arch, num_hwts):
        self._arch = get_arch(arch)
        self._n = _check_hwts(num_hwts)
        w = self._arch.word_bits
        super().__init__({
            "bus": In(AXI4LiteSignature(CONTROL_ADDR_WIDTH, w)),
            "hw2sw": Out(FifoReadSignature(w)).array(num_hwts),
            "hw2sw_fill": In(16).array(num_hwts),
            "sw2hw": Out(FifoWriteSignature(w)).array(num_hwts),
            "sw2hw_free": In(16).array(num_hwts),
        })

    def elaborate(self, platform):
        m = Module()
        w = self._arch.word_bits
        m.submodules.target = t = AXI4LiteTarget(CONTROL_ADDR_WIDTH, w)
        wiring.connect(m, wiring.flipped(self.bus), t.bus)
        msb = 1 << (w - 1)

        r_thread, r_reg = t.read_index[2:], t.read_index[:2]
        w_thread, w_reg = t.write_index[2:], t.write_index[:2]
        m.d.comb += [t.read_error.eq(r_thread >= self._n), t.write_error.eq(w_thread >= self._n)]
        for i in range(self._n):
            hw2sw, sw2hw = self.hw2sw[i], self.sw2hw[i]
            m.d.comb += sw2hw.data.eq(t.write_data)
            with m.If(r_thread == i):
                with m.Switch(r_reg):
                    with m.Case(OsifRegister.HW2SW_DATA):
                        m.d.comb += [
                            t.read_data.eq(Mux(hw2sw.empty, 0, hw2sw.data)),
                            hw2sw.re.eq(t.read_en),
                        ]
                    with m.Case(OsifRegister.HW2SW_EMPTY):
                        m.d.comb += t.read_data.eq(Mux(hw2sw.empty, msb, 0) |
                                                   self.hw2sw_fill[i])
                    with m.Case(OsifRegister.SW2HW_FULL):
                        m.d.comb += t.read_data.eq(Mux(sw2hw.full, msb, 0) |
                                                   self.sw2hw_free[i])
            with m.If((w_thread == i) & (w_reg == OsifRegister.SW2HW_DATA)):
                m.d.comb += sw2hw.we.eq(t.write_en)
        return m


class OsifIntc(wiring.Component):
    """reconos_osif_intc: a level interrupt when an enabled thread's hw2sw FIFO has data
    (docs/reconos.md).

    Register ``j`` (byte offset ``4*j``, 32-bit semantics in the low half of a 64-bit bus):
    write = enable mask of threads ``32j..32j+31``; read = pending = ``has_data & enable``.

    Members
    -------
    bus : In(AXI4LiteSignature(16, W*8))
    has_data : In(num_hwts)
        ``FIFO_Has_Data`` of each slot's hw2sw FIFO.
    irq : Out(1)
        OR over all threads of ``has_data & enable``.
    """

    def __init__(self, arch, num_hwts):
        self._arch = get_arch(arch)
        self._n = _check_hwts(num_hwts)
        super().__init__({
            "bus": In(AXI4LiteSignature(CONTROL_ADDR_WIDTH, self._arch.word_bits)),
            "has_data": In(num_hwts),
            "irq": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        w = self._arch.word_bits
        m.submodules.target = t = AXI4LiteTarget(CONTROL_ADDR_WIDTH, w)
        wiring.connect(m, wiring.flipped(self.bus), t.bus)
        enable = Signal(self._n)
        pending = Signal(self._n)
        m.d.comb += [pending.eq(self.has_data & enable), self.irq.eq(pending.any())]
        # Registers are 4 bytes apart whatever the bus width (the driver does 32-bit I/O);
        # on a 64-bit bus register 2k+1 is the upper half of word k.
        r_reg = t.read_addr[2:]
        w_reg = t.write_addr[2:]
        read_word = Signal(32)
        write_word = Signal(32)
        if w == 64:
            m.d.comb += [
                t.read_data.eq(Mux(t.read_addr[2], read_word << 32, read_word)),
                write_word.eq(Mux(t.write_addr[2], t.write_data[32:], t.write_data[:32])),
            ]
        else:
            m.d.comb += [t.read_data.eq(read_word), write_word.eq(t.write_data)]
        for j in range(-(-self._n // 32)):
            lo, hi = 32 * j, min(32 * j + 32, self._n)
            with m.If(r_reg == j):
                m.d.comb += read_word.eq(pending[lo:hi])
            with m.If(t.write_en & (w_reg == j)):
                m.d.sync += enable[lo:hi].eq(write_word[:hi - lo])
        return m


class ProcControl(wiring.Component):
    """reconos_proc_control: thread resets and signals, MMU page table and faults, TLB and
    memory-path status (docs/reconos.md, register indices in :class:`ProcControlRegister`).

    r64: 64-bit registers at ``8*index``; r32: 32-bit registers at the driver's offsets
    (:func:`~hdl.reconos.protocol.proc_control_offset`).

    Members
    -------
    bus : In(AXI4LiteSignature(16, W*8))
    hwt_reset : Out(num_hwts)
        Per-thread reset (``Hwt_Rst_i``), all ones after reset: every thread held in reset.
    hwt_signal : Out(num_hwts)
        Per-thread ``HWT_Signal``.
    sys_reset : Out(1)
        ``PROC_Sys_Rst``: 16 cycles after a write to SYS_RESET.
    pgd : Out(addr_bits)
        Page-table base (physical).
    tlb_flush : Out(1)
        One-cycle pulse, registered (the cycle after the write): invalidate the TLB (write to
        TLB_FLUSH or to PGD).
    mmu_pgf : In(1)
        The MMU waits in a page fault; ``mmu_fault_addr`` is the faulting VA.
    mmu_fault_addr : In(64)
    mmu_retry : Out(1)
        One-cycle pulse: restart the walk (write to FAULT_ADDR).
    mmu_abort : Out(1)
        One-cycle pulse: give up the faulting request (write to FAULT_ABORT).
    tlb_hit, tlb_miss : In(1)
        One-cycle pulses counted into TLB_HITS / TLB_MISSES.
    mem_error : In(MemStatus width)
        One-cycle pulses of :class:`MemStatus` bits, ORed into MEM_STATUS.
    mem_error_addr : In(addr_bits)
        Address of the failing request, captured with the first error after a clear.
    irq_pgf : Out(1)
        ``PROC_Pgf_Int``: set when a page fault starts, cleared by reading FAULT_ADDR.
    """

    def __init__(self, arch, num_hwts):
        self._arch = get_arch(arch)
        self._n = _check_hwts(num_hwts)
        a = self._arch
        super().__init__({
            "bus": In(AXI4LiteSignature(CONTROL_ADDR_WIDTH, a.word_bits)),
            "hwt_reset": Out(num_hwts, init=(1 << num_hwts) - 1),
            "hwt_signal": Out(num_hwts),
            "sys_reset": Out(1),
            "pgd": Out(a.addr_bits),
            "tlb_flush": Out(1),
            "mmu_pgf": In(1),
            "mmu_fault_addr": In(64),
            "mmu_retry": Out(1),
            "mmu_abort": Out(1),
            "tlb_hit": In(1),
            "tlb_miss": In(1),
            "mem_error": In(len(MemStatus)),
            "mem_error_addr": In(a.addr_bits),
            "irq_pgf": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        a = self._arch
        w = a.word_bits
        m.submodules.target = t = AXI4LiteTarget(CONTROL_ADDR_WIDTH, w)
        wiring.connect(m, wiring.flipped(self.bus), t.bus)
        R = ProcControlRegister
        byte_shift = (w // 8).bit_length() - 1
        index_of = {r: proc_control_offset(a, r, self._n) >> byte_shift for r in R}

        hits = Signal(w)
        misses = Signal(w)
        status = Signal(len(MemStatus))
        error_addr = Signal(a.addr_bits)
        reset_count = Signal(range(SYS_RESET_CYCLES + 1))
        pgf_last = Signal()

        m.d.comb += self.sys_reset.eq(reset_count != 0)
        with m.If(reset_count != 0):
            m.d.sync += reset_count.eq(reset_count - 1)
        with m.If(self.tlb_hit):
            m.d.sync += hits.eq(hits + 1)
        with m.If(self.tlb_miss):
            m.d.sync += misses.eq(misses + 1)
        m.d.sync += pgf_last.eq(self.mmu_pgf)
        with m.If(self.mmu_pgf & ~pgf_last):
            m.d.sync += self.irq_pgf.eq(1)
        new_errors = Signal.like(status)
        m.d.comb += new_errors.eq(self.mem_error |
                                  Mux(self.mmu_pgf & ~pgf_last, int(MemStatus.PAGE_FAULT), 0))
        with m.If(new_errors.any()):
            m.d.sync += status.eq(status | new_errors)
            with m.If(status == 0):
                m.d.sync += error_addr.eq(Mux(self.mem_error.any(), self.mem_error_addr,
                                              self.mmu_fault_addr))

        values = {
            R.NUM_HWTS: Const(self._n, w),
            R.PGD: self.pgd,
            R.FAULT_ADDR: self.mmu_fault_addr[:w],
            R.TLB_HITS: hits,
            R.TLB_MISSES: misses,
            R.HWT_RESET: self.hwt_reset,
            R.HWT_SIGNAL: self.hwt_signal,
            R.MEM_STATUS: status,
            R.MEM_ERROR_ADDR: error_addr,
        }
        decoded = Signal()
        for r, index in index_of.items():
            with m.If(t.read_index == index):
                m.d.comb += decoded.eq(1)
                if r in values:
                    m.d.comb += t.read_data.eq(values[r])
                with m.If(t.read_en):
                    if r == R.FAULT_ADDR:
                        m.d.sync += self.irq_pgf.eq(0)
                    if r == R.MEM_STATUS:
                        # a new error in this very cycle survives the clear
                        m.d.sync += status.eq(new_errors)
        m.d.comb += t.read_error.eq(~decoded)

        # the flush is registered: the register decode does not reach into the MMU's request
        # path (the pulse comes one cycle after the write, as if the write came a cycle later)
        flush = Signal()
        m.d.sync += self.tlb_flush.eq(flush)
        w_decoded = Signal()
        for r, index in index_of.items():
            with m.If(t.write_index == index):
                m.d.comb += w_decoded.eq(1)
                with m.If(t.write_en):
                    if r == R.PGD:
                        m.d.sync += self.pgd.eq(t.write_data)
                        m.d.comb += flush.eq(1)
                    elif r == R.FAULT_ADDR:
                        m.d.comb += self.mmu_retry.eq(1)
                    elif r == R.SYS_RESET:
                        m.d.sync += reset_count.eq(SYS_RESET_CYCLES)
                    elif r == R.HWT_RESET:
                        m.d.sync += self.hwt_reset.eq(t.write_data)
                    elif r == R.HWT_SIGNAL:
                        m.d.sync += self.hwt_signal.eq(t.write_data)
                    elif r == R.TLB_FLUSH:
                        m.d.comb += flush.eq(1)
                    elif r == R.FAULT_ABORT:
                        m.d.comb += self.mmu_abort.eq(1)
        m.d.comb += t.write_error.eq(~w_decoded)
        # The system reset also flushes (the TLB's valid bits are cleared by it anyway).
        with m.If(self.sys_reset):
            m.d.comb += flush.eq(1)
        return m
