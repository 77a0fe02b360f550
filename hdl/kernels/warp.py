"""Perspective warp with bilinear interpolation, as ``cv2.warpPerspective`` computes it
(docs/kernels.md): the image projection of the AutoRace lane-following chain."""

import math
from fractions import Fraction

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, signed
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..logic import adder_tree
from ..params import ParameterError, check_int
from ..stream import StreamFIFO
from .image import FrameGuard, check_image_params, image_stream_signature

__all__ = ["PerspectiveWarp", "CoordinateDivider", "MATRIX_FRACTION_BITS", "COORD_FRACTION_BITS",
           "QUOTIENT_BITS"]

#: fraction bits of the matrix entries (each double is rounded to a multiple of 2**-64)
MATRIX_FRACTION_BITS = 64
#: fraction bits of a source coordinate (OpenCV computes it in float32)
COORD_FRACTION_BITS = 16
#: the most quotient bits a coordinate division needs (a 4096-pixel source): |x| <
#: 2**(QUOTIENT_BITS - 16) pixels, else outside. A warp takes as many as its source needs
QUOTIENT_BITS = 28
#: registers from a beat's quotients to its output pixels (``PerspectiveWarp.elaborate``)
PIXEL_STAGES = 7


def _fixed(value, what):
    try:
        exact = Fraction(float(value))
    except (TypeError, ValueError, OverflowError):
        raise ParameterError(what, value, "a finite number") from None
    return round(exact * (1 << MATRIX_FRACTION_BITS))


