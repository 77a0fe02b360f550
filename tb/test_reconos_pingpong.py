"""ReconROS ping-pong nodes in hardware threads (paper §5.1, Tables 3 and 4): an echo node
and a copy node, co-simulated with the software model (delegates, broker, process memory with
a page table the MMU walks). Spec: docs/reconos.md."""

import cocotb

from host.reconos import Resource
from host.simulator import clock_cycles

from .harness import amount, cocotb_bench
from .reconos_pingpong_tb import PingPongTB, run_round_trips
from .reconos_tb import system_configs


@cocotb.test()
async def echo_and_copy_round_trips(dut):
    """Echo and copy nodes answer messages of 4 B .. 16 KiB (64 KiB in make test-full)
    byte-exactly (sizes that are not a multiple of the word exercise the copy node's tail)."""
    tb = PingPongTB(dut)
    rt = await tb.setup()
    sizes = [4, 13, 8192, amount(16384, 65536) + 5]
    echo = await run_round_trips(tb, "/ping", tb.pong, sizes, 1)
    copy = await run_round_trips(tb, "/ping_copy", tb.pong_copy, sizes, 2, payload_only=True)
    dut._log.info("echo cycles %s copy cycles %s", echo, copy)
    assert not rt.errors, rt.errors
    # the MMU walked the page table the model built: misses were counted, and hits
    from hdl.reconos.protocol import ProcControlRegister as R
    hits = await rt.proc_read(R.TLB_HITS)
    misses = await rt.proc_read(R.TLB_MISSES)
    assert misses > 0 and hits > misses, (hits, misses)


@cocotb.test()
async def suspend_and_resume_repeatedly(dut):
    """HWT_Signal while the echo thread waits in ROS_TAKE: it writes THREAD_EXIT; reset +
    RESUME restarts it; three times on one slot, and it still echoes."""
    tb = PingPongTB(dut)
    rt = await tb.setup()
    for round_ in range(3):
        await run_round_trips(tb, "/ping", tb.pong, [16], 10 + round_)
        await rt.suspend_thread(tb.ECHO)
        assert rt.log[tb.ECHO][-1][0] == "thread_exit"
        await rt.resume_thread(tb.ECHO)
    await run_round_trips(tb, "/ping", tb.pong, [24, 4], 20)
    # the copy thread in the other slot was never disturbed
    await run_round_trips(tb, "/ping_copy", tb.pong_copy, [40], 21, payload_only=True)
    assert not rt.errors, rt.errors


@cocotb.test()
async def bad_calls_get_a_defined_outcome(dut):
    """An unknown command word is ignored (no reply) and recorded; a handle of the wrong
    resource type is refused (no reply, an error recorded, where ReconOS panics); the stuck
    thread is suspended through HWT_Signal and the other slots keep working."""
    tb = PingPongTB(dut)
    rt = await tb.setup()
    slot = tb.BAD
    for kinds in (("sem", "sem"), ("sem", "mutex")):
        res = [Resource("mbox", 8), Resource(kinds[0], 0), Resource(kinds[1], 0)]
        await rt.create_thread(slot, res)
        await clock_cycles(dut.aclk, 3000)
        if kinds[1] == "sem":
            assert res[1].state.value == 1 and res[2].state.value == 1
            assert rt.ignored[slot][-1] == 0x123
        else:
            assert "handle 2 is mutex, expected sem" in rt.errors[-1]
        await rt.suspend_thread(slot)
        await run_round_trips(tb, "/ping", tb.pong, [32], 30)
        await run_round_trips(tb, "/ping_copy", tb.pong_copy, [64], 31, payload_only=True)


CONFIGS = system_configs()

#: make test: r32 on Icarus; the other three in test-full (r64 on Verilator runs the same
#: round trips through the system benches of test_reconos_calls in make test)
test_reconos_pingpong = cocotb_bench("reconos", CONFIGS, long=[("system_r32", "verilator"),
                                                             ("system_r64", "icarus"),
                                                             ("system_r64", "verilator")])
