"""ReconROS compatibility of the hardware-thread API: every OS call's command code and word
sequence (docs/reconos.md) as the thread writes them, the replies it reads (full
word width: defect 5), the fixed sequences of defects 1-3, the interruptible take (
including a late reply followed by a stray 0x904: defect 25), and HWT_Signal during a
blocking call (docs/reconos.md). The test plays the delegate through the reconos_osif
registers."""

import cocotb

from hdl.reconos.protocol import CALLS, INTERRUPTED_REPLY, SIGNAL_THREAD_START, Command
from hdl.reconos.threads import REPORT_MBOX

from .harness import cocotb_bench
from .reconos_tb import BLOCKED_SEM, ReconosTB, slot_of, system_configs


class CallsTB(ReconosTB):
    def __init__(self, dut):
        super().__init__(dut)
        self.slot = slot_of(self.params, "calls", h_report="absent")

    async def expect(self, words, what):
        got = [await self.runtime.osif_read(self.slot) for _ in words]
        assert got == list(words), f"{what}: thread wrote {[hex(g) for g in got]}, " \
                                   f"spec says {[hex(w) for w in words]}"

    async def reply(self, *words):
        for w in words:
            await self.runtime.osif_write(self.slot, w)

    async def expect_report(self, value, what):
        """The thread reports a received value with MBOX_PUT(REPORT_MBOX, value)."""
        cmd = await self.runtime.osif_read(self.slot)
        h = await self.runtime.osif_read(self.slot)
        v = await self.runtime.osif_read(self.slot)
        assert (cmd, h) == (Command.MBOX_PUT, REPORT_MBOX), f"{what}: no report"
        if value is not None:
            assert v == value, f"{what}: thread received 0x{v:x}, delegate sent 0x{value:x}"
        await self.reply(0)
        return v


@cocotb.test()
async def control_registers(dut):
    """reconos_osif, osif_intc and proc_control registers at the spec's offsets and bits."""
    from cocotb.triggers import ClockCycles

    from hdl.reconos.protocol import OsifRegister as O
    from hdl.reconos.protocol import ProcControlRegister as R
    from hdl.reconos.protocol import osif_register_offset
    tb = CallsTB(dut)
    await tb.reset()
    rt = await tb.start_runtime()
    w = tb.arch.word_bits
    msb = 1 << (w - 1)
    n, slot = tb.num_hwts, tb.slot
    assert await rt.proc_read(R.NUM_HWTS) == n
    assert await rt.proc_read(R.HWT_RESET) == (1 << n) - 1   # every thread held in reset
    assert await rt.proc_read(R.HWT_SIGNAL) == 0
    assert await rt.proc_read(R.TLB_HITS) == 0 and await rt.proc_read(R.TLB_MISSES) == 0

    async def osif(reg):
        return await rt._read(tb.osif, osif_register_offset(tb.arch, slot, reg))
    assert await osif(O.HW2SW_EMPTY) == msb            # empty, fill 0
    assert await osif(O.SW2HW_FULL) == 8               # not full, 8 free
    assert int(dut.irq_osif.value) == 0
    await rt.start_slot(slot)                          # the thread reports START (3 words)
    await ClockCycles(dut.aclk, 20)
    assert await osif(O.HW2SW_EMPTY) == 3              # not empty, fill 3
    assert int(dut.irq_osif.value) == 0                # not enabled
    await rt._write(tb.intc, 0, 1 << slot)
    await ClockCycles(dut.aclk, 2)
    assert int(dut.irq_osif.value) == 1
    assert await rt._read(tb.intc, 0) & 0xFFFF_FFFF == 1 << slot   # pending
    await rt._write(tb.intc, 0, 0)
    assert await osif(O.HW2SW_DATA) == Command.MBOX_PUT   # the read pops
    assert await osif(O.HW2SW_EMPTY) == 2
    resp = await tb.proc.read(0x1000, tb.arch.word_bytes)  # no register there
    assert int(resp.resp) == 2                         # SLVERR
    await rt.proc_write(R.HWT_SIGNAL, 1 << slot)
    assert await rt.proc_read(R.HWT_SIGNAL) == 1 << slot


@cocotb.test()
async def every_call_word_sequence(dut):
    tb = CallsTB(dut)
    await tb.reset()
    rt = await tb.start_runtime()
    w = tb.arch.word_bits
    await rt.start_slot(tb.slot)
    await tb.expect_report(SIGNAL_THREAD_START, "THREAD_INIT")
    prog = tb.params["threads"][tb.slot]["program"]
    covered = set()
    for i, (name, args) in enumerate(prog):
        c = CALLS[name]
        if name == "ros_take_interruptable":
            await tb.expect([Command.ROS_TAKE_INTERRUPTABLE, *args], name)
            cancel = prog[i + 1][0]
            assert cancel == "ros_take_interruptable_cancel"
            if args == [5, 6]:
                # no message: the cancel word comes, the delegate answers all ones
                await tb.expect([Command.ROS_TAKE_INTERRUPTABLE_CANCEL], "cancel")
                await tb.reply(INTERRUPTED_REPLY(w))
                await tb.expect_report(INTERRUPTED_REPLY(w), "cancel ptr")
                await tb.expect_report(0, "cancel: no message")
            else:
                # the message arrives first; a 0x904 may follow and is to be ignored
                ptr = 0xBEEF_0000 | i
                await tb.reply(ptr)
                word = await rt.osif_read(tb.slot)
                if word == Command.ROS_TAKE_INTERRUPTABLE_CANCEL:
                    word = await rt.osif_read(tb.slot)
                assert word == Command.MBOX_PUT
                assert [await rt.osif_read(tb.slot), await rt.osif_read(tb.slot)] == \
                    [REPORT_MBOX, ptr]
                await tb.reply(0)
                await tb.expect_report(1, "late message delivered")
            covered |= {name, "ros_take_interruptable_cancel"}
            continue
        if name == "ros_take_interruptable_cancel":
            continue
        if name == "sem_wait" and args == [BLOCKED_SEM]:
            await tb.expect([Command.SEM_WAIT, BLOCKED_SEM], "blocked sem_wait")
            await rt._set_signal(tb.slot, 1)
            await tb.expect([Command.THREAD_EXIT], "HWT_Signal during a blocking call")
            continue
        await tb.expect([int(c.command), *args], name)
        replies = [(0xA000_0000 + 16 * i + k) | ((0xCAFE << 40) if w == 64 else 0)
                   for k in range(len(c.replies))]
        await tb.reply(*replies)
        for k, r in enumerate(replies):
            await tb.expect_report(r, f"{name} reply {c.replies[k]}")
        covered.add(name)
    assert covered | {"thread_init", "thread_exit"} == set(CALLS), \
        set(CALLS) - covered


CONFIGS = system_configs()

#: make test: r32 on Icarus, r64 on Verilator; the other two in test-full
test_reconos_calls = cocotb_bench("reconos", CONFIGS, long=[("system_r32", "verilator"),
                                                             ("system_r64", "icarus")])
