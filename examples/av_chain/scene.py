"""Driving scenes for the lane-following chain (docs/av_chain.md): a road with a yellow left
and a white right stripe that curves over time, drawn in the bird's-eye plane and seen
through the camera's homography, a traffic light that is dark, then red, then green, and a
camera whose exposure drifts (what the image compensation is for). Every frame comes with its
ground truth: the lane centre in the bird's-eye view and the light's phase.

``python scene.py out_dir [frames]`` writes the frames as PNG files and ``truth.json``.
"""

import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

from gen.av_chain import CAMERA_CORNERS as CORNERS
from host.autorace import BEV_CORNERS, BEV_SIZE, CAMERA_SIZE

import numpy as np

LANE_WIDTH = 300
STRIPE_WIDTH = 16
BAND_TOP = 400
ASPHALT = (92, 96, 98)
SKY = (225, 200, 150)
YELLOW = (40, 200, 230)
WHITE = (235, 235, 235)
RED_LAMP, GREEN_LAMP, DARK_LAMP = (30, 30, 230), (60, 220, 40), (40, 40, 40)


@dataclass(frozen=True)
class Geometry:
    """The scene at ``scale`` (1: the 640x480 camera, the 1000x600 bird's-eye view; the
    short tests use 0.2)."""
    scale: float = 1.0

    def sized(self, v):
        return int(round(v * self.scale))

    @property
    def camera(self):
        return tuple(self.sized(v) for v in CAMERA_SIZE)

    @property
    def bev(self):
        return tuple(self.sized(v) for v in BEV_SIZE)

    @property
    def corners(self):
        return tuple((self.sized(x), self.sized(y)) for x, y in CORNERS)

    @property
    def bev_corners(self):
        return tuple((self.sized(x), self.sized(y)) for x, y in BEV_CORNERS)

    @property
    def band_top(self):
        return self.sized(BAND_TOP)

    @property
    def lane_width(self):
        return 2 * self.sized(LANE_WIDTH / 2)

    def homography(self):
        from host.autorace import homography
        return homography(self.corners, self.bev_corners)


@dataclass
class Frame:
    index: int
    image: np.ndarray          # camera, bgr8
    centre: float              # ground truth: the lane centre (bird's-eye column, band mean)
    light: str                 # "dark", "red" or "green"


def lane_centre_at(t, y, scale=1.0):
    """Column of the lane centre in bird's-eye row ``y`` at frame ``t``: a slow sway and a
    curve that comes and goes."""
    y = y / scale
    sway = 60 * math.sin(2 * math.pi * t / 90)
    curve = 1.6e-4 * math.sin(2 * math.pi * t / 55) * (BEV_SIZE[1] - y) ** 2
    return (500 + sway + curve) * scale


def phase(t, red_from, green_from):
    return "dark" if t < red_from else "red" if t < green_from else "green"


def bird_view(t, rng, geometry=Geometry()):
    """The road in the bird's-eye plane at 4x resolution (anti-aliased when reduced)."""
    import cv2
    s, g = 4, geometry
    w, h = g.bev
    road = np.empty((h * s, w * s, 3), np.uint8)
    road[:] = ASPHALT
    ys = (np.arange(h * s) + 0.5) / s
    xs = (np.arange(w * s) + 0.5) / s
    centre = np.array([lane_centre_at(t, y, g.scale) for y in ys])[:, None]
    half = max(STRIPE_WIDTH * g.scale, 2) / 2
    lane = LANE_WIDTH * g.scale
    left = np.abs(xs[None, :] - (centre - lane / 2)) < half
    right = np.abs(xs[None, :] - (centre + lane / 2)) < half
    road[left] = YELLOW
    road[right] = WHITE
    small = cv2.resize(road, (w, h), interpolation=cv2.INTER_AREA)
    texture = rng.normal(0, 3, small.shape)
    return np.clip(small + texture, 0, 255).astype(np.uint8)


def camera_view(bev, t, rng, light, geometry=Geometry()):
    """The camera image: the road through the homography, sky above, the traffic light,
    exposure drift and sensor noise."""
    import cv2
    g = geometry
    h = g.homography()
    size = g.camera
    cam = cv2.warpPerspective(bev, h, size, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    # what lies beyond the bird's-eye plane is sky
    ones = np.full(bev.shape[:2], 255, np.uint8)
    seen = cv2.warpPerspective(ones, h, size, flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP) > 0
    cam[~seen] = SKY
    z = g.sized
    cv2.rectangle(cam, (z(560), z(30)), (z(600), z(130)), (25, 25, 25), -1)
    lamps = {"red": (RED_LAMP, DARK_LAMP), "green": (DARK_LAMP, GREEN_LAMP),
             "dark": (DARK_LAMP, DARK_LAMP)}[light]
    cv2.circle(cam, (z(580), z(55)), z(14), lamps[0], -1, lineType=cv2.LINE_AA)
    cv2.circle(cam, (z(580), z(105)), z(14), lamps[1], -1, lineType=cv2.LINE_AA)
    gain = 0.75 + 0.2 * math.sin(2 * math.pi * t / 40)
    offset = 15 * math.cos(2 * math.pi * t / 65)
    noisy = cam.astype(np.float64) * gain + offset + rng.normal(0, 2, cam.shape)
    return np.clip(np.round(noisy), 0, 255).astype(np.uint8)


def frames(count=100, *, seed=1, red_from=None, green_from=None, geometry=Geometry()):
    """The scene's frames: ``count`` of them at 30 fps, the light red from frame
    ``red_from`` (default 30 % of the way) and green from ``green_from`` (60 %)."""
    rng = np.random.default_rng(seed)
    red_from = int(0.3 * count) if red_from is None else red_from
    green_from = int(0.6 * count) if green_from is None else green_from
    g = geometry
    band = np.arange(g.band_top, g.bev[1]) + 0.5
    for t in range(count):
        light = phase(t, red_from, green_from)
        bev = bird_view(t, rng, g)
        image = camera_view(bev, t, rng, light, g)
        centre = float(np.mean([lane_centre_at(t, y, g.scale) for y in band]))
        yield Frame(t, image, centre, light)


def main(argv):
    import cv2
    out = Path(argv[1])
    count = int(argv[2]) if len(argv) > 2 else 100
    out.mkdir(parents=True, exist_ok=True)
    truth = []
    for f in frames(count):
        cv2.imwrite(str(out / f"frame_{f.index:03d}.png"), f.image)
        truth.append({"frame": f.index, "centre": round(f.centre, 3), "light": f.light})
    (out / "truth.json").write_text(json.dumps(truth, indent=1) + "\n")
    print(f"scene: wrote {count} frames and truth.json to {out}")


if __name__ == "__main__":
    main(sys.argv)
