"""The ReconROS demo nodes as hardware threads, co-simulated with the software model:
the sort service server and action server (docs/reconos.md, defect 14 fixed), the
ReconOS mailbox sort thread, two threads sharing a counter under a mutex, and the Sobel
service pair of the paper's Listings 2 and 3 (docs/reconos.md) on a real photograph."""

import random
import struct

import cocotb
import pytest

from host.reconos import Resource

from .harness import cocotb_bench
from .reconos_apps_tb import SORT_ACTION, AppsTB, run_sobel_pair, run_sort_requests
from .reconos_tb import apps_configs, slot_of


@cocotb.test()
async def sort_service_fills_the_response(dut):
    """2048 values (the demo), odd and tiny counts (read-modify-write tail on r64), an
    oversized and an empty request (answered with an empty ``sorted``) (defect 14)."""
    tb = AppsTB(dut)
    rt = await tb.setup()
    await tb.start_sort_service()
    await run_sort_requests(tb, [2048, 1001, 1, 2049, 0, 2048], seed=1)
    assert not rt.errors, rt.errors
    calls = [c[0] for c in rt.log[tb.SORT_SRV]]
    assert calls.count("ros_message_set_size") == 6 and calls.count("ros_services_response") == 6


@cocotb.test()
async def sort_action_goal_feedback_result(dut):
    """The demo's client: ``random.sample(range(1, 100000), 2048)``; the goal is accepted,
    feedback percentages rise to 100.0, the result holds the sorted values. An empty goal
    is rejected and the server takes the next one."""
    tb = AppsTB(dut)
    rt = await tb.setup()
    await tb.start_sort_action()
    rng = random.Random(2)
    for unsorted in ([], rng.sample(range(1, 100000), 2048), rng.sample(range(1, 100000), 333)):
        goal = tb.broker.send_goal("sort", {"unsorted": unsorted})
        accepted = await tb.within(goal.accepted.get(), "action goal decision")
        if not unsorted:
            assert accepted is False
            continue
        assert accepted is True
        goal.request_result()
        result = await tb.within(goal.result.get(), "action result")
        assert result["result"]["sorted"] == sorted(unsorted)
        percents = []
        while len(goal.feedback):
            fb = goal.feedback.get_nowait()
            assert bytes(fb["goal_id"]["uuid"]) == goal.goal_id
            percents.append(fb["feedback"]["percent"])
        assert percents and percents == sorted(percents) and percents[-1] == 100.0, percents
        assert all(0 < p <= 100.0 for p in percents)
    assert not rt.errors, rt.errors


@cocotb.test()
async def hardware_action_client_and_server(dut):
    """A hardware action client (the call sequencer) sends a goal to the hardware sort action
    server: accepted, result requested, feedback taken, result taken into the client's
    message; the try variants read both reply words (defect 2) and the next call works."""
    from hdl.reconos.protocol import SIGNAL_THREAD_START
    tb = AppsTB(dut)
    rt = await tb.setup()
    await tb.start_sort_action()
    client = slot_of(tb.params, "calls")
    res = [Resource("mbox", 64), Resource("rosactionc", "sort"),
           Resource("rosactionmsggoalreq", SORT_ACTION + "_SendGoal_Request"),
           Resource("rosactionmsgresultres", SORT_ACTION + "_GetResult_Response"),
           Resource("rosactionmsgfeedback", SORT_ACTION + "_FeedbackMessage")]
    await rt.create_thread(client, res)
    unsorted = random.Random(5).sample(range(1, 100000), 700)
    rt.msgs.write(res[2].ptr, SORT_ACTION + "_SendGoal_Request",
                  {"goal_id": {"uuid": list(range(16, 32))}, "goal": {"unsorted": unsorted}})
    await tb.within(rt.exited[client].wait(), "action client")
    report = [res[0].state.get_nowait() for _ in range(len(res[0].state))]
    init, sent, accept, ret, rsend, fb, fb_try, ptr, try_ptr, try_ret = report
    assert (init, sent, accept, ret, rsend, fb) == (SIGNAL_THREAD_START, 0, 1, 0, 0, 0), report
    assert fb_try in (0, 1) and (ptr, try_ptr, try_ret) == (res[3].ptr, 0, 1), report
    result = rt.msgs.read(res[3].ptr, SORT_ACTION + "_GetResult_Response")
    assert result["result"]["sorted"] == sorted(unsorted)
    feedback = rt.msgs.read(res[4].ptr, SORT_ACTION + "_FeedbackMessage")
    assert bytes(feedback["goal_id"]["uuid"]) == bytes(range(16, 32))
    assert 0 < feedback["feedback"]["percent"] <= 100.0
    assert not rt.errors, rt.errors


