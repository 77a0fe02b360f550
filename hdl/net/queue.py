"""Queues of received frames: keep or drop a frame on a decision made from its first bytes,
read it out while it still arrives (cut-through) or later (store-and-forward)."""

from amaranth.hdl import Cat, Const, DomainRenamer, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.fifo import AsyncFIFO, SyncFIFO
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int
from ..stream import RegisterSlice, keep_count
from .mac import BRIDGE_DEPTH, FrameStatus, FrameStreamSignature, RxBeatSignature

__all__ = ["FrameStreamSignature", "FrameQueue", "FrameToRxBeats", "FrameStreamBridge"]

class FrameQueue(wiring.Component):
    """Received frames in a block-RAM queue, kept or dropped on a decision.

    A frame's bytes are written as they arrive. While it arrives, ``decide`` with ``keep``
    says whether to keep it (the parent looks at the destination address); a dropped frame,
    or one that ends without a decision, is rewound out of the queue, and so is a kept frame
    that does not fit (``overflow`` pulses). A kept frame can be read from the cycle after
    it is kept, one byte behind the writer, so with a reader that keeps up the queue adds a
    few cycles of latency (cut-through); a reader that waits gets the whole frame later
    (store-and-forward). The read's enable depends on registers only (the decision and the
    pointers), so neither the parent's decision nor the writer's arithmetic is on the path
    into the block RAM's read port. A kept frame
    that no longer fits once its reader has begun it cannot be rewound: it ends at the last
    byte that fit, marked bad with a size error (its :data:`~hdl.net.mac.FrameStatus`; a
    transmitter sends it with ``tx_er``, a parser drops it), and ``overflow`` pulses.

    Parameters
    ----------
    depth : int
        Bytes of queue, a power of two in 64..65536.
    frames : int
        Kept frames the queue may hold at once (the status FIFO's depth), 2..64.
    registered : bool
        Put ``m_axis`` behind a register slice: the block RAM's read data then ends at a
        flip-flop (its clock-to-output is most of a 125 MHz cycle on ECP5), for one more cycle
        of latency.

    Members
    -------
    rx : In(RxBeatSignature(1))
        Bytes and end status from a :class:`~hdl.net.mac.GmiiRx`. Every frame ends with
        ``end`` (as a MAC's do): the first beat after an end begins the next frame.
    decide : In(1)
        Pulse while the frame arrives (at or after its first byte, before its end): the
        decision ...
    keep : In(1)
        ... to keep it.
    m_axis : Out(FrameStreamSignature())
        The kept frames. Once a frame's first byte is offered its bytes follow without a gap
        as long as the frame arrives without one.
    overflow : Out(1)
        Pulse: a kept frame was dropped, or cut short, because the queue was full.
    level : Out(range(depth + 1))
        Bytes in the queue.
    """

    def __init__(self, depth=2048, frames=8, *, registered=False):
        check_int("depth", depth, 64, 65536)
        self._registered = bool(registered)
        if depth & (depth - 1):
            raise ParameterError("depth", depth, "a power of two in 64..65536")
        self._depth = depth
        self._frames = check_int("frames", frames, 2, 64)
        super().__init__({
            "rx": In(RxBeatSignature(1)), "decide": In(1), "keep": In(1),
            "m_axis": Out(FrameStreamSignature()), "overflow": Out(1),
            "level": Out(range(depth + 1)),
        })

    def elaborate(self, platform):
        m = Module()
        n = self._depth
        aw = (n - 1).bit_length()
        m.submodules.mem = mem = Memory(shape=9, depth=n, init=[])     # byte + last
        wr = mem.write_port()
        rd = mem.read_port()
        m.submodules.status = status = SyncFIFO(width=FrameStatus.size, depth=self._frames)
        written = Signal(FrameStatus)
        rx = self.rx

        wp = Signal(aw + 1)          # next byte of the arriving frame
        start = Signal(aw + 1)       # its first byte
        done_wp = Signal(aw + 1)     # end of the last complete kept frame
        rp = Signal(aw + 1)
        # the write pointer of a full queue (one byte short of n, for the last-byte mark),
        # kept beside rp so that fullness is an equality of registers, not a subtraction
        full_wp = Signal(aw + 1, init=n - 1)
        arriving = Signal()
        kept = Signal()
        decided = Signal()
        full_seen = Signal()
        began = Signal()             # the reader has taken the arriving frame's first byte
        last_byte = Signal(8)
        newest = Signal(aw + 1)      # the arriving frame's newest byte ...
        has_bytes = Signal()         # ... once it has one (wp != start)
        m.d.comb += self.level.eq(wp - rp)
        full = wp == full_wp

        with m.If(rx.valid):
            # a frame's first byte is the first beat after an end (every frame has one),
            # known from ``arriving`` rather than from the 11-bit index: the receive clock's
            # longest path ran from that comparison into ``wp``
            with m.If(~arriving):
                m.d.sync += [arriving.eq(1), kept.eq(0), decided.eq(0), start.eq(wp),
                             full_seen.eq(0), began.eq(0)]
                with m.If(full):
                    m.d.sync += [full_seen.eq(1), has_bytes.eq(0)]
                with m.Else():
                    m.d.comb += [wr.en.eq(1), wr.addr.eq(wp[:aw]), wr.data.eq(rx.data)]
                    m.d.sync += [wp.eq(wp + 1), last_byte.eq(rx.data), newest.eq(wp),
                                 has_bytes.eq(1)]
            with m.Elif(arriving & ~full_seen):
                with m.If(full):
                    m.d.sync += full_seen.eq(1)
                with m.Else():
                    m.d.comb += [wr.en.eq(1), wr.addr.eq(wp[:aw]), wr.data.eq(rx.data)]
                    m.d.sync += [wp.eq(wp + 1), last_byte.eq(rx.data), newest.eq(wp),
                                 has_bytes.eq(1)]
        with m.If(self.decide & arriving & ~decided):
            m.d.sync += [decided.eq(1), kept.eq(self.keep)]
        # (``decide`` comes with a byte, never with the end pulse: at the end the decision is
        # in ``kept``)
        # cut short: a size error, the only reason given (as a MAC gives one). A begun
        # frame's status FIFO has room: every frame before it has been read out
        cut_short = full_seen & began
        with m.If(rx.end & arriving):
            m.d.sync += arriving.eq(0)
            with m.If(kept & (~full_seen | began) & status.w_rdy & has_bytes):
                # mark the last byte and record the frame's status
                m.d.comb += [wr.en.eq(1), wr.addr.eq((wp - 1)[:aw]),
                             wr.data.eq(Cat(last_byte, 1)),
                             status.w_en.eq(1),
                             status.w_data.eq(written),
                             written.bad.eq(~rx.ok | cut_short),
                             written.err_fcs.eq(rx.err_fcs & ~cut_short),
                             written.err_rx_er.eq(rx.err_rx_er & ~cut_short),
                             written.err_size.eq(rx.err_size | cut_short),
                             self.overflow.eq(cut_short)]
                m.d.sync += done_wp.eq(wp)
            with m.Else():
                m.d.sync += wp.eq(start)
                with m.If(kept):
                    m.d.comb += self.overflow.eq(1)

        # reading: up to the byte before the arriving kept frame's newest, whole frames after
        # from registers only: the reader follows a kept frame from the cycle after its
        # decision, up to the newest byte written (``newest`` is ``wp - 1`` once a byte is)
        # (both comparisons side by side, the choice between them after)
        reading_kept = arriving & kept & (~full_seen | began)
        readable = Mux(reading_kept & has_bytes, rp != newest, rp != done_wp)
        out_valid = Signal()
        out = self.m_axis
        if self._registered:
            # the bytes and ``tlast`` through the slice; a frame's status joins its last byte
            # after it, so the status FIFO is read from the slice's registers too
            m.submodules.out_slice = out_slice = RegisterSlice(FrameStreamSignature())
            sliced = out_slice.m_axis
            m.d.comb += [self.m_axis.tvalid.eq(sliced.tvalid), self.m_axis.tdata.eq(sliced.tdata),
                         self.m_axis.tlast.eq(sliced.tlast), sliced.tready.eq(self.m_axis.tready),
                         out_slice.s_axis.tuser.eq(0)]
            out = out_slice.s_axis
        fetch = readable & (~out_valid | out.tready)
        m.d.comb += [rd.addr.eq(rp[:aw]), rd.en.eq(fetch)]
        with m.If(fetch):
            m.d.sync += [rp.eq(rp + 1), full_wp.eq(full_wp + 1), out_valid.eq(1)]
            with m.If(reading_kept & (rp == start)):
                m.d.sync += began.eq(1)
        with m.Elif(out.tready):
            m.d.sync += out_valid.eq(0)
        m.d.comb += [out.tvalid.eq(out_valid), out.tdata.eq(rd.data[:8]),
                     out.tlast.eq(rd.data[8])]
        done = self.m_axis
        m.d.comb += [done.tuser.eq(Mux(done.tlast, status.r_data, 0)),
                     status.r_en.eq(done.tvalid & done.tready & done.tlast)]
        return m


