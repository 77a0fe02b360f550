"""Streaming k x k neighbourhood filters with line buffers and OpenCV border modes."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, signed
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import Out

from ..params import ParameterError, check_choice
from ..stream.fifo import StreamFIFO
from .image import (BORDERS, FrameGuard, check_image_params, image_kernel_members,
                    image_stream_signature)

__all__ = ["WindowFilter", "border_index"]


def border_index(x, size, border):
    """Where pixel ``x`` of a line of ``size`` comes from: an index in ``0..size-1``, or
    ``None`` for the constant (zero) border. Plain-Python form of the hardware's mapping."""
    if 0 <= x < size:
        return x
    if border == "constant":
        return None
    if border == "replicate":
        return 0 if x < 0 else size - 1
    return -x if x < 0 else 2 * (size - 1) - x


class WindowContext:
    """What :meth:`WindowFilter.compute` sees of the output position.

    Attributes
    ----------
    row : Value
        Output row (0..height-1).
    beat : Value
        Output beat in its row (0..width/P-1); pixel ``p`` of the beat is column
        ``beat * P + p``.
    width_beats, height : Value
        Size of the frame, in beats per row and rows.

    All four belong to the window's pipeline stage, like the pixels; a value derived from them
    goes through :meth:`register` as often as the pixel arithmetic does.
    """

    def __init__(self, row, beat, width_beats, height, register):
        self.row, self.beat, self.width_beats, self.height = row, beat, width_beats, height
        self._register = register

    def register(self, value, name="stage"):
        """``value`` one pipeline stage later, held while the output stalls."""
        return self._register(value, name)


