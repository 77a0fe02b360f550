"""ReconROS ping-pong nodes in hardware threads (paper §5.1, Tables 3 and 4): an echo node
and a copy node, co-simulated with the software model (delegates, broker, process memory with
a page table the MMU walks). Spec: reconos.md §3, §5, §6."""

import random

import cocotb
from cocotb.triggers import RisingEdge

from .harness import cocotb_bench
from .models.reconos_sw import Resource
from .reconos_tb import ReconosTB, slot_of

IMAGE = "sensor_msgs/msg/Image"


#: slot 2: post semaphore 1, post semaphore 2, then an unknown command word
BAD_PROGRAM = [["sem_post", [1]], ["sem_post", [2]], ["command", [0x123]]]




def image(size, rng, seq=0):
    return {
        "header": {"stamp": {"sec": seq, "nanosec": 7}, "frame_id": "cam"},
        "height": 1, "width": size, "encoding": "mono8", "is_bigendian": 0, "step": size,
        "data": bytes(rng.randrange(256) for _ in range(size)),
    }


class PingPongTB(ReconosTB):
    async def setup(self):
        self.ECHO = slot_of(self.params, "echo")
        self.COPY = slot_of(self.params, "copy")
        self.BAD = slot_of(self.params, "calls", h_report=0)
        await self.reset()
        rt = await self.start_runtime()
        self.echo_res = [Resource("rosnode", "echo"), Resource("rossub", "/ping"),
                         Resource("rospub", "/pong"), Resource("rosmsg", IMAGE)]
        self.copy_res = [Resource("rosnode", "copy"), Resource("rossub", "/ping_copy"),
                         Resource("rospub", "/pong_copy"), Resource("rosmsg", IMAGE),
                         Resource("rosmsg", IMAGE)]
        self.pong = self.broker.subscribe("/pong")
        self.pong_copy = self.broker.subscribe("/pong_copy")
        await rt.create_thread(self.ECHO, self.echo_res)
        await rt.create_thread(self.COPY, self.copy_res)
        return rt

    async def ping(self, topic, reply_queue, value, limit):
        """Publish ``value`` and wait for the reply; return (reply, cycles)."""
        self.broker.publish(topic, value)
        n = 0
        while not len(reply_queue):
            await RisingEdge(self.dut.aclk)
            n += 1
            assert n <= limit, (f"no reply on {topic} within {limit} cycles; delegate logs "
                                f"{dict(self.runtime.log)}, ignored {dict(self.runtime.ignored)}")
        return reply_queue.get_nowait(), n


async def run_round_trips(tb, topic, queue, sizes, seed, *, payload_only=False):
    """Ping with Images of the given payload sizes; the echo returns the whole message, the
    copy node a new message with the same payload."""
    rng = random.Random(seed)
    results = []
    for i, size in enumerate(sizes):
        value = image(size, rng, i)
        reply, cycles = await tb.ping(topic, queue, value, limit=200_000 + 40 * size)
        if payload_only:
            assert reply["data"] == value["data"], \
                f"{topic}: the payload of a {size}-byte message differs"
        else:
            assert reply == value, f"{topic}: the reply to a {size}-byte message differs"
        results.append((size, cycles))
    return results


@cocotb.test()
async def echo_and_copy_round_trips(dut):
    """Echo and copy nodes answer messages of 4 B .. 64 KiB byte-exactly (sizes that are not a
    multiple of the word exercise the copy node's tail)."""
    tb = PingPongTB(dut)
    rt = await tb.setup()
    sizes = [4, 13, 8192, 65536 + 5]
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
    from cocotb.triggers import ClockCycles
    tb = PingPongTB(dut)
    rt = await tb.setup()
    slot = tb.BAD
    for kinds in (("sem", "sem"), ("sem", "mutex")):
        res = [Resource("mbox", 8), Resource(kinds[0], 0), Resource(kinds[1], 0)]
        await rt.create_thread(slot, res)
        await ClockCycles(dut.aclk, 3000)
        if kinds[1] == "sem":
            assert res[1].state.value == 1 and res[2].state.value == 1
            assert rt.ignored[slot][-1] == 0x123
        else:
            assert "handle 2 is mutex, expected sem" in rt.errors[-1]
        await rt.suspend_thread(slot)
        await run_round_trips(tb, "/ping", tb.pong, [32], 30)
        await run_round_trips(tb, "/ping_copy", tb.pong_copy, [64], 31, payload_only=True)


from .reconos_tb import system_configs  # noqa: E402 (uses this module's programs)

CONFIGS = system_configs()

#: make test: r32 on Icarus, r64 on Verilator; the other two in test-full
test_reconos_pingpong = cocotb_bench("reconos", CONFIGS, long=[("system_r32", "verilator"),
                                                             ("system_r64", "icarus")])
