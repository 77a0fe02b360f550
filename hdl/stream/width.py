"""Width converters between AXI4-Stream beats of different byte counts (byte 0 first)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int
from .signature import AXIStreamSignature

__all__ = ["StreamDownsizer", "StreamUpsizer", "StreamRepacker", "ByteWindow", "keep_count",
           "keep_count_shallow"]


def keep_count(tkeep):
    """Number of set bits of a contiguous-from-bit-0 ``tkeep``."""
    count = Const(0, range(len(tkeep) + 1))
    for i in range(len(tkeep)):
        count = Mux(tkeep[i], i + 1, count)
    return count


def keep_count_shallow(tkeep):
    """:func:`keep_count` of a ``tkeep`` contiguous from bit 0, in logic of logarithmic depth
    (for wide beats): bit ``j`` of the count is set where the ones end inside an odd block of
    ``2**j`` bits."""
    nbits = len(tkeep)
    width = nbits.bit_length()
    ones = [tkeep[i] for i in range(nbits)] + [Const(0)]
    bits = []
    for j in range(width):
        size = 1 << j
        ends = [ones[start - 1] & ~ones[min(start + size, nbits + 1) - 1]
                for start in range(size, nbits + 1, 2 * size)]
        bits.append(Cat(*ends).any())
    return Cat(*bits)


def _check_width(data_width):
    check_int("data_width", data_width, 16, 1024, multiple_of=8)


class StreamDownsizer(wiring.Component):
    """Splits beats of ``data_width`` bits into one-byte beats, byte 0 first.

    Full throughput: one byte per cycle, the next beat taken in the cycle the previous one's
    last byte leaves.

    Parameters
    ----------
    data_width : int
        Width of the input's ``tdata``, a multiple of 8 in 16..1024.

    Members
    -------
    s_axis : In(AXIStreamSignature(data_width))
        ``tkeep`` contiguous from byte 0. A beat with ``tkeep`` 0 carries no byte and is taken
        without output (its ``tlast`` is lost: it has no byte to mark).
    m_axis : Out(AXIStreamSignature(8, keep=False))
        The kept bytes in order; ``tlast`` on the last kept byte of a beat with ``tlast``.
    """

    def __init__(self, data_width):
        _check_width(data_width)
        self._width = data_width
        super().__init__({"s_axis": In(AXIStreamSignature(data_width)),
                          "m_axis": Out(AXIStreamSignature(8, keep=False))})

    def elaborate(self, platform):
        m = Module()
        W, B = self._width, self._width // 8
        buf = Signal(W)
        left = Signal(range(B + 1))         # bytes of the held beat still to send
        last = Signal()
        s, out = self.s_axis, self.m_axis
        m.d.comb += [out.tvalid.eq(left != 0), out.tdata.eq(buf[:8]),
                     out.tlast.eq(last & (left == 1))]
        sent = out.tvalid & out.tready
        m.d.comb += s.tready.eq((left == 0) | ((left == 1) & out.tready))
        with m.If(s.tvalid & s.tready):
            m.d.sync += [buf.eq(s.tdata), left.eq(keep_count(s.tkeep)), last.eq(s.tlast)]
        with m.Elif(sent):
            m.d.sync += [buf.eq(buf >> 8), left.eq(left - 1)]
        return m


class StreamUpsizer(wiring.Component):
    """Gathers one-byte beats into beats of ``data_width`` bits, byte 0 first.

    The input is a byte stream whose beat boundaries mean nothing, so a beat leaves when it is
    full, after a byte with ``tlast``, or, partial, as soon as the input has no byte to offer:
    bytes never wait for more bytes that may not come. Full throughput: one byte per cycle
    in, the next beat gathered while the previous one waits.

    Parameters
    ----------
    data_width : int
        Width of the output's ``tdata``, a multiple of 8 in 16..1024.

    Members
    -------
    s_axis : In(AXIStreamSignature(8, keep=False))
        Bytes.
    m_axis : Out(AXIStreamSignature(data_width))
        ``tkeep`` contiguous from byte 0 (bytes outside it are not cleared); a beat that is
        not full carries ``tlast``, as does a beat whose last byte carried it (so ``tkeep`` is
        partial only with ``tlast``).
    """

    def __init__(self, data_width):
        _check_width(data_width)
        self._width = data_width
        super().__init__({"s_axis": In(AXIStreamSignature(8, keep=False)),
                          "m_axis": Out(AXIStreamSignature(data_width))})

    def elaborate(self, platform):
        m = Module()
        W, B = self._width, self._width // 8
        # bytes 0..B-2 gathered in place (byte ``count`` is written next), and the output
        # register they move into, with the incoming byte at ``count``, when the beat closes
        acc = [Signal(8, name=f"acc{i}") for i in range(B - 1)]
        count = Signal(range(B))
        data = Signal(W)
        keep = Signal(B)
        last = Signal()
        valid = Signal()
        s, out = self.s_axis, self.m_axis
        m.d.comb += [out.tvalid.eq(valid), out.tdata.eq(data), out.tkeep.eq(keep),
                     out.tlast.eq(last)]
        free = ~valid | out.tready          # the output register is empty after this cycle
        with m.If(out.tready):
            m.d.sync += valid.eq(0)
        take = s.tvalid & s.tready
        closes = (count == B - 1) | s.tlast
        # the input may wait only while a closed beat cannot move on
        m.d.comb += s.tready.eq(free | ~closes)
        with m.If(take & ~closes):
            m.d.sync += count.eq(count + 1)
            for i in range(B - 1):
                with m.If(count == i):
                    m.d.sync += acc[i].eq(s.tdata)
        flush = ~take & (count != 0) & free     # the input has no byte: the beat leaves
        with m.If((take & closes) | flush):
            # bytes 0..count with the incoming byte, bytes 0..count - 1 without it (bytes
            # beyond tkeep are not cleared)
            m.d.sync += [valid.eq(1), count.eq(0), last.eq(flush | s.tlast),
                         keep.eq(Cat(Const(1, 1), *(count >= i for i in range(1, B - 1)),
                                     count == B - 1)),
                         data.eq(Cat(*(Mux(count == i, s.tdata, acc[i])
                                       for i in range(B - 1)), s.tdata))]
            with m.If(flush):
                m.d.sync += keep.eq(Cat(*(count > i for i in range(B - 1)), Const(0, 1)))
        return m


class StreamRepacker(wiring.Component):
    """Regroups a byte stream from beats of ``in_bytes`` into beats of ``out_bytes`` at full
    rate, for widths that are not multiples of each other (64-bit memory words into 24-bit
    ``bgr8`` pixels and back).

    A buffer of ``in_bytes + out_bytes - 1`` bytes takes an input beat in every cycle in which
    its bytes fit after the output beat of that cycle leaves, so the slower side sets the
    rate: ``min(in_bytes, out_bytes)`` bytes per cycle when neither side pauses. An output
    beat leaves full, or, after an input beat with ``tlast``, with the bytes that remain
    (``tkeep`` partial and ``tlast`` set; a last beat that fills the output exactly carries
    ``tlast`` with every byte). Until that beat has left, no input is taken.

    Parameters
    ----------
    in_bytes, out_bytes : int
        Bytes of an input and of an output beat, 1..128.
    eager : bool
        Bytes never wait for more that may not come: when the input offers nothing while
        less than a beat is held, those bytes leave the next cycle as a partial beat with
        ``tlast``, as after an input ``tlast`` (for a byte stream whose beat boundaries mean
        nothing, such as a TCP session's received bytes).

    Members
    -------
    s_axis : In(AXIStreamSignature(8 * in_bytes))
        ``tkeep`` contiguous from byte 0 (partial only with ``tlast``). A beat with
        ``tkeep`` 0 and ``tlast`` ends the message after the bytes before it, or carries
        nothing when none are held (its ``tlast`` has no byte to mark and is lost).
    m_axis : Out(AXIStreamSignature(8 * out_bytes))
        The bytes in order, ``tkeep`` contiguous from byte 0.
    """

    def __init__(self, in_bytes, out_bytes, *, eager=False):
        check_int("in_bytes", in_bytes, 1, 128)
        check_int("out_bytes", out_bytes, 1, 128)
        self._in, self._out = in_bytes, out_bytes
        self._eager = bool(eager)
        super().__init__({"s_axis": In(AXIStreamSignature(8 * in_bytes)),
                          "m_axis": Out(AXIStreamSignature(8 * out_bytes))})

    in_bytes = property(lambda self: self._in)
    out_bytes = property(lambda self: self._out)

    def elaborate(self, platform):
        m = Module()
        Bi, Bo = self._in, self._out
        C = Bi + Bo - 1
        buf = [Signal(8, name=f"buf{j}") for j in range(C)]
        count = Signal(range(C + 1))
        last = Signal()                     # a tlast was taken; its bytes are still held
        s, out = self.s_axis, self.m_axis

        m.d.comb += [out.tvalid.eq((count >= Bo) | (last & (count != 0))),
                     out.tdata.eq(Cat(*buf[:Bo])),
                     out.tlast.eq(last & (count <= Bo)),
                     out.tkeep.eq(Cat(*((count > i) for i in range(Bo))))]
        take_out = out.tvalid & out.tready
        after = Signal(range(C + 1))        # bytes held once this cycle's output has left
        m.d.comb += after.eq(Mux(take_out, Mux(count >= Bo, count - Bo, 0), count))
        m.d.comb += s.tready.eq((~last | (take_out & out.tlast)) & (after < Bo))
        take_in = s.tvalid & s.tready
        n_in = keep_count(s.tkeep)
        shifted = [Mux(take_out, buf[j + Bo] if j + Bo < C else 0, buf[j]) for j in range(C)]
        m.d.sync += [b.eq(v) for b, v in zip(buf, _land_beat(shifted, s.tdata, Bi, after, Bo,
                                                           take_in))]
        new_count = Signal(range(C + 1))
        m.d.comb += new_count.eq(after + Mux(take_in, n_in, 0))
        m.d.sync += [count.eq(new_count),
                     last.eq(Mux(take_in, s.tlast, last & ~(take_out & out.tlast)) &
                             (new_count != 0))]
        if self._eager:
            with m.If(~last & (count != 0) & (count < Bo) & ~s.tvalid):
                m.d.sync += last.eq(1)
        return m


class ByteWindow(wiring.Component):
    """Presents a byte stream as a window from which 0..``nbytes`` bytes are taken per cycle.

    The input's beat boundaries mean nothing (a TCP session's received bytes: beats of 1 to
    ``nbytes`` bytes); the consumer takes what it needs (a length field byte by byte, a
    message body ``nbytes`` at a time), at full rate: a beat enters in the cycle the bytes
    it follows make room for it. The window holds up to ``2 * nbytes - 1`` bytes.

    Parameters
    ----------
    nbytes : int
        Bytes of an input beat and of the window, 1..16.

    Members
    -------
    s_axis : In(AXIStreamSignature(8 * nbytes))
        Bytes; ``tkeep`` contiguous from byte 0; ``tlast`` is ignored.
    window : Out(8 * nbytes)
        The next bytes, the first in bits 0..7 (those beyond ``avail`` mean nothing).
    avail : Out(range(2 * nbytes))
        Bytes in the window (more than ``nbytes`` may be held; ``window`` shows ``nbytes``).
    amount : In(range(nbytes + 1))
        Bytes taken if ``take``, at most ``avail``.
    take : In(1)
        Take ``amount`` bytes this cycle.
    """

    def __init__(self, nbytes):
        self._n = check_int("nbytes", nbytes, 1, 16)
        super().__init__({"s_axis": In(AXIStreamSignature(8 * nbytes)),
                          "window": Out(8 * nbytes), "avail": Out(range(2 * nbytes)),
                          "amount": In(range(nbytes + 1)), "take": In(1)})

    def elaborate(self, platform):
        m = Module()
        B = self._n
        C = 2 * B - 1
        buf = [Signal(8, name=f"buf{j}") for j in range(C)]
        count = Signal(range(C + 1))
        s = self.s_axis
        m.d.comb += [self.window.eq(Cat(*buf[:B])), self.avail.eq(count)]
        taken = Mux(self.take, self.amount, 0)
        left = Signal(range(C + 1))
        m.d.comb += [left.eq(count - taken), s.tready.eq(left < B)]
        accept = s.tvalid & s.tready
        shifted = [buf[j] for j in range(C)]
        for a in range(1, B + 1):          # drop ``taken`` bytes from the front
            shifted = [Mux(taken == a, buf[j + a] if j + a < C else 0, shifted[j])
                       for j in range(C)]
        m.d.sync += [b.eq(v) for b, v in zip(buf, _land_beat(shifted, s.tdata, B, left, B,
                                                           accept))]
        m.d.sync += count.eq(left + Mux(accept, keep_count(s.tkeep), 0))
        return m


def _land_beat(held, data, nbytes, at, positions, enable):
    """The bytes of a buffer once an ``nbytes``-byte beat ``data`` has landed behind the
    ``at`` bytes ``held`` keeps (``at`` < ``positions``), if ``enable``: the byte values,
    one per byte of ``held``."""
    values = []
    for j, value in enumerate(held):
        for a in range(positions):
            if a <= j < a + nbytes:
                value = Mux(enable & (at == a), data.word_select(j - a, 8), value)
        values.append(value)
    return values
