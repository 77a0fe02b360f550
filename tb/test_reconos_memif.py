"""The MEMIF path in amaranth.sim: MemifEngine -> FIFOs -> MemifArbiter -> MMU ->
MemoryController -> a Python AXI4 memory with random response delays, against a byte-array
model. Spec: docs/reconos.md (request format, splitting, arbiter, MMU walk, controller)."""

import random

import pytest
from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.sim import Simulator

from hdl.reconos.fifo import ReconosFifo
from hdl.reconos.hwt import MemifEngine
from hdl.reconos.memctrl import MemoryController
from hdl.reconos.memif import MemifArbiter
from hdl.reconos.mmu import MMU
from hdl.reconos.protocol import arch as get_arch
from host.reconos import ProcessMemory


class _Ram:
    def __init__(self, size):
        self.data = bytearray(size)

    def read(self, addr, n):
        if addr + n > len(self.data):
            raise IndexError(addr)
        return bytes(self.data[addr:addr + n])

    def write(self, addr, data):
        if addr + len(data) > len(self.data):
            raise IndexError(addr)
        self.data[addr:addr + len(data)] = data


DEPTH = 64


class MemoryPath(wiring.Component):
    """n MemifEngines, each with its hwt2mem/mem2hwt FIFOs, sharing one arbiter, MMU and
    controller (the memory half of :class:`~hdl.reconos.ReconosSystem`)."""

    def __init__(self, arch, n):
        self.a = get_arch(arch)
        self.n = n
        # small FIFOs keep amaranth.sim fast; the engine's credits follow the depth
        self.engines = [MemifEngine(self.a, mem2hwt_depth=DEPTH) for _ in range(n)]
        self.arbiter = MemifArbiter(self.a, n)
        self.mmu = MMU(self.a, n)
        self.ctrl = MemoryController(self.a, n)
        super().__init__({})

    def elaborate(self, platform):
        m = Module()
        m.submodules.arbiter = self.arbiter
        m.submodules.mmu = self.mmu
        m.submodules.ctrl = self.ctrl
        wiring.connect(m, self.arbiter.req, self.mmu.s_req)
        wiring.connect(m, self.mmu.m_req, self.ctrl.s_req)
        wiring.connect(m, self.arbiter.wdata, self.ctrl.s_wdata)
        wiring.connect(m, self.ctrl.m_rdata, self.mmu.s_rdata)
        wiring.connect(m, self.mmu.m_rdata, self.arbiter.rdata)
        for i, e in enumerate(self.engines):
            m.submodules[f"engine{i}"] = e
            m.submodules[f"h2m{i}"] = h2m = ReconosFifo(self.a.word_bits, DEPTH)
            m.submodules[f"m2h{i}"] = m2h = ReconosFifo(self.a.word_bits, DEPTH)
            wiring.connect(m, e.memif_hwt2mem, h2m.w)
            wiring.connect(m, e.memif_mem2hwt, m2h.r)
            wiring.connect(m, self.arbiter.hwt2mem[i], h2m.r)
            wiring.connect(m, self.arbiter.mem2hwt[i], m2h.w)
        return m


async def transfer(ctx, ready, *payload):
    """Tick until a cycle in which ``ready`` was high at the clock edge; return the payload
    sampled at that edge."""
    while True:
        _, _, r, *values = await ctx.tick().sample(ready, *payload)
        if r:
            return values


def axi_memory(axi, ram, rng, *, delay=0.3):
    """An AXI4 subordinate process: INCR bursts, random delays on every channel."""
    wb = len(axi.wdata) // 8

    async def process(ctx):
        while True:
            await ctx.tick()
            # reads
            if ctx.get(axi.arvalid):
                ctx.set(axi.arready, 1)
                addr, n = await transfer(ctx, axi.arvalid, axi.araddr, axi.arlen)
                n += 1
                ctx.set(axi.arready, 0)
                for k in range(n):
                    while rng.random() < delay:
                        await ctx.tick()
                    try:
                        word = int.from_bytes(ram.read(addr + k * wb, wb), "little")
                        resp = 0
                    except IndexError:
                        word, resp = 0, 2
                    ctx.set(axi.rdata, word)
                    ctx.set(axi.rresp, resp)
                    ctx.set(axi.rlast, k == n - 1)
                    ctx.set(axi.rvalid, 1)
                    await transfer(ctx, axi.rready)
                    ctx.set(axi.rvalid, 0)
            elif ctx.get(axi.awvalid):
                ctx.set(axi.awready, 1)
                addr, n = await transfer(ctx, axi.awvalid, axi.awaddr, axi.awlen)
                n += 1
                ctx.set(axi.awready, 0)
                resp = 0
                for k in range(n):
                    while rng.random() < delay:
                        await ctx.tick()
                    ctx.set(axi.wready, 1)
                    data, strb, wlast = await transfer(ctx, axi.wvalid, axi.wdata, axi.wstrb,
                                                       axi.wlast)
                    ctx.set(axi.wready, 0)
                    assert wlast == (k == n - 1)
                    raw = data.to_bytes(wb, "little")
                    for b in range(wb):
                        if strb >> b & 1:
                            try:
                                ram.write(addr + k * wb + b, raw[b:b + 1])
                            except IndexError:
                                resp = 2
                while rng.random() < delay:
                    await ctx.tick()
                ctx.set(axi.bresp, resp)
                ctx.set(axi.bvalid, 1)
                await transfer(ctx, axi.bready)
                ctx.set(axi.bvalid, 0)
    return process


