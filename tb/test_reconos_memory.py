"""The MEMIF path of the ``reconos`` top under real and bad requests: copies through the
MEMIF engine in two contending slots, raw requests of bad lengths, page faults with and
without a mapping, TLB invalidation, AXI error responses and (r32) 1 MiB sections.
docs/reconos.md, ReconROS defects 6, 7, 8, 9 and 11."""

import random

import cocotb

from hdl.reconos.protocol import MemStatus
from hdl.reconos.protocol import ProcControlRegister as R
from host.reconos import PAGE

from .harness import amount, cocotb_bench
from .reconos_memory_tb import COPY, READ, WRITE, MemoryTB, run_copies
from .reconos_tb import system_configs


@cocotb.test()
async def copies_in_contending_slots(dut):
    """Both slots copy at the same time (round-robin arbitration); every byte arrives, none
    past the end is touched. The largest copy is 16 KiB in make test (four pages), 64 KiB in
    make test-full."""
    tb = MemoryTB(dut)
    rt = await tb.setup()
    sizes = [tb.arch.word_bytes, 256, 8192 + 8 * tb.arch.word_bytes, amount(16384, 65536)]
    t0 = cocotb.start_soon(run_copies(tb, 0, sizes, 1))
    t1 = cocotb.start_soon(run_copies(tb, 1, sizes[::-1], 2))
    await t0
    await t1
    assert await tb.status() == 0
    assert not rt.errors, rt.errors


