"""The test bench of the ``av_chain`` top (gen.av_chain.AvChain): driving-scene frames into the
camera port, every topic's tap and the command port recorded with the cycle of each beat, and
the software chain (host/autorace.py, OpenCV) as the golden model of every stage."""

import logging
import os
import random
import sys

import cocotb
import numpy as np
from cocotb.triggers import RisingEdge
from cocotbext.axi import AxiStreamBus, AxiStreamFrame, AxiStreamSource

from gen.av_chain import scaled_params
from gen.tops import build_av_chain
from host import autorace
from host.simulator import start_clock
from tb.harness import ROOT, bench_params
from tb.streams import PacketSink, bursty_pauses, random_pauses, reset_aresetn

sys.path.insert(0, str(ROOT / "examples" / "av_chain"))
import scene  # noqa: E402  (the example's scene generator)

__all__ = ["CLOCK_NS", "SMALL", "AvChainTB"]

CLOCK_NS = 10


#: the short configuration: the scene at a fifth of its size, 1 pixel per beat
SMALL = scaled_params(0.2, 1)


class AvChainTB:
    TAPS = ("tap_a", "tap_b", "tap_c", "tap_d", "tap_e", "tap_f", "command")

    def __init__(self, dut):
        self.dut = dut
        self.params = bench_params()
        self.p = self.params["pixels_per_beat"]
        self.camera_size, self.bev_size = tuple(self.params["camera"]), tuple(self.params["bev"])
        self.rng = random.Random(cocotb.RANDOM_SEED)
        self.log = logging.getLogger("cocotb.tb")
        start_clock(dut.aclk, CLOCK_NS)
        self.frame_in = []           # cycle of each camera frame's last beat
        self.cycle = 0
        self._start_sinks()
        self.geometry = scene.Geometry(self.params["camera"][0] / scene.CAMERA_SIZE[0])
        self.reference = autorace.SoftwareChain(build_av_chain(**self.params).config)
        self.expected_stops, self.expected_starts = [], []
        self._frame = 0

    def _start_sinks(self):
        dut = self.dut
        self.source = AxiStreamSource(AxiStreamBus.from_prefix(dut, "camera"), dut.aclk,
                                      dut.aresetn, reset_active_level=False)
        self.source.log.setLevel(logging.WARNING)
        self.sinks = {name: PacketSink(dut, name, dut.aclk) for name in self.TAPS}
        cocotb.start_soon(self._watch_camera())

    async def _watch_camera(self):
        d = self.dut
        while True:
            await RisingEdge(d.aclk)
            self.cycle += 1
            if d.camera_tvalid.value == 1 and d.camera_tready.value == 1 and \
                    d.camera_tlast.value == 1:
                self.frame_in.append(self.cycle)

    async def reset(self):
        await reset_aresetn(self.dut)

    def set_pauses(self, idle, backpressure):
        self.source.set_pause_generator(random_pauses(random.Random(self.rng.random()), idle)
                                        if idle else None)
        for sink in self.sinks.values():
            sink.set_pause_generator(bursty_pauses(random.Random(self.rng.random()),
                                                   backpressure, 8) if backpressure else None)

    async def send(self, image):
        await self.source.send(AxiStreamFrame(image.tobytes()))

    def frames(self, count, **kwargs):
        return list(scene.frames(count, geometry=self.geometry, **kwargs))

    def images(self, tap, size):
        w, h = size
        return [np.frombuffer(bytes(p.data), np.uint8).reshape(h, w, 3)
                for p in self.sinks[tap].packets]

    async def wait_for(self, condition, timeout_cycles, what):
        for _ in range(timeout_cycles):
            if condition():
                return
            await RisingEdge(self.dut.aclk)
        raise AssertionError(f"timeout after {timeout_cycles} cycles waiting for {what}")

    def check_stages(self, frames):
        """Every stage of every frame against OpenCV and the software nodes (the frames' tap
        packets are consumed); returns the per-frame report."""
        report = [self.check_frame(f) for f in frames]
        self.check_events()
        return report

    def _pop(self, tap):
        packets = self.sinks[tap].packets
        assert packets, f"{tap}: no packet for the frame"
        return bytes(packets.pop(0).data)

    def check_frame(self, frame):
        """One frame's outputs (the oldest packet of every tap) against the golden models."""
        lane = int.from_bytes(self._pop("tap_d"), "little")
        command = int.from_bytes(self._pop("command"), "little")
        return self.check_result(frame, lane, command, self.sinks)

    def check_result(self, frame, lane, command, images=None):
        """A frame's lane result and command against the software nodes and, with ``images``
        (sinks of ``tap_a``, ``tap_b``, ``tap_c`` holding the frame's packets first), every
        stage's image against OpenCV; returns the frame's report."""
        from hdl.kernels.lane import DRIVE_COMMAND, LANE_RESULT
        k = self._frame
        self._frame += 1
        (cw, ch), (bw, bh) = self.camera_size, self.bev_size
        entry = {"frame": k, "truth": frame.centre, "light": frame.light}
        r = LANE_RESULT.from_bits(lane)
        got = (r.centre if r.has_centre else None, r.left if r.has_left else None,
               r.right if r.has_right else None)
        if images is not None:
            def pop(tap, w, h):
                packets = images[tap].packets
                assert packets, f"{tap}: no packet for frame {k}"
                return np.frombuffer(bytes(packets.pop(0).data), np.uint8).reshape(h, w, 3)
            comp, blurred, bev = pop("tap_a", cw, ch), pop("tap_b", cw, ch), pop("tap_c", bw, bh)
            # lane following is checked on the hardware's bird's-eye view (within 1 of OpenCV)
            step = self.reference.step(frame.image, bev=bev)
            assert (comp == step.compensated).all(), f"frame {k}: compensation differs from OpenCV"
            assert (blurred == step.blurred).all(), f"frame {k}: blur differs from OpenCV"
            diff = np.abs(bev.astype(int) - step.projected.astype(int))
            assert diff.max() <= 1, f"frame {k}: projection differs by {diff.max()}"
            assert got == step.lane, f"frame {k}: lane {got} != {step.lane}"
            entry["off_by_one"] = int((diff.max(axis=2) > 0).sum())
        else:
            step = self.reference.step(frame.image, lane=got)
        if step.stop:
            self.expected_stops.append(k)
        if step.start:
            self.expected_starts.append(k)
        cmd = DRIVE_COMMAND.from_bits(command)
        assert (cmd.speed, cmd.turn) == step.command, f"frame {k}: command"
        entry.update(centre=got[0], speed=cmd.speed, turn=cmd.turn, red=step.red,
                     green=step.green)
        return entry

    def check_events(self):
        self.check_event_beats(
            [int.from_bytes(p.data, "little") for p in self.sinks["tap_e"].packets],
            [int.from_bytes(p.data, "little") for p in self.sinks["tap_f"].packets])

    def check_event_beats(self, stops, starts):
        """The frames of the stop (E) and start (F) events against the golden rule."""
        assert stops == self.expected_stops and starts == self.expected_starts, (stops, starts)


PARAMS = bench_params() if "ROSGATE_PARAMS" in os.environ else {}
