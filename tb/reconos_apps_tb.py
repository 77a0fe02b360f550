"""The test bench of the ReconROS demo nodes as hardware threads (the ``apps`` system of
:mod:`tb.reconos_tb`): the sort service and action servers, the mailbox sort, the shared
counter and the Sobel service pair, each started with the resources ReconROS gives it."""

import random
from pathlib import Path

import cocotb
import cv2
from cocotb.triggers import with_timeout

from host.reconos import Resource
from host.reconos.messages import image_message as image_msg
from host.simulator import clock_cycles

from .models.sobel import sobel_byte_lanes
from .reconos_tb import ReconosTB, slot_of

IMAGES = Path(__file__).resolve().parent.parent / "examples" / "images"
IMAGE = "sensor_msgs/msg/Image"
SOBEL_SRV = "application_msgs/srv/SobelSrv"
SORT_SRV = "sorter_msgs/srv/Sort"
SORT_ACTION = "sorter_msgs/action/Sort"
#: simulated time limit of one request (the bench clock is 100 MHz)
LIMIT_US = 20_000


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
        # the application's main() prepares the response image (docs/reconos.md: bgr8)
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


async def run_sobel(tb, pixels, seq, *, step=None):
    """Publish an image to the DIP node; return the filtered image (or None after 2 ms of
    silence when the server refuses it)."""
    value = image_msg(pixels, step=step, seq=seq)
    tb.broker.publish("/image_raw", value)
    if step is not None and step != pixels.shape[1] * 3:
        await clock_cycles(tb.dut.aclk, 200_000)
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


