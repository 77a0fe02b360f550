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

import numpy as np

#: camera points that become the bird's-eye corners (top-left, top-right, bottom-right,
#: bottom-left): the camera sees the road from 1.2 bird's-eye pixels ahead of its bumper
CORNERS = ((260, 260), (380, 260), (620, 460), (20, 460))
from host.autorace import BEV_SIZE, CAMERA_SIZE  # noqa: E402
LANE_WIDTH = 300
STRIPE_WIDTH = 16
BAND_TOP = 400
ASPHALT = (92, 96, 98)
SKY = (225, 200, 150)
YELLOW = (40, 200, 230)
WHITE = (235, 235, 235)
RED_LAMP, GREEN_LAMP, DARK_LAMP = (30, 30, 230), (60, 220, 40), (40, 40, 40)


@dataclass
class Frame:
    index: int
    image: np.ndarray          # camera, bgr8
    centre: float              # ground truth: the lane centre (bird's-eye column, band mean)
    light: str                 # "dark", "red" or "green"


def lane_centre_at(t, y):
    """Column of the lane centre in bird's-eye row ``y`` at frame ``t``: a slow sway and a
    curve that comes and goes."""
    sway = 60 * math.sin(2 * math.pi * t / 90)
    curve = 1.6e-4 * math.sin(2 * math.pi * t / 55) * (BEV_SIZE[1] - y) ** 2
    return 500 + sway + curve


def phase(t, red_from, green_from):
    return "dark" if t < red_from else "red" if t < green_from else "green"


def camera_homography():
    from host.autorace import homography
    return homography(CORNERS)


def bird_view(t, rng):
    """The road in the bird's-eye plane at 4x resolution (anti-aliased when reduced)."""
    import cv2
    s = 4
    w, h = BEV_SIZE
    road = np.empty((h * s, w * s, 3), np.uint8)
    road[:] = ASPHALT
    ys = (np.arange(h * s) + 0.5) / s
    xs = (np.arange(w * s) + 0.5) / s
    centre = np.array([lane_centre_at(t, y) for y in ys])[:, None]
    half = STRIPE_WIDTH / 2
    left = np.abs(xs[None, :] - (centre - LANE_WIDTH / 2)) < half
    right = np.abs(xs[None, :] - (centre + LANE_WIDTH / 2)) < half
    road[left] = YELLOW
    road[right] = WHITE
    small = cv2.resize(road, BEV_SIZE, interpolation=cv2.INTER_AREA)
    texture = rng.normal(0, 3, small.shape)
    return np.clip(small + texture, 0, 255).astype(np.uint8)


def camera_view(bev, t, rng, light):
    """The camera image: the road through the homography, sky above, the traffic light,
    exposure drift and sensor noise."""
    import cv2
    h = camera_homography()
    cam = cv2.warpPerspective(bev, h, CAMERA_SIZE, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    # what lies beyond the bird's-eye plane is sky
    ones = np.full(bev.shape[:2], 255, np.uint8)
    seen = cv2.warpPerspective(ones, h, CAMERA_SIZE,
                               flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP) > 0
    cam[~seen] = SKY
    cv2.rectangle(cam, (560, 30), (600, 130), (25, 25, 25), -1)
    lamps = {"red": (RED_LAMP, DARK_LAMP), "green": (DARK_LAMP, GREEN_LAMP),
             "dark": (DARK_LAMP, DARK_LAMP)}[light]
    cv2.circle(cam, (580, 55), 14, lamps[0], -1, lineType=cv2.LINE_AA)
    cv2.circle(cam, (580, 105), 14, lamps[1], -1, lineType=cv2.LINE_AA)
    gain = 0.75 + 0.2 * math.sin(2 * math.pi * t / 40)
    offset = 15 * math.cos(2 * math.pi * t / 65)
    noisy = cam.astype(np.float64) * gain + offset + rng.normal(0, 2, cam.shape)
    return np.clip(np.round(noisy), 0, 255).astype(np.uint8)


def frames(count=100, *, seed=1, red_from=None, green_from=None):
    """The scene's frames: ``count`` of them at 30 fps, the light red from frame
    ``red_from`` (default 30 % of the way) and green from ``green_from`` (60 %)."""
    rng = np.random.default_rng(seed)
    red_from = int(0.3 * count) if red_from is None else red_from
    green_from = int(0.6 * count) if green_from is None else green_from
    band = np.arange(BAND_TOP, BEV_SIZE[1]) + 0.5
    for t in range(count):
        light = phase(t, red_from, green_from)
        bev = bird_view(t, rng)
        image = camera_view(bev, t, rng, light)
        centre = float(np.mean([lane_centre_at(t, y) for y in band]))
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
