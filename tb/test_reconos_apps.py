"""The ReconROS demo nodes as hardware threads, co-simulated with the software model:
the sort service server and action server (spec reconos.md §9.2, defect 14 fixed), the
ReconOS mailbox sort thread, two threads sharing a counter under a mutex, and the Sobel
service pair of the paper's Listings 2 and 3 (spec §9.1) on a real photograph."""

import random
import struct
from pathlib import Path

import cocotb
import cv2
import pytest
from cocotb.triggers import ClockCycles, with_timeout

from .harness import cocotb_bench
from .models.reconos_sw import Resource
from .models.sobel import sobel_byte_lanes
from .reconos_tb import ReconosTB, apps_configs, slot_of

IMAGES = Path(__file__).resolve().parent.parent / "examples" / "images"
IMAGE = "sensor_msgs/msg/Image"
SOBEL_SRV = "application_msgs/srv/SobelSrv"
SORT_SRV = "sorter_msgs/srv/Sort"
SORT_ACTION = "sorter_msgs/action/Sort"
#: simulated time limit of one request (the bench clock is 100 MHz)
LIMIT_US = 20_000


def image_msg(pixels, *, encoding="bgr8", step=None, seq=0):
    height, width = pixels.shape[:2]
    return {"header": {"stamp": {"sec": seq, "nanosec": 0}, "frame_id": "camera"},
            "height": height, "width": width, "encoding": encoding, "is_bigendian": 0,
            "step": step if step is not None else width * 3, "data": pixels.tobytes()}


class AppsTB(ReconosTB):
    async def setup(self):
        await self.reset()
        from gen.msg import MessageLibrary
        from .reconos_tb import EXAMPLE_MESSAGES
        rt = await self.start_runtime(MessageLibrary(EXAMPLE_MESSAGES, store="ros2_humble"))
        p = self.params
        self.SORT_SRV = slot_of(p, "sort_service")
        self.SORT_ACT = slot_of(p, "sort_action")
        self.MBOX_SORT = slot_of(p, "mbox_sort")
        self.COUNTERS = [slot_of(p, "counter", 0), slot_of(p, "counter", 1)]
        self.SOBEL = slot_of(p, "sobel_server")
        self.DIP = slot_of(p, "dip")
        return rt

    async def within(self, coro, what, limit_us=LIMIT_US):
        """Await ``coro`` for at most ``limit_us`` of simulated time."""
        try:
            return await with_timeout(coro, limit_us, "us")
        except Exception as exc:
            if type(exc).__name__ != "SimTimeoutError":
                raise
            raise AssertionError(f"{what}: no answer within {limit_us} us; delegate logs "
                                 f"{dict(self.runtime.log)}, errors {self.runtime.errors}")

    async def start_sort_service(self):
        await self.runtime.create_thread(self.SORT_SRV, [
            Resource("rosnode", "sorter"), Resource("rossrvmsgreq", SORT_SRV + "_Request"),
            Resource("rossrvs", "sorter"), Resource("rossrvmsgres", SORT_SRV + "_Response")])

    async def start_sort_action(self):
        await self.runtime.create_thread(self.SORT_ACT, [
            Resource("rosnode", "sorter_action"),
            Resource("rosactionmsggoalreq", SORT_ACTION + "_SendGoal_Request"),
            Resource("rosactionmsgresultres", SORT_ACTION + "_GetResult_Response"),
            Resource("rosactionmsgfeedback", SORT_ACTION + "_FeedbackMessage"),
            Resource("rosactions", "sort")])

    async def start_sobel_pair(self):
        rt = self.runtime
        server = [Resource("rosnode", "Sobel"), Resource("rossrvmsgreq", SOBEL_SRV + "_Request"),
                  Resource("rossrvs", "sobelservice"),
                  Resource("rossrvmsgres", SOBEL_SRV + "_Response")]
        await rt.create_thread(self.SOBEL, server)
        # the application's main() prepares the response image (spec §9.1: bgr8)
        import numpy as np
        rt.msgs.write(server[3].ptr, SOBEL_SRV + "_Response",
                      {"img": image_msg(np.zeros((0, 0, 3), np.uint8))})
        await rt.create_thread(self.DIP, [
            Resource("rosnode", "DIP"), Resource("rossub", "/image_raw"),
            Resource("rospub", "/image_filtered"), Resource("rosmsg", IMAGE),
            Resource("rossrvmsgreq", SOBEL_SRV + "_Request"),
            Resource("rossrvc", "sobelservice"),
            Resource("rossrvmsgres", SOBEL_SRV + "_Response")])
        self.filtered = self.broker.subscribe("/image_filtered")


