"""cocotb side of ``make bench`` for the fpgaDDS lane-following chain (docs/av_chain.md): the
``av_chain`` top at full size, no idle and no backpressure, one scene frame at a time (the
next once the command for the last one is out, as at 30 fps).

Per frame: the chain-alpha latency (the cycle the frame's last beat enters the compensation to
the cycle Lane Control's command leaves), the lane result and the command, checked against
the software nodes; every ``CHECK_EVERY``-th frame also every stage's image against OpenCV.
Nothing runs in Python on the cycles between beats: the camera port and the image taps are
compiled stream ports (:data:`HARNESS`; the camera's frame goes in whole, the taps' images
come out whole), the rare results are read when their ``tvalid`` rises and cycles come from the
simulation time. Results go to ``ROSGATE_BENCH_OUT``."""

import json
import os
from types import SimpleNamespace

import cocotb
from cocotb.triggers import Event, ReadOnly, RisingEdge
from cocotb.utils import get_sim_time

from host.compiled.streams import stream_harness, stream_sink, stream_source
from tb.av_chain_tb import CLOCK_NS, AvChainTB

#: frames whose images are captured and compared at every tap
CHECK_EVERY = 25
#: the image taps, always ready
IMAGE_TAPS = ("tap_a", "tap_b", "tap_c")
#: the Verilator harness of the bench (``run_bench(..., harness=...)``): the camera and the
#: image taps on compiled stream ports
HARNESS = stream_harness(sources=["camera"], sinks=list(IMAGE_TAPS))


def cycle_now():
    return int(get_sim_time("ns") // CLOCK_NS)


class EventTap:
    """Records the beats of a rarely valid, always ready output stream with their cycles."""

    def __init__(self, dut, prefix):
        self.tvalid = getattr(dut, f"{prefix}_tvalid")
        self.tdata = getattr(dut, f"{prefix}_tdata")
        getattr(dut, f"{prefix}_tready").value = 1
        self.beats = []
        self.arrived = Event()
        cocotb.start_soon(self._run(dut.aclk))

    async def _run(self, clock):
        while True:
            await RisingEdge(self.tvalid)
            while True:
                await ReadOnly()
                if self.tvalid.value != 1:
                    break
                self.beats.append((int(self.tdata.value), cycle_now()))
                self.arrived.set()
                await RisingEdge(clock)


class FastChainTB(AvChainTB):
    """:class:`~tb.av_chain_tb.AvChainTB` without per-cycle Python: image taps captured only
    for the frames to check."""

    def __init__(self, dut):
        self.dut = dut
        super().__init__(dut)

    def _start_sinks(self):
        dut = self.dut
        self.camera = stream_source(dut, "camera")
        self.images = {n: stream_sink(dut, n) for n in IMAGE_TAPS}
        self.events = {n: EventTap(dut, n) for n in ("tap_d", "tap_e", "tap_f", "command")}

    async def send_frame(self, image):
        """The frame into the camera port, whole; returns the cycle its last beat was taken."""
        await self.camera.send(image.tobytes())
        await self.camera.wait()
        return cycle_now()

    def take_images(self):
        """Each image tap's packets since the last call, as the :class:`tb.streams.PacketSink`
        packets :meth:`check_result` reads."""
        taken = {}
        for name, sink in self.images.items():
            packets = []
            while not sink.empty():
                packets.append(SimpleNamespace(data=bytes(sink.recv_nowait().tdata)))
            taken[name] = SimpleNamespace(packets=packets)
        return taken


@cocotb.test()
async def measure_chain(dut):
    tb = FastChainTB(dut)
    count = int(os.environ.get("ROSGATE_AV_FRAMES", 100))
    report, latencies = [], []
    await tb.reset()
    for frame in tb.frames(count):
        check_images = frame.index % CHECK_EVERY == 0
        n = len(tb.events["command"].beats)
        tb.events["command"].arrived.clear()
        t_in = await tb.send_frame(frame.image)
        while len(tb.events["command"].beats) == n:
            await tb.events["command"].arrived.wait()
            tb.events["command"].arrived.clear()
        await RisingEdge(dut.aclk)
        command, t_out = tb.events["command"].beats[-1]
        lane = tb.events["tap_d"].beats[-1][0]
        latencies.append(t_out - t_in)
        images = tb.take_images()
        report.append(tb.check_result(frame, lane, command, images if check_images else None))
        tb.log.info("frame %d: %d cycles", frame.index, latencies[-1])
    tb.check_event_beats([d for d, _ in tb.events["tap_e"].beats],
                         [d for d, _ in tb.events["tap_f"].beats])
    out = {"latencies": latencies, "frames": report, "stops": tb.expected_stops,
           "starts": tb.expected_starts}
    with open(os.environ["ROSGATE_BENCH_OUT"], "w") as f:
        json.dump(out, f)
