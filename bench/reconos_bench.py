"""cocotb side of ``make bench`` for the ReconOS memory path: copies through the MEMIF engine
of a memory-test thread (one slot, zero-wait AxiRam), each checked byte for byte; cycles of the
whole operation and of the AXI activity (first address handshake to last response); and single
raw read requests of each burst length, their data checked."""

import json
import os
import random

import cocotb
from cocotb.triggers import FallingEdge

from host.reconos import PAGE
from tb.reconos_memory_tb import COPY, READ, MemoryTB


class BusWatch:
    """Cycles and beats of the AXI4 memory port."""

    def __init__(self, dut):
        self.dut = dut
        self.cycle = 0
        self.first = self.last = None
        self.beats = 0
        cocotb.start_soon(self._run())

    def reset(self):
        self.first = self.last = None
        self.beats = 0

    async def _run(self):
        d = self.dut
        while True:
            await FallingEdge(d.aclk)
            self.cycle += 1
            ar = int(d.m_axi_mem_arvalid.value) and int(d.m_axi_mem_arready.value)
            if ar and self.first is None:
                self.first = self.cycle
            if int(d.m_axi_mem_rvalid.value) and int(d.m_axi_mem_rready.value):
                self.beats += 1
                self.last = self.cycle
            if int(d.m_axi_mem_wvalid.value) and int(d.m_axi_mem_wready.value):
                self.beats += 1
            if int(d.m_axi_mem_bvalid.value) and int(d.m_axi_mem_bready.value):
                self.last = self.cycle


@cocotb.test()
async def measure(dut):
    sizes = json.loads(os.environ["ROSGATE_BENCH_CASE"])["sizes"]
    tb = MemoryTB(dut, ram_size=1 << 26)
    await tb.setup()
    mem = tb.memory
    biggest = max(sizes)
    src = mem.malloc(biggest, align=PAGE)
    dst = mem.malloc(biggest, align=PAGE)
    rng = random.Random(1)
    pattern = rng.randbytes(1 << 20)
    for off in range(0, biggest, 1 << 20):
        mem.write(src + off, pattern[:min(1 << 20, biggest - off)])
    # warm the TLB as a copy loop that runs repeatedly would have it
    watch = BusWatch(dut)
    records = []
    for size in sizes:
        watch.reset()
        _, cycles = await tb.op(0, COPY, src, dst, size, limit=50 * size + 100_000)
        data = mem.read(dst, size)
        assert data == mem.read(src, size), f"copy of {size} B differs"
        mem.write(dst, bytes(min(size, 1 << 20)))
        records.append({"bytes": size, "op_cycles": cycles,
                        "bus_cycles": watch.last - watch.first + 1, "beats": watch.beats})
        dut._log.info("copy %d B: %d cycles (bus %d, %d beats)", size, cycles,
                      records[-1]["bus_cycles"], watch.beats)
    bursts = []
    lengths = json.loads(os.environ["ROSGATE_BENCH_CASE"]).get("bursts", [])
    if lengths:     # the page of ``src`` into the TLB first: every measured read hits
        await tb.op(0, READ, src, tb.arch.word_bytes, results=1)
    for length in lengths:
        # one raw read request of ``length`` bytes at a 256-B boundary (never split)
        watch.reset()
        words = -(-length // tb.arch.word_bytes)
        got, _ = await tb.op(0, READ, src, length, results=words)
        assert b"".join(w.to_bytes(tb.arch.word_bytes, "little") for w in got) == \
            mem.read(src, words * tb.arch.word_bytes), f"read of {length} B differs"
        bursts.append({"length": length, "bus_cycles": watch.last - watch.first + 1,
                       "beats": watch.beats})
        dut._log.info("read burst %d B: %d bus cycles", length, bursts[-1]["bus_cycles"])
    with open(os.environ["ROSGATE_BENCH_OUT"], "w") as f:
        json.dump({"copies": records, "bursts": bursts}, f)
