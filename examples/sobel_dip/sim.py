"""Software nodes of the Sobel/DIP application (paper Fig. 5) for ``rosgate sim``.

Node 1, the camera, publishes each photograph on /image_raw as a ``bgr8``
sensor_msgs/Image and waits for its filtered version before sending the next (the paper
measures one image at a time). Node 4, the viewer, takes /image_filtered, writes the result
and OpenCV's result as PNG and compares them byte for byte.

``--arg images=a.png,b.png`` chooses the photographs (paths relative to this folder, or
names in ``examples/images``); default: the 80x60 coffee photograph.
"""

from pathlib import Path

import cv2
import numpy as np
from cocotb.queue import Queue

from tb.models.sobel import sobel_byte_lanes_cv2

HERE = Path(__file__).resolve().parent
IMAGES = HERE.parent / "images"
SOBEL_RESPONSE = "application_msgs/srv/SobelSrv_Response"


def image_msg(pixels, seq):
    height, width = pixels.shape[:2]
    return {"header": {"stamp": {"sec": seq, "nanosec": 0}, "frame_id": "camera"},
            "height": height, "width": width, "encoding": "bgr8", "is_bigendian": 0,
            "step": width * 3, "data": pixels.tobytes()}


def _paths(ctx):
    names = ctx.args.get("images", "coffee_80x60.png").split(",")
    out = []
    for name in names:
        path = HERE / name if (HERE / name).is_file() else IMAGES / name
        if not path.is_file():
            raise FileNotFoundError(f"--arg images: no photograph {name!r} in {HERE} or "
                                    f"{IMAGES}")
        out.append(path)
    return out


def setup(ctx):
    """The application's main(): the Sobel server's response is a bgr8 image (spec §9.1)."""
    res = ctx.resource("Sobel", "filter_service_msg_res")
    ctx.messages.write(res.ptr, SOBEL_RESPONSE,
                       {"img": image_msg(np.zeros((0, 0, 3), np.uint8), 0)})
    ctx.filtered = ctx.broker.subscribe("/image_filtered")
    ctx.sent = Queue()
    ctx.viewed = Queue()
    ctx.results["images"] = []


async def camera(ctx):
    """Publish each photograph; wait until the viewer has it."""
    for seq, path in enumerate(_paths(ctx)):
        pixels = cv2.imread(str(path), cv2.IMREAD_COLOR)
        start = ctx.now()
        ctx.broker.publish("/image_raw", image_msg(pixels, seq))
        ctx.sent.put_nowait((path, pixels, start))
        await ctx.viewed.get()
    ctx.sent.put_nowait(None)


async def viewer(ctx):
    """Take each filtered image, write it and OpenCV's result, compare them."""
    while (item := await ctx.sent.get()) is not None:
        path, pixels, start = item
        out = await ctx.filtered.get()
        _check(ctx, path, pixels, out, ctx.now() - start)
        ctx.viewed.put_nowait(path)


def _check(ctx, path, pixels, out, cycles):
    ctx.log(f"viewer: {path.name} ({pixels.shape[1]}x{pixels.shape[0]}) filtered in "
            f"{cycles} cycles")
    height, width = pixels.shape[:2]
    got = np.frombuffer(out["data"], np.uint8).reshape(height, width, 3)
    golden = sobel_byte_lanes_cv2(pixels)
    ctx.out.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(ctx.out / f"{path.stem}_filtered.png"), got)
    cv2.imwrite(str(ctx.out / f"{path.stem}_opencv.png"), golden)
    ctx.results["images"].append({
        "image": path.name, "width": width, "height": height, "cycles": cycles,
        "bit_exact": bool(np.array_equal(got, golden)),
        "header_ok": (out["height"], out["width"], out["encoding"], out["step"]) ==
                     (height, width, "bgr8", width * 3),
        "filtered_png": str(ctx.out / f"{path.stem}_filtered.png"),
        "opencv_png": str(ctx.out / f"{path.stem}_opencv.png")})


NODES = [camera, viewer]