@cocotb.test()
async def bad_lengths_are_rejected_not_hung(dut):
    """Defect 6: lengths that are not a non-zero multiple of W, longer than 256 B or crossing a
    256-B boundary are answered (zeros / drained) with BAD_REQUEST; memory is untouched and the
    next request works."""
    tb = MemoryTB(dut)
    await tb.setup()
    wb = tb.arch.word_bytes
    mem = tb.memory
    buf = mem.malloc(4096)
    mem.write(buf, bytes(range(256)) * 16)
    before = mem.read(buf, 4096)
    for length in (wb // 2, 0, 3 * wb + 1, 512, 256):
        words = -(-length // wb)
        addr = buf + (128 if length == 256 else 0)   # 256 B at offset 128 crosses a boundary
        got, _ = await tb.op(0, READ, addr, length, results=max(words, 1))
        assert got == [0] * max(words, 1), (length, got)
        assert MemStatus.BAD_REQUEST in await tb.status(), length
        await tb.op(0, WRITE, addr, length, 0x55, results=1)
        assert MemStatus.BAD_REQUEST in await tb.status(), length
    assert mem.read(buf, 4096) == before
    assert await tb.status() == 0   # read-to-clear
    got, _ = await tb.op(0, READ, buf + 8 * wb, 2 * wb, results=2)
    expect = [int.from_bytes(before[8 * wb + k * wb:8 * wb + (k + 1) * wb], "little")
              for k in range(2)]
    assert got == expect
    await tb.op(0, WRITE, buf, 2 * wb, 7, results=1)
    assert [int.from_bytes(mem.read(buf + k * wb, wb), "little") for k in range(2)] == [7, 8]


@cocotb.test()
async def page_faults_map_on_demand_and_keep_data(dut):
    """Defect 7: a page missing from the hardware page table faults, the handler maps it
    (read-touch) and the walk retries: the data the software wrote survives."""
    tb = MemoryTB(dut)
    rt = await tb.setup()
    wb = tb.arch.word_bytes
    mem = tb.memory
    buf = mem.malloc(3 * PAGE, populate=False, align=PAGE)
    data = bytes(random.Random(4).randrange(256) for _ in range(3 * PAGE))
    mem.write(buf, data)
    got, _ = await tb.op(0, READ, buf + PAGE + 64, 4 * wb, results=4)
    assert got == [int.from_bytes(data[PAGE + 64 + k * wb:PAGE + 64 + (k + 1) * wb], "little")
                   for k in range(4)]
    await tb.op(0, COPY, buf, buf + 2 * PAGE + 256, 512)
    assert mem.read(buf + 2 * PAGE + 256, 512) == data[:512]
    assert mem.read(buf + PAGE, PAGE) == data[PAGE:2 * PAGE]   # nothing zeroed
    assert len(mem.faults) >= 3 and not rt.unresolved_faults
    assert MemStatus.PAGE_FAULT in await tb.status()


@cocotb.test()
async def unmapped_address_is_aborted_and_other_slot_continues(dut):
    """A pointer outside the process: the fault cannot be resolved, the runtime aborts the
    request (FAULT_ABORT), the thread gets zeros, the status says PAGE_FAULT, and the other
    slot's copy completes."""
    tb = MemoryTB(dut)
    rt = await tb.setup()
    wb = tb.arch.word_bytes
    other = cocotb.start_soon(run_copies(tb, 1, [4096, 256], 8))
    bogus = 0x7_0000_0000 if tb.arch.name == "r64" else 0xE000_0000
    got, _ = await tb.op(0, READ, bogus, 2 * wb, results=2)
    assert got == [0, 0]
    assert rt.unresolved_faults == [bogus]
    assert MemStatus.PAGE_FAULT in await tb.status()
    await other
    got, _ = await tb.op(0, WRITE, bogus + 64, wb, 1, results=1)   # also aborted, no hang
    assert rt.unresolved_faults == [bogus, bogus + 64]


@cocotb.test()
async def tlb_flush_makes_a_remap_visible(dut):
    """Defect 8: after the page table changes, the TLB keeps the old translation until the
    flush register (or a PGD write) invalidates it; then the new mapping is used."""
    tb = MemoryTB(dut)
    rt = await tb.setup()
    wb = tb.arch.word_bytes
    mem = tb.memory
    a, b = mem.malloc(PAGE, align=PAGE), mem.malloc(PAGE, align=PAGE)
    mem.write(a, (1).to_bytes(wb, "little"))
    mem.write(b, (2).to_bytes(wb, "little"))
    assert (await tb.op(0, READ, a, wb))[0] == [1]
    hits = await rt.proc_read(R.TLB_HITS)
    mem.remap(a, b)
    assert (await tb.op(0, READ, a, wb))[0] == [1]          # stale, from the TLB
    assert await rt.proc_read(R.TLB_HITS) > hits            # hits really count (defect 16)
    await rt.proc_write(R.TLB_FLUSH, 1)
    assert (await tb.op(0, READ, a, wb))[0] == [2]
    mem.remap(a, a)                                          # back (frame of b is still b's)


@cocotb.test()
async def axi_error_response_is_reported(dut):
    """Defect 9: a page mapped to a physical address with no memory behind it: the read gets
    SLVERR (data zero), the write's response is checked; status and address say so; the next
    good request works."""
    tb = MemoryTB(dut)
    rt = await tb.setup()
    wb = tb.arch.word_bytes
    mem = tb.memory
    va = mem.malloc(PAGE, align=PAGE)
    mem._map(va // PAGE, (tb.ram_size + 16 * PAGE) // PAGE)
    got, _ = await tb.op(0, READ, va + 8 * wb, 2 * wb, results=2)
    assert got == [0, 0]
    assert MemStatus.AXI_SLVERR in await tb.status()
    await tb.op(0, WRITE, va, wb, 9, results=1)
    assert MemStatus.AXI_SLVERR in await tb.status()
    assert await rt.proc_read(R.MEM_ERROR_ADDR) == tb.ram_size + 16 * PAGE
    ok = mem.malloc(64)
    await tb.op(0, WRITE, ok, wb, 3, results=1)
    # a raw write answers once its data is in the FIFO; a read of the same word is ordered
    # behind the write by the controller, so after it the word is in memory
    got, _ = await tb.op(0, READ, ok, wb, results=1)
    assert got == [3]
    assert int.from_bytes(mem.read(ok, wb), "little") == 3


@cocotb.test()
async def armv7_section_mapping(dut):
    """Defect 11 (r32 only): a 1 MiB section descriptor translates (ReconOS treats it as a
    page table)."""
    tb = MemoryTB(dut)
    await tb.setup()
    if tb.arch.name != "r32":
        return
    mem = tb.memory
    sec = mem.map_section()
    data = bytes(random.Random(6).randrange(256) for _ in range(1024))
    mem.write(sec + 0x8_1000, data)
    await tb.op(0, COPY, sec + 0x8_1000, sec + 0xF_F000, 1024)
    assert mem.read(sec + 0xF_F000, 1024) == data


CONFIGS = system_configs()

#: make test: r32 on Icarus, r64 on Verilator; the other two in test-full
test_reconos_memory = cocotb_bench("reconos", CONFIGS, long=[("system_r32", "verilator"),
                                                             ("system_r64", "icarus")])