class CoordinateDivider(wiring.Component):
    """``2**16 n / w`` for each of ``count`` numerators over one denominator ``w``, as a
    reciprocal and a product each, pipelined: one set of divisions per cycle. A
    :class:`PerspectiveWarp` has one per pixel lane (its ``div<p>``), for the lane's x and y
    over their common denominator.

    The denominator's range ``lo <= w <= hi`` is known when the divider is built (the warp's
    denominator is a linear function of the destination pixel), so it is scaled by a
    constant power of two, ``w' = floor(w / 2**s)`` with ``2**(T-1) <= lo'`` (``T`` the
    precision), and the numerators with it, ``n' = floor(n / 2**s)``; for ``s < 0`` both are
    shifted left, exactly. ``R = floor(2**K / w')`` with ``K = b + T - 1`` (``b`` the bits of
    ``hi'``) comes from a non-restoring division, ``b + 1`` steps of an adder as wide as
    ``w'`` (``bits_per_stage`` of them per register stage); then each quotient is
    ``floor(n' R / 2**(K - 16))``.

    The result differs from ``floor(2**16 n / w)`` by at most 1 (a unit of ``2**-16``):
    truncating ``w``, ``n`` and ``R`` to ``T`` significant bits moves a quotient below
    ``2**quotient_bits`` by less than ``2**(quotient_bits + 2 - T) + 2**(17 - T)`` units,
    and leaving out ``n'``'s low :attr:`numerator_drop` bits by less than a sixteenth more:
    about a third in all for the default ``T = quotient_bits + 4``. ``outside[i]`` when
    quotient ``i`` lies outside ``[-2**quotient_bits, 2**quotient_bits)`` (within a unit of
    the exact one's limit, either answer); a numerator so large that no denominator of the
    range brings it inside is outside before the product (``|n'| >= 2**(quotient_bits - 15 +
    b)``), so the multipliers are as wide as the quotients need, whatever the numerators'
    width.

    Parameters
    ----------
    width : int
        Bits of each ``n`` (signed).
    count : int
        Numerators sharing the denominator.
    denominator_range : (int, int)
        The smallest and largest ``w`` the divider is given (``0 < lo <= hi``); a ``w``
        outside the range gives quotients of no meaning.
    quotient_bits : int
        Bits of a quotient's magnitude, 17 or more (16 of them below the point).
    precision : int or None
        ``T``, the significant bits kept of ``w``, ``n`` and ``R``: ``quotient_bits + 4`` if
        None; ``quotient_bits + 3`` at least.
    bits_per_stage : int
        Reciprocal bits per register stage, 1 to 4: fewer cycles, longer paths.

    Members
    -------
    n : In(signed(width)).array(count)
        Numerators, taken with ``w`` while ``valid``.
    w : In(hi.bit_length())
        The denominator.
    valid : In(1)
    q : Out(signed(quotient_bits + 1)).array(count)
        Quotients, :attr:`latency` cycles after their inputs.
    outside : Out(1).array(count)
    q_valid : Out(1)
        ``valid``, delayed with the quotients.
    """

    #: bits of ``R`` per partial product (a multiplier block's unsigned input)
    CHUNK_BITS = 17

    def __init__(self, width, count=2, *, denominator_range, quotient_bits=QUOTIENT_BITS,
                 precision=None, bits_per_stage=1):
        check_int("width", width, 2, 1 << 12)
        check_int("count", count, 1, 16)
        check_int("quotient_bits", quotient_bits, COORD_FRACTION_BITS + 1, 64)
        if precision is None:
            precision = quotient_bits + 4
        check_int("precision", precision, quotient_bits + 3, 128)
        try:
            lo, hi = (int(v) for v in denominator_range)
        except (TypeError, ValueError):
            raise ParameterError("denominator_range", denominator_range,
                                 "two integers (lo, hi)") from None
        if not 0 < lo <= hi:
            raise ParameterError("denominator_range", denominator_range, "0 < lo <= hi")
        self._count = count
        self._q = quotient_bits
        self._t = precision
        self._per_stage = check_int("bits_per_stage", bits_per_stage, 1, 4)
        #: the scale: w' = w / 2**shift (a left shift when negative)
        self.shift = lo.bit_length() - precision
        #: bits of the largest scaled denominator
        self.scaled_bits = self._scaled(hi).bit_length()
        super().__init__({"n": In(signed(width)).array(count), "w": In(hi.bit_length()),
                          "valid": In(1), "q": Out(signed(quotient_bits + 1)).array(count),
                          "outside": Out(1).array(count), "q_valid": Out(1)})

    def _scaled(self, v):
        return v >> self.shift if self.shift >= 0 else v << -self.shift

    @property
    def reciprocal_exponent(self):
        """``K``: the reciprocal is ``floor(2**K / w')``."""
        return self.scaled_bits + self._t - 1

    @property
    def numerator_drop(self):
        """Low bits of ``n'`` left out of the products (``T - 21``, at least 0): they move a
        quotient by less than ``2**(u + 17 - T)`` units, a sixteenth."""
        return max(0, self._t - 21)

    @property
    def numerator_limit(self):
        """``|n'|`` at or above ``2**numerator_limit`` is outside for any ``w`` of the range."""
        return self._q - COORD_FRACTION_BITS + 1 + self.scaled_bits

    @property
    def latency(self):
        """Cycles from a set of inputs to its quotients: the scaled inputs, the division's
        ``b + 1`` quotient bits at ``bits_per_stage`` per register stage, the partial products,
        their sum."""
        return 3 - (-(self.scaled_bits + 1) // self._per_stage)

    def elaborate(self, platform):
        m = Module()
        Q, F, T = self._q, COORD_FRACTION_BITS, self._t
        b = self.scaled_bits
        K = self.reciprocal_exponent
        L = self.numerator_limit
        # the numerators' low bits below what the quotients need (numerator_drop)
        u = self.numerator_drop
        NW = L + 1 - u
        steps = b + 1

        # scaled inputs; a numerator beyond the limit is outside and multiplies as 0
        den, v = Signal(b, name="den"), Signal(name="v0")
        m.d.sync += [den.eq(self._scaled(self.w)), v.eq(self.valid)]
        nums, far = [], []
        for i in range(self._count):
            scaled = self._scaled(self.n[i])
            high = scaled >> L
            beyond = (high != 0) & (high != -1)
            num, out = Signal(signed(NW), name=f"num{i}"), Signal(name=f"far{i}")
            m.d.sync += [num.eq(Mux(beyond, 0, scaled >> u)), out.eq(beyond)]
            nums.append(num)
            far.append(out)

        # R = floor(2**K / w'), non-restoring: the remainder r starts at 2**(T-2) (< w'),
        # each stage doubles it and subtracts w' (r >= 0, quotient bit 1) or adds it (0); the
        # quotient is the bits with the final remainder's "not negative" appended, taken
        # modulo 2**steps
        rem = Const(1 << (T - 2), signed(b + 1))
        quo = Const(0, 0)
        stage = 0
        for k in range(steps):
            neg = rem[-1]
            # 2r + w' or 2r - w' = 2r + ~w' + 1, modulo 2**(b+1) (the result fits): one
            # adder, the carry entering as the doubled remainder's low bit
            wide = Cat(den, Const(0, 1))
            rem = (Cat(~neg, rem)[:b + 1] + Mux(neg, wide, ~wide))[:b + 1].as_signed()
            quo = Cat(~neg, quo)
            if (k + 1) % self._per_stage and k != steps - 1:
                continue
            stage += 1
            rem_n = Signal(signed(b + 1), name=f"rem{stage}")
            quo_n = Signal(k + 1, name=f"quo{stage}")
            # the delay lines have no reset (Xilinx maps them to shift-register LUTs)
            den_n = Signal(b, name=f"den{stage}", reset_less=True)
            v_n = Signal(name=f"v{stage}")
            nums_n = [Signal(signed(NW), name=f"num{i}_{stage}", reset_less=True)
                      for i in range(self._count)]
            far_n = [Signal(name=f"far{i}_{stage}", reset_less=True) for i in range(self._count)]
            m.d.sync += [rem_n.eq(rem), quo_n.eq(quo), den_n.eq(den), v_n.eq(v)]
            m.d.sync += [a.eq(b_) for a, b_ in zip(nums_n + far_n, nums + far)]
            rem, quo, den, v, nums, far = rem_n, quo_n, den_n, v_n, nums_n, far_n
        recip = Cat(~rem[-1], quo[:steps - 1])

        # n' R as partial products of CHUNK_BITS of R each, then their sum
        C = self.CHUNK_BITS
        chunks = [recip[k:k + C] for k in range(0, steps, C)]
        v_p, v_s = Signal(name="v_p"), Signal(name="v_s")
        m.d.sync += [v_p.eq(v), v_s.eq(v_p)]
        for i in range(self._count):
            parts = []
            for j, chunk in enumerate(chunks):
                part = Signal(signed(NW + len(chunk) + 1), name=f"part{i}_{j}")
                m.d.sync += part.eq(nums[i] * chunk)
                parts.append((part, j * C))
            far_p, far_s = Signal(name=f"far{i}_p"), Signal(name=f"far{i}_s")
            total = sum(part.as_signed() << shift for part, shift in parts)
            full = Signal(signed(NW + 1 + steps), name=f"prod{i}")
            m.d.sync += [far_p.eq(far[i]), far_s.eq(far_p), full.eq(total)]
            quotient = full >> (K - F - u)
            m.d.comb += [self.q[i].eq(quotient),
                         self.outside[i].eq(far_s | (quotient >= (1 << Q))
                                            | (quotient < -(1 << Q)))]
        m.d.comb += self.q_valid.eq(v_s)
        return m


class PerspectiveWarp(wiring.Component):
    """``cv2.warpPerspective(src, H, (dst_width, dst_height))`` on ``bgr8`` frames: bilinear
    interpolation, border constant 0.

    A source frame is stored (four banks by row and column parity, so one read per bank
    gives a pixel's 2x2 neighbourhood; only the :attr:`stored_window` the map can read), then
    the destination frame streams out, ``P`` pixels per beat. Each destination pixel's source
    position is ``((m0 x + m1 y + m2) / (m6 x + m7 y + m8), (m3 x + m4 y + m5) / (...))``,
    the sums exact with the inverse matrix's entries as multiples of ``2**-64``, the
    quotients in units of ``2**-16`` pixel, equal to the exact quotient's floor or one unit
    off (a :class:`CoordinateDivider` per lane: one reciprocal of the denominator and a
    product for x and for y). The value is the bilinear mix of the
    four neighbours with the fractions' products as weights (they sum to ``2**32``), rounded
    to nearest; neighbours outside the source count as 0.

    OpenCV (5.x) computes the position and the mix in float32 and rounds the result, so the
    two differ by at most 1, and only in a pixel whose value lies within float32's error of a
    half (about 1 % of the pixels of a photograph); never by more.

    Parameters
    ----------
    matrix : 3x3 numbers
        The inverse map, destination pixel -> source pixel (``cv2.invert(H)`` of the forward
        homography, which ``cv2.warpPerspective`` uses); its bottom row must give the
        denominator one sign over the whole destination (checked at the four corners; a
        negative one is made positive by scaling the map by -1).
    src_width, src_height : int
        The source frame (the input must be exactly this size).
    dst_width, dst_height : int
        The destination frame.
    pixels_per_beat : int
        1, 2, 4 or 8, in and out.

    Members
    -------
    i : In(image_stream_signature(3, P))
        Source frames.
    o : Out(image_stream_signature(3, P))
        Destination frames, ``tuser`` on the first beat, ``tlast`` on the last.
    err_short, err_long, err_size : Out(1)
        Bad source frames (:class:`~hdl.kernels.image.FrameGuard`; the size is the
        parameters').
    outside : Out(32)
        Destination pixels of the last frame whose whole neighbourhood lay outside the source.
    """

    def __init__(self, matrix, *, src_width, src_height, dst_width, dst_height,
                 pixels_per_beat=1):
        check_image_params(3, pixels_per_beat, src_width, src_height, channel_choices=(3,))
        check_int("dst_width", dst_width, pixels_per_beat, 1 << 12)
        check_int("dst_height", dst_height, 1, 1 << 12)
        if dst_width % pixels_per_beat:
            raise ParameterError("dst_width", dst_width,
                                 f"a multiple of pixels_per_beat ({pixels_per_beat})")
        if src_width % 2 or src_height % 2:
            raise ParameterError("src_width, src_height", (src_width, src_height),
                                 "even sizes (the frame store's banks)")
        rows = [list(r) for r in matrix]
        if len(rows) != 3 or any(len(r) != 3 for r in rows):
            raise ParameterError("matrix", matrix, "3 rows of 3 numbers")
        self._m = [_fixed(v, f"matrix[{i // 3}][{i % 3}]")
                   for i, v in enumerate(x for r in rows for x in r)]
        self._dst = (dst_width, dst_height)
        if all(self._linear(2, x, y) < 0 for x, y in self._corners):
            # the same map scaled by -1: the denominator becomes positive
            self._m = [-v for v in self._m]
        for x, y in self._corners:
            if self._linear(2, x, y) <= 0:
                raise ParameterError("matrix", matrix,
                                     f"a map whose denominator is positive over the "
                                     f"destination (at ({x}, {y}) it is not: the homography "
                                     f"maps that pixel to infinity or behind the camera)")
        self._p = pixels_per_beat
        self._src = (src_width, src_height)
        sig = image_stream_signature(3, pixels_per_beat)
        super().__init__({"i": In(sig), "o": Out(sig), "err_short": Out(1),
                          "err_long": Out(1), "err_size": Out(1), "outside": Out(32)})

    pixels_per_beat = property(lambda self: self._p)

    def _linear(self, k, x, y):
        """Row ``k`` of the map at destination pixel ``(x, y)``: the x (0) or y (1) numerator,
        or the denominator (2), as the coordinate registers hold it."""
        return self._m[3 * k] * x + self._m[3 * k + 1] * y + self._m[3 * k + 2]

    def _register_values(self):
        """Every value a coordinate register takes: the three sums at the corners of the
        destination, one row past the last (the row registers step there after the last
        beat), a linear function's extremes."""
        dw, dh = self._dst
        return [[self._linear(k, x, y) for x in (0, dw - 1) for y in (0, dh)]
                for k in range(3)]

    @property
    def _divider_width(self):
        # the numerators' registers, signed
        return max(abs(v) for vs in self._register_values() for v in vs).bit_length() + 1

    @property
    def _corners(self):
        """The destination's corner pixels: a linear function of the pixel, and the source
        position (the map keeps the rectangle convex), has its extremes there."""
        dw, dh = self._dst
        return ((0, 0), (dw - 1, 0), (0, dh - 1), (dw - 1, dh - 1))

    @property
    def _denominator_range(self):
        # the denominator where a pixel is issued (positive there: checked at the corners)
        values = [self._linear(2, x, y) for x, y in self._corners]
        return min(values), max(values)

    @property
    def _quotient_bits(self):
        # a source coordinate of magnitude 2**k or more has no neighbour inside once
        # 2**k >= the source's size (a coordinate x has x and x + 1 as neighbours)
        sw, sh = self._src
        return max((sw - 1).bit_length(), (sh - 1).bit_length(), 1) + COORD_FRACTION_BITS

    @property
    def stored_window(self):
        """``(x0, y0, width, height)``: the part of the source frame the store keeps, every
        pixel the map can read. The map takes the destination rectangle to a convex
        quadrilateral (its denominator has one sign there), so the source positions lie
        between its corners' extremes; a pixel's neighbours reach one further, and a computed
        position may lie one pixel off (its last bit), so the window reaches one more each
        way, clipped to the frame. ``x0`` is a multiple of the store's word (2 pixels, P at
        2 pixels per beat and more), ``y0`` is even, and the sizes keep the banks whole."""
        sw, sh = self._src
        align = 2 * max(self._p // 2, 1)
        xs, ys = [], []
        for x, y in self._corners:
            w = self._linear(2, x, y)
            xs.append(Fraction(self._linear(0, x, y), w))
            ys.append(Fraction(self._linear(1, x, y), w))

        def span(values, size, step):
            low = min(max(math.floor(min(values)) - 1, 0), size - 1)
            high = min(max(math.floor(max(values)) + 2, low), size - 1)
            low -= low % step
            high += step - 1 - high % step
            return low, high + 1 - low

        (x0, kw), (y0, kh) = span(xs, sw, align), span(ys, sh, 2)
        return x0, y0, kw, kh

    #: the names of the :class:`CoordinateDivider` submodules, ``div<p>`` (a regular
    #: expression over a hierarchical module name)
    DIVIDER_SUBMODULES = r"\.div\d+$"

    def coordinate_divider(self):
        """A new :class:`CoordinateDivider` as this warp instantiates it
        :attr:`coordinate_divider_count` times (one per pixel lane, for x and y): resource
        estimates synthesise it once."""
        return CoordinateDivider(self._divider_width, 2,
                                 denominator_range=self._denominator_range,
                                 quotient_bits=self._quotient_bits, bits_per_stage=2)

    coordinate_divider_count = property(lambda self: self._p)

    def elaborate(self, platform):
        m = Module()
        P = self._p
        sw, sh = self._src
        dw, dh = self._dst
        m.submodules.guard = guard = FrameGuard(3, P, sw, sh, min_width=sw, min_height=sh)
        wiring.connect(m, wiring.flipped(self.i), guard.i)
        m.d.comb += [guard.width.eq(sw), guard.height.eq(sh),
                     self.err_short.eq(guard.err_short), self.err_long.eq(guard.err_long),
                     self.err_size.eq(guard.err_size)]

        # the frame store keeps the window the map reads (stored_window): bank (row & 1,
        # col & 1) holds pixel (r, c) at ((r - y0) >> 1) * w/2 + ((c - x0) >> 1); a beat of P
        # pixels writes P/2 (or 1) pixels into each bank it touches
        per_word = max(P // 2, 1)
        x0, y0, kw, kh = self.stored_window
        words_per_row = kw // 2 // per_word
        depth = (kh // 2) * words_per_row
        # each bank is copied once per pair of pixel lanes (every lane reads its own 2x2
        # neighbourhood in the same cycle); the even lane's read shares its copy's port with
        # the write port (stores and reads never overlap), so a copy fits one true-dual-port
        # block RAM and the store takes P/2 copies instead of P
        copies = max(P // 2, 1)
        # block RAM by name: Yosys' UltraScale+ mapping (0.23) takes a one-port bank (1 px/clk)
        # for distributed RAM, which it then fails to map
        banks = [[[Memory(shape=24 * per_word, depth=depth, init=[],
                          attrs={"ram_style": "block"}) for _ in range(copies)]
                  for _ in range(2)] for _ in range(2)]
        shared_addr = [[[Signal(range(depth), name=f"addr{r}{c}_{k}") for k in range(copies)]
                        for c in range(2)] for r in range(2)]
        for r in range(2):
            for c in range(2):
                for k in range(copies):
                    m.submodules[f"bank{r}{c}_{k}"] = banks[r][c][k]
        row, col = Signal(range(sh + 1)), Signal(range(sw + 1))
        storing = Signal(init=1)
        take = guard.o.tvalid & guard.o.tready
        m.d.comb += guard.o.tready.eq(storing)
        word_addr = ((row - y0) >> 1) * words_per_row + ((col - x0) >> 1) // per_word
        kept = (row >= y0) & (row < y0 + kh) & (col >= x0) & (col < x0 + kw)
        for r in range(2):
            for c in range(2):
                if P == 1:
                    data = guard.o.tdata
                    hit = (row[0] == r) & (col[0] == c)
                else:
                    data = Cat(*(guard.o.tdata.word_select(k, 24) for k in range(c, P, 2)))
                    hit = row[0] == r
                for k in range(copies):
                    wp = banks[r][c][k].write_port()
                    m.d.comb += [wp.addr.eq(shared_addr[r][c][k]), wp.data.eq(data),
                                 wp.en.eq(take & hit & kept)]
        with m.If(take):
            with m.If(col + P == sw):
                m.d.sync += [col.eq(0), row.eq(row + 1)]
            with m.Else():
                m.d.sync += col.eq(col + P)
            with m.If(guard.o.tlast):
                m.d.sync += [storing.eq(0), row.eq(0), col.eq(0)]

        # destination coordinates: numerators per lane, stepped exactly
        m0, m1, m2, m3, m4, m5, m6, m7, m8 = self._m
        width = self._divider_width
        x_row = [Signal(signed(width), name=f"xn_row{k}") for k in range(3)]
        x_lane = [[Signal(signed(width), name=f"n{k}_lane{p}") for k in range(3)]
                  for p in range(P)]
        step = (m0, m3, m6)
        down = (m1, m4, m7)
        start = (m2, m5, m8)
        dx, dy = Signal(range(dw + 1)), Signal(range(dh + 1))
        issuing = Signal()
        m.submodules.out_fifo = out_fifo = StreamFIFO(image_stream_signature(3, P), 64)
        divs = [self.coordinate_divider() for _ in range(P)]
        latency = divs[0].latency
        in_flight = Signal(range(latency + PIXEL_STAGES + 4))
        # the FIFO has room for every beat in flight; decided a cycle ahead (a flip-flop in
        # front of the coordinate registers' enables): the beats in flight and in the FIFO
        # grow by at most one a cycle
        room = Signal()
        m.d.sync += room.eq(out_fifo.level + in_flight + 1 < 60)
        issue = issuing & room
        last_beat = (dx + P == dw) & (dy == dh - 1)

        for p, d in enumerate(divs):
            m.submodules[f"div{p}"] = d
            m.d.comb += [d.n[0].eq(x_lane[p][0]), d.n[1].eq(x_lane[p][1]),
                         d.w.eq(x_lane[p][2]), d.valid.eq(issue)]
        with m.If(issue):
            with m.If(dx + P == dw):
                m.d.sync += [dx.eq(0), dy.eq(dy + 1)]
                for k in range(3):
                    m.d.sync += x_row[k].eq(x_row[k] + down[k])
                    for p in range(P):
                        m.d.sync += x_lane[p][k].eq(x_row[k] + down[k] + p * step[k])
                with m.If(dy == dh - 1):
                    m.d.sync += issuing.eq(0)
            with m.Else():
                m.d.sync += dx.eq(dx + P)
                for k in range(3):
                    for p in range(P):
                        m.d.sync += x_lane[p][k].eq(x_lane[p][k] + P * step[k])

        def delayed(value, name, cycles=1):
            """``value`` through ``cycles`` registers."""
            for _ in range(cycles):
                reg = Signal(Value.cast(value).shape(), name=name)
                m.d.sync += reg.eq(value)
                value = reg
            return value

        # the frame's beat flags travel with the division
        first_flag, last_flag = Signal(), Signal()
        m.d.comb += [first_flag.eq((dx == 0) & (dy == 0)), last_flag.eq(last_beat)]
        flags = delayed(Cat(first_flag, last_flag), "div_flags", latency)

        # The pixel pipeline behind the dividers, a register stage each (PIXEL_STAGES):
        #   A  the source pixel (integer parts), its fractions, "far outside"
        #   N  each bank's neighbour row and column (sy or sy + 1, sx or sx + 1); the weights
        #   R  the banks' reads (their address registers) and the inside flags
        #   W  the read words
        #   V  each neighbour's channel values (chosen by bank parity, 0 outside)
        #   X  the products value x weight
        #   S  their sums; rounded into the output FIFO
        # so that no stage holds more than one carry chain or multiplier behind a choice.
        F = COORD_FRACTION_BITS
        one = 1 << F
        out_valid = delayed(divs[0].q_valid, "pix_valid", PIXEL_STAGES)
        out_flags = delayed(flags, "pix_flags", PIXEL_STAGES)

        out_pixels, none_inside = [], []
        for p in range(P):
            d = divs[p]
            # A
            sx = delayed((d.q[0] >> F)[:self._quotient_bits].as_signed(), f"sx{p}")
            sy = delayed((d.q[1] >> F)[:self._quotient_bits].as_signed(), f"sy{p}")
            ax, ay = delayed(d.q[0][:F], f"ax{p}"), delayed(d.q[1][:F], f"ay{p}")
            away = delayed(d.outside[0] | d.outside[1], f"away{p}")
            # N: pixel (r, c) of the neighbourhood comes from bank ((sy + r) & 1, (sx + c) & 1)
            ny = [delayed(Mux(sy[0] == r, sy, sy + 1)[:len(sy) + 1].as_signed(), f"ny{p}_{r}")
                  for r in range(2)]
            nx = [delayed(Mux(sx[0] == c, sx, sx + 1)[:len(sx) + 1].as_signed(), f"nx{p}_{c}")
                  for c in range(2)]
            away_n = delayed(away, f"away_n{p}")
            sx0, sy0 = delayed(sx[0], f"sx0n{p}"), delayed(sy[0], f"sy0n{p}")
            weights = {}
            for dyo, wy in ((0, one - ay), (1, ay)):
                for dxo, wx in ((0, one - ax), (1, ax)):
                    w = Signal(2 * F + 1, name=f"w{p}_{dyo}{dxo}")
                    m.d.sync += w.eq(wx * wy)
                    weights[(dyo, dxo)] = w
            # R: the reads; the flags and weights travel beside them to W
            reads = {}
            for r in range(2):
                for c in range(2):
                    port = banks[r][c][p // 2].read_port()
                    addr = (((ny[r] - y0) >> 1) * words_per_row
                            + ((nx[c] - x0) >> 1)[:16] // per_word)
                    if p % 2 == 0:
                        shared = shared_addr[r][c][p // 2]
                        m.d.comb += [shared.eq(Mux(storing, word_addr, addr)),
                                     port.addr.eq(shared)]
                    else:
                        m.d.comb += port.addr.eq(addr)
                    inside = delayed(~away_n & (ny[r] >= y0) & (ny[r] < y0 + kh)
                                     & (nx[c] >= x0) & (nx[c] < x0 + kw), f"in{p}_{r}{c}")
                    sel = (delayed((nx[c] >> 1)[:16] % per_word, f"sel{p}_{r}{c}")
                           if per_word > 1 else None)
                    # W
                    word = delayed(port.data, f"word{p}_{r}{c}")
                    inside_w = delayed(inside, f"in_w{p}_{r}{c}")
                    sel_w = delayed(sel, f"sel_w{p}_{r}{c}") if sel is not None else None
                    px = word.word_select(sel_w, 24) if sel_w is not None else word
                    reads[(r, c)] = (px, inside_w)
            sx0_w, sy0_w = delayed(sx0, f"sx0w{p}", 2), delayed(sy0, f"sy0w{p}", 2)
            weights_w = {k: delayed(w, f"{w.name}_w", 2) for k, w in weights.items()}
            # V, X, S
            channels = []
            for ch in range(3):
                products = []
                for (dyo, dxo), wgt in weights_w.items():
                    # neighbour (dyo, dxo) is in bank ((sy + dyo) & 1, (sx + dxo) & 1)
                    value = Const(0, 8)
                    for (r, c), (px, inside) in reads.items():
                        mine = ((sy0_w ^ dyo) == r) & ((sx0_w ^ dxo) == c)
                        value = Mux(mine & inside, px.word_select(ch, 8), value)
                    value_v = delayed(value, f"v{p}_{ch}_{dyo}{dxo}")
                    wgt_v = delayed(wgt, f"{wgt.name}_v")
                    products.append(delayed(value_v * wgt_v, f"x{p}_{ch}_{dyo}{dxo}"))
                acc = Signal(2 * F + 9, name=f"acc{p}_{ch}")
                m.d.sync += acc.eq(adder_tree(products))
                channels.append(acc)
            half = 1 << (2 * F - 1)
            out_pixels.append(Cat(*(((a + half) >> (2 * F))[:8] for a in channels)))
            # the pixels whose neighbourhood is all outside, counted at S
            none = ~(reads[(0, 0)][1] | reads[(0, 1)][1] | reads[(1, 0)][1] | reads[(1, 1)][1])
            none_inside.append(delayed(none, f"none_s{p}", 3))
        m.d.comb += [out_fifo.s_axis.tvalid.eq(out_valid),
                     out_fifo.s_axis.tdata.eq(Cat(*out_pixels)),
                     out_fifo.s_axis.tuser.eq(out_flags[0]),
                     out_fifo.s_axis.tlast.eq(out_flags[1])]
        wiring.connect(m, out_fifo.m_axis, wiring.flipped(self.o))
        m.d.sync += in_flight.eq(in_flight + issue - out_valid)

        outside = Signal(32)
        none_count = sum(none_inside)
        with m.If(out_valid):
            m.d.sync += outside.eq(outside + none_count)
            with m.If(out_flags[1]):
                m.d.sync += [self.outside.eq(outside + none_count), outside.eq(0)]

        # one frame at a time: store the source, issue the destination, let it drain
        with m.FSM():
            with m.State("STORE"):
                with m.If(~storing):
                    m.d.sync += [issuing.eq(1), dx.eq(0), dy.eq(0)]
                    for k in range(3):
                        m.d.sync += x_row[k].eq(start[k])
                        for p in range(P):
                            m.d.sync += x_lane[p][k].eq(start[k] + p * step[k])
                    m.next = "ISSUE"
            with m.State("ISSUE"):
                with m.If(issue & last_beat):
                    m.next = "DRAIN"
            with m.State("DRAIN"):
                with m.If((in_flight == 0) & ~out_valid):
                    m.d.sync += storing.eq(1)
                    m.next = "STORE"
        return m
