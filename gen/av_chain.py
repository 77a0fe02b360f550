"""The fpgaDDS autonomous-driving chain as hardware nodes on hardware-mapped topics
(docs/av_chain.md, the fpgaDDS paper's Fig. 6):

    camera -> Image Compensation -> A -> Gaussian Blur -> B -> Image Projection -> C
           -> Lane Following -> D -> Lane Control -> command
    A -> Red Traffic Light -> E (stop) -> Lane Control
    A -> Green Traffic Light (armed by E) -> F (start) -> Lane Control

Every arrow is a :class:`hdl.dds.Topic`; topics A, B, C and D have one more subscriber, a
tap for the test bench (tie its ``tready`` high otherwise).
"""

from dataclasses import dataclass

from amaranth.hdl import Module, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from hdl.dds import Topic
from hdl.kernels import (GaussianBlur, ImageCompensation, LaneControl, LaneDetector,
                         PerspectiveWarp, TrafficLightDetector)
from hdl.kernels.colour import TRAFFIC_DETECTION
from hdl.kernels.image import image_stream_signature
from hdl.stream import AXIStreamSignature

__all__ = ["ChainConfig", "AvChain", "LightEvent", "homography", "inverse_map", "BEV_CORNERS",
           "chain_config"]

#: where the corners of AutoRace's 1000x600 bird's-eye view lie in it: top-left, top-right,
#: bottom-right, bottom-left
BEV_CORNERS = ((200, 0), (800, 0), (800, 600), (200, 600))


def homography(corners, bev_corners=BEV_CORNERS):
    """The projection's homography, camera pixel -> bird's-eye pixel: the four camera points
    ``corners`` (top-left, top-right, bottom-right, bottom-left) become ``bev_corners``
    (``cv2.getPerspectiveTransform``, as AutoRace's image_projection computes it)."""
    import cv2
    import numpy as np
    return cv2.getPerspectiveTransform(np.array(corners, np.float32),
                                       np.array(bev_corners, np.float32))


def inverse_map(matrix):
    """The destination -> source map the projection hardware takes: ``cv2.invert(matrix)``,
    as ``cv2.warpPerspective`` inverts it."""
    import cv2
    import numpy as np
    return cv2.invert(np.asarray(matrix, np.float64))[1]


def chain_config(*, corners, bev_corners=BEV_CORNERS, **params):
    """A :class:`ChainConfig` whose projection maps ``corners`` to ``bev_corners``."""
    matrix = inverse_map(homography(corners, bev_corners))
    return ChainConfig(matrix=tuple(tuple(float(v) for v in row) for row in matrix),
                       **params)

EVENT_STREAM = AXIStreamSignature(64, keep=False)


@dataclass(frozen=True)
class ChainConfig:
    """The chain's sizes and parameters (defaults: the paper's 640x480 camera and AutoRace's
    1000x600 bird's-eye view)."""
    matrix: tuple                      # the projection's inverse map (cv2.invert(H))
    camera: tuple = (640, 480)
    bev: tuple = (1000, 600)
    pixels_per_beat: int = 4
    clip_percent: float = 1.0
    blur_ksize: int = 5
    band_top: int = 400
    lane_width: int = 300
    lane_min_pixels: int = 200
    yellow: tuple = ((20, 100, 100), (40, 255, 255))
    white: tuple = ((0, 0, 170), (179, 60, 255))
    red_ranges: tuple = (((0, 150, 150), (10, 255, 255)), ((170, 150, 150), (179, 255, 255)))
    green_range: tuple = ((45, 150, 150), (90, 255, 255))
    light_min_pixels: int = 100
    kp: int = 2560
    kd: int = 7168
    max_speed: int = 220
    max_turn: int = 2000
    target: int = 500