class FrameToRxBeats(wiring.Component):
    """A frame stream back into the :class:`~hdl.net.mac.RxBeatSignature` a
    :class:`~hdl.net.rx.FrameParser` takes: beats with their index, then the end pulse with
    the status, then ``gap`` idle cycles so the parser's consumers can read its fields.
    Every ``rx`` member comes from a flip-flop (a beat leaves the cycle after it is taken):
    the queue's read and the arbiter's choice end here, not in the parser.

    Parameters
    ----------
    lanes : int
        Bytes per beat, 1 or 2.
    gap : int
        Idle cycles after each frame's end (at least 1).

    Members
    -------
    s_axis : In(FrameStreamSignature(lanes))
        Frames; a gap inside a frame becomes a gap in ``rx.valid``.
    rx : Out(RxBeatSignature(lanes))
    """

    def __init__(self, *, lanes=1, gap=16):
        self._lanes = check_int("lanes", lanes, 1, 2)
        self._gap = check_int("gap", gap, 1, 255)
        super().__init__({"s_axis": In(FrameStreamSignature(lanes)),
                          "rx": Out(RxBeatSignature(lanes))})

    def elaborate(self, platform):
        m = Module()
        L = self._lanes
        s, rx = self.s_axis, self.rx
        index = Signal(range(2048))
        wait = Signal(range(self._gap + 2))
        took = s.tvalid & s.tready
        n = keep_count(s.tkeep) if L > 1 else 1
        # ``index`` counts the bytes taken; ``rx.index`` is the beat's own (at the end pulse,
        # the frame's length, as a MAC reports it)
        m.d.comb += s.tready.eq(wait == 0)
        m.d.sync += [rx.data.eq(s.tdata), rx.valid.eq(took), rx.index.eq(index)]
        ended = Signal()
        m.d.sync += [ended.eq(0), rx.end.eq(ended)]
        with m.If(wait != 0):
            m.d.sync += wait.eq(wait - 1)
        with m.If(wait == 1):
            m.d.sync += index.eq(0)
        with m.If(took):
            m.d.sync += index.eq(Mux(index > 2047 - L, 2048 - L, index + n))
            with m.If(s.tlast):
                m.d.sync += [ended.eq(1), wait.eq(self._gap + 1)]
        with m.If(took & s.tlast):
            status = FrameStatus(s.tuser)
            m.d.sync += [rx.ok.eq(~status.bad), rx.err_fcs.eq(status.err_fcs),
                         rx.err_rx_er.eq(status.err_rx_er), rx.err_size.eq(status.err_size)]
        return m


