"""Sobel filters (docs/reconos.md; docs/kernels.md)."""

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import check_choice, check_int
from ..stream import AXIStreamSignature
from .window import WindowFilter

__all__ = ["Sobel", "SobelByteLanes"]


class SobelByteLanes(wiring.Component):
    """The ReconROS demo's Sobel filter, "per byte lane" (docs/reconos.md), streaming.

    The image is a ``height`` x ``words`` array of little-endian 32-bit words; each byte
    lane k of a word is filtered on its own (horizontal neighbours are 4 bytes apart)::

        gx = sum(p * [1,2,1; 0,0,0; -1,-2,-1]),  gy = sum(p * [1,0,-1; 2,0,-2; 1,0,-1])
        out = (|gx| + |gy|) >> 3

    (row-major correlation). Native border (defect 12 fixed): the whole frame is written;
    rows 0 and ``height-1`` and word columns 0 and ``words-1`` are 0. On rows
    1..height-2 x columns 1..words-2 the output equals ReconROS'; ReconROS leaves row
    ``height-2`` and the border unwritten.

    Two line buffers of ``max_words`` words (block RAM); one word per cycle in and out; the
    output of row r streams while row r+1 arrives.

    Parameters
    ----------
    max_words : int
        Largest row in 32-bit words (ReconROS: 480, a 640-pixel ``bgr8`` row), 3..8192.

    Members
    -------
    i : In(AXIStreamSignature(32, keep=False))
        ``height * words`` words, row by row. ``tlast`` is not interpreted: the frame size
        comes from ``words`` and ``height``.
    o : Out(AXIStreamSignature(32, keep=False))
        ``height * words`` filtered words, ``tlast`` on the last.
    words : In(range(max_words + 1))
        Words per row, 3..``max_words``; sampled at the start of a frame.
    height : In(32)
        Rows, at least 3; sampled at the start of a frame.
    busy : Out(1)
        A frame is in progress.
    """

    def __init__(self, max_words=480):
        self._max_words = check_int("max_words", max_words, 3, 8192)
        sig = AXIStreamSignature(32, keep=False)
        super().__init__({
            "i": In(sig),
            "o": Out(sig),
            "words": In(range(max_words + 1)),
            "height": In(32),
            "busy": Out(1),
        })

    max_words = property(lambda self: self._max_words)

    def elaborate(self, platform):
        m = Module()
        n = self._max_words
        m.submodules.lb_top = lb_top = Memory(shape=32, depth=n, init=[])
        m.submodules.lb_mid = lb_mid = Memory(shape=32, depth=n, init=[])
        rd_top, rd_mid = lb_top.read_port(), lb_mid.read_port()
        wr_top, wr_mid = lb_top.write_port(), lb_mid.write_port()

        words = Signal.like(self.words)
        height = Signal(32)
        in_row, row = Signal(32), Signal(32)
        in_col, col = Signal(range(n)), Signal(range(n))
        s1_valid, s1_data = Signal(), Signal(32)
        w1 = [Signal(32, name=f"w1_{k}") for k in ("top", "mid", "bot")]
        w2 = [Signal(32, name=f"w2_{k}") for k in ("top", "mid", "bot")]
        o_valid, o_data, o_last = Signal(), Signal(32), Signal()
        zeros = Signal(range(n + 2))
        out_free = ~o_valid | self.o.tready
        m.d.comb += [self.o.tvalid.eq(o_valid), self.o.tdata.eq(o_data),
                     self.o.tlast.eq(o_last)]
        with m.If(self.o.tvalid & self.o.tready):
            m.d.sync += o_valid.eq(0)

        # the filter on the window: column a = w1 (c-2), b = w2 (c-1), c = the new column
        top_c, mid_c, bot_c = rd_top.data, rd_mid.data, s1_data
        result = Signal(32)
        for k in range(4):
            def lane(v):
                return v.word_select(k, 8)
            ta, ma, ba = (lane(v) for v in w1)
            tb, bb = lane(w2[0]), lane(w2[2])
            tc, mc, bc = lane(top_c), lane(mid_c), lane(bot_c)
            gx_p, gx_n = ta + 2 * tb + tc, ba + 2 * bb + bc
            gy_p, gy_n = ta + 2 * ma + ba, tc + 2 * mc + bc
            ax = Mux(gx_p >= gx_n, gx_p - gx_n, gx_n - gx_p)
            ay = Mux(gy_p >= gy_n, gy_p - gy_n, gy_n - gy_p)
            m.d.comb += result.word_select(k, 8).eq((ax[:11] + ay[:11]) >> 3)

        with m.FSM():
            with m.State("IDLE"):
                with m.If(self.i.tvalid):
                    m.d.sync += [words.eq(self.words), height.eq(self.height),
                                 zeros.eq(self.words), in_row.eq(0), in_col.eq(0)]
                    m.next = "TOP"
            with m.State("TOP"):
                # row 0 is border: zeros
                m.d.comb += self.busy.eq(1)
                with m.If(out_free):
                    m.d.sync += [o_valid.eq(1), o_data.eq(0), o_last.eq(0),
                                 zeros.eq(zeros - 1)]
                    with m.If(zeros == 1):
                        m.next = "RUN"
            with m.State("RUN"):
                m.d.comb += self.busy.eq(1)
                emit = (row >= 2) & ((col >= 1) | (row >= 3))
                go = Signal()
                m.d.comb += go.eq(s1_valid & (~emit | out_free))
                capture = Signal()
                m.d.comb += [capture.eq((~s1_valid | go) & ~(in_row == height)),
                             self.i.tready.eq(capture),
                             rd_top.en.eq(capture & self.i.tvalid),
                             rd_mid.en.eq(capture & self.i.tvalid),
                             rd_top.addr.eq(in_col), rd_mid.addr.eq(in_col)]
                with m.If(go):
                    m.d.sync += s1_valid.eq(0)
                with m.If(capture & self.i.tvalid):
                    m.d.sync += [s1_valid.eq(1), s1_data.eq(self.i.tdata), row.eq(in_row),
                                 col.eq(in_col)]
                    with m.If(in_col == words - 1):
                        m.d.sync += [in_col.eq(0), in_row.eq(in_row + 1)]
                    with m.Else():
                        m.d.sync += in_col.eq(in_col + 1)
                with m.If(go):
                    m.d.comb += [wr_top.en.eq(1), wr_top.addr.eq(col), wr_top.data.eq(mid_c),
                                 wr_mid.en.eq(1), wr_mid.addr.eq(col), wr_mid.data.eq(s1_data)]
                    m.d.sync += [w1[0].eq(w2[0]), w1[1].eq(w2[1]), w1[2].eq(w2[2]),
                                 w2[0].eq(top_c), w2[1].eq(mid_c), w2[2].eq(bot_c)]
                    with m.If(emit):
                        m.d.sync += [o_valid.eq(1), o_last.eq(0),
                                     o_data.eq(Mux(col >= 2, result, 0))]
                    with m.If((row == height - 1) & (col == words - 1)):
                        m.d.sync += zeros.eq(words + 1)
                        m.next = "BOTTOM"
            with m.State("BOTTOM"):
                # the last column of row height-2, then row height-1: zeros
                m.d.comb += self.busy.eq(1)
                with m.If(out_free):
                    m.d.sync += [o_valid.eq(1), o_data.eq(0), o_last.eq(zeros == 1),
                                 zeros.eq(zeros - 1)]
                    with m.If(zeros == 1):
                        m.next = "IDLE"
        return m


