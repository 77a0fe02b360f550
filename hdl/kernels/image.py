"""Image streams and the frame guard in front of every image kernel (docs/kernels.md).

An image stream carries a frame of ``height`` rows of ``width`` pixels, row by row, ``P``
pixels per beat (pixel ``k`` of a beat in bits ``[k*8*C, (k+1)*8*C)``, channel ``c`` of a
pixel in its byte ``c``; ``bgr8`` is B, G, R), ``tuser[0]`` on the first beat of a frame and
``tlast`` on the last.
"""

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_choice, check_int
from ..stream import AXIStreamSignature

__all__ = ["BORDERS", "PIXELS_PER_BEAT", "image_stream_signature", "check_image_params",
           "image_kernel_members", "FrameGuard"]

#: border modes: OpenCV ``BORDER_REFLECT_101`` (``gfedcb|abcdefgh|gfedcba``),
#: ``BORDER_REPLICATE`` and ``BORDER_CONSTANT`` with value 0
BORDERS = ("reflect101", "replicate", "constant")

PIXELS_PER_BEAT = (1, 2, 4, 8)


def image_stream_signature(channels, pixels_per_beat):
    """AXI-Stream of ``pixels_per_beat`` pixels of ``channels`` bytes per beat, ``tuser[0]``
    at the start of a frame, ``tlast`` at its end."""
    return AXIStreamSignature(8 * channels * pixels_per_beat, keep=False, user_width=1)


def check_image_params(channels, pixels_per_beat, max_width, max_height, *, channel_choices):
    """Validate the common image-kernel parameters; raise :class:`ParameterError` naming the
    bad value."""
    check_choice("channels", channels, channel_choices)
    check_choice("pixels_per_beat", pixels_per_beat, PIXELS_PER_BEAT)
    check_int("max_width", max_width, 1, 1 << 14)
    check_int("max_height", max_height, 1, 1 << 14)
    if max_width % pixels_per_beat:
        raise ParameterError("max_width", max_width,
                             f"a multiple of pixels_per_beat ({pixels_per_beat})")


def image_kernel_members(channels, out_channels, pixels_per_beat, max_width, max_height):
    """The signature members every image kernel has: ``i``, ``o``, ``width``, ``height`` and
    the :class:`FrameGuard` error pulses."""
    return {
        "i": In(image_stream_signature(channels, pixels_per_beat)),
        "o": Out(image_stream_signature(out_channels, pixels_per_beat)),
        "width": In(range(max_width + 1)),
        "height": In(range(max_height + 1)),
        "err_short": Out(1),
        "err_long": Out(1),
        "err_size": Out(1),
    }


