"""cocotb side of ``make bench`` for the ReconROS demo nodes (the ``apps`` system of
tb.reconos_tb): cycles of a sort service call, a sort action goal, a mailbox sort, a Sobel
service call and a DIP + Sobel round trip on the 640x480 photograph; every result checked
against its golden model."""

import json
import os
import random
import struct

import cocotb
import cv2
from cocotb.triggers import ClockCycles

from host.reconos import Resource
from tb.models.sobel import sobel_byte_lanes
from tb.reconos_apps_tb import IMAGES, AppsTB, check_sobel, image_msg, run_sobel


def now_cycles():
    return int(cocotb.utils.get_sim_time("ns") // 10)


async def timed(tb, coro, what):
    start = now_cycles()
    value = await tb.within(coro, what, limit_us=200_000)
    return value, now_cycles() - start


@cocotb.test()
async def measure_apps(dut):
    tb = AppsTB(dut, ram_size=1 << 26)
    rt = await tb.setup()
    rng = random.Random(1)
    records = {}

    await tb.start_sort_service()
    values = [rng.randrange(1 << 31) for _ in range(2048)]
    res, records["sort_service"] = await timed(
        tb, tb.broker.call("sorter", {"unsorted": values}), "sort service")
    assert res["sorted"] == sorted(values)

    await tb.start_sort_action()
    unsorted = rng.sample(range(1, 100000), 2048)
    start = now_cycles()
    goal = tb.broker.send_goal("sort", {"unsorted": unsorted})
    goal.request_result()
    assert await tb.within(goal.accepted.get(), "goal") is True
    res = await tb.within(goal.result.get(), "result", limit_us=200_000)
    records["sort_action"] = now_cycles() - start
    assert res["result"]["sorted"] == sorted(unsorted)
    records["sort_action_feedbacks"] = len(goal.feedback)

    mbox = [Resource("mbox", 2), Resource("mbox", 2)]
    await rt.create_thread(tb.MBOX_SORT, mbox)
    addr = tb.memory.malloc(8192)
    tb.memory.write(addr, struct.pack("<2048I", *values))
    mbox[0].state.put(addr)
    _, records["mbox_sort"] = await timed(tb, mbox[1].state.get(), "mailbox sort")
    assert list(struct.unpack("<2048I", tb.memory.read(addr, 8192))) == sorted(values)

    photo = cv2.imread(str(IMAGES / "coffee_640x480.png"), cv2.IMREAD_COLOR)
    await tb.start_sobel_pair()
    # the server alone, called as a ROS service (P-RR Table 6 "raw HW")
    res, records["sobel_service"] = await timed(
        tb, tb.broker.call("sobelservice", {"img": image_msg(photo)}), "sobel service")
    want, _ = sobel_byte_lanes(photo.tobytes(), 480, 480)
    assert res["img"]["data"] == want
    await ClockCycles(dut.aclk, 10)
    # DIP + server: subscribe, copy into the request, service, copy back, publish
    start = now_cycles()
    check_sobel(await run_sobel(tb, photo, 0), photo)
    records["sobel_pair"] = now_cycles() - start
    assert not rt.errors, rt.errors
    with open(os.environ["ROSGATE_BENCH_OUT"], "w") as f:
        json.dump(records, f)
