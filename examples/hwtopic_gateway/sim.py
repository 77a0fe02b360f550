"""Software side of the hardware-topic gateway demo for ``rosgate sim``: a camera publishes
images on /inputtopic; Threadb puts each on the hardware topic "nicehwtopic", where Threada
(its subscriber) publishes it on /outputtopic and the gateway on /topic/gateway. A viewer
checks that both software topics carry every image unchanged, in order. Then images published
on /topic/gateway go through the gateway onto the hardware topic and out of Threada on
/outputtopic (the gateway ignores its own publications, in software and in hardware).

``--arg images=N`` (default 3) random ``bgr8`` images of random sizes up to
``--arg max_side=S`` (default 24) pixels, with random frame ids and stamps."""

import random

from cocotb.queue import Queue
from host.reconos.messages import random_image_message
from host.sim_args import SimArg

def setup(ctx):
    ctx.outputs = ctx.broker.subscribe("/outputtopic")
    ctx.gateway = ctx.broker.subscribe("/topic/gateway")
    ctx.results["sent"] = []
    ctx.done = Queue()


async def camera(ctx):
    rng = random.Random(int(ctx.args.get("seed", 7)))
    n, side = int(ctx.args.get("images", 3)), int(ctx.args.get("max_side", 24))
    for k in range(n):
        value = random_image_message(rng, side)
        start = ctx.now()
        ctx.broker.publish("/inputtopic", value)
        got = await ctx.outputs.get()
        via_gateway = await ctx.gateway.get()
        ctx.results["sent"].append({
            "path": "/inputtopic -> /outputtopic and /topic/gateway",
            "width": value["width"], "height": value["height"], "bytes": len(value["data"]),
            "cycles": ctx.now() - start, "equal": got == value and via_gateway == value})
        ctx.log(f"camera: image {k} ({value['width']}x{value['height']} {value['encoding']}) "
                f"{'came back equal' if got == value and via_gateway == value else 'DIFFERS'}"
                f" after {ctx.now() - start} cycles")
    for k in range(n):
        value = random_image_message(rng, side)
        start = ctx.now()
        ctx.broker.publish("/topic/gateway", value)
        got = await ctx.outputs.get()
        ctx.results["sent"].append({
            "path": "/topic/gateway -> /outputtopic", "width": value["width"],
            "height": value["height"], "bytes": len(value["data"]),
            "cycles": ctx.now() - start, "equal": got == value})
    await ctx.cycles(20_000)
    # /topic/gateway holds the camera's own n publications (it subscribes it too); anything
    # more would be an echo the gateway should have dropped
    ctx.results["extra_outputs"] = len(ctx.outputs) + len(ctx.gateway) - n
    ctx.results["all_equal"] = all(s["equal"] for s in ctx.results["sent"])


def summary(results, clock_mhz):
    lines = [f"{'path':<48} {'size':>7} {'bytes':>6} {'cycles':>7}  equal"]
    for s in results["sent"]:
        lines.append(f"{s['path']:<48} {s['width']:>3}x{s['height']:<3} {s['bytes']:>6} "
                     f"{s['cycles']:>7}  {'yes' if s['equal'] else 'NO'}")
    lines.append(f"{sum(s['equal'] for s in results['sent'])} of {len(results['sent'])} "
                 f"images unchanged; {results['extra_outputs']} messages more than sent")
    return lines


ARGS = {
    "seed": SimArg("seed of the random images", 7, kind=int),
    "images": SimArg("images the camera sends", 3, kind=int),
    "max_side": SimArg("largest width and height of an image, pixels", 24, kind=int),
}

NODES = [camera]