class FrameGuard(wiring.Component):
    """Makes every frame exactly ``width`` x ``height`` pixels, whatever ``tlast`` says.

    The size is sampled at the first beat of each frame. A frame that ends (``tlast``) early is
    padded with zero pixels to its size (``err_short``); one that runs past its size is cut
    there (``tlast`` on the last beat of the size) and the rest is dropped up to its ``tlast``
    (``err_long``). A frame whose size the kernel cannot process (width not a multiple of the
    pixels per beat, or outside ``min_width``..``max_width``, height outside
    ``min_height``..``max_height``) is dropped up to its ``tlast`` (``err_size``). Each error
    output pulses for one cycle per bad frame. Input ``tuser`` is ignored; output ``tuser[0]``
    marks the first beat of each frame. No buffering: beats pass through combinationally.
    The error pulses are registered (one cycle after the beat that shows the error).

    Parameters
    ----------
    channels : int
        Bytes per pixel.
    pixels_per_beat : int
        1, 2, 4 or 8.
    max_width, max_height, min_width, min_height : int
        The frame sizes the kernel behind the guard accepts.

    Members
    -------
    i : In(image_stream_signature(channels, pixels_per_beat))
        Frames as they come.
    o : Out(image_stream_signature(channels, pixels_per_beat))
        Frames of exactly ``frame_width`` x ``frame_height`` pixels.
    width, height : In
        Frame size, sampled at a frame's first beat.
    frame_width, frame_height : Out
        Size of the frame whose beats are at ``o`` (while no frame is in progress: ``width``
        and ``height``, which the next frame will get).
    err_short, err_long, err_size : Out(1)
        One-cycle pulses, see above.
    """

    def __init__(self, channels, pixels_per_beat, max_width, max_height, *, min_width=1,
                 min_height=1):
        self._p = pixels_per_beat
        self._max_width, self._max_height = max_width, max_height
        self._min_width, self._min_height = min_width, min_height
        sig = image_stream_signature(channels, pixels_per_beat)
        super().__init__({
            "i": In(sig),
            "o": Out(sig),
            "width": In(range(max_width + 1)),
            "height": In(range(max_height + 1)),
            "frame_width": Out(range(max_width + 1)),
            "frame_height": Out(range(max_height + 1)),
            "err_short": Out(1),
            "err_long": Out(1),
            "err_size": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        p = self._p
        shift = p.bit_length() - 1
        beats_max = self._max_width // p
        wb = Signal(range(beats_max + 1))
        h = Signal(range(self._max_height + 1))
        col = Signal(range(beats_max + 1))
        row = Signal(range(self._max_height + 1))
        active = Signal()

        cur_wb = Mux(active, wb, self.width >> shift)
        cur_h = Mux(active, h, self.height)
        at_last = (col == cur_wb - 1) & (row == cur_h - 1)
        size_ok = ((self.width & (p - 1)) == 0) & (self.width >= self._min_width) & \
                  (self.width <= self._max_width) & (self.height >= self._min_height) & \
                  (self.height <= self._max_height)
        m.d.comb += [self.frame_width.eq(cur_wb << shift), self.frame_height.eq(cur_h),
                     self.o.tuser.eq(~active)]
        err_short, err_long, err_size = Signal(), Signal(), Signal()
        m.d.sync += [self.err_short.eq(err_short), self.err_long.eq(err_long),
                     self.err_size.eq(err_size)]

        def step():
            with m.If(~active):
                m.d.sync += [wb.eq(cur_wb), h.eq(cur_h), active.eq(1)]
            with m.If(at_last):
                m.d.sync += [active.eq(0), col.eq(0), row.eq(0)]
            with m.Elif(col == cur_wb - 1):
                m.d.sync += [col.eq(0), row.eq(row + 1)]
            with m.Else():
                m.d.sync += col.eq(col + 1)

        with m.FSM():
            with m.State("PASS"):
                with m.If(~active & ~size_ok):
                    m.d.comb += self.i.tready.eq(1)
                    with m.If(self.i.tvalid):
                        m.d.comb += err_size.eq(1)
                        with m.If(~self.i.tlast):
                            m.next = "DROP"
                with m.Else():
                    m.d.comb += [self.o.tvalid.eq(self.i.tvalid), self.i.tready.eq(self.o.tready),
                                 self.o.tdata.eq(self.i.tdata), self.o.tlast.eq(at_last)]
                    with m.If(self.i.tvalid & self.o.tready):
                        step()
                        with m.If(at_last):
                            with m.If(~self.i.tlast):
                                m.d.comb += err_long.eq(1)
                                m.next = "DROP"
                        with m.Elif(self.i.tlast):
                            m.d.comb += err_short.eq(1)
                            m.next = "PAD"
            with m.State("PAD"):
                m.d.comb += [self.o.tvalid.eq(1), self.o.tlast.eq(at_last)]
                with m.If(self.o.tready):
                    step()
                    with m.If(at_last):
                        m.next = "PASS"
            with m.State("DROP"):
                m.d.comb += self.i.tready.eq(1)
                with m.If(self.i.tvalid & self.i.tlast):
                    m.next = "PASS"
        return m