class FrameStreamBridge(wiring.Component):
    """Frames from the GMII clock to the core clock: a byte stream in, two-byte beats out.

    A :class:`FrameQueue`'s bytes (domain ``gmii_domain``) are paired and cross an
    asynchronous FIFO; on ``sync`` they leave as a :func:`FrameStreamSignature` of 2 lanes
    (the last beat of a frame of odd length with ``tkeep`` 0b01), the status on the last.
    A reader on a core clock of half the GMII clock takes a byte-wide writer's rate.
    ``s_axis.tready`` comes from a flip-flop (a ready-only register slice, no latency while
    the FIFO has room): the FIFO's fullness, a comparison of its pointers, stays out of the
    writer's paths (a :class:`FrameQueue` takes its frame status on the handshake of the
    last byte).

    Parameters
    ----------
    gmii_domain : str
        The writer's domain.

    Members
    -------
    s_axis : In(FrameStreamSignature(1))
        In ``gmii_domain``.
    m_axis : Out(FrameStreamSignature(2))
        In ``sync``.
    """

    def __init__(self, *, gmii_domain="gmii"):
        self._domain = gmii_domain
        super().__init__({"s_axis": In(FrameStreamSignature(1)),
                          "m_axis": Out(FrameStreamSignature(2))})

    def elaborate(self, platform):
        m = Module()
        sig = FrameStreamSignature(2)
        m.submodules.fifo = fifo = AsyncFIFO(width=sig.payload_width, depth=BRIDGE_DEPTH,
                                             w_domain=self._domain, r_domain="sync")
        in_slice = RegisterSlice(FrameStreamSignature(1), ready_only=True)
        m.submodules.in_slice = in_slice = DomainRenamer(self._domain)(in_slice)
        wiring.connect(m, wiring.flipped(self.s_axis), in_slice.s_axis)
        s = in_slice.m_axis
        low = Signal(8)
        have_low = Signal()
        beat = sig.flip().create()
        # a beat is complete with its second byte, or a frame's last byte alone
        push = s.tvalid & (have_low | s.tlast)
        m.d.comb += [beat.tdata.eq(Cat(Mux(have_low, low, s.tdata), Mux(have_low, s.tdata, 0))),
                     beat.tkeep.eq(Cat(Const(1), have_low)), beat.tlast.eq(s.tlast),
                     beat.tuser.eq(s.tuser),
                     fifo.w_data.eq(sig.pack(beat)), fifo.w_en.eq(push),
                     s.tready.eq(~push | fifo.w_rdy)]
        with m.If(s.tvalid & s.tready):
            m.d[self._domain] += [low.eq(s.tdata), have_low.eq(~push)]
        o = self.m_axis
        m.d.comb += [*sig.unpack(o, fifo.r_data), o.tvalid.eq(fifo.r_rdy),
                     fifo.r_en.eq(o.tready)]
        return m
