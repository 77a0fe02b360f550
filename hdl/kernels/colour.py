"""Per-pixel colour kernels, bit-exact with OpenCV (docs/kernels.md): BGR to GRAY,
BGR to HSV, ``inRange``, and a traffic-light detector built from them."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import data, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int
from ..stream import AXIStreamSignature
from .image import (FrameGuard, check_image_params, image_kernel_members,
                    image_stream_signature)

__all__ = ["PixelKernel", "BgrToGray", "BgrToHsv", "InRange", "TrafficLightDetector",
           "GRAY_WEIGHTS", "HSV_SHIFT", "TRAFFIC_DETECTION", "hsv_tables"]

#: (B, G, R) weights of OpenCV's 8-bit BGR to GRAY: ``(sum(w * c) + 2**14) >> 15``
GRAY_WEIGHTS = (3735, 19235, 9798)

HSV_SHIFT = 12

#: the detection beat of :class:`TrafficLightDetector` (64 bits, first member lowest)
TRAFFIC_DETECTION = data.StructLayout({"red_pixels": 31, "red": 1, "green_pixels": 31,
                                       "green": 1})


def hsv_tables(hue_range=180):
    """OpenCV's reciprocal tables of ``RGB2HSV_b``: ``sdiv[v] = round((255 << 12) / v)`` and
    ``hdiv[d] = round((hue_range << 12) / (6 d))`` (round half to even, as ``cvRound``),
    entry 0 being 0."""
    sdiv = [0] + [round((255 << HSV_SHIFT) / v) for v in range(1, 256)]
    hdiv = [0] + [round((hue_range << HSV_SHIFT) / (6 * d)) for d in range(1, 256)]
    return sdiv, hdiv


class PixelKernel(wiring.Component):
    """Base of the per-pixel kernels: frame guard, a stall-as-one pipeline, image out.

    Subclasses set :attr:`LATENCY` (pipeline registers inside :meth:`compute`) and implement
    :meth:`compute`. One beat in and one out per cycle when neither side stalls; latency
    ``LATENCY + 1`` cycles.

    Members
    -------
    i : In(image_stream_signature(channels, pixels_per_beat))
        Input frames (see :mod:`hdl.kernels.image`).
    o : Out(image_stream_signature(out_channels, pixels_per_beat))
        Output frames of the same size, ``tuser[0]`` on the first beat, ``tlast`` on the
        last.
    width, height : In
        Frame size in pixels, sampled at a frame's first beat (width a multiple of P).
    err_short, err_long, err_size : Out(1)
        Bad frames, see :class:`~hdl.kernels.image.FrameGuard`.
    """

    LATENCY = 0

    def __init__(self, *, channels, out_channels, pixels_per_beat, max_width, max_height,
                 members=None):
        check_image_params(channels, pixels_per_beat, max_width, max_height,
                           channel_choices=(channels,))
        self._c, self._oc, self._p = channels, out_channels, pixels_per_beat
        self._max_width, self._max_height = max_width, max_height
        super().__init__({
            **image_kernel_members(channels, out_channels, pixels_per_beat, max_width,
                                   max_height),
            **(members or {}),
        })

    pixels_per_beat = property(lambda self: self._p)
    max_width = property(lambda self: self._max_width)
    max_height = property(lambda self: self._max_height)

    def compute(self, m, pixels, stage):
        """Return the ``P`` output pixels of the input ``pixels`` (each ``8 * channels``
        bits). ``stage(value)`` registers a value (advancing with the pipeline); exactly
        :attr:`LATENCY` registers must lie on every path. ``self.adv`` enables other
        registers and memory read ports."""
        raise NotImplementedError

    def elaborate(self, platform):
        m = Module()
        P = self._p
        m.submodules.guard = guard = FrameGuard(self._c, P, self._max_width, self._max_height)
        wiring.connect(m, wiring.flipped(self.i), guard.i)
        m.d.comb += [guard.width.eq(self.width), guard.height.eq(self.height),
                     self.err_short.eq(guard.err_short), self.err_long.eq(guard.err_long),
                     self.err_size.eq(guard.err_size)]
        o_valid = Signal()
        self.adv = adv = Signal()
        m.d.comb += [adv.eq(~o_valid | self.o.tready), guard.o.tready.eq(adv),
                     self.o.tvalid.eq(o_valid)]

        def stage(value):
            reg = Signal.like(value) if isinstance(value, Signal) else Signal(value.shape())
            with m.If(adv):
                m.d.sync += reg.eq(value)
            return reg

        pixels = [guard.o.tdata.word_select(p, 8 * self._c) for p in range(P)]
        outputs = self.compute(m, pixels, stage)
        meta = Cat(guard.o.tvalid, guard.o.tlast, guard.o.tuser)
        for _ in range(self.LATENCY):
            meta = stage(meta)
        with m.If(adv):
            m.d.sync += [o_valid.eq(meta[0]), self.o.tlast.eq(meta[1]),
                         self.o.tuser.eq(meta[2]), self.o.tdata.eq(Cat(*outputs))]
        return m


class BgrToGray(PixelKernel):
    """``bgr8`` to ``mono8``, bit-exact with ``cv2.cvtColor(COLOR_BGR2GRAY)``:
    ``Y = (9798 R + 19235 G + 3735 B + 16384) >> 15``.

    Parameters
    ----------
    pixels_per_beat, max_width, max_height : int
        See :class:`PixelKernel`.
    """

    #: the three weighted channels are registered before their sum
    LATENCY = 1

    def __init__(self, *, pixels_per_beat=1, max_width=640, max_height=480):
        super().__init__(channels=3, out_channels=1, pixels_per_beat=pixels_per_beat,
                         max_width=max_width, max_height=max_height)

    def compute(self, m, pixels, stage):
        outs = []
        for px in pixels:
            b, g, r = (px.word_select(c, 8) for c in range(3))
            wb, wg, wr = GRAY_WEIGHTS
            pb, pg, pr = stage(wb * b), stage(wg * g), stage(wr * r)
            outs.append(((pb + pg + pr + (1 << 14)) >> 15)[:8])
        return outs


class BgrToHsv(PixelKernel):
    """``bgr8`` to 8-bit HSV (H in 0..179), bit-exact with ``cv2.cvtColor(COLOR_BGR2HSV)``
    (OpenCV's ``RGB2HSV_b``: two 256-entry reciprocal ROMs and two multipliers, no divider).

    Output pixel bytes: H, S, V. Latency 5 cycles.

    Parameters
    ----------
    pixels_per_beat, max_width, max_height : int
        See :class:`PixelKernel`.
    """

    #: the pixel, the ROM addresses, the reciprocal ROMs, the two products
    LATENCY = 4

    def __init__(self, *, pixels_per_beat=1, max_width=640, max_height=480):
        super().__init__(channels=3, out_channels=3, pixels_per_beat=pixels_per_beat,
                         max_width=max_width, max_height=max_height)

    def compute(self, m, pixels, stage):
        sdiv, hdiv = hsv_tables(180)
        m.submodules.sdiv = srom = Memory(shape=21, depth=256, init=sdiv)
        m.submodules.hdiv = hrom = Memory(shape=18, depth=256, init=hdiv)
        half = 1 << (HSV_SHIFT - 1)
        outs = []
        for px in pixels:
            # the pixel registered first: the frame guard's padding multiplexer stays out of
            # the comparisons
            px = stage(px)
            b, g, r = (px.word_select(c, 8) for c in range(3))
            v = Signal(8)
            mn = Signal(8)
            m.d.comb += [v.eq(Mux(b > g, Mux(b > r, b, r), Mux(g > r, g, r))),
                         mn.eq(Mux(b < g, Mux(b < r, b, r), Mux(g < r, g, r)))]
            d = Signal(8)
            m.d.comb += d.eq(v - mn)
            hn = Signal(signed(12))
            with m.If(v == r):
                m.d.comb += hn.eq(g - b)
            with m.Else():
                with m.If(v == g):
                    m.d.comb += hn.eq(b - r + 2 * d)
                with m.Else():
                    m.d.comb += hn.eq(r - g + 4 * d)
            # v, d and hn registered before they address the ROMs and again beside their data;
            # the products registered before their rounding
            v1, d1, hn1 = stage(v), stage(d), stage(hn)
            sp, hp = srom.read_port(), hrom.read_port()
            m.d.comb += [sp.addr.eq(v1), sp.en.eq(self.adv), hp.addr.eq(d1), hp.en.eq(self.adv)]
            v2, d2, hn2 = stage(v1), stage(d1), stage(hn1)
            sprod = stage(d2 * sp.data)
            hprod = Signal(signed(32))
            m.d.comb += hprod.eq(hn2 * hp.data)
            hprod, v3 = stage(hprod), stage(v2)
            s = ((sprod + half) >> HSV_SHIFT)[:8]
            hq = Signal(signed(12))
            m.d.comb += hq.eq((hprod + half) >> HSV_SHIFT)
            h = Mux(hq < 0, hq + 180, hq)[:8]
            outs.append(Cat(h, s, v3))
        return outs


class InRange(PixelKernel):
    """``cv2.inRange`` on a 3-channel image: 255 where ``lower[c] <= pixel[c] <= upper[c]``
    for every channel, else 0 (``mono8`` out).

    Members
    -------
    lower, upper : In(24)
        Bounds, channel c in byte c; may change at any time (applied per beat).
    """

    def __init__(self, *, pixels_per_beat=1, max_width=640, max_height=480):
        super().__init__(channels=3, out_channels=1, pixels_per_beat=pixels_per_beat,
                         max_width=max_width, max_height=max_height,
                         members={"lower": In(24), "upper": In(24)})

    def compute(self, m, pixels, stage):
        return [in_range(px, self.lower, self.upper).replicate(8) for px in pixels]


def in_range(pixel, lower, upper):
    """1 where every byte of ``pixel`` lies within the bytes of ``lower`` and ``upper``
    (values, or tuples of constants per channel: then a comparison that always holds, with 0
    or 255, is left out)."""
    ok = Const(1, 1)
    for c in range(len(pixel) // 8):
        x = pixel.word_select(c, 8)
        if isinstance(lower, tuple):
            if lower[c] > 0:
                ok = ok & (x >= lower[c])
        else:
            ok = ok & (x >= lower.word_select(c, 8))
        if isinstance(upper, tuple):
            if upper[c] < 255:
                ok = ok & (x <= upper[c])
        else:
            ok = ok & (x <= upper.word_select(c, 8))
    return ok


class TrafficLightDetector(wiring.Component):
    """Red and green traffic-light detection on ``bgr8`` frames (the fpgaDDS chain's HSV
    detector): per frame, count the pixels whose HSV lies in the red ranges (two, for the hue
    wrap) and in the green range (``inRange`` semantics), and send one detection beat.

    Detection beat (``det``, :data:`TRAFFIC_DETECTION`, ``tlast`` set): red pixel count,
    red detected (count >= ``min_pixels``), green count, green detected.
    If the previous detection has not been taken when a frame ends, the pixel stream stalls.

    Parameters
    ----------
    pixels_per_beat, max_width, max_height : int
        As for :class:`BgrToHsv`.

    Members
    -------
    i : In(image_stream_signature(3, pixels_per_beat))
        ``bgr8`` frames.
    det : Out(AXIStreamSignature(64, keep=False))
        One detection per frame.
    width, height : In
        Frame size (see :class:`PixelKernel`).
    red_lower0, red_upper0, red_lower1, red_upper1, green_lower, green_upper : In(24)
        HSV bounds (H in byte 0, S in byte 1, V in byte 2); absent when the ``bounds``
        parameter fixes them (a dict of these names to (H, S, V) tuples).
    min_pixels : In(31)
        Pixels a colour needs for a detection; absent when the ``min_pixels`` parameter fixes
        it.
    err_short, err_long, err_size : Out(1)
        Bad frames (:class:`~hdl.kernels.image.FrameGuard`); a cut or padded frame still
        yields a detection (padding is black, so it never counts).
    """

    BOUNDS = ("red_lower0", "red_upper0", "red_lower1", "red_upper1", "green_lower",
              "green_upper")

    def __init__(self, *, pixels_per_beat=1, max_width=640, max_height=480, bounds=None,
                 min_pixels=None):
        check_int("max_width", max_width, 1, 1 << 14)
        self._p, self._max_width, self._max_height = pixels_per_beat, max_width, max_height
        if bounds is not None:
            missing = [n for n in self.BOUNDS if n not in bounds]
            if missing:
                raise ParameterError("bounds", bounds, f"all of {', '.join(self.BOUNDS)}")
            bounds = {n: tuple(bounds[n]) for n in self.BOUNDS}
        self._bounds = bounds
        self._min_pixels = (None if min_pixels is None else
                            check_int("min_pixels", min_pixels, 0, (1 << 31) - 1))
        super().__init__({
            "i": In(image_stream_signature(3, pixels_per_beat)),
            "det": Out(AXIStreamSignature(64, keep=False)),
            "width": In(range(max_width + 1)),
            "height": In(range(max_height + 1)),
            **({name: In(24) for name in self.BOUNDS} if bounds is None else {}),
            **({"min_pixels": In(31)} if min_pixels is None else {}),
            "err_short": Out(1),
            "err_long": Out(1),
            "err_size": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        P = self._p
        m.submodules.hsv = hsv = BgrToHsv(pixels_per_beat=P, max_width=self._max_width,
                                          max_height=self._max_height)
        wiring.connect(m, wiring.flipped(self.i), hsv.i)
        m.d.comb += [hsv.width.eq(self.width), hsv.height.eq(self.height),
                     self.err_short.eq(hsv.err_short), self.err_long.eq(hsv.err_long),
                     self.err_size.eq(hsv.err_size)]
        red, green = Signal(31), Signal(31)
        red_n = red
        green_n = green
        bound = (self._bounds.get if self._bounds is not None else
                 lambda name: getattr(self, name))
        min_pixels = self._min_pixels if self._min_pixels is not None else self.min_pixels
        for p in range(P):
            px = hsv.o.tdata.word_select(p, 24)
            is_red = in_range(px, bound("red_lower0"), bound("red_upper0")) | \
                in_range(px, bound("red_lower1"), bound("red_upper1"))
            red_n = red_n + is_red
            green_n = green_n + in_range(px, bound("green_lower"), bound("green_upper"))
        det_valid = Signal()
        m.d.comb += [self.det.tvalid.eq(det_valid), self.det.tlast.eq(1),
                     hsv.o.tready.eq(~(det_valid & ~self.det.tready & hsv.o.tlast))]
        with m.If(self.det.tvalid & self.det.tready):
            m.d.sync += det_valid.eq(0)
        with m.If(hsv.o.tvalid & hsv.o.tready):
            with m.If(hsv.o.tlast):
                det = data.View(TRAFFIC_DETECTION, self.det.tdata)
                m.d.sync += [red.eq(0), green.eq(0), det_valid.eq(1),
                             det.red_pixels.eq(red_n[:31]),
                             det.red.eq(red_n[:31] >= min_pixels),
                             det.green_pixels.eq(green_n[:31]),
                             det.green.eq(green_n[:31] >= min_pixels)]
            with m.Else():
                m.d.sync += [red.eq(red_n), green.eq(green_n)]
        return m