class LightEvent(wiring.Component):
    """Turns a traffic-light detector's beat per frame into events: ``colour`` ``"red"``
    sends a stop event on every frame with red; ``"green"`` sends a start event on a frame
    with green once armed by a stop event (``arm``), and disarms.

    Members
    -------
    det : In(AXIStreamSignature(64, keep=False))
        :data:`~hdl.kernels.colour.TRAFFIC_DETECTION` beats.
    arm : In(stream.Signature(1))
        Stop events (green only; always ready).
    event : Out(EVENT_STREAM)
        One beat per event, ``tdata`` the frame's number, ``tlast`` set.
    """

    def __init__(self, colour):
        self.colour = colour
        super().__init__({"det": In(EVENT_STREAM), "arm": In(stream.Signature(1)),
                          "event": Out(EVENT_STREAM)})

    def elaborate(self, platform):
        m = Module()
        det = TRAFFIC_DETECTION(self.det.tdata)
        frame = Signal(32)
        armed = Signal()
        seen = det.red if self.colour == "red" else (det.green & armed)
        pending = Signal()
        m.d.comb += [self.arm.ready.eq(1), self.event.tvalid.eq(pending),
                     self.event.tlast.eq(1), self.det.tready.eq(~pending)]
        with m.If(self.arm.valid):
            m.d.sync += armed.eq(1)
        with m.If(self.event.tvalid & self.event.tready):
            m.d.sync += pending.eq(0)
        with m.If(self.det.tvalid & self.det.tready):
            m.d.sync += frame.eq(frame + 1)
            with m.If(seen):
                m.d.sync += [pending.eq(1), self.event.tdata.eq(frame)]
                if self.colour == "green":
                    m.d.sync += armed.eq(0)
        return m


