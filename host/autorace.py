"""The TurtleBot3 AutoRace lane-following nodes in software, with OpenCV (docs/av_chain.md):
the reference of the fpgaDDS chain and the software variant of ``examples/av_chain``.

Image compensation is the AutoRace node as it is written; the projection is
``cv2.warpPerspective`` to a 1000x600 bird's-eye view; lane following, lane control and the
traffic lights are the integer rules of docs/av_chain.md, which the hardware nodes compute
too.
"""

from dataclasses import dataclass, fields

import numpy as np

from gen.av_chain import BEV_CORNERS, ChainConfig, homography, inverse_map

__all__ = ["BEV_SIZE", "BEV_CORNERS", "CAMERA_SIZE", "LaneParams", "LightParams", "ControlParams",
           "compensate", "blur", "project", "homography", "inverse_map", "lane_centre",
           "LaneControl", "traffic_lights", "ChainStep", "SoftwareChain"]

CAMERA_SIZE = (640, 480)
#: the chain's parameters as the hardware takes them (gen.av_chain.ChainConfig): one
#: definition for both
_CHAIN = {f.name: f.default for f in fields(ChainConfig)}

#: the bird's-eye view (width, height): AutoRace's projection output
BEV_SIZE = (1000, 600)


def _cv2():
    import cv2
    return cv2


def compensate(image, clip_percent=1.0):
    """The AutoRace ``image_compensation`` node as it is written: the grey histogram
    (``cv2.calcHist``), ``clip_percent`` of the pixels clipped half at each end, then
    ``cv2.convertScaleAbs(image, -1, alpha, beta)`` with ``alpha = 255 / (max_gray -
    min_gray)``, ``beta = -min_gray * alpha``. Where the node fails (a range of 0: division by
    zero; no bin below the upper limit: its loop runs off the histogram) the frame passes
    unchanged and ``max_gray`` is -1, as the hardware does. Returns ``(image, min_gray,
    max_gray)``."""
    cv2 = _cv2()
    hist_size = 256
    gray_image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if clip_percent == 0:
        min_gray, max_gray, _, _ = cv2.minMaxLoc(gray_image)
        min_gray, max_gray = int(min_gray), int(max_gray)
    else:
        hist = cv2.calcHist([gray_image], [0], None, [hist_size], [0, hist_size])
        accumulator = np.cumsum(hist)
        total = accumulator[hist_size - 1]
        clip = clip_percent * (total / 100.0)
        clip /= 2.0
        min_gray = 0
        while accumulator[min_gray] < clip:
            min_gray += 1
        max_gray = hist_size - 1
        while max_gray >= 0 and accumulator[max_gray] >= (total - clip):
            max_gray -= 1
    input_range = max_gray - min_gray
    if input_range == 0:
        return image.copy(), min_gray, max_gray
    alpha = (hist_size - 1) / input_range
    beta = -min_gray * alpha
    return cv2.convertScaleAbs(image, -1, alpha, beta), min_gray, max_gray


def blur(image, ksize=5):
    """``cv2.GaussianBlur(image, (k, k), 0)`` (border reflect 101)."""
    return _cv2().GaussianBlur(image, (ksize, ksize), 0)


def project(image, matrix, size=BEV_SIZE):
    """``cv2.warpPerspective(image, matrix, size)``: bilinear, border constant 0."""
    cv2 = _cv2()
    return cv2.warpPerspective(image, matrix, tuple(size), flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0)


@dataclass(frozen=True)
class LaneParams:
    """Lane following: HSV bounds of the left (yellow) and right (white) stripe and the band of
    bird's-eye rows they are looked for in; ``lane_width`` places the centre when one stripe
    is missing."""
    yellow_lower: tuple = _CHAIN["yellow"][0]
    yellow_upper: tuple = _CHAIN["yellow"][1]
    white_lower: tuple = _CHAIN["white"][0]
    white_upper: tuple = _CHAIN["white"][1]
    band_top: int = _CHAIN["band_top"]
    lane_width: int = _CHAIN["lane_width"]
    min_pixels: int = _CHAIN["lane_min_pixels"]


def lane_centre(bev, params=LaneParams()):
    """The lane centre in the bird's-eye view: the mean column of the yellow pixels and of the
    white pixels in rows ``band_top`` to the bottom, the centre half-way between, rounded half
    up: ``(2 Sy Nw + 2 Sw Ny + 2 Ny Nw) // (4 Ny Nw)`` with ``S`` the column sums and ``N``
    the counts. With fewer than ``min_pixels`` of one colour, the other stripe's mean
    -+ ``lane_width / 2``; with neither, ``None``. Returns ``(centre, left, right)`` (means
    rounded down, ``None`` where missing)."""
    cv2 = _cv2()
    band = cv2.cvtColor(bev[params.band_top:], cv2.COLOR_BGR2HSV)
    cols = np.arange(band.shape[1], dtype=np.int64)
    sums = []
    for lower, upper in ((params.yellow_lower, params.yellow_upper),
                         (params.white_lower, params.white_upper)):
        mask = cv2.inRange(band, np.array(lower, np.uint8), np.array(upper, np.uint8)) > 0
        n = int(mask.sum())
        s = int((mask * cols).sum())
        sums.append((s, n) if n >= params.min_pixels else (0, 0))
    (sy, ny), (sw, nw) = sums
    left = sy // ny if ny else None
    right = sw // nw if nw else None
    if ny and nw:
        centre = (2 * sy * nw + 2 * sw * ny + 2 * ny * nw) // (4 * ny * nw)
    elif ny:
        centre = (2 * sy + ny * params.lane_width + ny) // (2 * ny)
    elif nw:
        centre = (2 * sw - nw * params.lane_width + nw) // (2 * nw)
    else:
        centre = None
    return centre, left, right


