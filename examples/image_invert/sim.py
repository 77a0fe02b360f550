"""Software side of the image inverter for ``rosgate sim``: a camera publishes images on
/image_in, one at a time, and checks each that comes back on /image_inverted: every data
byte 255 minus the one sent, every other field unchanged. ``--arg images=N`` (default 6)
random images (``bgr8``, ``rgb8``, ``mono8``, ``mono16``) of 0 to ``--arg max_side`` (default
40) pixels a side, so every length of the last memory word occurs."""

import random

from host.reconos.messages import random_image_message
from host.sim_args import SimArg

def setup(ctx):
    ctx.inverted = ctx.broker.subscribe("/image_inverted")
    ctx.results["images"] = []


async def camera(ctx):
    rng = random.Random(int(ctx.args.get("seed", 1)))
    count, side = int(ctx.args.get("images", 6)), int(ctx.args.get("max_side", 40))
    for k in range(count):
        value = random_image_message(rng, side, min_side=0)
        start = ctx.now()
        ctx.broker.publish("/image_in", value)
        got = await ctx.inverted.get()
        want = dict(value, data=bytes(255 - b for b in value["data"]))
        ctx.results["images"].append({"width": value["width"], "height": value["height"],
                                      "encoding": value["encoding"],
                                      "bytes": len(value["data"]),
                                      "cycles": ctx.now() - start, "equal": got == want})
        ctx.progress(k + 1, count, "images")
        ctx.log(f"camera: {value['width']}x{value['height']} {value['encoding']} "
                f"{'inverted' if got == want else 'DIFFERS'} after {ctx.now() - start} cycles")
    ctx.results["all_equal"] = all(i["equal"] for i in ctx.results["images"])


def summary(results, clock_mhz):
    lines = [f"{'size':>9} {'encoding':>8} {'bytes':>6} {'cycles':>7}  inverted"]
    for i in results["images"]:
        lines.append(f"{i['width']:>4}x{i['height']:<4} {i['encoding']:>8} {i['bytes']:>6} "
                     f"{i['cycles']:>7}  {'yes' if i['equal'] else 'NO'}")
    lines.append(f"{sum(i['equal'] for i in results['images'])} of {len(results['images'])} "
                 f"images inverted byte for byte at {clock_mhz:g} MHz")
    return lines


ARGS = {
    "images": SimArg("images the camera sends", 6, kind=int),
    "seed": SimArg("seed of the random images", 1, kind=int),
    "max_side": SimArg("largest width and height, pixels", 40, kind=int),
}

NODES = [camera]
