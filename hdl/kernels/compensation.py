"""Image compensation of the TurtleBot3 AutoRace camera pipeline: clip the grey histogram and
stretch the image linearly, bit-exact with ``cv2.convertScaleAbs`` (docs/kernels.md)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.fifo import SyncFIFOBuffered

from ..params import ParameterError, check_int
from .colour import GRAY_WEIGHTS
from .equalize import (ROUND_STAGES, _shift_for_rounding, byte_table, histogram_banks,
                       round_to_float32, stream_through_table)
from .image import FrameGuard, check_image_params, image_kernel_members

__all__ = ["ImageCompensation", "clip_hundredths"]

#: alpha = 255 / range is computed as floor(255 * 2**SCALE_BITS / range) before rounding
SCALE_BITS = 64
#: cycles the table waits after the division's end for alpha and beta in float32 and their
#: exponents (the longest chain, three roundings, the product and five registers, takes
#: 3 * ROUND_STAGES + 6)
CONSTANT_STAGES = 4 * ROUND_STAGES + 6
#: registers between an entry's x and its table value
TABLE_STAGES = 4 + ROUND_STAGES


def clip_hundredths(clip_percent):
    """The clip percentage in hundredths of a percent (an int), from a number with at most two
    decimals in 0..100; raise :class:`~hdl.params.ParameterError` otherwise."""
    hundredths = round(float(clip_percent) * 100)
    if abs(hundredths - float(clip_percent) * 100) > 1e-6 or not 0 <= hundredths <= 10000:
        raise ParameterError("clip_percent", clip_percent,
                             "a percentage in 0..100 with at most two decimals")
    return hundredths


class ImageCompensation(wiring.Component):
    """The AutoRace ``image_compensation`` node on ``bgr8`` frames, one frame of latency.

    A frame streams into a frame buffer while the histogram of its grey image
    (``cv2.cvtColor(BGR2GRAY)``) is counted. Then, with ``N`` pixels and ``c =
    clip_percent * N / 200``:

    * ``min_gray`` is the first bin whose cumulative count reaches ``c``, ``max_gray`` the last
      bin whose cumulative count stays below ``N - c`` (-1 if none); with ``clip_percent`` 0,
      the smallest and largest grey values (``cv2.minMaxLoc``);
    * ``range = max_gray - min_gray``; ``alpha = 255 / range``, ``beta = -min_gray * alpha``.

    Every channel of every pixel becomes ``cv2.convertScaleAbs(x, alpha, beta)`` =
    ``min(255, rint(|x - min_gray| * 255 / |range|))``, rounded half to even; the table of its
    256 values is built with one division per frame and one step per entry (about 300
    cycles). A range of 0 (the node would divide by zero) passes the frame unchanged. The
    frame then streams out while the next one streams in.

    Parameters
    ----------
    clip_percent : float
        Share of the pixels clipped, half at each end: 0..100 in steps of 0.01 (AutoRace's
        default: 1.0).
    pixels_per_beat : int
        1, 2, 4 or 8.
    max_width, max_height : int
        Largest frame; the frame buffer holds ``max_width * max_height`` pixels.

    Members
    -------
    i : In(image_stream_signature(3, pixels_per_beat))
        ``bgr8`` frames.
    o : Out(image_stream_signature(3, pixels_per_beat))
        The compensated frames.
    width, height : In
        Frame size, sampled at a frame's first beat.
    min_gray, max_gray : Out(signed(10))
        The last frame's clip limits (valid from its first output beat).
    err_short, err_long, err_size : Out(1)
        Bad frames (:class:`~hdl.kernels.image.FrameGuard`).
    """

    def __init__(self, *, clip_percent=1.0, pixels_per_beat=1, max_width=640, max_height=480):
        check_image_params(3, pixels_per_beat, max_width, max_height, channel_choices=(3,))
        self._clip = clip_hundredths(clip_percent)
        check_int("max_width * max_height", max_width * max_height, 1, 1 << 24)
        self._p, self._max_width, self._max_height = pixels_per_beat, max_width, max_height
        members = image_kernel_members(3, 3, pixels_per_beat, max_width, max_height)
        members["min_gray"] = wiring.Out(range(-1, 256))
        members["max_gray"] = wiring.Out(range(-1, 256))
        super().__init__(members)

    pixels_per_beat = property(lambda self: self._p)
    clip_percent = property(lambda self: self._clip / 100)

    def elaborate(self, platform):
        m = Module()
        P = self._p
        max_pixels = self._max_width * self._max_height
        count_bits = max_pixels.bit_length()
        m.submodules.guard = guard = FrameGuard(3, P, self._max_width, self._max_height)
        wiring.connect(m, wiring.flipped(self.i), guard.i)
        m.d.comb += [guard.width.eq(self.width), guard.height.eq(self.height),
                     self.err_short.eq(guard.err_short), self.err_long.eq(guard.err_long),
                     self.err_size.eq(guard.err_size)]

        m.submodules.frame = frame = SyncFIFOBuffered(width=24 * P + 1, depth=max_pixels // P)
        hists = histogram_banks(m, P, count_bits)
        lut_wr, lut_reads = byte_table(m, "lut", 3 * P)

        # input: frame buffer; grey value (registered), bin read, increment a cycle later
        filling = Signal(init=1)
        total = Signal(count_bits + 1)
        take = guard.o.tvalid & guard.o.tready
        m.d.comb += [guard.o.tready.eq(filling & frame.w_rdy),
                     frame.w_en.eq(take), frame.w_data.eq(Cat(guard.o.tdata, guard.o.tlast))]
        weights = [Signal(23, name=f"weighted{p}_{c}") for p in range(P) for c in range(3)]
        grey_valid, inc_valid = Signal(), Signal()
        m.d.sync += [grey_valid.eq(take), inc_valid.eq(grey_valid)]
        for p in range(P):
            px = guard.o.tdata.word_select(p, 24)
            for c, weight in enumerate(GRAY_WEIGHTS):
                m.d.sync += weights[3 * p + c].eq(weight * px.word_select(c, 8))
        inc_bin = [Signal(8, name=f"inc_bin{p}") for p in range(P)]
        for p, (wr, rd) in enumerate(hists):
            grey = ((weights[3 * p] + weights[3 * p + 1] + weights[3 * p + 2] + (1 << 14))
                    >> 15)[:8]
            m.d.comb += rd.addr.eq(grey)
            m.d.sync += inc_bin[p].eq(grey)
        with m.If(inc_valid):
            for p, (wr, rd) in enumerate(hists):
                m.d.comb += [wr.en.eq(1), wr.addr.eq(inc_bin[p]), wr.data.eq(rd.data + 1)]
        with m.If(take):
            m.d.sync += total.eq(total + P)
            with m.If(guard.o.tlast):
                m.d.sync += filling.eq(0)

        # output: every channel through the table
        draining = stream_through_table(m, frame, lut_reads, self.o, 3 * P)

        # the limits: one scan of the bins (clearing them)
        # a bin's count (the banks' sum) is registered the cycle after its read, and it and
        # 20000 times it the cycle after that (the multiplier and the histogram's block RAMs
        # are not one cycle's routing apart); the scan compares 20000 * the running count
        # with the two limits, so its cycle holds one addition and two comparisons
        j = Signal(9)
        lo, hi = Signal(range(-1, 256)), Signal(range(-1, 256))
        lo_found = Signal()
        clip_scaled = Signal(count_bits + 15)        # 20000 * c = N * clip_hundredths
        hi_limit = Signal(count_bits + 16)           # 20000 * (N - c)
        hist_sum = Signal(count_bits + 1)
        bin_count, bin_scaled = Signal(count_bits + 1), Signal(count_bits + 16)
        acc_scaled = Signal(count_bits + 16)          # 20000 * the bins' count so far
        m.d.comb += hist_sum.eq(sum(rd.data for _, rd in hists))
        hist_sum_r = Signal.like(hist_sum)
        m.d.sync += [hist_sum_r.eq(hist_sum), bin_count.eq(hist_sum_r),
                     bin_scaled.eq(hist_sum_r * 20000)]
        # alpha and beta as the node computes them (float64) and OpenCV converts them (float32)
        R = Signal(9)                                   # |range|
        numer = Signal(SCALE_BITS + 8)
        quotient = Signal(SCALE_BITS + 8)
        remainder = Signal(10)
        div_step = Signal(range(SCALE_BITS + 9))

        def reg(value, name):
            value = Value.cast(value)
            r = Signal(value.shape(), name=name)
            m.d.sync += r.eq(value)
            return r

        a53, a53_s = round_to_float32(m, quotient, remainder != 0, "alpha53", stage=reg,
                                      bits=53)
        a53, a53_s = reg(a53, "alpha53_r"), reg(a53_s, "alpha53_s_r")
        a24, a24_s = round_to_float32(m, a53, Const(0), "alpha24", stage=reg)
        product = reg(lo[:8] * a53, "beta_product")
        b53, b53_s = round_to_float32(m, product, Const(0), "beta53", stage=reg, bits=53)
        b24, b24_s = round_to_float32(m, reg(b53, "beta53_r"), Const(0), "beta24", stage=reg)
        b53_s = reg(reg(reg(b53_s, "beta53_s_r"), "beta53_s_r2"), "beta53_s_r3")
        a53_s_late = reg(reg(reg(a53_s, "alpha53_s_d1"), "alpha53_s_d2"), "alpha53_s_d3")
        # the float32 constants registered, then beta's exponent and the smaller exponent
        # each in a stage of its own: the rounding's last addition, the exponents' sum, their
        # comparison and the table's shifts were one path into the table's registers
        a24, a24_s = reg(a24, "alpha24_r"), reg(a24_s, "alpha24_s_r")
        b24, b24_s = reg(b24, "beta24_r"), reg(b24_s, "beta24_s_r")
        eb = reg(b24_s + b53_s, "eb")
        e_min = reg(Mux((lo == 0) | (a24_s <= eb), a24_s, eb), "e_min")
        wait = Signal(range(CONSTANT_STAGES + 1))
        ma, mb = Signal(24), Signal(24)                  # |a| = ma 2**Ea, |b| = mb 2**Eb
        ea_sh, eb_sh = Signal(6), Signal(6)              # Ea + L, Eb + L
        frac_bits = Signal(7)                            # L: fraction bits of the table sum

        # the table: v = |x * a + b| rounded to float32 (OpenCV's fused multiply-add), then to
        # an integer, half to even; x enters one per cycle
        x = Signal(9)
        scan_valid = Signal()
        valid, addr = reg(scan_valid, "tab_v0"), reg(x[:8], "tab_x0")
        t1 = reg(x[:8] * ma, "tab_xa")
        shifted_a = Signal(48)
        shifted_b = Signal(48)
        m.d.comb += [shifted_a.eq(t1 << ea_sh), shifted_b.eq(mb << eb_sh)]
        t2 = reg(Mux(shifted_a >= shifted_b, shifted_a - shifted_b, shifted_b - shifted_a),
                 "tab_sum")
        vm, vs = round_to_float32(m, t2, Const(0), "tab_v", stage=reg)
        # the integer part's shift is registered beside the mantissa (frac_bits is constant
        # while the table is built), so the last stage holds only the shift and the rounding
        vm, k_shift = reg(vm, "tab_vm"), reg(frac_bits - vs, "tab_k")
        # the shift, then the rounding (two stages)
        for k in range(TABLE_STAGES - 1):
            valid, addr = reg(valid, f"tab_v{k + 1}"), reg(addr, f"tab_x{k + 1}")
        whole, first, rest = _shift_for_rounding(vm, k_shift[:7])
        whole, first, rest = reg(whole, "tab_whole"), reg(first, "tab_first"), \
            reg(rest, "tab_rest")
        no_fraction = reg(k_shift <= 0, "tab_no_fraction")
        # the rounded value saturates at 255: its low byte and the carry out of it are
        # enough, with "above 255" read from the high bits of the shifted value beside them
        # (not a carry chain through all of them)
        low = Signal(9)
        m.d.comb += low.eq(whole[:8] + (first & (rest | whole[0])))
        saturated = no_fraction | (whole[8:] != 0) | low[8]
        with m.If(valid):
            m.d.comb += [lut_wr.en.eq(1), lut_wr.addr.eq(addr),
                         lut_wr.data.eq(Mux(saturated, 255, low[:8]))]
        in_flight = Signal(range(TABLE_STAGES + 1))

        with m.FSM():
            with m.State("FILL"):
                with m.If(~filling & ~grey_valid & ~inc_valid & ~draining):
                    m.d.sync += [j.eq(0), acc_scaled.eq(0), lo_found.eq(0), hi.eq(-1),
                                 lo.eq(0), clip_scaled.eq(total * self._clip),
                                 hi_limit.eq(total * (20000 - self._clip))]
                    for _, rd in hists:
                        m.d.comb += rd.addr.eq(0)
                    m.next = "FIRST"
            with m.State("FIRST"):
                for _, rd in hists:
                    m.d.comb += rd.addr.eq(1)
                m.next = "SECOND"
            with m.State("SECOND"):
                # bin 0's count is registered; bin 2 is read
                for _, rd in hists:
                    m.d.comb += rd.addr.eq(2)
                m.next = "BIN"
            with m.State("BIN"):
                # bin j's count is in bin_count; bin j + 3 is read
                for wr, _ in hists:
                    m.d.comb += [wr.en.eq(1), wr.addr.eq(j), wr.data.eq(0)]
                new_acc = acc_scaled + bin_scaled
                m.d.sync += acc_scaled.eq(new_acc)
                if self._clip:
                    with m.If(~lo_found & (new_acc >= clip_scaled)):
                        m.d.sync += [lo.eq(j), lo_found.eq(1)]
                    with m.If(new_acc < hi_limit):
                        m.d.sync += hi.eq(j)
                else:
                    with m.If(~lo_found & (bin_count != 0)):
                        m.d.sync += [lo.eq(j), lo_found.eq(1)]
                    with m.If(bin_count != 0):
                        m.d.sync += hi.eq(j)
                for _, rd in hists:
                    m.d.comb += rd.addr.eq(j + 3)
                m.d.sync += j.eq(j + 1)
                with m.If(j == 255):
                    m.next = "RANGE"
            with m.State("RANGE"):
                diff = hi - lo
                m.d.sync += [R.eq(Mux(diff < 0, -diff, diff)), numer.eq(255 << SCALE_BITS),
                             quotient.eq(0), remainder.eq(0), div_step.eq(SCALE_BITS + 7),
                             self.min_gray.eq(lo), self.max_gray.eq(hi), x.eq(0)]
                with m.If(diff == 0):
                    m.next = "IDENTITY"
                with m.Else():
                    m.next = "DIVIDE"
            with m.State("DIVIDE"):
                # floor(255 * 2**SCALE_BITS / R), one quotient bit per cycle
                rem = Cat(numer[-1], remainder[:-1])
                ge = rem >= R
                m.d.sync += [remainder.eq(Mux(ge, rem - R, rem)), numer.eq(numer << 1),
                             quotient.eq(Cat(ge, quotient[:-1])), div_step.eq(div_step - 1)]
                with m.If(div_step == 0):
                    m.d.sync += wait.eq(CONSTANT_STAGES)
                    m.next = "CONSTANTS"
            with m.State("CONSTANTS"):
                m.d.sync += wait.eq(wait - 1)
                with m.If(wait == 0):
                    # exponents relative to 2**-SCALE_BITS: Ea = a24_s + a53_s, Eb = b24_s +
                    # b53_s + a53_s (eb above); L = -min(Ea, Eb) + SCALE_BITS (e_min above)
                    m.d.sync += [ma.eq(a24), mb.eq(Mux(lo == 0, 0, b24)),
                                 ea_sh.eq(a24_s - e_min),
                                 eb_sh.eq(Mux(lo == 0, 0, eb - e_min)),
                                 frac_bits.eq(SCALE_BITS - a53_s_late - e_min)]
                    m.next = "TABLE"
            with m.State("TABLE"):
                m.d.comb += scan_valid.eq(1)
                m.d.sync += x.eq(x + 1)
                with m.If(x == 255):
                    # FLUSH and DONE take TABLE_STAGES cycles: the last entry is written in
                    # the last of them, and a table read sees a write from the cycle before
                    m.d.sync += in_flight.eq(TABLE_STAGES - 2)
                    m.next = "FLUSH"
            with m.State("FLUSH"):
                m.d.sync += in_flight.eq(in_flight - 1)
                with m.If(in_flight == 0):
                    m.next = "DONE"
            with m.State("IDENTITY"):
                m.d.comb += [lut_wr.en.eq(1), lut_wr.addr.eq(x), lut_wr.data.eq(x)]
                m.d.sync += x.eq(x + 1)
                with m.If(x == 255):
                    m.next = "DONE"
            with m.State("DONE"):
                m.d.sync += [draining.eq(1), filling.eq(1), total.eq(0)]
                m.next = "FILL"
        return m