@dataclass(frozen=True)
class ControlParams:
    """Lane control: PD gains in 1/1024 (mrad/s per pixel), top speed (mm/s), the limits."""
    kp: int = _CHAIN["kp"]
    kd: int = _CHAIN["kd"]
    max_speed: int = _CHAIN["max_speed"]
    max_turn: int = _CHAIN["max_turn"]
    target: int = _CHAIN["target"]


class LaneControl:
    """AutoRace's ``control_lane`` in integers: ``error = centre - target``; the turn rate
    ``-(kp error + kd (error - last_error)) / 1024`` mrad/s (rounded toward zero, limited to
    ``max_turn``); the speed ``max_speed (500 - |error|) / 500`` mm/s (0 beyond). A stop
    command holds both at 0 until a start command; a frame without a centre keeps the last
    command."""

    def __init__(self, params=ControlParams()):
        self.params = params
        self.last_error = 0
        self.stopped = False
        self.command = (0, 0)

    def stop(self):
        self.stopped = True

    def start(self):
        self.stopped = False

    def step(self, centre):
        """One lane-following result: the new ``(speed_mm_s, turn_mrad_s)``."""
        p = self.params
        if centre is not None:
            error = centre - p.target
            raw = p.kp * error + p.kd * (error - self.last_error)
            turn = -(abs(raw) // 1024) * (1 if raw > 0 else -1)
            turn = max(-p.max_turn, min(p.max_turn, turn))
            speed = max(0, p.max_speed * (500 - abs(error)) // 500)
            self.last_error = error
            self.command = (speed, turn)
        if self.stopped:
            return (0, 0)
        return self.command


@dataclass(frozen=True)
class LightParams:
    """Traffic lights: HSV ranges of a lit red lamp (red wraps around H = 0) and a lit green
    one, and the pixels that make a detection."""
    red_ranges: tuple = _CHAIN["red_ranges"]
    green_range: tuple = _CHAIN["green_range"]
    min_pixels: int = _CHAIN["light_min_pixels"]


def traffic_lights(image, params=LightParams()):
    """``(red, green)``: whether the image has at least ``min_pixels`` of a lit red lamp and of
    a lit green one."""
    cv2 = _cv2()
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    red = np.zeros(image.shape[:2], bool)
    for lower, upper in params.red_ranges:
        red |= cv2.inRange(hsv, np.array(lower, np.uint8), np.array(upper, np.uint8)) > 0
    green = cv2.inRange(hsv, np.array(params.green_range[0], np.uint8),
                        np.array(params.green_range[1], np.uint8)) > 0
    return int(red.sum()) >= params.min_pixels, int(green.sum()) >= params.min_pixels


@dataclass
class ChainStep:
    """What the software chain made of one camera frame."""
    compensated: np.ndarray      # topic A
    blurred: np.ndarray          # topic B
    projected: np.ndarray        # topic C, the bird's-eye view
    lane: tuple                  # topic D: (centre, left, right) as lane_centre gives them
    red: bool
    green: bool
    stop: bool                   # a stop event (topic E) for this frame
    start: bool                  # a start event (topic F)
    command: tuple               # (speed_mm_s, turn_mrad_s)


class SoftwareChain:
    """The whole chain of a :class:`gen.av_chain.ChainConfig` in software, frame by frame:
    the reference of the hardware variants and the software variant itself. Traffic lights
    are detected on the compensated image; red sends a stop event on every red frame and
    arms green; green sends a start event on its first green frame after that."""

    def __init__(self, config):
        self.config = c = config
        self.lane_params = LaneParams(yellow_lower=c.yellow[0], yellow_upper=c.yellow[1],
                                      white_lower=c.white[0], white_upper=c.white[1],
                                      band_top=c.band_top, lane_width=c.lane_width,
                                      min_pixels=c.lane_min_pixels)
        self.light_params = LightParams(red_ranges=c.red_ranges, green_range=c.green_range,
                                        min_pixels=c.light_min_pixels)
        self.control = LaneControl(ControlParams(kp=c.kp, kd=c.kd, max_speed=c.max_speed,
                                                 max_turn=c.max_turn, target=c.target))
        self.armed = False

    def project(self, image):
        """The projection with the config's destination -> source map (what
        ``cv2.warpPerspective`` computes from the forward homography)."""
        cv2 = _cv2()
        return cv2.warpPerspective(image, np.array(self.config.matrix, np.float64),
                                   tuple(self.config.bev),
                                   flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    def step(self, image, bev=None, lane=None):
        """One camera frame through every node: a :class:`ChainStep`. To follow a hardware
        chain whose projection rounds differently (within 1, as the hardware does), lane
        following can take the hardware's bird's-eye view ``bev`` instead of its own
        projection, or lane control the hardware's lane result ``lane``."""
        c = self.config
        a = compensate(image, c.clip_percent)[0]
        b = blur(a, c.blur_ksize)
        projected = self.project(b)
        if lane is None:
            lane = lane_centre(projected if bev is None else bev, self.lane_params)
        red, green = traffic_lights(a, self.light_params)
        stop = red
        if red:
            self.control.stop()
            self.armed = True
        start = green and self.armed
        if start:
            self.control.start()
            self.armed = False
        command = self.control.step(lane[0])
        return ChainStep(a, b, projected, lane, red, green, stop, start, command)