class WindowFilter(wiring.Component):
    """Base of the k x k filters: a pipeline from an image stream to an image stream.

    ``k - 1`` line buffers of ``max_width`` pixels (one block RAM word holds a column of
    them) and a horizontal register of ``2L + 1`` beats (``L = ceil(R / P)``, ``R = k // 2``)
    give every output pixel its k x k neighbourhood, with rows and columns outside the frame
    supplied by the border mode. Subclasses implement :meth:`compute`.

    Timing: a frame of ``height`` rows of ``width / P`` beats takes
    ``(height + R) * (width / P + L)`` cycles (``R`` rows drain after the last input row,
    ``L`` beats after each row) plus 5 between frames, when neither side stalls. The window's
    pixels are registered after the border selection, and a subclass splits its arithmetic
    into :attr:`compute_stages` registered stages (:meth:`WindowContext.register`), so that
    the path between two registers stays short enough for the target clock; each stage adds
    a cycle of latency, none of throughput.

    The pipeline never stalls. Results enter a small output FIFO (:attr:`output_depth`
    entries), and a step starts only while a FIFO entry is reserved for its result (one
    credit per entry, returned when a result leaves at ``o`` or a step turns out to make
    none). Backpressure at ``o`` therefore stops the input, not the pipeline: no enable
    fans out from ``o.tready`` to the thousands of pipeline registers of a wide filter,
    which is what kept the router from finishing such filters.

    Parameters
    ----------
    ksize : int
        Window size, 3 or 5.
    channels : int
        Bytes per pixel.
    out_channels : int
        Bytes per output pixel.
    pixels_per_beat : int
        1, 2, 4 or 8.
    max_width, max_height : int
        Largest frame; the line buffers hold ``max_width`` pixels.
    border : str
        One of :data:`~hdl.kernels.image.BORDERS`.

    Members
    -------
    i : In(image_stream_signature(channels, pixels_per_beat))
        Input frames (see :mod:`hdl.kernels.image`).
    o : Out(image_stream_signature(out_channels, pixels_per_beat))
        Filtered frames of the same size, ``tuser[0]`` on the first beat, ``tlast`` on the
        last.
    width, height : In
        Frame size in pixels, sampled at the first beat of a frame; the width must be a
        multiple of P, at least ``max(k, (2L + 1) P)``, and the height at least k. Other sizes
        drop the frame (``err_size``).
    err_short, err_long, err_size : Out(1)
        A frame ended early (padded with zero pixels), ran late (cut) or had a size the
        filter cannot process (dropped): one-cycle pulses (:class:`FrameGuard`).
    busy : Out(1)
        A frame is in the pipeline.
    """

    def __init__(self, ksize, *, channels, out_channels, pixels_per_beat, max_width,
                 max_height, border, channel_choices=(1, 2, 3, 4)):
        check_choice("ksize", ksize, (3, 5))
        check_image_params(channels, pixels_per_beat, max_width, max_height,
                           channel_choices=channel_choices)
        check_choice("border", border, BORDERS)
        self._k, self._c, self._oc, self._p = ksize, channels, out_channels, pixels_per_beat
        self._r = ksize // 2
        self._l = -(-self._r // pixels_per_beat)
        self._max_width, self._max_height, self._border = max_width, max_height, border
        self._min_width = max(ksize, (2 * self._l + 1) * pixels_per_beat)
        if max_width < self._min_width or max_height < ksize:
            raise ParameterError("max_width x max_height", f"{max_width}x{max_height}",
                                 f"at least {self._min_width}x{ksize} for ksize {ksize} and "
                                 f"{pixels_per_beat} pixels per beat")
        super().__init__({
            **image_kernel_members(channels, out_channels, pixels_per_beat, max_width,
                                   max_height),
            "busy": Out(1),
        })

    ksize = property(lambda self: self._k)
    channels = property(lambda self: self._c)
    out_channels = property(lambda self: self._oc)
    pixels_per_beat = property(lambda self: self._p)
    max_width = property(lambda self: self._max_width)
    max_height = property(lambda self: self._max_height)
    border = property(lambda self: self._border)
    min_width = property(lambda self: self._min_width)

    @property
    def output_depth(self):
        """Entries of the output FIFO: enough credits to cover the round trip from a step's
        start through the pipeline and the FIFO back to its credit, so that a frame flows
        at one beat per cycle while ``o`` is ready."""
        round_trip = self.pipeline_stages + 4
        return max(16, 1 << (round_trip - 1).bit_length())

    @property
    def pipeline_stages(self):
        """Registers between a step's start and the output FIFO's input."""
        return 6 + self.compute_stages

    def cycles_per_frame(self, width, height):
        """Cycles between frames when neither side stalls (see the class docstring)."""
        return (height + self._r) * (width // self._p + self._l) + 5

    #: registered stages inside :meth:`compute` on every path from a pixel to an output
    compute_stages = 0

    def compute(self, m, pixel, ctx):
        """Return the ``P`` output pixels (``8 * out_channels`` bits each).

        ``pixel(p, dy, dx)`` is the input pixel at row ``row + dy - R`` and column
        ``beat * P + p + dx - R`` (``dy, dx`` in ``0..k-1``), border applied; ``ctx`` is a
        :class:`WindowContext`. Every path from a pixel to a result passes
        :attr:`compute_stages` times through ``ctx.register``; the result is registered once
        more in front of the output FIFO.
        """
        raise NotImplementedError

    def elaborate(self, platform):
        m = Module()
        k, R, L, P = self._k, self._r, self._l, self._p
        pix_bits = 8 * self._c
        beat_bits = pix_bits * P
        max_wb = self._max_width // P
        max_h = self._max_height

        m.submodules.guard = guard = FrameGuard(self._c, P, self._max_width, max_h,
                                                min_width=self._min_width, min_height=k)
        wiring.connect(m, wiring.flipped(self.i), guard.i)
        m.d.comb += [guard.width.eq(self.width), guard.height.eq(self.height),
                     self.err_short.eq(guard.err_short), self.err_long.eq(guard.err_long),
                     self.err_size.eq(guard.err_size)]

        m.submodules.lines = lines = Memory(shape=(k - 1) * beat_bits, depth=max_wb, init=[])
        rd = lines.read_port()
        wr = lines.write_port()

        depth = self.output_depth
        m.submodules.out_fifo = out_fifo = StreamFIFO(image_stream_signature(self._oc, P), depth)
        wiring.connect(m, out_fifo.m_axis, wiring.flipped(self.o))
        # credits: FIFO entries not reserved by a step in the pipeline or a result in the FIFO
        credits = Signal(range(depth + 1), init=depth)
        drop = Signal()
        pop = Signal()
        m.d.comb += pop.eq(self.o.tvalid & self.o.tready)

        # stage 0: the step counters; one step per column beat, L flush steps per row
        wb = Signal(range(max_wb + 1))
        h = Signal(range(max_h + 1))
        run = Signal()
        r0 = Signal(range(max_h + R + 1))
        c0 = Signal(range(max_wb + L + 1))
        # "c0 < wb", "r0 < h" and the ends of a row and of the frame are kept in flip-flops
        # beside the counters: the guard's ready (and through it the upstream handshake)
        # does not wait for comparisons as long as the counters. The guard's minimum size
        # makes wb and h at least 1, so both flags start a frame set.
        col_in, row_in = Signal(), Signal()
        wb_last, h_last = Signal.like(wb), Signal.like(h)
        c0_end, r0_end = Signal.like(c0), Signal.like(r0)
        needs_input = row_in & col_in
        go0 = Signal()
        room = credits != 0
        m.d.comb += [go0.eq(run & room & (~needs_input | guard.o.tvalid)),
                     guard.o.tready.eq(run & room & needs_input),
                     rd.addr.eq(Mux(col_in, c0, 0))]
        m.d.sync += credits.eq(credits - go0 + pop + drop)
        v1, v1b, v2, v3 = Signal(), Signal(), Signal(), Signal()
        # the size registers serve the stages up to 3: a frame starts once the last one has
        # left them
        with m.If(~run & ~v1 & ~v1b & ~v2 & ~v3 & guard.o.tvalid):
            beats = guard.frame_width // P
            m.d.sync += [wb.eq(beats), h.eq(guard.frame_height),
                         wb_last.eq(beats - 1), h_last.eq(guard.frame_height - 1),
                         c0_end.eq(beats + L - 1), r0_end.eq(guard.frame_height + R - 1),
                         r0.eq(0), c0.eq(0), col_in.eq(1), row_in.eq(1), run.eq(1)]
        with m.If(go0):
            with m.If(c0 == c0_end):
                m.d.sync += [c0.eq(0), col_in.eq(1)]
                with m.If(r0 == r0_end):
                    m.d.sync += run.eq(0)
                with m.Else():
                    m.d.sync += [r0.eq(r0 + 1), row_in.eq(row_in & (r0 != h_last))]
            with m.Else():
                m.d.sync += [c0.eq(c0 + 1), col_in.eq(col_in & (c0 != wb_last))]

        # stage 1: line buffer data; vertical border selection
        r1, c1, w1 = Signal.like(r0), Signal.like(c0), Signal()
        d1 = Signal(beat_bits)
        m.d.sync += [v1.eq(go0), r1.eq(r0), c1.eq(c0), w1.eq(needs_input),
                     d1.eq(guard.o.tdata)]
        m.d.comb += [wr.addr.eq(c1), wr.en.eq(v1 & w1),
                     wr.data.eq(Cat(d1, rd.data[:(k - 2) * beat_bits]))]
        # the line buffer's output registered before the vertical selection (the block RAM's
        # output and the selection do not fit one 100 MHz period together at 4 pixels/clock)
        r1b, c1b = Signal.like(r0), Signal.like(c0)
        d1b, q1b = Signal(beat_bits), Signal((k - 1) * beat_bits)
        m.d.sync += [v1b.eq(v1), r1b.eq(r1), c1b.eq(c1), d1b.eq(d1), q1b.eq(rd.data)]
        sources = [d1b] + [q1b.word_select(i, beat_bits) for i in range(k - 1)]
        # which source each window row takes is worked out in stage 1 and registered beside
        # the data, so stage 1b is a plain multiplexer
        rows_in = Mux(r1 < h, r1, h)            # source s holds row rows_in - s
        taps1 = []
        zero1 = []
        hs = Signal(signed(h.shape().width + 2))
        m.d.comb += hs.eq(h)
        for t in range(k):
            n = Signal(signed(r1.shape().width + 2), name=f"vrow{t}")
            m.d.comb += n.eq(r1 - 2 * R + t)
            if self._border == "reflect101":
                src_row = Mux(n < 0, -n, Mux(n > hs - 1, 2 * (hs - 1) - n, n))
            elif self._border == "replicate":
                src_row = Mux(n < 0, 0, Mux(n > hs - 1, hs - 1, n))
            else:
                src_row = n
            sel, sel_b = Signal(range(k), name=f"vsel{t}"), Signal(range(k), name=f"vsel_b{t}")
            zero, zero_b = Signal(name=f"vzero{t}"), Signal(name=f"vzero_b{t}")
            m.d.comb += [sel.eq(rows_in - src_row),
                         zero.eq((n < 0) | (n > hs - 1) if self._border == "constant" else 0)]
            m.d.sync += [sel_b.eq(sel), zero_b.eq(zero)]
            tap = Signal(beat_bits, name=f"vtap{t}")
            with m.Switch(sel_b):
                for s in range(k):
                    with m.Case(s):
                        m.d.comb += tap.eq(sources[s])
            taps1.append(tap)
            zero1.append(zero_b)

        r2, c2 = Signal.like(r0), Signal.like(c0)
        taps2 = [Signal(beat_bits, name=f"taps2_{t}") for t in range(k)]
        m.d.sync += [v2.eq(v1b), r2.eq(r1b), c2.eq(c1b)]
        m.d.sync += [t2.eq(Mux(z, 0, t1)) for t1, t2, z in zip(taps1, taps2, zero1)]

        # stage 2: horizontal register of 2L + 1 beats (oldest first)
        hreg = [[Signal(beat_bits, name=f"hreg{b}_{t}") for t in range(k)]
                for b in range(2 * L + 1)]
        row3, beat3 = Signal(range(max_h)), Signal(range(max_wb + L + 1))
        makes_output = (r2 >= R) & (c2 >= L)
        m.d.comb += drop.eq(v2 & ~makes_output)
        m.d.sync += [v3.eq(v2 & makes_output), row3.eq(r2 - R), beat3.eq(c2 - L)]
        with m.If(v2):
            for b in range(2 * L):
                m.d.sync += [hreg[b][t].eq(hreg[b + 1][t]) for t in range(k)]
            m.d.sync += [hreg[2 * L][t].eq(taps2[t]) for t in range(k)]

        # stage 3: horizontal border selection
        flat = [[hreg[f // P][t].word_select(f % P, pix_bits) for t in range(k)]
                for f in range((2 * L + 1) * P)]
        left = [beat3 == c for c in range(L)]
        right = [beat3 == wb - e for e in range(1, L + 1)]
        cache = {}

        def pixel(p, dy, dx):
            key = (p, dy, dx)
            if key in cache:
                return cache[key]
            default = L * P + p + dx - R
            value = flat[default][dy]
            for c in range(L):
                x = c * P + p + dx - R
                if x < 0:
                    src = border_index(x, 1 << 30, self._border)
                    alt = Const(0, pix_bits) if src is None else flat[src + (L - c) * P][dy]
                    value = Mux(left[c], alt, value)
            for e in range(1, L + 1):
                x_rel = p + dx - R - e * P
                if x_rel >= 0:
                    if self._border == "constant":
                        alt = Const(0, pix_bits)
                    elif self._border == "replicate":
                        alt = flat[(e + L) * P - 1][dy]
                    else:
                        alt = flat[(e + L) * P - 2 - x_rel][dy]
                    value = Mux(right[e - 1], alt, value)
            sig = Signal(pix_bits, name=f"win_p{p}_y{dy}_x{dx}")
            m.d.sync += sig.eq(value)
            cache[key] = sig
            return sig

        def register(value, name):
            value = Value.cast(value)
            reg = Signal(value.shape(), name=name)
            m.d.sync += reg.eq(value)
            return reg

        # stage 4: the window registered; the compute stages follow
        v4, row4, beat4 = Signal(), Signal.like(row3), Signal.like(beat3)
        wb4, h4, last4, user4 = Signal.like(wb), Signal.like(h), Signal(), Signal()
        m.d.sync += [v4.eq(v3), row4.eq(row3), beat4.eq(beat3), wb4.eq(wb), h4.eq(h),
                     last4.eq((row3 == h_last) & (beat3 == wb_last)),
                     user4.eq((row3 == 0) & (beat3 == 0))]
        ctx = WindowContext(row4, beat4, wb4, h4, register)
        outputs = self.compute(m, pixel, ctx)
        valid, last, user = v4, last4, user4
        stage_valids = [v4]
        for n in range(self.compute_stages):
            valid = register(valid, f"v_compute{n}")
            last, user = register(last, f"last_compute{n}"), register(user, f"user_compute{n}")
            stage_valids.append(valid)
        # the results registered once more before the FIFO's memory: a credit guarantees room
        fifo_in = out_fifo.s_axis
        m.d.sync += [fifo_in.tvalid.eq(valid), fifo_in.tdata.eq(Cat(*outputs)),
                     fifo_in.tlast.eq(last), fifo_in.tuser.eq(user)]
        m.d.comb += self.busy.eq(run | v1 | v1b | v2 | v3 | fifo_in.tvalid |
                                 Cat(*stage_valids).any() | (out_fifo.level != 0))
        return m
