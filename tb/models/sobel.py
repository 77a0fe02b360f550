"""Golden models of the Sobel filters, written from the spec (reconos.md §9.1)."""

import numpy as np

__all__ = ["sobel_byte_lanes", "SOBEL_FX", "SOBEL_FY"]

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
