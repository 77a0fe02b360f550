"""Gaussian blur, bit-exact with ``cv2.GaussianBlur(sigma=0)`` (docs/kernels.md)."""

from amaranth.hdl import Cat

from ..logic import shifted_sum
from ..params import check_choice
from .window import WindowFilter

__all__ = ["GaussianBlur", "GAUSSIAN_TAPS"]

#: ksize -> (binomial taps, rounding shift): ``(sum(K * p) + 2**(s-1)) >> s`` with
#: ``K = outer(taps, taps)``
GAUSSIAN_TAPS = {3: ((1, 2, 1), 4), 5: ((1, 4, 6, 4, 1), 8)}


class GaussianBlur(WindowFilter):
    """3 x 3 or 5 x 5 Gaussian blur with ``sigma = 0`` on an 8-bit image stream.

    Per channel ``(sum(K * p) + 2**(s-1)) >> s`` with ``K = outer([1,2,1])``, ``s = 4`` or
    ``K = outer([1,4,6,4,1])``, ``s = 8``: the vertical sums are kept exact, the horizontal
    sum of them is rounded once, which is what ``cv2.GaussianBlur`` computes for 8-bit images.

    Parameters
    ----------
    ksize : int
        3 or 5.
    channels : int
        Bytes per pixel: 1 (``mono8``), 3 (``bgr8``) or 4.
    pixels_per_beat, max_width, max_height
        As for :class:`~hdl.kernels.window.WindowFilter`.
    border : str
        ``"reflect101"`` (OpenCV's default) or ``"replicate"``.

    Members
    -------
    See :class:`~hdl.kernels.window.WindowFilter`.
    """

    def __init__(self, ksize=3, *, channels=3, pixels_per_beat=1, max_width=640,
                 max_height=480, border="reflect101"):
        check_choice("border", border, ("reflect101", "replicate"))
        super().__init__(ksize, channels=channels, out_channels=channels,
                         pixels_per_beat=pixels_per_beat, max_width=max_width,
                         max_height=max_height, border=border, channel_choices=(1, 3, 4))

    #: the vertical (column) sums, then the horizontal sum; the rounding at ``o``
    compute_stages = 2

    def compute(self, m, pixel, ctx):
        taps, shift = GAUSSIAN_TAPS[self.ksize]
        k = self.ksize
        outputs = []
        for p in range(self.pixels_per_beat):
            lanes = []
            for c in range(self.channels):
                columns = [ctx.register(shifted_sum(
                    [(taps[dy], pixel(p, dy, dx).word_select(c, 8)) for dy in range(k)]),
                    f"column{dx}_p{p}_c{c}") for dx in range(k)]
                total = ctx.register(shifted_sum(list(zip(taps, columns))),
                                     f"total_p{p}_c{c}")
                lanes.append(((total + (1 << (shift - 1))) >> shift)[:8])
            outputs.append(Cat(*lanes))
        return outputs
