"""Software nodes of the Sobel/DIP application (ReconROS paper, Fig. 5) for ``rosgate sim``.

Node 1, the camera, publishes each photograph on /image_raw as a ``bgr8`` sensor_msgs/Image
and waits for its filtered version before sending the next (the paper measures one image at a
time). Node 4, the viewer, takes /image_filtered, writes it as ``<stem>_filtered.png``, the
reference result and a montage (input | rosgate | reference), and compares rosgate's result
with the reference byte for byte.

The reference is OpenCV's Sobel edge image (``cv2.Sobel`` dx and dy, ``convertScaleAbs``,
``cv2.add``, BORDER_REFLECT_101) when the Sobel thread runs in its default ``opencv`` mode,
and the paper's per-byte-lane filter, computed with ``cv2.filter2D``, in ``reconros`` mode
(``--param Sobel.mode=reconros``).

``--arg images=a.png,b.png`` chooses the photographs (paths, or names in
``examples/images``); default: the 80x60 coffee photograph.
"""

from pathlib import Path

import cv2
import numpy as np
from cocotb.queue import Queue

from host.reconos.messages import image_message as image_msg
from host.sim_args import SimArg

HERE = Path(__file__).resolve().parent
IMAGES = HERE.parent / "images"
SOBEL_RESPONSE = "application_msgs/srv/SobelSrv_Response"
#: ReconROS paper Table 6, Sobel row (640x480 bgr8, Zynq-7100 at 100 MHz), ms
PAPER_MS = {"raw HW": 22.28, "pp HW": 68.54, "raw SW": 37.53}
#: the ReconROS demo's Sobel kernels (row-major correlation)
SOBEL_FX = np.array([[1, 2, 1], [0, 0, 0], [-1, -2, -1]], dtype=np.float32)
SOBEL_FY = np.array([[1, 0, -1], [2, 0, -2], [1, 0, -1]], dtype=np.float32)


def opencv_sobel(pixels):
    """OpenCV's Sobel edge image of a ``bgr8`` image, per channel."""
    gx = cv2.Sobel(pixels, cv2.CV_16S, 1, 0, ksize=3, borderType=cv2.BORDER_REFLECT_101)
    gy = cv2.Sobel(pixels, cv2.CV_16S, 0, 1, ksize=3, borderType=cv2.BORDER_REFLECT_101)
    return cv2.add(cv2.convertScaleAbs(gx), cv2.convertScaleAbs(gy))


def reconros_sobel(pixels):
    """The paper's per-byte-lane Sobel: each byte lane of the 32-bit word grid of a ``bgr8``
    image correlated with the demo's kernels (``cv2.filter2D`` into int16),
    ``(|gx| + |gy|) >> 3``, border words 0."""
    height, width = pixels.shape[:2]
    lanes = np.ascontiguousarray(pixels).reshape(height, width * 3 // 4, 4)
    out = np.zeros_like(lanes)
    for k in range(4):
        lane = np.ascontiguousarray(lanes[:, :, k])
        gx = cv2.filter2D(lane, cv2.CV_16S, SOBEL_FX).astype(np.int32)
        gy = cv2.filter2D(lane, cv2.CV_16S, SOBEL_FY).astype(np.int32)
        out[:, :, k] = (np.abs(gx) + np.abs(gy)) >> 3
    out[0], out[-1], out[:, 0], out[:, -1] = 0, 0, 0, 0
    return out.reshape(height, width, 3)


REFERENCES = {"opencv": ("opencv", opencv_sobel), "reconros": ("reference", reconros_sobel)}


def _mode(project):
    thread = next((t for t in project.threads if t.name == "Sobel"), None)
    return "opencv" if thread is None else thread.params.get("mode", "opencv")


def _paths(args):
    names = [n for n in args.get("images", "coffee_80x60.png").split(",") if n]
    if not names:
        raise ValueError("--arg images= names no photograph")
    out = []
    for name in names:
        path = Path(name).expanduser()
        for candidate in (path, HERE / path, IMAGES / path):
            if candidate.is_file():
                out.append(candidate.resolve())
                break
        else:
            raise ValueError(f"--arg images: no file {name!r} (looked in the current folder, "
                             f"{HERE} and {IMAGES})")
    return out


def _read(path):
    pixels = cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_COLOR)
    if pixels is None:
        raise ValueError(f"--arg images: {path} is not an image OpenCV can read")
    return pixels