@pytest.mark.parametrize("arch", ["r64", "r32"])
def test_memory_path_reads_and_writes_through_the_mmu(arch):
    """Two engines write random data to random aligned places and read it back, at the same
    time; the data and memory equal the model and every request stays inside 256-B chunks."""
    a = get_arch(arch)
    wb = a.word_bytes
    ram = _Ram(1 << 22)
    mem = ProcessMemory(arch, ram, len(ram.data))
    bufs = [mem.malloc(20000), mem.malloc(20000)]
    dut = MemoryPath(arch, 2)
    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(axi_memory(dut.ctrl.axi, ram, random.Random(9)), background=True)
    results = {}

    def engine_test(i):
        e = dut.engines[i]

        async def bench(ctx):
            ctx.set(dut.mmu.pgd, mem.pgd)
            r = random.Random(i)
            for trial in range(4):
                length = r.randrange(1, 400) * wb
                offset = r.randrange(0, 20000 - length) // wb * wb
                va = bufs[i] + offset
                words = [r.getrandbits(a.word_bits) for _ in range(length // wb)]
                # write
                ctx.set(e.write_cmd.payload.addr, va)
                ctx.set(e.write_cmd.payload.length, length)
                ctx.set(e.write_cmd.valid, 1)
                await transfer(ctx, e.write_cmd.ready)
                ctx.set(e.write_cmd.valid, 0)
                for wd in words:
                    ctx.set(e.write_data.payload, wd)
                    ctx.set(e.write_data.valid, 1)
                    await transfer(ctx, e.write_data.ready)
                ctx.set(e.write_data.valid, 0)
                for _ in range(20000):
                    _, _, done = await ctx.tick().sample(e.write_done)
                    if done:
                        break
                else:
                    raise AssertionError("write_done never came")
                expect = b"".join(wd.to_bytes(wb, "little") for wd in words)
                assert mem.read(va, length) == expect, f"engine {i} trial {trial}: memory"
                # read back
                ctx.set(e.read_cmd.payload.addr, va)
                ctx.set(e.read_cmd.payload.length, length)
                ctx.set(e.read_cmd.valid, 1)
                await transfer(ctx, e.read_cmd.ready)
                ctx.set(e.read_cmd.valid, 0)
                got = []
                ctx.set(e.read_data.ready, 1)
                for _ in range(100000):
                    _, _, valid, payload = await ctx.tick().sample(
                        e.read_data.valid, e.read_data.payload)
                    if valid:
                        got.append(payload.data)
                        if payload.last:
                            break
                ctx.set(e.read_data.ready, 0)
                assert got == words, f"engine {i} trial {trial}: read back"
            results[i] = True
        return bench

    for i in range(2):
        sim.add_testbench(engine_test(i))
    sim.run()
    assert results == {0: True, 1: True}


def concurrent_axi_memory(axi, ram, rng, *, max_delay=24):
    """An AXI4 subordinate whose read and write channels run apart, as AXI allows: reads are
    accepted at once and answered later, each word read from ``ram`` when it is sent; a
    write's words are kept and reach ``ram`` only a random time after its last word, when its
    response is sent. A controller that lets a read overtake an earlier write of the same
    place (or a write overtake an earlier read) sees the other's data."""
    from collections import deque
    wb = len(axi.wdata) // 8
    accepted = deque()

    async def delay(ctx, most):
        for _ in range(rng.randrange(most + 1)):
            await ctx.tick()

    async def read_addresses(ctx):
        ctx.set(axi.arready, 1)
        while True:
            addr, n = await transfer(ctx, axi.arvalid, axi.araddr, axi.arlen)
            accepted.append((addr, n + 1))

    async def read_data(ctx):
        while True:
            await ctx.tick()
            if not accepted:
                continue
            addr, n = accepted.popleft()
            await delay(ctx, max_delay)
            for k in range(n):
                await delay(ctx, 2)
                ctx.set(axi.rdata, int.from_bytes(ram.read(addr + k * wb, wb), "little"))
                ctx.set(axi.rresp, 0)
                ctx.set(axi.rlast, k == n - 1)
                ctx.set(axi.rvalid, 1)
                await transfer(ctx, axi.rready)
                ctx.set(axi.rvalid, 0)

    async def writes(ctx):
        while True:
            ctx.set(axi.awready, 1)
            addr, n = await transfer(ctx, axi.awvalid, axi.awaddr, axi.awlen)
            ctx.set(axi.awready, 0)
            words = []
            for k in range(n + 1):
                await delay(ctx, 2)
                ctx.set(axi.wready, 1)
                word, strb, last = await transfer(ctx, axi.wvalid, axi.wdata, axi.wstrb,
                                                  axi.wlast)
                ctx.set(axi.wready, 0)
                assert last == (k == n)
                words.append((word, strb))
            await delay(ctx, max_delay)
            for k, (word, strb) in enumerate(words):
                raw = word.to_bytes(wb, "little")
                for b in range(wb):
                    if strb >> b & 1:
                        ram.write(addr + k * wb + b, raw[b:b + 1])
            ctx.set(axi.bresp, 0)
            ctx.set(axi.bvalid, 1)
            await transfer(ctx, axi.bready)
            ctx.set(axi.bvalid, 0)

    return read_addresses, read_data, writes


@pytest.mark.parametrize("arch", ["r64", "r32"])
def test_controller_orders_reads_and_writes_of_a_page(arch):
    """Random reads and writes of a few bytes to a whole chunk, over two pages, into the
    controller in one order; the memory runs its read and write channels apart with random
    delays. Every read returns what the requests before it left in memory (a byte-array
    model in request order), and reads and writes of different pages overlap on the bus."""
    a = get_arch(arch)
    wb = a.word_bytes
    rng = random.Random(5)
    ram = _Ram(1 << 16)
    model = bytearray(len(ram.data))
    ctrl = MemoryController(a, 1)
    pages = (0x2000, 0x5000)
    requests, expected_reads = [], []
    for _ in range(120):
        base = rng.choice(pages) + rng.randrange(0, 4096, 256)
        words = rng.randint(1, 256 // wb)
        addr = base + rng.randrange(256 // wb - words + 1) * wb
        if rng.random() < 0.5:
            data = [rng.getrandbits(8 * wb) for _ in range(words)]
            for k, word in enumerate(data):
                model[addr + k * wb:addr + (k + 1) * wb] = word.to_bytes(wb, "little")
            requests.append((1, addr, data))
        else:
            expected_reads.append([int.from_bytes(model[addr + k * wb:addr + (k + 1) * wb],
                                                  "little") for k in range(words)])
            requests.append((0, addr, words))
    sim = Simulator(ctrl)
    sim.add_clock(1e-8)
    for process in concurrent_axi_memory(ctrl.axi, ram, random.Random(11)):
        sim.add_testbench(process, background=True)
    write_words = [word for write, _, data in requests if write for word in data]
    got, overlap = [], []

    async def send_requests(ctx):
        for write, addr, body in requests:
            ctx.set(ctrl.s_req.payload.write, write)
            ctx.set(ctrl.s_req.payload.addr, addr)
            ctx.set(ctrl.s_req.payload.length, (len(body) if write else body) * wb)
            ctx.set(ctrl.s_req.valid, 1)
            await transfer(ctx, ctrl.s_req.ready)
        ctx.set(ctrl.s_req.valid, 0)

    async def send_write_data(ctx):
        for word in write_words:
            ctx.set(ctrl.s_wdata.payload.data, word)
            ctx.set(ctrl.s_wdata.valid, 1)
            await transfer(ctx, ctrl.s_wdata.ready)
        ctx.set(ctrl.s_wdata.valid, 0)

    async def take_read_data(ctx):
        total = sum(map(len, expected_reads))
        while len(got) < total:
            ctx.set(ctrl.m_rdata.ready, int(rng.random() < 0.8))
            _, _, valid, ready, payload = await ctx.tick().sample(
                ctrl.m_rdata.valid, ctrl.m_rdata.ready, ctrl.m_rdata.payload)
            if valid and ready:
                got.append(payload.data)

    async def watch(ctx):
        async for _, _, rvalid, rready, wvalid, wready in ctx.tick().sample(
                ctrl.axi.rvalid, ctrl.axi.rready, ctrl.axi.wvalid, ctrl.axi.wready):
            overlap.append(bool(rvalid and rready and wvalid and wready))

    sim.add_testbench(send_requests)
    sim.add_testbench(send_write_data)
    sim.add_testbench(take_read_data)
    sim.add_testbench(watch, background=True)
    sim.run()
    assert got == [w for words in expected_reads for w in words]
    assert any(overlap), "no cycle moved a read word and a write word together"
