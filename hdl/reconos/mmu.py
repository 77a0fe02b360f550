"""The MEMIF MMU: virtual to physical translation with a TLB and a hardware page-table walk
(docs/reconos.md)."""

import operator
from functools import reduce

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int
from .memif import rdata_layout, request_layout
from .protocol import arch as get_arch

__all__ = ["TLB", "MMU", "PAGE_BITS"]

PAGE_BITS = 12


class TLB(wiring.Component):
    """A fully associative TLB of 4 KiB translations with round-robin replacement.

    Parameters
    ----------
    vpn_bits, ppn_bits : int
        Widths of the virtual and physical page numbers.
    entries : int
        2..256.

    Members
    -------
    lookup_vpn : In(vpn_bits)
    hit : Out(1)
        The ``lookup_vpn`` of the previous cycle is in a valid entry: the comparison with
        every entry is registered, and ``hit`` and ``hit_ppn`` are made from that register.
    hit_ppn : Out(ppn_bits)
    write : In(1)
        Store ``write_vpn -> write_ppn`` into the next entry of the round-robin pointer. Only
        for a VPN that is in no valid entry (the MMU writes after a lookup missed): at most one
        entry matches a lookup, and ``hit_ppn`` is the OR of the matching entries' PPNs.
    write_vpn, write_ppn : In
    flush : In(1)
        Invalidate every entry (ReconROS defect 8, docs/reconos.md: ReconOS only clears them on
        system reset).
    """

    def __init__(self, vpn_bits, ppn_bits, entries):
        check_int("tlb_entries", entries, 2, 256)
        self._entries = entries
        super().__init__({
            "lookup_vpn": In(vpn_bits), "hit": Out(1), "hit_ppn": Out(ppn_bits),
            "write": In(1), "write_vpn": In(vpn_bits), "write_ppn": In(ppn_bits),
            "flush": In(1),
        })

    def elaborate(self, platform):
        m = Module()
        n = self._entries
        valid = Signal(n)
        vpns = [Signal.like(self.lookup_vpn, name=f"vpn{i}") for i in range(n)]
        ppns = [Signal.like(self.hit_ppn, name=f"ppn{i}") for i in range(n)]
        nxt = Signal(range(n))
        # at most one entry matches (see ``write``), so the PPN is an OR of the matching
        # entries, not a chain of n priority multiplexers
        match = Signal(n)
        m.d.sync += match.eq(Cat(valid[i] & (vpns[i] == self.lookup_vpn) for i in range(n)))
        m.d.comb += [
            self.hit.eq(match.any()),
            self.hit_ppn.eq(reduce(operator.or_,
                                   (Mux(match[i], ppns[i], 0) for i in range(n)))),
        ]
        with m.If(self.write):
            for i in range(n):
                with m.If(nxt == i):
                    m.d.sync += [vpns[i].eq(self.write_vpn), ppns[i].eq(self.write_ppn),
                                 valid[i].eq(1)]
            m.d.sync += nxt.eq(Mux(nxt == n - 1, 0, nxt + 1))
        with m.If(self.flush):
            m.d.sync += valid.eq(0)
        return m


