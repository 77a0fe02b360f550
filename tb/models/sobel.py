"""Golden models of the Sobel filters, written from the spec (docs/reconos.md)."""

import numpy as np

__all__ = ["sobel_byte_lanes", "sobel_byte_lanes_cv2", "SOBEL_FX", "SOBEL_FY"]

#: row-major correlation kernels of the ReconROS demo
SOBEL_FX = np.array([[1, 2, 1], [0, 0, 0], [-1, -2, -1]], dtype=np.int16)
SOBEL_FY = np.array([[1, 0, -1], [2, 0, -2], [1, 0, -1]], dtype=np.int16)


def sobel_byte_lanes(payload, height, words):
    """The ReconROS per-byte-lane Sobel of a ``height`` x ``words`` image of 32-bit words.

    Returns ``(out, written)``: ``out`` the output bytes of rosgate's native mode (interior
    rows 1..height-2 x word columns 1..words-2 computed, the border 0) and ``written`` a
    boolean ``height x words`` mask of the words ReconROS itself writes (rows 1..height-3,
    columns 1..words-2: row height-2 is never written, defect 12)."""
    p = np.frombuffer(bytes(payload), dtype=np.uint8).reshape(height, words, 4).astype(np.int16)
    gx = np.zeros((height - 2, words - 2, 4), dtype=np.int16)
    gy = np.zeros_like(gx)
    for di in range(3):
        for dj in range(3):
            window = p[di:di + height - 2, dj:dj + words - 2]
            gx += SOBEL_FX[di, dj] * window
            gy += SOBEL_FY[di, dj] * window
    out = np.zeros((height, words, 4), dtype=np.uint8)
    out[1:-1, 1:-1] = ((np.abs(gx) + np.abs(gy)) >> 3).astype(np.uint8)
    written = np.zeros((height, words), dtype=bool)
    written[1:height - 2, 1:words - 1] = True
    return out.tobytes(), written


def sobel_byte_lanes_cv2(pixels):
    """The same filter computed by OpenCV: each byte lane of the 32-bit word grid of a
    ``bgr8`` image (``H x W x 3``, ``3W`` a multiple of 4) correlated with ``SOBEL_FX`` and
    ``SOBEL_FY`` by ``cv2.filter2D`` into int16, ``(|gx|+|gy|) >> 3``, border words 0.
    Returns the ``H x W x 3`` output image."""
    import cv2
    height, width = pixels.shape[:2]
    if (width * 3) % 4:
        raise ValueError(f"a row of {width} bgr8 pixels is not a whole number of 32-bit words")
    lanes = np.ascontiguousarray(pixels).reshape(height, width * 3 // 4, 4)
    out = np.zeros_like(lanes)
    for k in range(4):
        lane = np.ascontiguousarray(lanes[:, :, k])
        gx = cv2.filter2D(lane, cv2.CV_16S, SOBEL_FX.astype(np.float32))
        gy = cv2.filter2D(lane, cv2.CV_16S, SOBEL_FY.astype(np.float32))
        out[:, :, k] = (np.abs(gx.astype(np.int32)) + np.abs(gy.astype(np.int32))) >> 3
    out[0], out[-1], out[:, 0], out[:, -1] = 0, 0, 0, 0
    return out.reshape(height, width, 3)