class AvChain(wiring.Component):
    """The chain of :data:`ChainConfig` with its seven nodes and six topics.

    Members
    -------
    camera : In(image_stream_signature(3, P))
        Camera frames (``bgr8``, ``camera`` size).
    command : Out(AXIStreamSignature(64, keep=False))
        Lane Control's :data:`~hdl.kernels.lane.DRIVE_COMMAND` per frame.
    tap_a, tap_b, tap_c : Out(image_stream_signature(3, P))
        Topics A (compensated), B (blurred) and C (bird's-eye view).
    tap_d : Out(EVENT_STREAM)
        Topic D: :data:`~hdl.kernels.lane.LANE_RESULT` per frame.
    tap_e, tap_f : Out(EVENT_STREAM)
        Topics E (stop) and F (start).
    errors : Out(8)
        The nodes' bad-frame pulses, ORed per node.
    """

    def __init__(self, config):
        self.config = c = config
        P = c.pixels_per_beat
        img = image_stream_signature(3, P)
        super().__init__({"camera": In(img), "command": Out(EVENT_STREAM),
                          "tap_a": Out(img), "tap_b": Out(img), "tap_c": Out(img),
                          "tap_d": Out(EVENT_STREAM), "tap_e": Out(EVENT_STREAM),
                          "tap_f": Out(EVENT_STREAM), "errors": Out(8)})

    def elaborate(self, platform):
        m = Module()
        c = self.config
        P = c.pixels_per_beat
        (cw, ch), (bw, bh) = c.camera, c.bev
        img = image_stream_signature(3, P)
        (rl0, ru0), (rl1, ru1) = c.red_ranges
        light_bounds = {"red_lower0": rl0, "red_upper0": ru0, "red_lower1": rl1,
                        "red_upper1": ru1, "green_lower": c.green_range[0],
                        "green_upper": c.green_range[1]}
        nodes = {
            "compensation": ImageCompensation(clip_percent=c.clip_percent, pixels_per_beat=P,
                                              max_width=cw, max_height=ch),
            "blur": GaussianBlur(c.blur_ksize, pixels_per_beat=P, max_width=cw, max_height=ch),
            "projection": PerspectiveWarp(c.matrix, src_width=cw, src_height=ch,
                                          dst_width=bw, dst_height=bh, pixels_per_beat=P),
            "lane_following": LaneDetector(width=bw, height=bh, band_top=c.band_top,
                                           lane_width=c.lane_width,
                                           min_pixels=c.lane_min_pixels, yellow=c.yellow,
                                           white=c.white, pixels_per_beat=P),
            "lane_control": LaneControl(kp=c.kp, kd=c.kd, max_speed=c.max_speed,
                                        max_turn=c.max_turn, target=c.target),
            "red_light": TrafficLightDetector(pixels_per_beat=P, max_width=cw, max_height=ch,
                                              bounds=light_bounds,
                                              min_pixels=c.light_min_pixels),
            "green_light": TrafficLightDetector(pixels_per_beat=P, max_width=cw,
                                                max_height=ch, bounds=light_bounds,
                                                min_pixels=c.light_min_pixels),
            "red_event": LightEvent("red"),
            "green_event": LightEvent("green"),
        }
        for name, node in nodes.items():
            m.submodules[name] = node
        comp, blur, proj = nodes["compensation"], nodes["blur"], nodes["projection"]
        lane, control = nodes["lane_following"], nodes["lane_control"]
        red, green = nodes["red_light"], nodes["green_light"]
        for det in (red, green):
            m.d.comb += [det.width.eq(cw), det.height.eq(ch)]
        for n in (comp, blur):
            m.d.comb += [n.width.eq(cw), n.height.eq(ch)]

        def topic(name, signature, publisher, subscribers):
            t = Topic(1, len(subscribers), signature.data_width, keep=False,
                      user_width=1 if signature.user_width else 0, monitor=False)
            m.submodules[f"topic_{name}"] = t
            wiring.connect(m, publisher, t.s_axis[0])
            for j, sub in enumerate(subscribers):
                wiring.connect(m, t.m_axis[j], sub)

        wiring.connect(m, wiring.flipped(self.camera), comp.i)
        topic("a", img, comp.o, [blur.i, red.i, green.i, wiring.flipped(self.tap_a)])
        topic("b", img, blur.o, [proj.i, wiring.flipped(self.tap_b)])
        topic("c", img, proj.o, [lane.i, wiring.flipped(self.tap_c)])
        topic("d", EVENT_STREAM, lane.o, [control.lane, wiring.flipped(self.tap_d)])
        wiring.connect(m, red.det, nodes["red_event"].det)
        wiring.connect(m, green.det, nodes["green_event"].det)
        # E: the stop events, to Lane Control and the green node; F: the start events
        stop_e = Topic(1, 3, 64, keep=False, monitor=False)
        start_f = Topic(1, 2, 64, keep=False, monitor=False)
        m.submodules.topic_e, m.submodules.topic_f = stop_e, start_f
        wiring.connect(m, nodes["red_event"].event, stop_e.s_axis[0])
        wiring.connect(m, nodes["green_event"].event, start_f.s_axis[0])
        for t, event_port, taps in ((stop_e, (control.stop, nodes["green_event"].arm),
                                     self.tap_e),
                                    (start_f, (control.start,), self.tap_f)):
            for j, port in enumerate(event_port):
                m.d.comb += [port.valid.eq(t.m_axis[j].tvalid), port.payload.eq(1),
                             t.m_axis[j].tready.eq(port.ready)]
            wiring.connect(m, t.m_axis[len(event_port)], wiring.flipped(taps))
        wiring.connect(m, control.o, wiring.flipped(self.command))
        errors = [comp.err_short | comp.err_long | comp.err_size,
                  blur.err_short | blur.err_long | blur.err_size,
                  proj.err_short | proj.err_long | proj.err_size,
                  lane.err_short | lane.err_long | lane.err_size,
                  red.err_short | red.err_long | red.err_size,
                  green.err_short | green.err_long | green.err_size]
        for k, e in enumerate(errors):
            m.d.comb += self.errors[k].eq(e)
        return m