def check(ctx):
    """Refuse, before anything is built, a photograph the Sobel thread cannot take."""
    sobel = ctx.threads.get("Sobel")
    if sobel is None:
        return                  # the service is served elsewhere (on DDS with --ros2)
    for path in _paths(ctx.args):
        height, width = _read(path).shape[:2]
        if not sobel.accepts(width, height):
            if sobel.mode == "opencv":
                rule = (f"{sobel.min_width}..{sobel.max_width} x 3..{sobel.max_height} pixels")
            else:
                rule = (f"rows of 4..{4 * sobel.max_words // 3} pixels whose 3 * width bytes "
                        f"are a multiple of {sobel.arch.word_bytes}, at least 3 rows")
            raise ValueError(f"--arg images: {path} is {width}x{height}; the Sobel thread "
                             f"({sobel.mode} mode) takes {rule}")


def accepts(ctx, name, value):
    """With ``--ros2``: the reason an image arriving from DDS cannot go to the hardware (the
    DIP node's subscription, or a call of the Sobel service), or ``None``."""
    image = value.get("img", value) if name == "/sobelservice" else value
    if name not in ("/image_raw", "/sobelservice"):
        return None
    width, height = image["width"], image["height"]
    if image["encoding"] != "bgr8":
        return f"encoding {image['encoding']!r}; the Sobel thread takes bgr8"
    if image["step"] != 3 * width or len(image["data"]) != image["step"] * height:
        return (f"{width}x{height} with step {image['step']} and {len(image['data'])} data "
                f"bytes; bgr8 needs step {3 * width} and {3 * width * height} bytes")
    sobel = ctx.threads.get("Sobel")
    if sobel is not None and not sobel.accepts(width, height):
        return (f"{width}x{height}: the Sobel thread ({sobel.mode} mode) takes "
                f"{sobel.min_width}..{sobel.max_width} x 3..{sobel.max_height} pixels"
                if sobel.mode == "opencv" else f"{width}x{height}: not a shape the Sobel "
                f"thread takes in {sobel.mode} mode")
    return None


def setup(ctx):
    """The application's main(): the Sobel server's response is a bgr8 image."""
    if any(t.name == "Sobel" for t in ctx.project.threads):
        res = ctx.resource("Sobel", "filter_service_msg_res")
        ctx.messages.write(res.ptr, SOBEL_RESPONSE,
                           {"img": image_msg(np.zeros((0, 0, 3), np.uint8), 0)})
    ctx.filtered = ctx.broker.subscribe("/image_filtered")
    ctx.sent = Queue()
    ctx.viewed = Queue()
    ctx.results["mode"] = _mode(ctx.project)
    ctx.results["clock_mhz"] = ctx.clock_mhz
    ctx.results["images"] = []


async def camera(ctx):
    """Publish each photograph; wait until the viewer has it."""
    paths = _paths(ctx.args)
    for seq, path in enumerate(paths):
        ctx.progress(seq, len(paths), "images")
        pixels = _read(path)
        ctx.log(f"camera: {path.name} ({pixels.shape[1]}x{pixels.shape[0]}) published")
        start = ctx.now()
        ctx.broker.publish("/image_raw", image_msg(pixels, seq))
        ctx.sent.put_nowait((path, pixels, start))
        await ctx.viewed.get()
    ctx.sent.put_nowait(None)


async def viewer(ctx):
    """Take each filtered image, write it, the reference and the montage, compare them."""
    while (item := await ctx.sent.get()) is not None:
        path, pixels, start = item
        out = await ctx.filtered.get()
        _check(ctx, path, pixels, out, ctx.now() - start)
        ctx.viewed.put_nowait(path)


