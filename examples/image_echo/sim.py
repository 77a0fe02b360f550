"""Software side of the image echo for ``rosgate sim`` without ``--ros2``: a camera publishes
photographs and random images on /image_in, one at a time; the Echo hardware thread
publishes each on /image_out; the camera checks that what comes back is what it sent, field
for field, and records the cycles from publish to echo. With ``--ros2`` a ROS 2 graph takes
the camera's place (docs/ros2.md).

``--arg images=N`` (default 4): the example photographs of ``examples/images`` that fit
``--arg max_bytes`` first, then random ``bgr8``/``mono8``/``rgb8``/``mono16`` images of up to
``--arg max_side=S`` (default 64) pixels a side, with random frame ids and stamps."""

import random
from pathlib import Path

import cv2
import numpy as np

from host.reconos.messages import image_message, random_image_message
from host.sim_args import SimArg

IMAGES = Path(__file__).resolve().parent.parent / "images"
def images(args):
    """(name, message) of the run: small photographs first, then random images."""
    rng = random.Random(int(args.get("seed", 1)))
    count, side = int(args.get("images", 4)), int(args.get("max_side", 64))
    limit = int(args.get("max_bytes", 65536))
    out = []
    for k, path in enumerate(sorted(IMAGES.glob("*.png"))):
        pixels = cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_COLOR)
        if pixels is not None and pixels.nbytes <= limit and len(out) < count:
            out.append((path.name, image_message(pixels, k, frame_id=path.stem)))
    while len(out) < count:
        out.append((f"random {len(out)}", random_image_message(rng, side)))
    return out


def setup(ctx):
    ctx.echoes = ctx.broker.subscribe("/image_out")
    ctx.results["images"] = []


async def camera(ctx):
    for name, value in images(ctx.args):
        start = ctx.now()
        ctx.broker.publish("/image_in", value)
        got = await ctx.echoes.get()
        equal = got == value
        ctx.results["images"].append({"image": name, "width": value["width"],
                                      "height": value["height"], "encoding": value["encoding"],
                                      "bytes": len(value["data"]), "cycles": ctx.now() - start,
                                      "equal": equal})
        ctx.log(f"camera: {name} ({value['width']}x{value['height']} {value['encoding']}) "
                f"{'echoed unchanged' if equal else 'echoed DIFFERENT'} after "
                f"{ctx.now() - start} cycles")
    await ctx.cycles(10_000)
    ctx.results["extra_echoes"] = len(ctx.echoes)
    ctx.results["all_equal"] = all(i["equal"] for i in ctx.results["images"])


def summary(results, clock_mhz):
    lines = [f"{'image':<24} {'size':>9} {'encoding':>8} {'bytes':>7} {'cycles':>7}  equal"]
    for i in results["images"]:
        lines.append(f"{i['image']:<24} {i['width']:>4}x{i['height']:<4} {i['encoding']:>8} "
                     f"{i['bytes']:>7} {i['cycles']:>7}  {'yes' if i['equal'] else 'NO'}")
    lines.append(f"{sum(i['equal'] for i in results['images'])} of {len(results['images'])} "
                 f"images echoed unchanged at {clock_mhz:g} MHz; {results['extra_echoes']} "
                 f"echoes more than sent")
    return lines


ARGS = {
    "images": SimArg("images the camera sends", 4, kind=int),
    "seed": SimArg("seed of the random images", 1, kind=int),
    "max_side": SimArg("largest width and height of a random image, pixels", 64, kind=int),
    "max_bytes": SimArg("largest photograph taken from examples/images, bytes", 65536,
                        kind=int),
}

NODES = [camera]