def _absdiff(a, b):
    return Mux(a >= b, a - b, b - a)


class Sobel(WindowFilter):
    """3 x 3 Sobel edge filter on an image stream (docs/kernels.md, docs/reconos.md).

    Modes:

    ``"opencv"``
        Per channel ``min(min(|Gx|, 255) + min(|Gy|, 255), 255)`` with OpenCV's
        ``Sobel(dx=1)`` and ``Sobel(dy=1)`` kernels, i.e.
        ``cv2.add(cv2.convertScaleAbs(gx), cv2.convertScaleAbs(gy))``, with the chosen border
        (default ``reflect101``, OpenCV's default).
    ``"reconros"``
        The ReconROS demo filter: a pixel is one 32-bit word (``channels=4``; a 640-pixel
        ``bgr8`` row is 480 such "pixels"), each byte lane filtered on its own,
        ``(|Gx| + |Gy|) >> 3``. Interior pixels equal ReconROS'; the frame's edge rows and
        columns, which ReconROS leaves unwritten (stale; docs/reconos.md defect 12), are 0.

    Parameters
    ----------
    mode : str
        ``"opencv"`` or ``"reconros"``.
    channels : int
        Bytes per pixel: 1 or 3 for ``opencv`` (``mono8``, ``bgr8``), 4 for ``reconros``.
    pixels_per_beat, max_width, max_height, border
        As for :class:`~hdl.kernels.window.WindowFilter` (``border`` only in ``opencv``
        mode).

    Members
    -------
    See :class:`~hdl.kernels.window.WindowFilter`; ``o`` has ``channels`` bytes per pixel.
    """

    MODES = ("opencv", "reconros")

    def __init__(self, mode="opencv", *, channels=3, pixels_per_beat=1, max_width=640,
                 max_height=480, border="reflect101"):
        self._mode = check_choice("mode", mode, self.MODES)
        if mode == "reconros":
            check_choice("channels", channels, (4,))
            border = "replicate"
        super().__init__(3, channels=channels, out_channels=channels,
                         pixels_per_beat=pixels_per_beat, max_width=max_width,
                         max_height=max_height, border=border,
                         channel_choices=(1, 3) if mode == "opencv" else (4,))

    mode = property(lambda self: self._mode)

    #: the four 3-tap sums, then their absolute differences; saturation and the sum at ``o``
    compute_stages = 2

    def compute(self, m, pixel, ctx):
        outputs = []
        for p in range(self.pixels_per_beat):
            lanes = []
            for c in range(self.channels):
                def q(dy, dx):
                    return pixel(p, dy, dx).word_select(c, 8)
                name = f"p{p}_c{c}"
                gx_pos = ctx.register(q(0, 2) + 2 * q(1, 2) + q(2, 2), f"gx_pos_{name}")
                gx_neg = ctx.register(q(0, 0) + 2 * q(1, 0) + q(2, 0), f"gx_neg_{name}")
                gy_pos = ctx.register(q(2, 0) + 2 * q(2, 1) + q(2, 2), f"gy_pos_{name}")
                gy_neg = ctx.register(q(0, 0) + 2 * q(0, 1) + q(0, 2), f"gy_neg_{name}")
                ax = ctx.register(_absdiff(gx_pos, gx_neg)[:10], f"ax_{name}")
                ay = ctx.register(_absdiff(gy_pos, gy_neg)[:10], f"ay_{name}")
                if self._mode == "opencv":
                    sx, sy = Mux(ax > 255, 255, ax), Mux(ay > 255, 255, ay)
                    total = sx + sy
                    lanes.append(Mux(total > 255, 255, total)[:8])
                else:
                    lanes.append(((ax + ay) >> 3)[:8])
            value = Cat(*lanes)
            if self._mode == "reconros":
                col = ctx.beat * self.pixels_per_beat + p
                edge = ((ctx.row == 0) | (ctx.row == ctx.height - 1) | (col == 0) |
                        (col == ctx.width_beats * self.pixels_per_beat - 1))
                for n in range(self.compute_stages):
                    edge = ctx.register(edge, f"edge_p{p}_{n}")
                value = Mux(edge, 0, value)
            outputs.append(value)
        return outputs