def _label(image, text):
    """``image`` with a caption bar above it."""
    bar = np.full((18, image.shape[1], 3), 32, np.uint8)
    cv2.putText(bar, text, (3, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1,
                cv2.LINE_AA)
    return np.vstack([bar, image])


def _check(ctx, path, pixels, out, cycles):
    height, width = pixels.shape[:2]
    mode = ctx.results["mode"]
    name, reference = REFERENCES[mode]
    got = np.frombuffer(out["data"], np.uint8)
    header_ok = (out["height"], out["width"], out["encoding"], out["step"]) == \
        (height, width, "bgr8", width * 3)
    got = got.reshape(height, width, 3) if header_ok and got.size == height * width * 3 \
        else np.zeros_like(pixels)
    golden = reference(pixels)
    exact = bool(header_ok and np.array_equal(got, golden))
    ctx.out.mkdir(parents=True, exist_ok=True)
    files = {"filtered_png": ctx.out / f"{path.stem}_filtered.png",
             f"{name}_png": ctx.out / f"{path.stem}_{name}.png",
             "montage_png": ctx.out / f"{path.stem}_montage.png"}
    cv2.imwrite(str(files["filtered_png"]), got)
    cv2.imwrite(str(files[f"{name}_png"]), golden)
    zoom = max(1, -(-160 // width))        # small images are shown enlarged

    def panel(image, text):
        return _label(cv2.resize(image, None, fx=zoom, fy=zoom,
                                 interpolation=cv2.INTER_NEAREST), text)
    gap = np.full((height * zoom + 18, 4, 3), 255, np.uint8)
    cv2.imwrite(str(files["montage_png"]), np.hstack([
        panel(pixels, "input"), gap, panel(got, "rosgate"), gap,
        panel(golden, "OpenCV" if mode == "opencv" else "paper's filter")]))
    ms = cycles / (ctx.clock_mhz * 1000)
    ctx.log(f"viewer: {path.name} ({width}x{height}) filtered in {cycles} cycles = {ms:.3f} ms "
            f"at {ctx.clock_mhz:g} MHz, {'equal to' if exact else 'DIFFERENT from'} "
            f"{'OpenCV' if mode == 'opencv' else 'the reference'}")
    ctx.results["images"].append({
        "image": path.name, "width": width, "height": height, "cycles": cycles, "ms": ms,
        "bit_exact": exact, "header_ok": header_ok,
        **{k: str(v) for k, v in files.items()}})


def summary(results, clock_mhz):
    """The lines ``rosgate sim`` prints: per image its latency and the speedup over the
    paper's Sobel figures (scaled to the image's pixels)."""
    mode = results["mode"]
    reference = "OpenCV" if mode == "opencv" else "the paper's filter"
    lines = [f"Sobel mode {mode}; system clock {clock_mhz:g} MHz; paper (Table 6, 640x480 "
             f"on Zynq at 100 MHz): raw HW {PAPER_MS['raw HW']} ms, ping-pong HW "
             f"{PAPER_MS['pp HW']} ms",
             f"{'image':<28} {'size':>9} {'cycles':>10} {'ms':>8} {'vs raw HW':>10} "
             f"{'vs pp HW':>9}  equal to {reference}"]
    for r in results["images"]:
        scale = r["width"] * r["height"] / (640 * 480)
        lines.append(f"{r['image'][:28]:<28} {r['width']:>4}x{r['height']:<4} "
                     f"{r['cycles']:>10} {r['ms']:>8.3f} "
                     f"{PAPER_MS['raw HW'] * scale / r['ms']:>9.1f}x "
                     f"{PAPER_MS['pp HW'] * scale / r['ms']:>8.1f}x  "
                     f"{'yes' if r['bit_exact'] else 'NO'}")
    exact = sum(r["bit_exact"] for r in results["images"])
    lines.append(f"{exact} of {len(results['images'])} images equal to {reference} byte for "
                 f"byte (speedups scale the paper's 640x480 times by the image's pixels)")
    return lines


ARGS = {
    "images": SimArg("photographs to filter, comma-separated (the current folder, this "
                     "example's folder or examples/images)", "coffee_80x60.png", files=True),
}

NODES = [camera, viewer]