class MMU(wiring.Component):
    """reconos_memif_mmu_usp (r64) / reconos_memif_mmu_zynq (r32) with rosgate's fixes.

    Translates the address of every request on ``s_req`` and forwards it on ``m_req``; a TLB
    hit forwards in one cycle. On a miss the MMU walks the page table with its own read
    requests (tag ``num_hwts``), whose data it takes from ``s_rdata``; other read data passes
    from ``s_rdata`` to ``m_rdata`` unchanged.

    * r64: ARMv8 4 KiB granule, 39-bit VA, three levels from ``pgd``: L1 at
      ``pgd + VA[38:30]*8``, L2 ``L1d[47:12] + VA[29:21]*8``, L3 ``L2d[47:12] + VA[20:12]*8``;
      bit 0 clear = fault; at L1/L2 bit 1 clear = block (1 GiB / 2 MiB).
    * r32: ARMv7 short descriptors: L1 at ``pgd[31:14] + VA[31:20]*4``; ``bits[1:0]`` 00 =
      fault, 01 = page table (L2 at ``L1d[31:10] + VA[19:12]*4``), 1x = section
      (``d[31:20] | VA[19:0]``, or with bit 18 a 16 MiB supersection ``d[31:24] | VA[23:0]``;
      ReconROS defect 11, docs/reconos.md). L2: 00 = fault, 01 = 64 KiB large page, 1x = 4 KiB page.

    A fault raises ``pgf`` with ``fault_addr`` = VA and waits: ``retry`` restarts the walk at
    the first level (the software has mapped the page); ``abort`` forwards the request with
    ``bad`` set, so the controller completes it without touching memory (rosgate addition:
    an address that cannot be mapped does not stall the other slots forever).

    Parameters
    ----------
    arch : str
    num_hwts : int
    tlb_entries : int
        Default 16 (ReconROS block designs).

    Members
    -------
    s_req : In(stream.Signature(request_layout)), m_req : Out(...)
        Requests with virtual / physical addresses.
    s_rdata : In(stream.Signature(rdata_layout)), m_rdata : Out(...)
    pgd : In(addr_bits)
    flush : In(1)
    pgf : Out(1)
    fault_addr : Out(64)
    retry, abort : In(1)
    tlb_hit, tlb_miss : Out(1)
        One-cycle pulses per translated request.
    """

    def __init__(self, arch, num_hwts, *, tlb_entries=16):
        self._arch = a = get_arch(arch)
        self._n = check_int("num_hwts", num_hwts, 1, 32)
        self._tlb_entries = check_int("tlb_entries", tlb_entries, 2, 256)
        req = stream.Signature(request_layout(a, num_hwts))
        rd = stream.Signature(rdata_layout(a, num_hwts))
        super().__init__({
            "s_req": In(req), "m_req": Out(req),
            "s_rdata": In(rd), "m_rdata": Out(rd),
            "pgd": In(a.addr_bits), "flush": In(1),
            "pgf": Out(1), "fault_addr": Out(64), "retry": In(1), "abort": In(1),
            "tlb_hit": Out(1), "tlb_miss": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        a = self._arch
        r64 = a.name == "r64"
        va_bits = 39 if r64 else 32
        pa_bits = a.addr_bits
        vpn_bits = va_bits - PAGE_BITS
        ppn_bits = pa_bits - PAGE_BITS
        m.submodules.tlb = tlb = TLB(vpn_bits, ppn_bits, self._tlb_entries)
        m.d.comb += tlb.flush.eq(self.flush)

        cur = Signal.like(self.s_req.payload)   # the request being translated
        va = cur.addr[:va_bits]
        desc = Signal(a.word_bits)              # last descriptor read
        level = Signal(2)
        desc_addr = Signal(pa_bits)
        ppn = Signal(ppn_bits)
        mmu_tag = self._n

        # Walk data for the MMU; everything else passes through.
        mine = Signal()
        m.d.comb += [
            mine.eq(self.s_rdata.payload.tag == mmu_tag),
            self.m_rdata.payload.eq(self.s_rdata.payload),
            self.m_rdata.valid.eq(self.s_rdata.valid & ~mine),
        ]
        with m.If(~mine):
            m.d.comb += self.s_rdata.ready.eq(self.m_rdata.ready)

        out = self.m_req
        m.d.comb += tlb.lookup_vpn.eq(self.s_req.payload.addr[PAGE_BITS:va_bits])

        def first_level():
            if r64:
                return Cat(Const(0, 3), va[30:39], self.pgd[PAGE_BITS:])
            return Cat(Const(0, 2), va[20:32], self.pgd[14:])

        # the TLB's lookup is registered: a request is translated in the cycle after it
        # arrived (its payload holds still until ready); a flush in between looks it up again
        looked = Signal()
        hit, hit_ppn = tlb.hit, tlb.hit_ppn

        with m.FSM():
            with m.State("IDLE"):
                # Hit: forward now. Miss: latch and walk.
                with m.If(out.ready):
                    m.d.sync += out.valid.eq(0)
                m.d.sync += looked.eq(self.s_req.valid & ~self.flush)
                with m.If(self.s_req.valid & looked & ~self.flush & (~out.valid | out.ready)):
                    m.d.sync += looked.eq(0)
                    m.d.comb += self.s_req.ready.eq(hit | self.s_req.payload.bad)
                    with m.If(self.s_req.payload.bad):
                        m.d.sync += [out.payload.eq(self.s_req.payload), out.valid.eq(1)]
                    with m.Elif(hit):
                        m.d.comb += self.tlb_hit.eq(1)
                        m.d.sync += [
                            out.payload.eq(self.s_req.payload),
                            out.payload.addr.eq(Cat(self.s_req.payload.addr[:PAGE_BITS],
                                                    hit_ppn)),
                            out.valid.eq(1),
                        ]
                    with m.Else():
                        m.d.comb += [self.s_req.ready.eq(1), self.tlb_miss.eq(1)]
                        m.d.sync += [cur.eq(self.s_req.payload), level.eq(0)]
                        m.next = "WALK_START"
            with m.State("WALK_START"):
                m.d.sync += [desc_addr.eq(first_level()), level.eq(0)]
                m.next = "WALK_READ"
            with m.State("WALK_READ"):
                m.d.sync += [
                    out.valid.eq(1),
                    out.payload.write.eq(0),
                    out.payload.length.eq(a.word_bytes),
                    out.payload.addr.eq(desc_addr),
                    out.payload.tag.eq(mmu_tag),
                    out.payload.bad.eq(0),
                ]
                m.next = "WALK_ISSUE"
            with m.State("WALK_ISSUE"):
                with m.If(out.ready):
                    m.d.sync += out.valid.eq(0)
                    m.next = "WALK_DATA"
            with m.State("WALK_DATA"):
                with m.If(mine):
                    m.d.comb += self.s_rdata.ready.eq(1)
                with m.If(self.s_rdata.valid & mine):
                    m.d.sync += desc.eq(self.s_rdata.payload.data)
                    m.next = "WALK_DECODE"
            with m.State("WALK_DECODE"):
                if r64:
                    table = desc[PAGE_BITS:48]
                    with m.If(~desc[0]):
                        m.next = "FAULT"
                    with m.Elif((level == 2) | ~desc[1]):
                        # page (L3), or block at L1 (1 GiB) / L2 (2 MiB)
                        with m.If(level == 0):
                            m.d.sync += ppn.eq(Cat(va[12:30], desc[30:48]))
                        with m.Elif(level == 1):
                            m.d.sync += ppn.eq(Cat(va[12:21], desc[21:48]))
                        with m.Else():
                            m.d.sync += ppn.eq(table)
                        m.next = "FILL"
                    with m.Else():
                        with m.If(level == 0):
                            m.d.sync += desc_addr.eq(Cat(Const(0, 3), va[21:30], table))
                        with m.Else():
                            m.d.sync += desc_addr.eq(Cat(Const(0, 3), va[12:21], table))
                        m.d.sync += level.eq(level + 1)
                        m.next = "WALK_READ"
                else:
                    kind = desc[:2]
                    with m.If(level == 0):
                        with m.If(kind == 0b00):
                            m.next = "FAULT"
                        with m.Elif(kind == 0b01):
                            m.d.sync += [desc_addr.eq(Cat(Const(0, 2), va[12:20], desc[10:32])),
                                         level.eq(1)]
                            m.next = "WALK_READ"
                        with m.Elif(desc[18]):
                            m.d.sync += ppn.eq(Cat(va[12:24], desc[24:32]))
                            m.next = "FILL"
                        with m.Else():
                            m.d.sync += ppn.eq(Cat(va[12:20], desc[20:32]))
                            m.next = "FILL"
                    with m.Else():
                        with m.If(kind == 0b00):
                            m.next = "FAULT"
                        with m.Elif(kind == 0b01):
                            m.d.sync += ppn.eq(Cat(va[12:16], desc[16:32]))
                            m.next = "FILL"
                        with m.Else():
                            m.d.sync += ppn.eq(desc[12:32])
                            m.next = "FILL"
            with m.State("FILL"):
                m.d.comb += [tlb.write.eq(1), tlb.write_vpn.eq(va[PAGE_BITS:]),
                             tlb.write_ppn.eq(ppn)]
                m.d.sync += [
                    out.payload.eq(cur),
                    out.payload.addr.eq(Cat(cur.addr[:PAGE_BITS], ppn)),
                    out.valid.eq(1),
                ]
                m.next = "IDLE"
            with m.State("FAULT"):
                m.d.comb += [self.pgf.eq(1), self.fault_addr.eq(cur.addr)]
                with m.If(self.retry):
                    m.next = "WALK_START"
                with m.Elif(self.abort):
                    m.d.sync += [out.payload.eq(cur), out.payload.bad.eq(1), out.valid.eq(1)]
                    m.next = "IDLE"
        return m