async def run_sort_requests(tb, sizes, seed):
    """Call the sort service with ``std::rand()``-like values; check each response."""
    rng = random.Random(seed)
    for n in sizes:
        values = [rng.randrange(1 << 31) for _ in range(n)]
        response = await tb.within(tb.broker.call("sorter", {"unsorted": values}),
                                   f"sort service, {n} values")
        want = sorted(values) if 0 < n <= 2048 else []
        assert response["sorted"] == want, f"sort service: {n} values sorted wrongly"


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


async def run_sobel(tb, pixels, seq, *, step=None):
    """Publish an image to the DIP node; return the filtered image (or None after 2 ms of
    silence when the server refuses it)."""
    value = image_msg(pixels, step=step, seq=seq)
    tb.broker.publish("/image_raw", value)
    if step is not None and step != pixels.shape[1] * 3:
        await ClockCycles(tb.dut.aclk, 200_000)
        return None
    return await tb.within(tb.filtered.get(), f"filtered image {seq}", limit_us=100_000)


def check_sobel(out, pixels):
    """The published image is the input's, its payload the spec's Sobel (native border;
    ReconROS' written region compared on its own as well)."""
    import numpy as np
    height, width = pixels.shape[:2]
    words = width * 3 // 4
    want, written = sobel_byte_lanes(pixels.tobytes(), height, words)
    assert (out["height"], out["width"], out["encoding"], out["step"]) == \
        (height, width, "bgr8", width * 3)
    got = np.frombuffer(out["data"], np.uint8).reshape(height, words, 4)
    ref = np.frombuffer(want, np.uint8).reshape(height, words, 4)
    assert (got[written] == ref[written]).all(), "ReconROS' written region differs"
    assert out["data"] == want, "the border or row height-2 differs from the native mode"


async def run_sobel_pair(dut, photo_name):
    """The DIP node sends each image to the Sobel server and publishes the result: a real
    photograph, a random image, a refused one (not published), the photograph again.
    Returns the cycles of the first round trip."""
    import numpy as np
    tb = AppsTB(dut)
    rt = await tb.setup()
    await tb.start_sobel_pair()
    photo = cv2.imread(str(IMAGES / photo_name), cv2.IMREAD_COLOR)
    rng = np.random.default_rng(4)
    noise = rng.integers(0, 256, size=(12, 16, 3), dtype=np.uint8)
    start = cocotb.utils.get_sim_time("ns")
    check_sobel(await run_sobel(tb, photo, 0), photo)
    cycles = int((cocotb.utils.get_sim_time("ns") - start) // 10)
    check_sobel(await run_sobel(tb, noise, 1), noise)
    # a step that is no multiple of the word and does not match the payload: refused
    odd = rng.integers(0, 256, size=(5, 20, 3), dtype=np.uint8)
    assert await run_sobel(tb, odd, 2, step=61) is None
    assert not len(tb.filtered)
    check_sobel(await run_sobel(tb, photo, 3), photo)
    assert not rt.errors, rt.errors
    return cycles


@cocotb.test()
async def sobel_service_pair_on_a_photograph(dut):
    """The Sobel service pair on an 80x60 ``bgr8`` photograph (640x480 in
    test_reconos_apps_full)."""
    await run_sobel_pair(dut, "coffee_80x60.png")


CONFIGS = apps_configs()
#: r64 on Verilator in ``make test``; r32, and both on Icarus, in the long matrix (a fresh
#: 2-core ``make test`` stays under 10 minutes; the ``reconos`` top itself runs on both
#: simulators and both architectures in ``make test`` through the system benches)
test_reconos_apps = cocotb_bench("reconos", {"apps_r64": CONFIGS["apps_r64"]},
                                 simulators=("verilator",))
test_reconos_apps_long = cocotb_bench(
    "reconos", {k: pytest.param(v, marks=pytest.mark.full) for k, v in CONFIGS.items()},
    simulators=("icarus",))
test_reconos_apps_r32 = cocotb_bench(
    "reconos", {"apps_r32": pytest.param(CONFIGS["apps_r32"], marks=pytest.mark.full)},
    simulators=("verilator",))
