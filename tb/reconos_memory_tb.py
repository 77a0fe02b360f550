"""The test bench of the MEMIF path: memory-test threads driven through their mailboxes
(operation codes of :class:`hdl.reconos.threads.MemoryTestThread`)."""

import random

from cocotb.triggers import RisingEdge

from hdl.reconos.protocol import MemStatus
from hdl.reconos.protocol import ProcControlRegister as R
from host.reconos import Resource

from .reconos_tb import ReconosTB

READ, WRITE, COPY = 0, 1, 2


class MemoryTB(ReconosTB):
    async def setup(self):
        await self.reset()
        rt = await self.start_runtime()
        self.slots = [i for i, t in enumerate(self.params["threads"]) if t["kind"] == "memtest"]
        self.res = []
        for slot in self.slots:
            res = [Resource("mbox", 16), Resource("mbox", 1024)]
            self.res.append(res)
            await rt.create_thread(slot, res)
        return rt

    async def op(self, slot, *words, results=1, limit=2_000_000):
        """Send an operation to memory-test thread number ``slot`` (0 or 1); return its result
        words and the cycles from the first command word to the last result."""
        cmd, out = self.res[slot][0].state, self.res[slot][1].state
        for wd in words:
            cmd.put(wd & ((1 << self.arch.word_bits) - 1))
        got, n = [], 0
        while len(got) < results:
            item = out.get_nowait()
            if item is None:
                await RisingEdge(self.dut.aclk)
                n += 1
                assert n <= limit, f"slot {slot}: operation {words[0]} did not finish"
            else:
                got.append(item)
        return got, n

    async def status(self):
        return MemStatus(await self.runtime.proc_read(R.MEM_STATUS))


async def run_copies(tb, slot, sizes, seed):
    rng = random.Random(seed)
    wb = tb.arch.word_bytes
    mem = tb.memory
    for size in sizes:
        src = mem.malloc(size + 512) + rng.randrange(0, 256, wb)
        dst = mem.malloc(size + 512) + rng.randrange(0, 256, wb)
        data = bytes(rng.randrange(256) for _ in range(size))
        mem.write(src, data)
        guard = mem.read(dst + size, 64)
        _, cycles = await tb.op(slot, COPY, src, dst, size)
        assert mem.read(dst, size) == data, f"slot {slot}: copy of {size} B differs"
        assert mem.read(dst + size, 64) == guard, f"slot {slot}: copy of {size} B overran"
        tb.dut._log.info("slot %d copied %d B in %d cycles", slot, size, cycles)


