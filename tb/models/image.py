"""Golden models of the image kernels: OpenCV where OpenCV defines the operation (
docs/kernels.md), the ReconROS Sobel from the spec (docs/reconos.md), and the frame
guard's
padding and cutting rule."""

from pathlib import Path

import numpy as np

__all__ = ["IMAGES", "load_image", "sobel", "gaussian", "gray", "hsv", "equalize", "in_range",
           "traffic_lights", "sobel_reconros", "guard_frame", "CV_BORDERS"]

IMAGES = Path(__file__).resolve().parents[2] / "examples" / "images"


def _cv2():
    import cv2
    return cv2


#: rosgate border name -> OpenCV border flag name
CV_BORDERS = {"reflect101": "BORDER_REFLECT_101", "replicate": "BORDER_REPLICATE",
              "constant": "BORDER_CONSTANT"}


def _border(name):
    return getattr(_cv2(), CV_BORDERS[name])


def load_image(name):
    """A photograph of ``examples/images`` as ``bgr8`` (``H x W x 3`` uint8)."""
    image = _cv2().imread(str(IMAGES / name), _cv2().IMREAD_COLOR)
    if image is None:
        raise FileNotFoundError(IMAGES / name)
    return image


def sobel(image, border="reflect101"):
    """``cv2.add(convertScaleAbs(Sobel dx), convertScaleAbs(Sobel dy))`` (docs/kernels.md,
    rosgate native Sobel)."""
    cv2 = _cv2()
    gx = cv2.Sobel(image, cv2.CV_16S, 1, 0, ksize=3, borderType=_border(border))
    gy = cv2.Sobel(image, cv2.CV_16S, 0, 1, ksize=3, borderType=_border(border))
    return cv2.add(cv2.convertScaleAbs(gx), cv2.convertScaleAbs(gy))


def sobel_reconros(words):
    """The ReconROS per-byte-lane Sobel of an ``H x W x 4`` array of 32-bit words' bytes,
    rosgate's native border (edge words 0)."""
    from .sobel import sobel_byte_lanes
    height, width = words.shape[:2]
    out, _ = sobel_byte_lanes(words.tobytes(), height, width)
    return np.frombuffer(out, np.uint8).reshape(height, width, 4)


def gaussian(image, ksize, border="reflect101"):
    """``cv2.GaussianBlur(image, (k, k), 0)`` with the border."""
    return _cv2().GaussianBlur(image, (ksize, ksize), 0, borderType=_border(border))


def gray(image):
    """``cv2.cvtColor(COLOR_BGR2GRAY)``."""
    cv2 = _cv2()
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def hsv(image):
    """``cv2.cvtColor(COLOR_BGR2HSV)`` (8-bit, H in 0..179)."""
    cv2 = _cv2()
    return cv2.cvtColor(image, cv2.COLOR_BGR2HSV)


def equalize(image):
    """``cv2.equalizeHist`` of a ``mono8`` image."""
    return _cv2().equalizeHist(image)


def compensate(image, clip_percent=1.0):
    """The AutoRace ``image_compensation`` node with OpenCV (:func:`host.autorace.compensate`):
    ``(image, min_gray, max_gray)``."""
    from host.autorace import compensate as node
    return node(image, clip_percent)


def in_range(image, lower, upper):
    """``cv2.inRange`` with per-channel bounds."""
    return _cv2().inRange(image, np.array(lower, np.uint8), np.array(upper, np.uint8))


def traffic_lights(image, red_ranges, green_range, min_pixels):
    """``(red_count, red, green_count, green)``: pixels of ``image`` (bgr8) whose HSV lies in
    either red range or in the green range (``cv2.inRange``), and whether each count reaches
    ``min_pixels``."""
    h = hsv(image)
    red = np.zeros(image.shape[:2], bool)
    for lower, upper in red_ranges:
        red |= in_range(h, lower, upper) > 0
    green = in_range(h, *green_range) > 0
    rc, gc = int(red.sum()), int(green.sum())
    return rc, rc >= min_pixels, gc, gc >= min_pixels


def guard_frame(data, frame_bytes):
    """What a kernel processes of ``data`` sent as one frame of ``frame_bytes``: cut to the
    size, or padded with zero bytes (spec of :class:`hdl.kernels.image.FrameGuard`)."""
    data = bytes(data)[:frame_bytes]
    return data + bytes(frame_bytes - len(data))
