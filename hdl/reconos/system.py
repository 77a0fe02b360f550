"""The ReconOS infrastructure around a set of hardware threads (docs/reconos.md)."""

from amaranth.hdl import ClockDomain, DomainRenamer, Module, ResetInserter, ResetSignal
from amaranth.lib.cdc import FFSynchronizer, ResetSynchronizer
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..bus import AXI4LiteSignature, AXI4Signature
from .control import CONTROL_ADDR_WIDTH, MAX_HWTS, OsifIntc, ProcControl, ReconosOsif
from .fifo import MEMIF_FIFO_DEPTH, OSIF_FIFO_DEPTH, ReconosFifo
from .hwt import ThreadSignature
from .memctrl import MemoryController
from .memif import MemifArbiter, request_layout
from .mmu import MMU
from .protocol import arch as get_arch
from ..params import check_int, check_power_of_two
from ..stream import PayloadRegisterSlice

__all__ = ["ReconosSystem"]


class ReconosSystem(wiring.Component):
    """Hardware threads in slots with their OSIF/MEMIF FIFOs, reconos_osif, osif_intc,
    proc_control, the MEMIF arbiter, the MMU and the AXI4 memory controller.

    ``proc_control``'s per-thread reset clears slot *i*'s thread and its four FIFOs; its
    system reset (and the bus reset) clears the arbiter, MMU, TLB and controller.

    Parameters
    ----------
    arch : str
        ``"r32"`` or ``"r64"``.
    threads : list of wiring.Component or None
        One per slot, each with the members of :func:`~hdl.reconos.hwt.ThreadSignature`.
        ``None`` leaves the slot empty and exposes its ports as ``slot<i>`` (the FIFO sides a
        thread connects to, for a thread implemented outside Amaranth) and ``slot<i>_rst``.
    tlb_entries : int
        TLB size (ReconROS block designs: 16).
    osif_depth, memif_depth : int
        FIFO depths (ReconROS: 8 and 128).
    async_slots : iterable of int
        Slots with their own clock (input ``slot<i>_clk``): the slot's thread runs in domain
        ``hwt<i>``, its four FIFOs cross clocks (``reconos_fifo_async``), HWT_Rst and
        HWT_Signal are synchronised into it.

    Members
    -------
    s_axi_osif, s_axi_intc, s_axi_proc : In(AXI4LiteSignature(16, W*8))
        reconos_osif, reconos_osif_intc and reconos_proc_control.
    m_axi_mem : Out(AXI4Signature(addr_bits, W*8, id_width=1, user_width=2))
        Process memory.
    irq_osif : Out(1)
        osif_intc's level interrupt.
    irq_pgf : Out(1)
        proc_control's page-fault interrupt.
    """

    def __init__(self, arch, threads, *, tlb_entries=16, osif_depth=OSIF_FIFO_DEPTH,
                 memif_depth=MEMIF_FIFO_DEPTH, async_slots=()):
        self._arch = a = get_arch(arch)
        threads = list(threads)
        check_int("slots", len(threads), 1, MAX_HWTS)
        self._osif_depth = check_power_of_two("osif_depth", osif_depth, 2, 4096)
        self._memif_depth = check_power_of_two("memif_depth", memif_depth, 2, 4096)
        expected = ThreadSignature(a).members
        external = {}
        for i, t in enumerate(threads):
            if t is None:
                external[f"slot{i}"] = In(ThreadSignature(a))
                external[f"slot{i}_rst"] = Out(1)
                continue
            for name, member in expected.items():
                if name not in t.signature.members or t.signature.members[name] != member:
                    raise ValueError(f"thread in slot {i} ({type(t).__name__}) lacks the slot "
                                     f"port {name!r} of a {a.name} hardware thread")
        self._threads = threads
        self._tlb_entries = tlb_entries
        self._async = sorted(set(async_slots))
        for i in self._async:
            check_int("async slot", i, 0, len(threads) - 1)
            if threads[i] is None:
                raise ValueError(f"async slot {i} is empty; a clock-crossing slot needs a thread")
            external[f"slot{i}_clk"] = In(1)
        w = a.word_bits
        super().__init__({
            "s_axi_osif": In(AXI4LiteSignature(CONTROL_ADDR_WIDTH, w)),
            "s_axi_intc": In(AXI4LiteSignature(CONTROL_ADDR_WIDTH, w)),
            "s_axi_proc": In(AXI4LiteSignature(CONTROL_ADDR_WIDTH, w)),
            "m_axi_mem": Out(AXI4Signature(a.addr_bits, w, id_width=1, user_width=2)),
            "irq_osif": Out(1),
            "irq_pgf": Out(1),
            **external,
        })

    def elaborate(self, platform):
        m = Module()
        a = self._arch
        n = len(self._threads)
        w = a.word_bits

        m.submodules.osif = osif = ReconosOsif(a, n)
        m.submodules.intc = intc = OsifIntc(a, n)
        m.submodules.proc = proc = ProcControl(a, n)
        wiring.connect(m, wiring.flipped(self.s_axi_osif), osif.bus)
        wiring.connect(m, wiring.flipped(self.s_axi_intc), intc.bus)
        wiring.connect(m, wiring.flipped(self.s_axi_proc), proc.bus)
        m.d.comb += [self.irq_osif.eq(intc.irq), self.irq_pgf.eq(proc.irq_pgf)]

        sys_rst = proc.sys_reset
        arbiter = ResetInserter(sys_rst)(MemifArbiter(a, n))
        mmu = ResetInserter(sys_rst)(MMU(a, n, tlb_entries=self._tlb_entries))
        ctrl = ResetInserter(sys_rst)(MemoryController(a, n))
        m.submodules.arbiter = arbiter
        m.submodules.mmu = mmu
        m.submodules.memctrl = ctrl
        # the slices keep the FIFO heads, the arbitration, the translation and the AXI side
        # in separate clock periods (a request takes two cycles more)
        layout = request_layout(a, n)
        m.submodules.req_slice = req_slice = ResetInserter(sys_rst)(PayloadRegisterSlice(layout))
        m.submodules.mem_slice = mem_slice = ResetInserter(sys_rst)(PayloadRegisterSlice(layout))
        wiring.connect(m, arbiter.req, req_slice.i)
        wiring.connect(m, req_slice.o, mmu.s_req)
        wiring.connect(m, mmu.m_req, mem_slice.i)
        wiring.connect(m, mem_slice.o, ctrl.s_req)
        wiring.connect(m, arbiter.wdata, ctrl.s_wdata)
        wiring.connect(m, ctrl.m_rdata, mmu.s_rdata)
        wiring.connect(m, mmu.m_rdata, arbiter.rdata)
        wiring.connect(m, ctrl.axi, wiring.flipped(self.m_axi_mem))
        m.d.comb += [
            mmu.pgd.eq(proc.pgd),
            mmu.flush.eq(proc.tlb_flush),
            mmu.retry.eq(proc.mmu_retry),
            mmu.abort.eq(proc.mmu_abort),
            proc.mmu_pgf.eq(mmu.pgf),
            proc.mmu_fault_addr.eq(mmu.fault_addr),
            proc.tlb_hit.eq(mmu.tlb_hit),
            proc.tlb_miss.eq(mmu.tlb_miss),
            proc.mem_error.eq(ctrl.error),
            proc.mem_error_addr.eq(ctrl.error_addr),
            arbiter.slot_reset.eq(proc.hwt_reset),
        ]

        has_data = []
        for i, thread in enumerate(self._threads):
            rst = proc.hwt_reset[i]
            hwt = "sync"
            if thread is None:
                thread = wiring.flipped(getattr(self, f"slot{i}"))
                m.d.comb += getattr(self, f"slot{i}_rst").eq(rst)
            elif i in self._async:
                hwt = f"hwt{i}"
                cd = ClockDomain(hwt, local=True)
                m.domains += cd
                m.d.comb += cd.clk.eq(getattr(self, f"slot{i}_clk"))
                m.submodules[f"slot{i}_rst_sync"] = ResetSynchronizer(
                    rst | ResetSignal("sync"), domain=hwt)
                m.submodules[f"slot{i}"] = DomainRenamer({"sync": hwt})(thread)
            else:
                m.submodules[f"slot{i}"] = ResetInserter(rst)(thread)
            fifos = {}
            # (name, depth, write domain, read domain)
            for name, depth, wd, rd in (
                    ("sw2hw", self._osif_depth, "sync", hwt),
                    ("hw2sw", self._osif_depth, hwt, "sync"),
                    ("hwt2mem", self._memif_depth, hwt, "sync"),
                    ("mem2hwt", self._memif_depth, "sync", hwt)):
                fifos[name] = f = ReconosFifo(w, depth, w_domain=wd, r_domain=rd)
                m.submodules[f"slot{i}_{name}"] = f
                # (a FIFO written in the slot's own domain is cleared by that domain's reset)
                m.d.comb += f.rst.eq(rst if wd == "sync" else 0)
            # The thread's ports are the FIFOs' far sides.
            wiring.connect(m, thread.osif_sw2hw, fifos["sw2hw"].r)
            wiring.connect(m, thread.osif_hw2sw, fifos["hw2sw"].w)
            wiring.connect(m, thread.memif_hwt2mem, fifos["hwt2mem"].w)
            wiring.connect(m, thread.memif_mem2hwt, fifos["mem2hwt"].r)
            if hwt == "sync":
                m.d.comb += thread.hwt_signal.eq(proc.hwt_signal[i])
            else:
                m.submodules[f"slot{i}_signal_sync"] = FFSynchronizer(
                    proc.hwt_signal[i], thread.hwt_signal, o_domain=hwt)
            wiring.connect(m, osif.hw2sw[i], fifos["hw2sw"].r)
            wiring.connect(m, osif.sw2hw[i], fifos["sw2hw"].w)
            m.d.comb += [osif.hw2sw_fill[i].eq(fifos["hw2sw"].r_fill),
                         osif.sw2hw_free[i].eq(fifos["sw2hw"].w_free)]
            wiring.connect(m, arbiter.hwt2mem[i], fifos["hwt2mem"].r)
            wiring.connect(m, arbiter.mem2hwt[i], fifos["mem2hwt"].w)
            has_data.append(fifos["hw2sw"].has_data)
        for i, hd in enumerate(has_data):
            m.d.comb += intc.has_data[i].eq(hd)
        return m
