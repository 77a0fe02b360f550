"""cocotb side of ``make bench`` for the fpgaDDS lane-following chain (docs/av_chain.md): the
``av_chain`` top at full size, no idle and no backpressure, one scene frame at a time (the
next one once the command for the last one is out, as at 30 fps); every stage of every frame
checked against its golden model; per frame the chain-alpha latency (the frame's last beat
into the compensation to the command out), the lane centre and the ground truth written to
``ROSGATE_BENCH_OUT``."""

import json
import os

import cocotb

from tb.av_chain_tb import AvChainTB


@cocotb.test()
async def measure_chain(dut):
    tb = AvChainTB(dut)
    tb.set_pauses(0, 0)
    await tb.reset()
    count = int(os.environ.get("ROSGATE_AV_FRAMES", 100))
    report, latencies = [], []
    for frame in tb.frames(count):
        await tb.send(frame.image)
        await tb.wait_for(lambda: tb.sinks["command"].packets, 2_000_000, "the command")
        latencies.append(tb.sinks["command"].packets[0].cycles[-1] - tb.frame_in[-1])
        report.append(tb.check_frame(frame))
        if frame.index % 10 == 0:
            tb.log.info("frame %d: %d cycles", frame.index, latencies[-1])
    tb.check_events()
    out = {"latencies": latencies, "frames": report, "stops": tb.expected_stops,
           "starts": tb.expected_starts}
    with open(os.environ["ROSGATE_BENCH_OUT"], "w") as f:
        json.dump(out, f)
