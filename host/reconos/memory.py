"""The process memory of a ReconROS application, as the hardware threads see it.

Written from the ReconOS spec (page tables, demand paging, the page-fault handler), not from
the RTL: the process's virtual memory in physical memory behind the system's AXI4 port (any
object with ``read(addr, n)`` and ``write(addr, data)``, such as cocotbext-axi's ``AxiRam``),
with a page table the model builds (ARMv8 4 KiB / 39-bit, three levels, for r64; ARMv7 short
descriptors with pages and 1 MiB sections for r32), demand-mapped pages and a page-fault
handler. Its heap is a first-fit allocator: :meth:`ProcessMemory.free` gives a block back,
and a later :meth:`~ProcessMemory.malloc` reuses it (its pages stay mapped, as a C heap keeps
them), so a run that frees what it no longer needs runs in bounded memory.
"""

from hdl.reconos.protocol import arch as get_arch
from host.compiled import MEMORY_OPTION

__all__ = ["ProcessMemory", "PAGE"]

PAGE = 4096

class ProcessMemory:
    """Virtual memory of one process in ``ram`` (an object with ``read(addr, n)`` and
    ``write(addr, data)``, e.g. cocotbext-axi's AxiRam).

    Parameters
    ----------
    arch : str
        ``"r32"`` or ``"r64"``.
    ram : Memory
    ram_size : int
        Bytes of physical memory; frames are handed out from ``phys_base`` upwards.
    heap_base : int
        First virtual address of :meth:`malloc` (r64 default above 4 GiB, so pointers need
        the full word: ReconROS defect 5, docs/reconos.md).
    """

    def __init__(self, arch, ram, ram_size, *, phys_base=0x1000, heap_base=None):
        self.arch = get_arch(arch)
        self.ram = ram
        self.ram_size = ram_size
        self._next_frame = phys_base
        self._next_va = heap_base if heap_base is not None else (
            0x12_3450_0000 if self.arch.name == "r64" else 0x4000_0000)
        self.pages = {}        # vpn -> pfn, pages the process owns
        self.mapped = set()    # vpns present in the hardware page table
        self.sections = {}     # r32: 1 MiB section index -> physical base
        self.faults = []       # VAs the fault handler was called for
        self.blocks = {}       # va -> size of the live heap blocks
        self._free = []        # [va, size] of freed heap extents, by address, coalesced
        #: bytes in live heap blocks now, and the most there were
        self.in_use = self.peak = 0
        self.pgd = self._frame(align=16 * 1024 if self.arch.name == "r32" else PAGE,
                               size=16 * 1024 if self.arch.name == "r32" else PAGE)
        self._tables = {}

    # ---- physical frames and page tables ----
    def _frame(self, *, align=PAGE, size=PAGE):
        base = -(-self._next_frame // align) * align
        if base + size > self.ram_size:
            used = self.usage()
            raise MemoryError(
                f"the co-simulation's physical memory is exhausted: {used['size']} bytes, "
                f"{used['in_use']} of them in {used['blocks']} live heap blocks (most "
                f"{used['peak']}), {used['free']} freed for reuse; more with {MEMORY_OPTION}")
        self._next_frame = base + size
        self.ram.write(base, bytes(size))
        return base

    def _word(self, pa, value=None):
        n = self.arch.word_bytes
        if value is None:
            return int.from_bytes(self.ram.read(pa, n), "little")
        self.ram.write(pa, value.to_bytes(n, "little"))

    def _table(self, key, size=PAGE, align=PAGE):
        if key not in self._tables:
            self._tables[key] = self._frame(size=size, align=align)
        return self._tables[key]

    def _map(self, vpn, pfn):
        va = vpn * PAGE
        if self.arch.name == "r64":
            l1 = self.pgd + ((va >> 30) & 0x1FF) * 8
            l2t = self._table(("l2", va >> 30))
            self._word(l1, l2t | 0b11)
            l2 = l2t + ((va >> 21) & 0x1FF) * 8
            l3t = self._table(("l3", va >> 21))
            self._word(l2, l3t | 0b11)
            self._word(l3t + ((va >> 12) & 0x1FF) * 8, (pfn * PAGE) | 0b11 | (1 << 10))
        else:
            l1 = self.pgd + (va >> 20) * 4
            l2t = self._table(("l2", va >> 20), size=1024, align=1024)
            self._word(l1, l2t | 0b01)
            self._word(l2t + ((va >> 12) & 0xFF) * 4, (pfn * PAGE) | 0b10)
        self.mapped.add(vpn)

    def unmap(self, va):
        """Remove the page of ``va`` from the hardware page table (the process keeps it)."""
        vpn = va // PAGE
        if self.arch.name == "r64":
            l3t = self._tables[("l3", (vpn * PAGE) >> 21)]
            self._word(l3t + (vpn & 0x1FF) * 8, 0)
        else:
            l2t = self._tables[("l2", (vpn * PAGE) >> 20)]
            self._word(l2t + (vpn & 0xFF) * 4, 0)
        self.mapped.discard(vpn)

    def remap(self, va, other_va):
        """Point the page of ``va`` at the frame of ``other_va`` (page table only)."""
        self._map(va // PAGE, self.pages[other_va // PAGE])

    def map_section(self, size=1 << 20):
        """r32: allocate a 1 MiB-aligned region mapped by one ARMv7 section descriptor
        (ReconROS defect 11, docs/reconos.md); return its VA."""
        if self.arch.name != "r32":
            raise ValueError("sections are an ARMv7 (r32) feature")
        va = -(-self._next_va // (1 << 20)) * (1 << 20)
        pa = self._frame(size=1 << 20, align=1 << 20)
        self._word(self.pgd + (va >> 20) * 4, pa | 0b10)
        for i in range((1 << 20) // PAGE):
            self.pages[va // PAGE + i] = pa // PAGE + i
        self.sections[va >> 20] = pa
        self._next_va = va + (1 << 20)
        return va

    # ---- the process's view ----
    def malloc(self, size, *, populate=True, align=64):
        """Allocate ``size`` bytes (zeroed) and return the VA. A freed extent that fits is
        reused first. With ``populate=False`` the block gets new pages that are missing from
        the hardware page table until the first fault."""
        if size < 0:
            raise ValueError(f"malloc of {size} bytes")
        size = max(size, 1)
        va = self._reuse(size, align) if populate else None
        if va is None:
            va = -(-self._next_va // align) * align
            if va > self._next_va:
                self._give_back(self._next_va, va - self._next_va)
            self._next_va = va + size
        self._back(va, size, populate)
        self.write(va, bytes(size))
        self.blocks[va] = size
        self.in_use += size
        self.peak = max(self.peak, self.in_use)
        return va

    def _back(self, va, size, populate):
        """Give the pages of ``[va, va + size)`` frames, and map them unless
        ``populate=False`` asks for a page fault first."""
        for vpn in range(va // PAGE, -(-(va + size) // PAGE)):
            if vpn not in self.pages:
                self.pages[vpn] = self._frame() // PAGE
                if populate:
                    self._map(vpn, self.pages[vpn])
            elif populate and vpn not in self.mapped:
                self._map(vpn, self.pages[vpn])

    def _reuse(self, size, align):
        """The VA of ``size`` bytes at ``align`` cut from the first freed extent that holds
        them (the rest stays free), or ``None``."""
        for i, (start, length) in enumerate(self._free):
            va = -(-start // align) * align
            if va + size > start + length:
                continue
            rest = [[start, va - start]] if va > start else []
            if va + size < start + length:
                rest.append([va + size, start + length - va - size])
            self._free[i:i + 1] = rest
            return va
        return None

    def owns(self, va):
        """Whether ``va`` is the start of a live heap block."""
        return va in self.blocks

    def free(self, va):
        """Give the block at ``va`` back for reuse (``free``); ``va`` must be a live block's
        start."""
        size = self.blocks.pop(va, None)
        if size is None:
            raise ValueError(f"free of 0x{va:x}: not the start of a live heap block")
        self.in_use -= size
        self._give_back(va, size)

    def _give_back(self, va, size):
        """Put ``[va, va + size)`` on the free list, merged with its free neighbours."""
        i = next((k for k, (start, _) in enumerate(self._free) if start > va),
                 len(self._free))
        self._free.insert(i, [va, size])
        if i + 1 < len(self._free) and va + size == self._free[i + 1][0]:
            self._free[i][1] += self._free.pop(i + 1)[1]
        if i > 0 and sum(self._free[i - 1]) == va:
            self._free[i - 1][1] += self._free.pop(i)[1]

    def usage(self):
        """What the heap holds: bytes in live blocks now and at most, live blocks, bytes
        freed for reuse, physical bytes handed out of the memory's size."""
        return {"in_use": self.in_use, "peak": self.peak, "blocks": len(self.blocks),
                "free": sum(n for _, n in self._free), "physical": self._next_frame,
                "size": self.ram_size}

    def translate(self, va):
        vpn = va // PAGE
        if vpn not in self.pages:
            raise KeyError(f"virtual address 0x{va:x} is not allocated")
        return self.pages[vpn] * PAGE + va % PAGE

    def read(self, va, n):
        out = bytearray()
        while n > 0:
            k = min(n, PAGE - va % PAGE)
            out += self.ram.read(self.translate(va), k)
            va, n = va + k, n - k
        return bytes(out)

    def write(self, va, data):
        data = bytes(data)
        while data:
            k = min(len(data), PAGE - va % PAGE)
            self.ram.write(self.translate(va), data[:k])
            va, data = va + k, data[k:]

    def handle_fault(self, va):
        """The page-fault handler (``proc_pgfhandler``): map the page if the process owns it.
        The page's contents are kept (ReconOS writes 0 to the faulting word: defect 7).
        Return whether the fault was resolved."""
        self.faults.append(va)
        vpn = va // PAGE
        if vpn in self.pages:
            self._map(vpn, self.pages[vpn])
            return True
        return False
