"""Bench of the exported ``av_chain`` top (gen.av_chain.AvChain; docs/av_chain.md): the fpgaDDS
lane-following chain as hardware nodes on hardware topics, fed driving-scene frames
(examples/av_chain/scene.py) at a fifth of the paper's size.

Golden models: OpenCV for compensation, blur and projection (the projection within 1, see
docs/kernels.md), host/autorace.py's software nodes for lane following, traffic lights and
lane control; the scene's ground truth for the light phases.
"""

from dataclasses import replace

import cocotb
import numpy as np
import pytest
from cocotb.triggers import RisingEdge
from cocotbext.axi import AxiStreamFrame

from tb.harness import cocotb_bench

from .av_chain_tb import SMALL, AvChainTB

CONFIGS = {"small_p1": SMALL}

# make test-full only, as the chain's other benches (its ReconROS variant in
# tb/test_project_sim.py, its export in tb/test_project_export.py): the latency and bad-frame
# test on Verilator, and every test on both simulators (the design is large: its
# idle-and-backpressure run takes half a minute). make test runs each of its nodes' kernels
# (tb/test_kernels_image.py, _warp, _lane).
test_av_chain = cocotb_bench("av_chain", {"small_p1": pytest.param(SMALL, marks=pytest.mark.full)},
                             simulators=("verilator",),
                             testcases=["chain_alpha_latency_and_bad_frames"])
test_av_chain_full = cocotb_bench("av_chain", {"small_p1_all": pytest.param(
    SMALL, marks=pytest.mark.full)})


@cocotb.test()
async def frames_equal_the_software_chain(dut):
    """Nine frames (dark, red, green light) under random idle at the camera and random
    backpressure on every tap and the command port: every stage equals its golden model, the
    stop events come on the red frames and the start event on the first green one."""
    tb = AvChainTB(dut)
    tb.set_pauses(0.2, 0.2)
    await tb.reset()
    frames = tb.frames(9, red_from=3, green_from=6)
    for f in frames:
        await tb.send(f.image)
    await tb.wait_for(lambda: len(tb.sinks["command"].packets) == len(frames), 2_000_000,
                      "the commands")
    report = tb.check_stages(frames)
    assert [r["light"] for r in report][3:7] == ["red", "red", "red", "green"]


@cocotb.test()
async def chain_alpha_latency_and_bad_frames(dut):
    """No idle, no backpressure: each frame's command comes one input-frame time (the
    compensation's output) and one output-frame time (the projection's) after the frame is
    in, plus the fixed steps (the blur's two rows, table, pipelines, divisions; under 1,000
    cycles more); the latency is the same for every frame (sd 0). A frame cut short is flagged by the compensation,
    padded, and the next frame's results are right."""
    tb = AvChainTB(dut)
    tb.set_pauses(0, 0)
    await tb.reset()
    frames = tb.frames(3)
    for f in frames:
        await tb.send(f.image)
        await tb.wait_for(lambda: len(tb.sinks["command"].packets) == f.index + 1, 200_000,
                          "the command")
    cw, ch = tb.camera_size
    bw, bh = tb.bev_size
    budget = cw * ch // tb.p + bw * bh // tb.p
    latencies = [p.cycles[-1] - t for p, t in zip(tb.sinks["command"].packets, tb.frame_in)]
    tb.log.info("chain alpha: %s cycles (in + out frame time %d)", latencies, budget)
    assert len(set(latencies)) == 1, latencies
    assert budget <= latencies[0] <= budget + 2 * cw // tb.p + 1000, (latencies, budget)

    # a frame cut after half its rows, then a good one
    errors = []

    async def watch():
        while True:
            await RisingEdge(dut.aclk)
            if int(dut.errors.value) & 1:
                errors.append(tb.cycle)
    cocotb.start_soon(watch())
    cut, good = tb.frames(5)[3:]
    data = cut.image.tobytes()[:cw * ch * 3 // 2]
    await tb.source.send(AxiStreamFrame(data))
    padded = np.frombuffer(data + bytes(cw * ch * 3 - len(data)), np.uint8).reshape(ch, cw, 3)
    await tb.send(good.image)
    await tb.wait_for(lambda: len(tb.sinks["command"].packets) == 5, 200_000, "the commands")
    assert len(errors) == 1, errors
    tb.check_stages(frames + [replace(cut, image=padded), good])
