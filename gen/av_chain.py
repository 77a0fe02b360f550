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

from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from hdl.dds import Topic
from hdl.kernels import (GaussianBlur, ImageCompensation, LaneControl, LaneDetector,
                         LightEvent, LightNode, PerspectiveWarp, TrafficLightDetector)
from hdl.kernels.image import image_stream_signature
from hdl.kernels.lane import EVENT_STREAM

__all__ = ["ChainConfig", "AvChain", "homography", "inverse_map", "BEV_CORNERS",
           "CAMERA_CORNERS", "NODES", "chain_config", "chain_node", "chain_topics",
           "scaled_params",
           "scaled_config", "reconros_thread"]

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


#: the camera points of the example scene (examples/av_chain) that become the bird's-eye
#: corners, top-left, top-right, bottom-right, bottom-left, at scale 1
CAMERA_CORNERS = ((260, 260), (380, 260), (620, 460), (20, 460))


def scaled_params(scale=1.0, pixels_per_beat=4):
    """The :func:`chain_config` arguments of the example chain at ``scale`` (1: the 640x480
    camera and the 1000x600 bird's-eye view; the short tests use 0.2): sizes, corners, the
    lane band and the controller's target scale with the image, pixel counts with its area."""
    def sized(v):
        return int(round(v * scale))
    return dict(corners=tuple((sized(x), sized(y)) for x, y in CAMERA_CORNERS),
                bev_corners=tuple((sized(x), sized(y)) for x, y in BEV_CORNERS),
                camera=(sized(640), sized(480)), bev=(sized(1000), sized(600)),
                pixels_per_beat=pixels_per_beat, band_top=sized(400),
                lane_width=2 * sized(150), lane_min_pixels=max(1, round(200 * scale ** 2)),
                light_min_pixels=max(1, round(100 * scale ** 2)), target=sized(500))


def scaled_config(scale=1.0, pixels_per_beat=4):
    """The :class:`ChainConfig` of :func:`scaled_params`."""
    return chain_config(**scaled_params(scale, pixels_per_beat))


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


#: the chain's nodes, in the order of the diagram
NODES = ("compensation", "blur", "projection", "lane_following", "lane_control", "red_light",
         "green_light")


def chain_node(config, name, *, events=False):
    """The kernel of node ``name`` (one of :data:`NODES`) of the chain ``config``; with
    ``events`` a traffic-light node is a :class:`~hdl.kernels.LightNode` (detector and event
    rule, a beat per frame), otherwise only its detector."""
    c = config
    P = c.pixels_per_beat
    (cw, ch), (bw, bh) = c.camera, c.bev
    (rl0, ru0), (rl1, ru1) = c.red_ranges
    light = dict(pixels_per_beat=P, max_width=cw, max_height=ch,
                 bounds={"red_lower0": rl0, "red_upper0": ru0, "red_lower1": rl1,
                         "red_upper1": ru1, "green_lower": c.green_range[0],
                         "green_upper": c.green_range[1]},
                 min_pixels=c.light_min_pixels)
    if name in ("red_light", "green_light"):
        colour = name.split("_")[0]
        return LightNode(colour, **light) if events else TrafficLightDetector(**light)
    builders = {
        "compensation": lambda: ImageCompensation(clip_percent=c.clip_percent,
                                                  pixels_per_beat=P, max_width=cw,
                                                  max_height=ch),
        "blur": lambda: GaussianBlur(c.blur_ksize, pixels_per_beat=P, max_width=cw,
                                     max_height=ch),
        "projection": lambda: PerspectiveWarp(c.matrix, src_width=cw, src_height=ch,
                                              dst_width=bw, dst_height=bh, pixels_per_beat=P),
        "lane_following": lambda: LaneDetector(width=bw, height=bh, band_top=c.band_top,
                                               lane_width=c.lane_width,
                                               min_pixels=c.lane_min_pixels, yellow=c.yellow,
                                               white=c.white, pixels_per_beat=P),
        "lane_control": lambda: LaneControl(kp=c.kp, kd=c.kd, max_speed=c.max_speed,
                                            max_turn=c.max_turn, target=c.target),
    }
    if name not in builders:
        raise ValueError(f"no chain node {name!r}; the nodes are {', '.join(NODES)}")
    return builders[name]()