@cocotb.test()
async def mailbox_sort_and_shared_counter(dut):
    """The ReconOS sort demo thread (address in through one mailbox, sorted in place, address
    back through another; all ones ends it) while two threads increment a shared counter
    under a mutex and post a semaphore per round: every increment counts."""
    tb = AppsTB(dut)
    rt = await tb.setup()
    wb = tb.arch.word_bytes
    mem = tb.memory
    sort_res = [Resource("mbox", 4), Resource("mbox", 4)]
    await rt.create_thread(tb.MBOX_SORT, sort_res)
    counter = mem.malloc(64)
    mem.write(counter, bytes(wb))
    shared = [Resource("mutex"), Resource("sem", 0)]
    cmds = [Resource("mbox", 4) for _ in tb.COUNTERS]
    for slot, cmd in zip(tb.COUNTERS, cmds):
        await rt.create_thread(slot, [cmd, *shared], init_data=counter)
    rng = random.Random(3)
    blocks = []
    for _ in range(2):
        addr = mem.malloc(8192)
        values = [rng.randrange(1 << 32) for _ in range(2048)]
        mem.write(addr, struct.pack("<2048I", *values))
        blocks.append((addr, values))
    total = 0
    for rnd, k in enumerate((40, 25)):
        for cmd in cmds:
            cmd.state.put(k)
        total += 2 * k
        addr, values = blocks[rnd]
        sort_res[0].state.put(addr)
        got = await tb.within(sort_res[1].state.get(), "mailbox sort")
        assert got == addr
        assert list(struct.unpack("<2048I", mem.read(addr, 8192))) == sorted(values)
        for _ in cmds:
            await tb.within(shared[1].state.wait(), "counter round")
        assert int.from_bytes(mem.read(counter, wb), "little") == total
    for cmd in cmds:
        cmd.state.put(0)
    sort_res[0].state.put((1 << tb.arch.word_bits) - 1)
    for slot in (*tb.COUNTERS, tb.MBOX_SORT):
        await tb.within(rt.exited[slot].wait(), f"slot {slot} exit")
    assert not rt.errors, rt.errors


@cocotb.test()
async def sobel_service_pair_on_a_photograph(dut):
    """The Sobel service pair on an 80x60 ``bgr8`` photograph (640x480 in
    test_reconos_apps_full)."""
    await run_sobel_pair(dut, "coffee_80x60.png")


CONFIGS = apps_configs()
#: all in the long matrix (to keep a fresh 2-core ``make test`` short; the
#: ``reconos`` top itself runs on both simulators and both architectures in ``make test``
#: through the system benches, and the example projects run the sort service, the sort
#: action and the Sobel pair there)
test_reconos_apps = cocotb_bench("reconos", {"apps_r64": pytest.param(CONFIGS["apps_r64"],
                                                                      marks=pytest.mark.full)},
                                 simulators=("verilator",))
test_reconos_apps_long = cocotb_bench(
    "reconos", {k: pytest.param(v, marks=pytest.mark.full) for k, v in CONFIGS.items()},
    simulators=("icarus",))
test_reconos_apps_r32 = cocotb_bench(
    "reconos", {"apps_r32": pytest.param(CONFIGS["apps_r32"], marks=pytest.mark.full)},
    simulators=("verilator",))
