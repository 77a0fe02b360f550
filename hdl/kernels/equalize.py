"""Histogram equalization, bit-exact with ``cv2.equalizeHist`` (docs/kernels.md)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.fifo import SyncFIFOBuffered
from amaranth.lib.memory import Memory

from ..params import ParameterError
from ..stream import skid_buffer
from .image import FrameGuard, check_image_params, image_kernel_members

__all__ = ["EqualizeHist", "ROUND_STAGES", "TABLE_STAGES", "round_to_float32",
           "histogram_banks", "byte_table", "stream_through_table"]

#: the reciprocal 255 / D is computed as floor(255 * 2**SCALE_BITS / D) before rounding
SCALE_BITS = 48


def _set_bit_index(value, *, highest):
    """Index of the highest (or lowest) set bit of ``value``, found by a binary tree: log2 of
    the width in multiplexers, not a priority chain as long as the value. For 0 it is 0 when
    ``highest``, else meaningless (test ``value.any()``)."""
    width = 1 << max(1, (len(value) - 1).bit_length())
    bits = Cat(value, Const(0, width - len(value)))

    def search(low, size):
        if size == 2:
            return bits[low] | bits[low + 1], (bits[low + 1] if highest else ~bits[low])
        found_low, index_low = search(low, size // 2)
        found_high, index_high = search(low + size // 2, size // 2)
        if highest:
            return found_low | found_high, Cat(Mux(found_high, index_high, index_low), found_high)
        return found_low | found_high, Cat(Mux(found_low, index_low, index_high), ~found_low)

    return search(0, width)[1]


def _leading_one(m, value, name):
    """Index of the highest set bit of ``value`` (0 for 0)."""
    lead = Signal(range(len(value)), name=name)
    m.d.comb += lead.eq(_set_bit_index(value, highest=True))
    return lead


def _shift_for_rounding(value, shift):
    """``value >> shift``, the first bit shifted out, and whether a bit below that one is
    set: round to nearest rounds up when the first is set and (a lower bit is, or the kept
    value is odd: ties to even)."""
    below = (shift - 1).as_unsigned()
    first = (shift != 0) & (value >> below)[0]
    # a bit below ``below`` is set when the lowest set bit is: its index by a tree, not the
    # mask 2**below - 1 (a subtraction: a carry chain as long as the value)
    rest = (shift > 1) & value.any() & (_set_bit_index(value, highest=False) < below)
    return value >> shift, first, rest


def _unregistered(value, name):
    return value


def round_to_float32(m, value, sticky_in, name, stage=_unregistered, *, bits=24):
    """Round the non-negative integer ``value`` (with ``sticky_in``: a non-zero remainder
    below it) to ``bits`` significant bits (24: float32, 53: float64), to nearest, ties to
    even. Returns ``(mantissa, shift)``: the rounded value is ``mantissa << shift``
    (``mantissa < 2**bits``).

    ``stage(value, name)`` is applied after the leading-one search and after the rounding
    decision: a register there splits the logic into three shorter paths (two cycles of
    latency)."""
    top = bits - 1
    lead = _leading_one(m, value, f"{name}_lead")
    shift = Signal(range(len(value) + 1), name=f"{name}_shift")
    m.d.comb += shift.eq(Mux(lead > top, lead - top, 0))
    value, sticky_in = stage(value, f"{name}_value"), stage(sticky_in, f"{name}_sticky")
    shift = stage(shift, f"{name}_shift_r")
    kept, round_bit, lower = Signal(bits, name=f"{name}_kept"), \
        Signal(name=f"{name}_round_bit"), Signal(name=f"{name}_lower")
    shifted, first, rest = _shift_for_rounding(value, shift)
    m.d.comb += [kept.eq(shifted), round_bit.eq(first), lower.eq(sticky_in | rest)]
    up = round_bit & (lower | kept[0])
    kept, up = stage(kept, f"{name}_kept_r"), stage(up, f"{name}_up")
    shift = stage(shift, f"{name}_shift_r2")
    mantissa = Signal(bits + 1, name=f"{name}_mant")
    m.d.comb += mantissa.eq(kept + up)
    out_m = Signal(bits, name=f"{name}_m")
    out_s = Signal(range(len(value) + 2), name=f"{name}_s")
    with m.If(mantissa[bits]):
        m.d.comb += [out_m.eq(mantissa >> 1), out_s.eq(shift + 1)]
    with m.Else():
        m.d.comb += [out_m.eq(mantissa), out_s.eq(shift)]
    return out_m, out_s


def histogram_banks(m, banks, count_bits):
    """``banks`` histograms of 256 bins (one per pixel of a beat): ``(write, read)`` port pairs,
    each read transparent for its write, so a bin read in the cycle it is incremented sees
    the new count."""
    out = []
    for p in range(banks):
        mem = Memory(shape=count_bits, depth=256, init=[])
        m.submodules[f"hist{p}"] = mem
        wr = mem.write_port()
        out.append((wr, mem.read_port(transparent_for=(wr,))))
    return out


class _TableWrite:
    """The write port of a :func:`byte_table`: ``en``, ``addr`` and ``data``."""

    def __init__(self, name):
        self.en = Signal(name=f"{name}_w_en")
        self.addr = Signal(8, name=f"{name}_w_addr")
        self.data = Signal(8, name=f"{name}_w_data")


def byte_table(m, name, read_ports):
    """A 256-entry byte table with one write port and ``read_ports`` synchronous read ports:
    one memory per read port, all written alike. A tool would copy a many-ported table this
    way anyway; written out, every flow maps it (Yosys' memory mapping fails on one memory
    with the twelve read ports of a 4 px/clk ``bgr8`` table). Returns ``(write, reads)``."""
    write = _TableWrite(name)
    reads = []
    for k in range(read_ports):
        m.submodules[f"{name}{k}"] = mem = Memory(shape=8, depth=256, init=[])
        port = mem.write_port()
        m.d.comb += [port.en.eq(write.en), port.addr.eq(write.addr), port.data.eq(write.data)]
        reads.append(mem.read_port())
    return write, reads


def stream_through_table(m, frame, reads, o, values):
    """Stream the frames of the buffer ``frame`` (``values`` bytes and a ``tlast`` bit per
    entry) out on ``o``, every byte through its table read port in ``reads``
    (:func:`byte_table`), once ``draining`` (returned) is set; ``draining`` clears at the
    frame's last beat. ``tuser`` marks each frame's first beat.

    The buffer's head passes a skid buffer, so its block RAMs' output multiplexers end in
    flip-flops, not in the tables' addresses. The skid buffer fills while the table is built
    (a frame is whole in the buffer before it drains), so it adds no cycle to a frame."""
    draining = Signal()
    o_valid, o_first = Signal(), Signal(init=1)
    adv = Signal()
    head_valid = Signal()
    head = Signal(len(frame.r_data))
    skid_buffer(m, len(head), frame.r_rdy, frame.r_en, frame.r_data, head_valid,
                adv & draining, head)
    m.d.comb += [adv.eq(~o_valid | o.tready), o.tvalid.eq(o_valid)]
    for k, port in enumerate(reads[:values]):
        m.d.comb += [port.addr.eq(head.word_select(k, 8)), port.en.eq(adv),
                     o.tdata.word_select(k, 8).eq(port.data)]
    out_last = head[8 * values]
    with m.If(adv):
        m.d.sync += [o_valid.eq(draining & head_valid), o.tlast.eq(out_last),
                     o.tuser.eq(o_first)]
        with m.If(draining & head_valid):
            m.d.sync += o_first.eq(out_last)
            with m.If(out_last):
                m.d.sync += draining.eq(0)
    return draining


#: registers in :func:`round_to_float32` when it is pipelined
ROUND_STAGES = 2
#: registers between a bin's scan and its table entry (x, product, rounding, result,
#: shift, rint)
TABLE_STAGES = 5 + ROUND_STAGES


class EqualizeHist(wiring.Component):
    """``cv2.equalizeHist`` on ``mono8`` frames, one frame of latency.

    A frame streams into a frame buffer (block RAM FIFO of ``max_width * max_height``
    pixels) while its histogram is counted; then its look-up table is computed (one bin per
    cycle and one division: about 320 cycles) exactly as OpenCV does: ``i0`` the first
    non-empty bin,
    ``scale = float32(255) / float32(N - hist[i0])``, ``lut[j] = 0`` for ``j <= i0`` and
    ``round_half_even(float32((cdf[j] - hist[i0]) * scale))`` above (a frame of one grey
    level maps to it). The float32 division and products are computed on integers with the
    IEEE round-to-nearest-even rule, so the result is exact, not an approximation. The
    entries pass a pipeline of :data:`TABLE_STAGES` registers (product, rounding, scaling),
    so one bin is scanned per cycle at 100 MHz. The frame then streams out through the table
    while the next frame streams in.

    Steady state: ``W H / P`` cycles per frame plus the table (about 330) and the division
    (``SCALE_BITS + 9`` = 57).

    Parameters
    ----------
    pixels_per_beat : int
        1, 2, 4 or 8 (P histogram banks).
    max_width, max_height : int
        Largest frame; the frame buffer holds ``max_width * max_height`` pixels.

    Members
    -------
    i : In(image_stream_signature(1, pixels_per_beat))
        ``mono8`` frames.
    o : Out(image_stream_signature(1, pixels_per_beat))
        Equalized frames, ``tuser[0]`` on the first beat, ``tlast`` on the last.
    width, height : In
        Frame size, sampled at a frame's first beat.
    err_short, err_long, err_size : Out(1)
        Bad frames (:class:`~hdl.kernels.image.FrameGuard`).
    """

    def __init__(self, *, pixels_per_beat=1, max_width=640, max_height=480):
        check_image_params(1, pixels_per_beat, max_width, max_height, channel_choices=(1,))
        if max_width * max_height > 1 << 22:
            # the pixel counts must stay exact float32 values (and the buffer sensible)
            raise ParameterError("max_width * max_height", max_width * max_height,
                                 "at most 4194304 pixels")
        self._p, self._max_width, self._max_height = pixels_per_beat, max_width, max_height
        super().__init__(image_kernel_members(1, 1, pixels_per_beat, max_width, max_height))

    pixels_per_beat = property(lambda self: self._p)

    def elaborate(self, platform):
        m = Module()
        P = self._p
        max_pixels = self._max_width * self._max_height
        count_bits = max_pixels.bit_length()
        m.submodules.guard = guard = FrameGuard(1, P, self._max_width, self._max_height)
        wiring.connect(m, wiring.flipped(self.i), guard.i)
        m.d.comb += [guard.width.eq(self.width), guard.height.eq(self.height),
                     self.err_short.eq(guard.err_short), self.err_long.eq(guard.err_long),
                     self.err_size.eq(guard.err_size)]

        m.submodules.frame = frame = SyncFIFOBuffered(width=8 * P + 1, depth=max_pixels // P)
        hists = histogram_banks(m, P, count_bits)
        lut_wr, lut_reads = byte_table(m, "lut", P)

        # input: frame buffer and histogram (read, then increment next cycle)
        filling = Signal(init=1)
        total = Signal(count_bits + 1)
        inc_valid = Signal()
        inc_bin = [Signal(8, name=f"inc_bin{p}") for p in range(P)]
        take = guard.o.tvalid & guard.o.tready
        m.d.comb += [guard.o.tready.eq(filling & frame.w_rdy),
                     frame.w_en.eq(take), frame.w_data.eq(Cat(guard.o.tdata, guard.o.tlast))]
        m.d.sync += inc_valid.eq(take)
        for p, (wr, rd) in enumerate(hists):
            pix = guard.o.tdata.word_select(p, 8)
            m.d.comb += rd.addr.eq(pix)
            with m.If(take):
                m.d.sync += inc_bin[p].eq(pix)
        with m.If(inc_valid):
            for p, (wr, rd) in enumerate(hists):
                m.d.comb += [wr.en.eq(1), wr.addr.eq(inc_bin[p]), wr.data.eq(rd.data + 1)]
        with m.If(take):
            m.d.sync += total.eq(total + P)
            with m.If(guard.o.tlast):
                m.d.sync += filling.eq(0)

        # output: through the table of the frame at the head of the buffer
        draining = stream_through_table(m, frame, lut_reads, self.o, P)

        # the table: scan the bins (clearing them), divide once at the first non-empty one
        j = Signal(9)
        cdf = Signal(count_bits + 1)
        found = Signal()
        i0 = Signal(8)
        h0 = Signal(count_bits + 1)
        denom = Signal(count_bits + 1)
        quotient = Signal(SCALE_BITS + 9)
        remainder = Signal(count_bits + 2)
        numer = Signal(SCALE_BITS + 9)
        div_step = Signal(range(SCALE_BITS + 10))
        scale_m = Signal(24)
        scale_s = Signal(range(SCALE_BITS + 12))
        hist_sum = sum(rd.data for _, rd in hists)

        def reg(value, name):
            # free-running: every stage follows its input one cycle later
            value = Value.cast(value)
            r = Signal(value.shape(), name=name)
            m.d.sync += r.eq(value)
            return r

        # the table entry of a scanned bin, TABLE_STAGES cycles after its scan
        scan_valid = Signal()
        x = Signal(count_bits + 1)
        valid, addr = reg(scan_valid, "table_v0"), reg(j[:8], "table_j0")
        x_r = reg(x, "table_x")
        prod = reg(x_r * scale_m, "table_prod")
        pm, ps = round_to_float32(m, prod, Const(0), "prod", stage=reg)
        pm, ps = reg(pm, "table_pm"), reg(ps, "table_ps")
        # value = pm * 2**(ps + scale_s - SCALE_BITS); scale_s + ps < SCALE_BITS
        frac = Signal(range(2 * SCALE_BITS + 4), name="table_frac")
        m.d.sync += frac.eq(SCALE_BITS - scale_s - ps)
        pm = reg(pm, "table_pm_r")
        for n in range(TABLE_STAGES - 1):
            valid, addr = reg(valid, f"table_v{n + 1}"), reg(addr, f"table_j{n + 1}")
        # rint: the first fraction bit decides, the bits below it break a tie; from 25
        # fraction bits on, pm < 2**24 is below one half and rounds to 0
        shifted, first, rest = _shift_for_rounding(pm, frac)
        whole = reg(shifted[:24], "table_whole")
        half_bit, lower = reg(first, "table_half_bit"), reg(rest, "table_lower")
        value = Signal(25)
        m.d.comb += value.eq(whole + (half_bit & (lower | whole[0])))
        with m.If(valid):
            m.d.comb += [lut_wr.en.eq(1), lut_wr.addr.eq(addr),
                         lut_wr.data.eq(Mux(value > 255, 255, value))]
        in_flight = Signal(range(TABLE_STAGES + 1))

        # the scale, once per frame, through the same rounding, pipelined
        qm, qs = round_to_float32(m, quotient, remainder != 0, "scale", stage=reg)
        round_wait = Signal(range(ROUND_STAGES + 1))

        def next_bin():
            # the next bin's read is issued now, so the scan takes one cycle per bin
            with m.If(j == 255):
                m.d.sync += in_flight.eq(TABLE_STAGES)
                m.next = "FLUSH"
            with m.Else():
                for _, rd in hists:
                    m.d.comb += rd.addr.eq(j + 1)
                m.d.sync += j.eq(j + 1)

        with m.FSM():
            with m.State("FILL"):
                with m.If(~filling & ~inc_valid & ~draining):
                    m.d.sync += [j.eq(0), cdf.eq(0), found.eq(0)]
                    m.next = "READ"
            with m.State("READ"):
                for _, rd in hists:
                    m.d.comb += rd.addr.eq(j)
                m.next = "BIN"
            with m.State("BIN"):
                # rd.data = hist[j] (summed over the banks); clear the bin
                for wr, _ in hists:
                    m.d.comb += [wr.en.eq(1), wr.addr.eq(j), wr.data.eq(0)]
                hj = Signal(count_bits + 1)
                m.d.comb += hj.eq(hist_sum)
                new_cdf = cdf + hj
                m.d.sync += cdf.eq(new_cdf)
                with m.If(~found & (hj != 0)):
                    m.d.sync += [found.eq(1), h0.eq(hj), denom.eq(total - hj), i0.eq(j)]
                    m.d.comb += [lut_wr.en.eq(1), lut_wr.addr.eq(j), lut_wr.data.eq(0)]
                    with m.If(hj == total):
                        m.next = "SINGLE"
                    with m.Else():
                        m.d.sync += [numer.eq(255 << SCALE_BITS), quotient.eq(0),
                                     remainder.eq(0), div_step.eq(SCALE_BITS + 8)]
                        m.next = "DIVIDE"
                with m.Elif(~found):
                    m.d.comb += [lut_wr.en.eq(1), lut_wr.addr.eq(j), lut_wr.data.eq(0)]
                    next_bin()
                with m.Else():
                    # lut[j] = rint(fl(fl(x) * scale)), x = cdf[j] - h0 < 2**24
                    m.d.comb += [scan_valid.eq(1), x.eq(new_cdf - h0)]
                    next_bin()
            with m.State("DIVIDE"):
                # floor(255 * 2**SCALE_BITS / denom), one quotient bit per cycle
                r = Cat(numer[-1], remainder[:-1])
                ge = r >= denom
                m.d.sync += [remainder.eq(Mux(ge, r - denom, r)), numer.eq(numer << 1),
                             quotient.eq(Cat(ge, quotient[:-1])), div_step.eq(div_step - 1)]
                with m.If(div_step == 0):
                    m.d.sync += round_wait.eq(ROUND_STAGES)
                    m.next = "ROUND"
            with m.State("ROUND"):
                m.d.sync += round_wait.eq(round_wait - 1)
                with m.If(round_wait == 0):
                    m.d.sync += [scale_m.eq(qm), scale_s.eq(qs)]
                    m.next = "NEXT"
            with m.State("SINGLE"):
                # one grey level: the table maps everything to it
                m.d.comb += [lut_wr.en.eq(1), lut_wr.addr.eq(j), lut_wr.data.eq(i0)]
                m.d.sync += j.eq(j + 1)
                with m.If(j == 255):
                    m.next = "DONE"
            with m.State("NEXT"):
                m.d.sync += j.eq(j + 1)
                with m.If(j == 255):
                    m.next = "DONE"
                with m.Else():
                    m.next = "READ"
            with m.State("FLUSH"):
                # the last entries leave the table pipeline
                m.d.sync += in_flight.eq(in_flight - 1)
                with m.If(in_flight == 0):
                    m.next = "DONE"
            with m.State("DONE"):
                m.d.sync += [draining.eq(1), filling.eq(1), total.eq(0)]
                m.next = "FILL"
        return m
