"""The transmit side of a TCP session's user stream: byte buffer, segmenter and descriptor
ring (docs/network.md "TCP session")."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ...params import check_int, check_power_of_two
from ...stream import AXIStreamSignature, keep_count
from ..checksum import ones_complement_add
from .banks import ByteBanks

__all__ = ["TcpTransmitBuffer"]


class TcpTransmitBuffer(wiring.Component):
    """User bytes kept until acknowledged, cut into segments as they arrive.

    Each byte written goes into a block-RAM buffer at its sequence number. The segmenter
    closes a segment at ``tlast``, at ``mss`` bytes, or after 16 cycles without a byte, and
    writes its descriptor (first sequence number, length, ones'-complement sum of its bytes
    summed while they were written) into a ring. Three ring pointers say which segments are
    acknowledged (freed as SND.UNA passes their end, one per cycle), sent and written. A
    segment is therefore sent at ``lanes`` bytes per cycle straight from the buffer, and
    resent unchanged until acknowledged. With 2 lanes the buffer is two byte banks
    (:class:`~hdl.net.tcp.banks.ByteBanks`), so that both the user's beats and the frame
    builder's reads move two bytes at any sequence number; a beat that would take a segment
    past ``mss`` closes the segment first and starts the next one.

    Parameters
    ----------
    depth : int
        Buffer bytes, a power of two in 2**11..2**16.
    descriptors : int
        Segments the ring holds (one stays unused), a power of two in 4..256.
    lanes : int
        Bytes per beat of ``s_axis`` and of the builder's reads, 1 or 2.

    Members
    -------
    s_axis : In(AXIStreamSignature(8 * lanes, keep=lanes > 1))
        The user's bytes (``tkeep`` contiguous from lane 0); ``tlast`` closes the segment at
        once. ``tready`` is high while ``accept`` is and there is room in the buffer and
        the ring.
    accept : In(1)
        The connection takes user bytes (ESTABLISHED or CLOSE-WAIT, no FIN queued).
    mss : In(11)
        The longest segment.
    taken : Out(range(lanes + 1))
        Bytes taken this cycle.
    fill : Out(17)
        Bytes held (written and not yet acknowledged).
    wr_seq : Out(32)
        Sequence number of the next byte the user writes (the FIN's, once one is queued).
    load, load_value : In(1), In(32)
        Set ``wr_seq`` (the sequence engine's write of a new connection's first number).
    snd_una : In(32)
        The oldest unacknowledged sequence number: a segment ending at or before it is freed.
    next_seq, next_len, next_sum : Out(32), Out(11), Out(16)
        The next segment to send: its sequence number, length and payload sum (valid while
        ``unsent``).
    unsent : Out(1)
        Closed segments wait to be sent.
    all_sent : Out(1)
        Every byte written is in a segment that was sent.
    in_flight : Out(range(descriptors))
        Segments sent and not yet freed.
    advance : In(1)
        The next segment was sent.
    rewind : In(1)
        Go back N: the next segment to send is the oldest one not freed (this cycle's free
        counted).
    reset : In(1)
        Drop every segment (the connection closed); ``wr_seq`` stays.
    rd_addr, rd_data : In(16), Out(8 * lanes)
        The frame builder reads the bytes at sequence numbers ``rd_addr`` (low 16 bits)
        .. ``rd_addr + lanes - 1``, one cycle later.
    """

    def __init__(self, *, depth=65536, descriptors=64, lanes=1):
        self._depth = check_power_of_two("depth", depth, 2048, 65536)
        self._descriptors = check_power_of_two("descriptors", descriptors, 4, 256)
        self._lanes = check_int("lanes", lanes, 1, 2)
        super().__init__({
            "s_axis": In(AXIStreamSignature(8 * lanes, keep=lanes > 1)),
            "accept": In(1), "mss": In(11), "taken": Out(range(lanes + 1)), "fill": Out(17),
            "wr_seq": Out(32), "load": In(1), "load_value": In(32), "snd_una": In(32),
            "next_seq": Out(32), "next_len": Out(11), "next_sum": Out(16),
            "unsent": Out(1), "all_sent": Out(1), "in_flight": Out(range(descriptors)),
            "advance": In(1), "rewind": In(1), "reset": In(1),
            "rd_addr": In(16), "rd_data": Out(8 * lanes),
        })

    def elaborate(self, platform):
        m = Module()
        depth, nd, L = self._depth, self._descriptors, self._lanes
        m.submodules.data = buffer = ByteBanks(depth, lanes=L)
        m.d.comb += [buffer.rd_addr.eq(self.rd_addr), self.rd_data.eq(buffer.rd_data)]

        m.submodules.ring = ring = Memory(shape=32 + 11 + 16, depth=nd, init=[])
        ring_w = ring.write_port()
        # the next segment's descriptor from a register: read with the address ``sending``
        # takes next, so that nothing waits for the ring's read (it sees this cycle's write)
        ring_send = ring.read_port(transparent_for=(ring_w,))
        ring_ack = ring.read_port(domain="comb")
        ptr_bits = nd.bit_length()
        written = Signal(ptr_bits)
        sending = Signal(ptr_bits)
        sending_next = Signal(ptr_bits)
        acked = Signal(ptr_bits)
        m.d.comb += [ring_send.addr.eq(sending_next[:-1]), ring_ack.addr.eq(acked[:-1])]
        m.d.comb += [self.next_seq.eq(ring_send.data[:32]), self.next_len.eq(ring_send.data[32:43]),
                     self.next_sum.eq(ring_send.data[43:59])]
        ack_seq, ack_len = ring_ack.data[:32], ring_ack.data[32:43]

        wr_seq = self.wr_seq
        seg_start = Signal(32)
        seg_len = Signal(11)
        seg_sum = Signal(16)
        idle = Signal(5)
        oldest = Mux(acked != written, ack_seq, Mux(seg_len != 0, seg_start, wr_seq))
        m.d.comb += self.fill.eq(wr_seq - oldest)
        ring_used = Signal(ptr_bits)
        m.d.comb += ring_used.eq(written - acked)
        s = self.s_axis
        n = keep_count(s.tkeep) if L > 1 else Const(1, 1)
        # a beat that does not fit into the open segment closes it first, without being taken
        too_long = s.tvalid & (seg_len + n > self.mss)
        m.d.comb += [
            s.tready.eq(self.accept & (ring_used < nd - 1) & (self.fill < depth - L) &
                        ~too_long),
            self.unsent.eq(sending != written),
            self.all_sent.eq((sending == written) & (seg_len == 0)),
            self.in_flight.eq(sending - acked),
        ]
        take = s.tvalid & s.tready
        m.d.comb += [buffer.wr_addr.eq(wr_seq[:16]), buffer.wr_data.eq(s.tdata),
                     buffer.wr_en.eq(Mux(take, s.tkeep if L > 1 else 1, 0)),
                     self.taken.eq(Mux(take, n, 0))]

        # the beat's bytes as a word of the segment's sum: the first in the high half if it
        # is at an even place of the segment, else in the low half (RFC 1071 sums are the
        # same byte-swapped)
        if L == 1:
            byte_word = Mux(seg_len[0], Cat(s.tdata, Const(0, 8)), Cat(Const(0, 8), s.tdata))
        else:
            second = Mux(s.tkeep[1], s.tdata[8:], 0)
            byte_word = Mux(seg_len[0], Cat(s.tdata[:8], second), Cat(second, s.tdata[:8]))
        new_sum = ones_complement_add(seg_sum, byte_word)
        new_len = (seg_len + n)[:11]
        close = Signal()
        close_len = Signal(11)
        close_sum = Signal(16)
        with m.If(take):
            m.d.sync += [wr_seq.eq(wr_seq + n), idle.eq(0)]
            with m.If(seg_len == 0):
                m.d.sync += seg_start.eq(wr_seq)
            with m.If((s.tlast & (new_len != 0)) | (new_len >= self.mss)):
                m.d.comb += [close.eq(1), close_len.eq(new_len), close_sum.eq(new_sum)]
                m.d.sync += [seg_len.eq(0), seg_sum.eq(0)]
            with m.Else():
                m.d.sync += [seg_len.eq(new_len), seg_sum.eq(new_sum)]
        with m.Elif(too_long & (ring_used < nd)):
            m.d.comb += [close.eq(1), close_len.eq(seg_len), close_sum.eq(seg_sum)]
            m.d.sync += [seg_len.eq(0), seg_sum.eq(0), idle.eq(0)]
        with m.Elif(seg_len != 0):
            m.d.sync += idle.eq(idle + 1)
            with m.If((idle == 15) & (ring_used < nd)):
                m.d.comb += [close.eq(1), close_len.eq(seg_len), close_sum.eq(seg_sum)]
                m.d.sync += [seg_len.eq(0), seg_sum.eq(0), idle.eq(0)]
        with m.If(self.load):
            m.d.sync += wr_seq.eq(self.load_value)
        start_of_closed = Mux(seg_len == 0, wr_seq, seg_start)
        m.d.comb += [ring_w.addr.eq(written[:-1]),
                     ring_w.data.eq(Cat(start_of_closed, close_len, close_sum)),
                     ring_w.en.eq(close)]
        with m.If(close):
            m.d.sync += written.eq(written + 1)

        # a segment is freed once SND.UNA reaches its end; sequence distances on this side
        # stay below 2**16, so they are taken modulo 2**18 and bit 17 is the sign
        behind = Signal(18)
        m.d.comb += behind.eq(self.snd_una[:18] - ack_seq[:18] - ack_len)
        free_now = (acked != written) & ~behind[17]
        acked_next = acked + free_now
        m.d.comb += sending_next.eq(sending)
        with m.If(free_now):
            m.d.sync += acked.eq(acked + 1)
            with m.If(sending == acked):
                m.d.comb += sending_next.eq(sending + 1)
        with m.If(self.advance):
            m.d.comb += sending_next.eq(sending + 1)
        with m.If(self.rewind):
            m.d.comb += sending_next.eq(acked_next)
        with m.If(self.reset):
            m.d.comb += sending_next.eq(written)
            m.d.sync += [acked.eq(written), seg_len.eq(0), seg_sum.eq(0)]
        m.d.sync += sending.eq(sending_next)
        return m