def chain_topics(config):
    """The chain's six topic fabrics (:class:`hdl.dds.Topic`), name -> fabric: A (compensated
    images) to the blur, the two light nodes and a tap; B, C and D each to its consumer and a
    tap; E (stop events) to lane control, the green node and a tap; F (start events) to lane
    control and a tap."""
    img = image_stream_signature(3, config.pixels_per_beat)

    def fabric(signature, subscribers):
        return Topic(1, subscribers, signature.data_width, keep=False,
                     user_width=1 if signature.user_width else 0, monitor=False)
    return {"a": fabric(img, 4), "b": fabric(img, 2), "c": fabric(img, 2),
            "d": fabric(EVENT_STREAM, 2), "e": fabric(EVENT_STREAM, 3),
            "f": fabric(EVENT_STREAM, 2)}


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
        cw, ch = c.camera
        nodes = {name: chain_node(c, name) for name in NODES}
        nodes["red_event"] = LightEvent("red")
        nodes["green_event"] = LightEvent("green")
        for name, node in nodes.items():
            m.submodules[name] = node
        comp, blur, proj = nodes["compensation"], nodes["blur"], nodes["projection"]
        lane, control = nodes["lane_following"], nodes["lane_control"]
        red, green = nodes["red_light"], nodes["green_light"]
        for det in (red, green):
            m.d.comb += [det.width.eq(cw), det.height.eq(ch)]
        for n in (comp, blur):
            m.d.comb += [n.width.eq(cw), n.height.eq(ch)]

        topics = chain_topics(c)
        for name, t in topics.items():
            m.submodules[f"topic_{name}"] = t

        def join(name, publisher, subscribers):
            wiring.connect(m, publisher, topics[name].s_axis[0])
            for j, sub in enumerate(subscribers):
                wiring.connect(m, topics[name].m_axis[j], sub)

        wiring.connect(m, wiring.flipped(self.camera), comp.i)
        join("a", comp.o, [blur.i, red.i, green.i, wiring.flipped(self.tap_a)])
        join("b", blur.o, [proj.i, wiring.flipped(self.tap_b)])
        join("c", proj.o, [lane.i, wiring.flipped(self.tap_c)])
        join("d", lane.o, [control.lane, wiring.flipped(self.tap_d)])
        wiring.connect(m, red.det, nodes["red_event"].det)
        wiring.connect(m, green.det, nodes["green_event"].det)
        stop_e, start_f = topics["e"], topics["f"]
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


def reconros_thread(ctx, name):
    """The ReconOS hardware thread of node ``name`` (one of :data:`NODES`) for a project's
    ``build(ctx)`` (examples/av_chain): its kernel in a
    :class:`~hdl.reconos.image_node.ImageNodeThread` or, for lane control, a
    :class:`~hdl.reconos.image_node.LaneControlThread`, with the resource names of the
    example's build.cfg. The thread's ``Parameters`` ``scale`` and ``pixels_per_beat`` choose
    the :func:`scaled_config`."""
    from hdl.reconos.image_node import ImageNodeThread, LaneControlThread
    scale = ctx.param("scale", 1.0, float)
    if not 0 < scale <= 1:
        raise ValueError(f"scale={scale!r} is not in (0, 1]")
    ppc = ctx.params.get("pixels_per_beat", "4")
    if not str(ppc).isdigit():
        raise ValueError(f"pixels_per_beat={ppc!r} is not 1, 2, 4 or 8")
    c = scaled_config(scale, int(ppc))
    kernel = chain_node(c, name, events=True)
    h = ctx.handle
    if name == "lane_control":
        return LaneControlThread(ctx.arch, kernel, h_lane=h("lane"), h_lane_msg=h("lane_in"),
                                 h_stop=h("stop"), h_stop_msg=h("stop_in"), h_start=h("start"),
                                 h_start_msg=h("start_in"), h_pub=h("pub"), h_out=h("cmd_out"))
    has = {r.name for r in ctx.thread.resources}
    out = {"lane_following": "lane_out", "red_light": "event_out",
           "green_light": "event_out"}.get(name, "image_out")
    sizes = {"compensation": (c.camera, c.camera), "blur": (c.camera, c.camera),
             "projection": (c.camera, c.bev), "lane_following": (c.bev, None),
             "red_light": (c.camera, None), "green_light": (c.camera, None)}[name]
    arm = dict(h_arm=h("arm"), h_arm_msg=h("arm_in")) if name == "green_light" else {}
    return ImageNodeThread(ctx.arch, kernel, h_sub=h("sub"), h_pub=h("pub"), h_in=h("image_in"),
                           h_out=h(out), image_offsets=ctx.offsets("sensor_msgs/msg/Image"),
                           in_size=sizes[0], out_size=sizes[1],
                           h_err=h("bad_frames") if "bad_frames" in has else None, **arm)
