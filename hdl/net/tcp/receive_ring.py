"""The receive ring of a TCP session: bytes written while a segment arrives, kept only when
the segment turns out good (docs/network.md "TCP session")."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ...params import ParameterError, check_int, check_power_of_two
from ...stream import AXIStreamSignature
from .banks import ByteBanks

__all__ = ["TcpReceiveRing"]


class TcpReceiveRing(wiring.Component):
    """A byte ring with a speculative write pointer.

    A segment's payload is written while its frame arrives, before its Ethernet FCS and TCP
    checksum are known, a cycle behind the parser (the payload, ``accept`` and ``skip`` pass
    a register first; ``written`` is complete a cycle after the last payload beat, before
    the FCS has passed). The bytes become readable on ``commit`` and are dropped on
    ``rollback``. Three pointers (17 bits, wrapping) hold the state: read, committed and
    speculative; the ring's free space is the receive window. With 2 lanes the ring is two
    byte banks (:class:`~hdl.net.tcp.banks.ByteBanks`): two bytes in and two out per cycle
    at any pointer.

    Parameters
    ----------
    depth : int
        Bytes, a power of two in 2**11..2**16 (one byte stays unused, so that a full ring is
        told apart from an empty one).
    lanes : int
        Bytes per beat of the payload, 1 or 2.
    read_lanes : int
        Bytes per beat of ``m_axis``, 1 or ``lanes`` (default): a byte-wide reader takes its
        bytes straight from the ring, so every byte the window counts as read has been read.

    Members
    -------
    payload_data, payload_valid, payload_keep, payload_offset : In
        The TCP payload of the arriving frame, ``lanes`` bytes per beat (the frame parser's
        ``payload_*``); ``payload_offset`` counts from the payload's first byte.
    accept : In(1)
        Sampled with the payload beat at offset 0: this segment may be written (it belongs
        to the connection, starts at or before RCV.NXT, and is not a RST).
    skip : In(16)
        Sampled with the beat at offset 0: how many of the segment's first bytes were
        already received (RCV.NXT - SEG.SEQ); they are not written again.
    written : Out(11)
        Bytes of the current segment written so far. When the ring fills, writing stops for
        the rest of the segment: what follows would not be contiguous.
    frame_end : In(1)
        The parser's verdict on the frame: ``written`` starts from zero for the next one.
    commit : In(1)
        The written bytes become readable (``commit`` wins over ``rollback``).
    rollback : In(1)
        The written bytes are dropped.
    discard : In(1)
        The committed bytes not yet read are dropped (a new connection starts empty).
    window : Out(16)
        Free bytes, at most 65535: the window to advertise.
    m_axis : Out(AXIStreamSignature(8 * read_lanes, keep=read_lanes > 1))
        Committed bytes in order, as many as are committed up to ``read_lanes`` per beat
        (``tkeep`` contiguous from lane 0); ``tlast`` is 0. Backpressure only fills the ring
        (and so closes the window).
    """

    def __init__(self, depth=65536, *, lanes=1, read_lanes=None):
        self._depth = check_power_of_two("depth", depth, 2048, 65536)
        self._lanes = check_int("lanes", lanes, 1, 2)
        self._read = lanes if read_lanes is None else read_lanes
        if self._read not in (1, lanes):
            raise ParameterError("read_lanes", read_lanes, f"1 or lanes ({lanes})")
        super().__init__({
            "payload_data": In(8 * lanes), "payload_valid": In(1), "payload_keep": In(lanes),
            "payload_offset": In(11),
            "accept": In(1), "skip": In(16), "written": Out(11),
            "frame_end": In(1), "commit": In(1), "rollback": In(1), "discard": In(1),
            "window": Out(16),
            "m_axis": Out(AXIStreamSignature(8 * self._read, keep=self._read > 1)),
        })

    def elaborate(self, platform):
        m = Module()
        depth, L = self._depth, self._lanes
        m.submodules.banks = banks = ByteBanks(depth, lanes=L)

        read = Signal(17)
        committed = Signal(17)
        speculative = Signal(17)
        # pointer differences are taken modulo 2**17 (the pointers wrap)
        used = Signal(17)
        free = Signal(17)
        m.d.comb += [used.eq(committed - read), free.eq(depth - 1 - used),
                     self.window.eq(Mux(free > 65535, 65535, free))]

        # reading: as many committed bytes as a beat holds
        R = self._read
        out = self.m_axis
        out_go = out.tvalid & out.tready
        full_beat = used >= R
        taken = Mux(full_beat, R, 1) if R > 1 else 1
        m.d.comb += [
            out.tvalid.eq(read != committed),
            out.tdata.eq(banks.rd_data[:8 * R]),
            banks.rd_addr.eq(Mux(out_go, read + taken, read)[:16]),
        ]
        if R > 1:
            m.d.comb += out.tkeep.eq(Cat(Const(1), full_beat))
        with m.If(out_go):
            m.d.sync += read.eq(read + taken)
        with m.If(self.discard):
            m.d.sync += read.eq(committed)

        # writing: the beat's payload bytes at or after ``skip``, while they fit; the parser's
        # payload and the connection's ``accept`` and ``skip`` through a register first
        p_data, p_keep = Signal(8 * L), Signal(L)
        p_valid, p_first = Signal(), Signal()
        offset = Signal(11)
        p_accept, p_skip = Signal(), Signal(16)
        m.d.sync += [p_data.eq(self.payload_data), p_keep.eq(self.payload_keep),
                     p_valid.eq(self.payload_valid), offset.eq(self.payload_offset),
                     p_first.eq(self.payload_valid & (self.payload_offset == 0)),
                     p_accept.eq(self.accept), p_skip.eq(self.skip)]
        writing = Signal()
        skipping = Signal(16)
        first = p_first
        on = Mux(first, p_accept, writing)
        skip = Mux(first, p_skip, skipping)
        in_use = Signal(17)
        m.d.comb += in_use.eq(speculative - read)
        lanes = [p_data[8 * k:8 * k + 8] for k in range(L)]
        wanted = [p_valid & on & p_keep[k] & (offset + k >= skip) for k in range(L)]
        if L == 1:
            fits = [in_use < depth - 1]
            data, count = lanes[0], wanted[0]
        else:
            # the wanted bytes are the beat's last ones: one (lane 0 or 1) or both
            fits = [in_use < depth - 1, in_use < depth - 2]
            data = Cat(Mux(wanted[0], lanes[0], lanes[1]), lanes[1])
            count = wanted[0] + wanted[1]
        write = [(count > k) & fits[k] for k in range(L)]
        n_written = Signal(range(L + 1))
        m.d.comb += n_written.eq(sum(write[1:], write[0]))
        m.d.comb += [banks.wr_addr.eq(speculative[:16]), banks.wr_data.eq(data),
                     banks.wr_en.eq(Cat(*write))]
        with m.If(first):
            m.d.sync += [writing.eq(p_accept), skipping.eq(p_skip)]
        m.d.sync += [speculative.eq(speculative + n_written),
                     self.written.eq(self.written + n_written)]
        with m.If(n_written != count):
            m.d.sync += writing.eq(0)           # the ring is full: the rest would not follow
        with m.If(self.frame_end):
            m.d.sync += self.written.eq(0)
        with m.If(self.commit):
            m.d.sync += committed.eq(speculative)
        with m.Elif(self.rollback):
            m.d.sync += speculative.eq(committed)
        return m
