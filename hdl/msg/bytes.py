"""Byte-granular stream realignment: pack chunks of 0..W/8 bytes into full AXI4-Stream beats,
and present a beat stream as a window from which any 0..W/8 bytes can be taken per cycle."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..logic import kept
from ..params import check_int, check_power_of_two
from ..stream import AXIStreamSignature, keep_count, keep_count_shallow, skid_buffer

__all__ = ["ChunkSignature", "ChunkRegisterSlice", "BytePacker", "ByteUnpacker",
           "WideByteUnpacker", "SettlingByteUnpacker", "byte_unpacker_class", "byte_mask"]


def byte_mask(value, nbytes, count):
    """``value`` (``nbytes`` bytes) with every byte at index ``>= count`` cleared."""
    return Cat(*(Mux(count > i, value.word_select(i, 8), 0) for i in range(nbytes)))


class ChunkSignature(wiring.Signature):
    """A chunk of ``0..data_width // 8`` bytes, seen from the producer (``Out``).

    Members
    -------
    data : Out(data_width)
        The bytes, byte 0 in bits 7..0; bytes at ``len`` and above are ignored.
    len : Out(range(data_width // 8 + 1))
        Number of bytes; 0 is a legal, empty chunk.
    last : Out(1)
        The last chunk of a message.
    valid, ready
        Handshake with AXI4-Stream rules (``valid`` does not wait for ``ready``).
    """

    def __init__(self, data_width):
        check_int("data_width", data_width, 8, 1024, multiple_of=8)
        self._data_width = data_width
        super().__init__({"data": Out(data_width), "len": Out(range(data_width // 8 + 1)),
                          "last": Out(1), "valid": Out(1), "ready": In(1)})

    data_width = property(lambda self: self._data_width)

    def __eq__(self, other):
        return type(other) is type(self) and other._data_width == self._data_width

    def __hash__(self):
        return hash((type(self), self._data_width))


class ChunkRegisterSlice(wiring.Component):
    """Register slice of a chunk link: ``o`` and ``i.ready`` from flip-flops, one chunk per
    cycle, one cycle of latency (see :class:`~hdl.stream.RegisterSlice`).

    Members
    -------
    i : In(ChunkSignature(data_width))
    o : Out(ChunkSignature(data_width))
        The same chunks in the same order.
    """

    def __init__(self, data_width):
        super().__init__({"i": In(ChunkSignature(data_width)),
                          "o": Out(ChunkSignature(data_width))})

    def elaborate(self, platform):
        m = Module()
        i, o = self.i, self.o
        payload_i = Cat(i.data, i.len, i.last)
        payload_o = Signal(len(payload_i))
        m.d.comb += Cat(o.data, o.len, o.last).eq(payload_o)
        skid_buffer(m, len(payload_i), i.valid, i.ready, payload_i, o.valid, o.ready, payload_o)
        return m


class BytePacker(wiring.Component):
    """Packs chunks into AXI4-Stream beats: every beat full except the last of a message.

    Takes one chunk per cycle and gives one beat per cycle in steady state, whatever the chunk
    sizes (a message may end with an empty chunk); a full beat leaves once the next byte or the
    end of the message is known, so latency is one to two cycles. ``first`` marks the first beat
    of a message (ReconROS' ``TUSER`` is its complement except on the last beat). A message of
    no bytes (only empty chunks) is one beat with ``tkeep`` 0 and ``tlast``.

    Members
    -------
    chunk : In(ChunkSignature(data_width))
    m_axis : Out(AXIStreamSignature(data_width))
        ``tkeep`` is all ones except on a message's last beat.
    first : Out(1)
        The beat on ``m_axis`` is the first of its message.
    """

    def __init__(self, data_width):
        super().__init__({"chunk": In(ChunkSignature(data_width)),
                          "m_axis": Out(AXIStreamSignature(data_width)),
                          "first": Out(1)})
        self._width = data_width

    def elaborate(self, platform):
        m = Module()
        W, B = self._width, self._width // 8
        buf = Signal(2 * W)
        count = Signal(range(2 * B + 1))
        final = Signal()       # the message's last chunk is in buf
        first = Signal(init=1)
        out, chunk = self.m_axis, self.chunk

        def beat_ready(count, final, first, *, beyond_beat=True):
            # A full beat waits for one more byte (or the end of the message): the message's
            # last chunk may be empty, and tlast must still land on its last byte. A count of
            # at most B bytes (``beyond_beat`` False) is never more than a beat.
            more = (count > B) if beyond_beat else Const(0)
            return more | (final & ((count != 0) | first))

        # ``tvalid`` comes from a flip-flop holding ``beat_ready`` of the registers: its next
        # value is built like the other next states below, so the consumer's ready meets
        # registers only
        valid = Signal()
        m.d.comb += [
            out.tvalid.eq(valid),
            out.tdata.eq(buf[:W]),
            out.tlast.eq(final & (count <= B)),
            out.tkeep.eq(Mux(count >= B, (1 << B) - 1,
                             Cat(*(count > i for i in range(B))))),
            self.first.eq(first),
        ]
        # The next state is built for a beat leaving and for none, each with and without a
        # chunk coming in, from registers and the chunk, on kept wires; the output handshake
        # (the consumer's ready) and the chunk's acceptance only choose.
        sent = out.tvalid & out.tready
        with m.If(sent):
            m.d.sync += first.eq(out.tlast)
        # Bytes of ``buf`` at ``count`` and above are zero. A beat that is not its message's
        # last leaves only with more than B bytes buffered, so it takes exactly B of them and
        # at most B stay; the last beat takes all. The bytes left after a beat are therefore
        # ``buf``'s upper half or nothing: no shifter by a byte count is needed.
        left_sent = Signal(range(B + 1))
        m.d.comb += [left_sent.eq(Mux(out.tlast, 0, count - B)),
                     chunk.ready.eq(Mux(sent, out.tlast | ~final, (count <= B) & ~final))]
        data = Cat(byte_mask(chunk.data, B, chunk.len), Const(0, W))
        shifted = Cat(Mux(out.tlast, 0, buf[W:]), Const(0, W))
        buf_sent_in = kept(m, (shifted | (data << (left_sent * 8)))[:2 * W], "buf_sent_in")
        buf_sent = kept(m, shifted, "buf_sent")
        # a chunk comes in without a beat leaving only while at most B bytes are buffered
        buf_in = kept(m, (buf | (data << (count[:len(left_sent)] * 8)))[:2 * W], "buf_in")
        count_sent_in = Signal(range(3 * B + 1))
        count_in = Signal(range(3 * B + 1))
        m.d.comb += [count_sent_in.eq(left_sent + chunk.len), count_in.eq(count + chunk.len)]
        valid_sent_in = kept(m, beat_ready(count_sent_in, chunk.last, out.tlast),
                             "valid_sent_in")
        valid_in = kept(m, beat_ready(count_in, chunk.last, first), "valid_in")
        valid_sent = kept(m, beat_ready(left_sent, final & ~out.tlast, out.tlast,
                                        beyond_beat=False), "valid_sent")
        with m.If(chunk.valid & chunk.ready):
            m.d.sync += [buf.eq(Mux(sent, buf_sent_in, buf_in)),
                         count.eq(Mux(sent, count_sent_in, count_in)),
                         final.eq(chunk.last),
                         valid.eq(Mux(sent, valid_sent_in, valid_in))]
        with m.Elif(sent):
            m.d.sync += [buf.eq(buf_sent), count.eq(left_sent),
                         final.eq(final & ~out.tlast), valid.eq(valid_sent)]
        return m


class ByteUnpacker(wiring.Component):
    """Presents an AXI4-Stream message as a byte window: take 0..W/8 bytes per cycle.

    One message at a time: after a beat with ``tlast`` is absorbed, ``ended`` is set and no
    further beat is accepted until ``flush``. ``flush`` discards the window and, if the
    message's ``tlast`` has not been seen, every input beat up to and including it.

    The consumer names the bytes it would take (``amount``) apart from its decision to take
    them (``take``): the window's next state is built for taking ``amount`` bytes and for
    taking none, and ``take`` only chooses between the two. A consumer whose ``amount`` comes
    from its registers and whose decision comes late keeps the barrel shift out of its
    decision's path.

    Members
    -------
    s_axis : In(AXIStreamSignature(data_width))
        ``tkeep`` must be contiguous from byte 0 (all ones but on a last beat).
    window : Out(data_width)
        The next ``avail`` bytes of the message (higher bytes zero).
    avail : Out(range(2 * data_width // 8 + 1))
        Bytes in the window; may exceed ``data_width // 8`` (only the first W/8 are shown).
    ended : Out(1)
        The message's last beat has been absorbed: ``avail`` bytes are all that is left.
    amount : In(range(data_width // 8 + 1))
        Bytes consumed if ``take``; at most ``avail`` then.
    take : In(1)
        Consume ``amount`` bytes this cycle.
    flush : In(1)
        Drop the rest of the message (window and input up to ``tlast``); ``take`` is ignored.
    dropping : Out(1)
        Discarding input beats after a ``flush``.
    """

    def __init__(self, data_width):
        super().__init__(self._members(data_width))
        self._width = data_width

    @staticmethod
    def _members(data_width):
        B = data_width // 8
        return {"s_axis": In(AXIStreamSignature(data_width)),
                "window": Out(data_width), "avail": Out(range(2 * B + 1)),
                "ended": Out(1), "amount": In(range(B + 1)), "take": In(1),
                "flush": In(1), "dropping": Out(1)}

    def _arrival(self, m, count, ended):
        """What the input beat brings, given the window's byte ``count`` and ``ended``:
        ``(n, beat, left, room_taken, room_kept)``, its byte count, its bytes with those past
        ``n`` zero, the bytes left after taking ``amount``, and whether it is absorbed when
        ``amount`` is taken and when nothing is."""
        B = self._width // 8
        s = self.s_axis
        n = keep_count(s.tkeep)
        left = Signal(range(2 * B + 1))
        m.d.comb += left.eq(count - self.amount)
        return (n, byte_mask(s.tdata, B, n), left, ~ended & (left <= B),
                ~ended & (count <= B))

    def elaborate(self, platform):
        m = Module()
        W, B = self._width, self._width // 8
        buf = Signal(2 * W)
        count = Signal(range(2 * B + 1))
        ended = Signal()
        dropping = Signal()
        s = self.s_axis
        m.d.comb += [self.window.eq(buf[:W]), self.avail.eq(count), self.ended.eq(ended),
                     self.dropping.eq(dropping)]

        # both next states, taking ``amount`` bytes and taking none, from registers and the
        # input beat; ``take`` chooses
        n, beat, left, room_taken, room_kept = self._arrival(m, count, ended)
        beat = Cat(beat, Const(0, W))
        shifted = buf >> (self.amount * 8)
        # A beat enters only at a byte offset of at most B (``room_*``), so the shifts take
        # the offsets' low bits: a shifter of B + 1 positions, not 2B + 1.
        nb = len(self.amount)
        # each next state on a kept wire: ``take`` and ``flush`` only choose
        buf_taken = kept(m, Mux(s.tvalid & room_taken, shifted | (beat << (left[:nb] * 8)),
                                shifted)[:2 * W], "buf_taken")
        buf_kept = kept(m, Mux(s.tvalid & room_kept, buf | (beat << (count[:nb] * 8)),
                               buf)[:2 * W], "buf_kept")

        with m.If(dropping):
            m.d.comb += s.tready.eq(1)
            with m.If(s.tvalid & s.tlast):
                m.d.sync += dropping.eq(0)
        with m.Elif(self.flush):
            m.d.sync += [count.eq(0), buf.eq(0), ended.eq(0), dropping.eq(~ended)]
        with m.Elif(self.take):
            m.d.comb += s.tready.eq(room_taken)
            m.d.sync += buf.eq(buf_taken)
            with m.If(s.tvalid & room_taken):
                m.d.sync += [count.eq(left + n), ended.eq(s.tlast)]
            with m.Else():
                m.d.sync += count.eq(left)
        with m.Else():
            m.d.comb += s.tready.eq(room_kept)
            m.d.sync += buf.eq(buf_kept)
            with m.If(s.tvalid & room_kept):
                m.d.sync += [count.eq(count + n), ended.eq(s.tlast)]
        return m


def _rotate_bytes(m, value, by, name):
    """The bytes of ``value`` rotated down by ``by`` byte positions (byte ``by`` first), one
    two-way choice per bit of ``by``; ``by`` ranges over the bytes of ``value``."""
    for k in range(len(by)):
        level = Signal(len(value), name=f"{name}{k}")
        m.d.comb += level.eq(Mux(by[k], value.rotate_right(8 << k), value))
        value = level
    return value


def _shift_down(m, value, by, element, width, name):
    """``value`` moved down by ``by`` elements of ``element`` bits, cut to ``width`` bits
    (zeros come in on top)."""
    for k in range(len(by)):
        level = Signal(len(value), name=f"{name}{k}")
        m.d.comb += level.eq(Mux(by[k], value >> (element << k), value))
        value = level
    return value[:width]


def _shift_bytes_up(m, value, by, width, name):
    """``value`` moved up by ``by`` bytes, cut to ``width`` bits (bytes moved out are lost)."""
    for k in range(len(by)):
        level = Signal(width, name=f"{name}{k}")
        m.d.comb += level.eq(Mux(by[k], Cat(Const(0, min(8 << k, width)), value), value))
        value = level
    return value


class WideByteUnpacker(ByteUnpacker):
    """:class:`ByteUnpacker` for wide datapaths: the same ports and contract, built so that
    its logic grows with the window, not with twice the window times its shift.

    Beats land unshifted in a ring of two beat slots: a message's beats are full but its
    last, so each one starts at a slot boundary. Taking ``amount`` bytes, the next window is
    the ring rotated to the new read position, the bytes beyond those still held cleared, and
    the arriving beat's bytes placed after them; taking none, it is the window with the
    arriving beat's bytes placed after the ones it holds. Both are built every cycle, from
    registers and the input beat, into flip-flops of their own, and the window is the one of
    the two that ``take`` chose in the cycle before (or empty after a ``flush``): ``take`` and
    ``flush`` reach two flip-flops instead of every bit of the window, and the window shows
    each move in the next cycle, as in :class:`ByteUnpacker`.

    A beat is written into its slot a cycle after it is accepted, from a register that samples
    the input every cycle, and is read from that register meanwhile: ``take``, which decides
    whether a beat is accepted, reaches one flip-flop there instead of every bit of a slot.

    A rotation of the two-beat ring by a byte position and two placements of a beat replace
    :class:`ByteUnpacker`'s shifts of a two-beat buffer by the amount and of the beat into it
    at either offset: about a third less logic at 512 bits (data_width must be a power of
    two, for the ring's positions to wrap).

    Members
    -------
    As :class:`ByteUnpacker`.
    """

    def __init__(self, data_width):
        check_power_of_two("data_width", data_width, 16, 1024)
        super().__init__(data_width)

    def elaborate(self, platform):
        m = Module()
        W, B = self._width, self._width // 8
        # the slots hold bytes only while ``count`` says so: no reset needed
        ring = Signal(2 * W, reset_less=True)
        # both next windows in flip-flops, and which of them is the window
        window_taken_r = Signal(W)
        window_kept_r = Signal(W)
        chose_taken = Signal()
        chose_empty = Signal()
        window = Signal(W)
        m.d.comb += window.eq(Mux(chose_empty, 0,
                                  Mux(chose_taken, window_taken_r, window_kept_r)))
        read = Signal(range(2 * B))      # ring position of the window's first byte
        write = Signal()                 # the slot the next beat goes to
        count = Signal(range(2 * B + 1))
        ended = Signal()
        dropping = Signal()
        s = self.s_axis
        m.d.comb += [self.window.eq(window), self.avail.eq(count), self.ended.eq(ended),
                     self.dropping.eq(dropping)]

        n, beat, left, room_taken, room_kept = self._arrival(m, count, ended)
        nb = len(self.amount)
        # ``read + amount`` wraps at 2B bytes: the ring's size is a power of two
        to = Signal(range(2 * B))
        m.d.comb += to.eq(read + self.amount)
        # the beat accepted last cycle, and the ring as if it were written already
        arrived = Signal(W, reset_less=True)
        arrived_slot = Signal()
        arrived_valid = Signal()
        m.d.sync += [arrived.eq(s.tdata), arrived_slot.eq(write),
                     arrived_valid.eq(s.tvalid & s.tready & ~dropping)]
        with m.If(arrived_valid):
            m.d.sync += ring.word_select(arrived_slot, W).eq(arrived)
        ring_now = Cat(*(Mux(arrived_valid & (arrived_slot == k), arrived,
                             ring.word_select(k, W)) for k in range(2)))
        held = byte_mask(_rotate_bytes(m, ring_now, to, "ring_at")[:W], B, left)
        after_left = _shift_bytes_up(m, beat, left[:nb], W, "beat_after_left")
        after_count = _shift_bytes_up(m, beat, count[:nb], W, "beat_after_count")
        m.d.sync += [
            window_taken_r.eq(held | Mux(s.tvalid & room_taken, after_left, 0)),
            window_kept_r.eq(window | Mux(s.tvalid & room_kept & ~dropping, after_count, 0)),
            chose_taken.eq(self.take & ~self.flush & ~dropping),
            chose_empty.eq(self.flush & ~dropping)]

        def absorb(room):
            m.d.comb += s.tready.eq(room)
            with m.If(s.tvalid & room):
                m.d.sync += [write.eq(~write), ended.eq(s.tlast)]

        with m.If(dropping):
            m.d.comb += s.tready.eq(1)
            with m.If(s.tvalid & s.tlast):
                m.d.sync += dropping.eq(0)
        with m.Elif(self.flush):
            m.d.sync += [count.eq(0), read.eq(0), write.eq(0), ended.eq(0),
                         dropping.eq(~ended)]
        with m.Elif(self.take):
            absorb(room_taken)
            m.d.sync += [read.eq(to), count.eq(left + Mux(s.tvalid & room_taken, n, 0))]
        with m.Else():
            absorb(room_kept)
            m.d.sync += count.eq(count + Mux(s.tvalid & room_kept, n, 0))
        return m


class SettlingByteUnpacker(ByteUnpacker):
    """:class:`ByteUnpacker` whose window comes from flip-flops, for a consumer that decides
    from the window's bytes: a take of any amount is absorbed in two cycles of settling, a
    take of a whole window decided without looking at it (``take_full``) moves on at once.

    The window and its ``avail`` and ``ended`` come from registers, built every cycle from
    registers: the beats, held unshifted in a ring of four beat slots, and copies of the read
    position and byte count that only a ``take_full`` moves at once (the others follow them a
    cycle later). ``take`` and ``flush`` reach the position, the counts and the flags, not the
    window's bits nor the logic that builds them. Both windows built in every cycle, the one
    at the read position and the one a window further on, are registered; a flip-flop that
    follows ``take_full`` chooses between them, so ``take_full`` reaches one flip-flop instead
    of every bit of the window, and the window at the read position (``settled_window``) is
    a register for the consumer's decisions. So after a take of ``amount`` bytes or a
    ``flush`` ``avail`` is 0 for two cycles (``ended`` then says whether nothing is left: 0
    unless the take emptied an ended message; ``settling`` marks the first of them); a beat
    shows in the window a cycle after it is accepted; a run of ``take_full`` moves W/8 bytes
    per cycle, with ``tready`` from a register, while the ring is three slots deep. While
    ``avail`` is 0 the window's bytes are undefined.

    ``data_width`` must be a power of two (the ring's positions wrap).

    Members
    -------
    As :class:`ByteUnpacker`, with ``avail`` at most ``data_width // 8`` and
    take_full : In(1)
        Consume ``data_width // 8`` bytes this cycle (at most ``avail``), whatever ``take``
        and ``amount`` say; ``flush`` comes first. Decided without the window, it keeps the
        window's flip-flops out of the decision's path.
    settling : Out(1)
        The first cycle after a take of ``amount`` bytes or a ``flush``: a consumer may let
        registers that follow the taken bytes a cycle later catch up (``avail`` is 0).
    settled_window : Out(data_width)
        ``window`` straight from flip-flops, in every cycle but one that follows a
        ``take_full`` (it then shows the bytes that were taken): for a consumer that decides
        from the window's bytes only after a take of ``amount`` bytes or a ``flush``.
    """

    #: beat slots of the ring (a power of two): one more than a window and the next need
    SLOTS = 4

    def __init__(self, data_width):
        check_power_of_two("data_width", data_width, 16, 1024)
        wiring.Component.__init__(self, {**self._members(data_width), "take_full": In(1),
                                         "settling": Out(1),
                                         "settled_window": Out(data_width)})
        self._width = data_width

    def elaborate(self, platform):
        m = Module()
        W, B = self._width, self._width // 8
        nb = B.bit_length() - 1
        ns = self.SLOTS.bit_length() - 1
        ring = Signal(self.SLOTS * W, reset_less=True)
        read = Signal(nb + ns)           # ring position of the window's first byte
        write = Signal(ns)               # the slot the next beat goes to
        count = Signal(range(self.SLOTS * B + 1))   # bytes held from ``read`` on
        # what the window is built from: ``read`` and ``count`` as they were a cycle before,
        # or as they are after a ``take_full`` (the window is not shown while they differ).
        # A byte shift moves each bit of a byte on its own lane, and the viewed slot, which
        # a ``take_full`` advances, has a copy per lane: each copy chooses for an eighth of
        # the multiplexers. (The byte within the slot, which a ``take_full`` keeps, has one:
        # synthesis would merge copies of a register that only loads.)
        view_phase = Signal(nb)
        view_slots = [Signal(ns, name=f"view_slot_lane{b}") for b in range(8)]
        view_count = Signal.like(count)
        stale = Signal()                 # a take or a flush moved ``read`` or ``count``
        ended = Signal()
        dropping = Signal()
        window = Signal(W)
        avail = Signal(range(B + 1))
        shown_ended = Signal()
        s = self.s_axis
        m.d.comb += [self.window.eq(window), self.avail.eq(avail), self.ended.eq(shown_ended),
                     self.dropping.eq(dropping), self.settling.eq(stale)]

        # every beat but a message's last is full: the slots in use end at a slot boundary,
        # and a beat is accepted while one of the four is free (``room``, a flip-flop)
        room = Signal(init=1)
        accepted = Signal()
        m.d.comb += [s.tready.eq(dropping | room), accepted.eq(s.tvalid & room & ~dropping)]
        arrived = Mux(accepted, keep_count_shallow(s.tkeep), 0)
        with m.If(accepted):
            m.d.sync += [ring.word_select(write, W).eq(s.tdata), ended.eq(s.tlast)]
        written = Signal.like(write)
        m.d.comb += written.eq(write + accepted)
        m.d.sync += [write.eq(written), view_phase.eq(Mux(self.take_full, view_phase, read[:nb]))]
        m.d.sync += [view_slot.eq(Mux(self.take_full, view_slot + 1, read[nb:]))
                     for view_slot in view_slots]

        # the three slots from the viewed read position on, shifted down to it: the window
        # there (bytes 0..B-1) and a window further (B..2B-1), each cut to the bytes held
        lanes = []
        for b, slot in enumerate(view_slots):
            # (named wires here and below: a simulator then slices them, not a long Cat)
            ring_lane = Signal(self.SLOTS * B, name=f"ring_lane{b}")
            m.d.comb += ring_lane.eq(ring[b::8])
            slots = Cat(*(ring_lane.word_select((slot + k)[:ns], B)
                          for k in range(self.SLOTS - 1)))
            lanes.append(_shift_down(m, slots, view_phase, 1, 2 * B, f"ring_ahead_lane{b}_"))
        ahead = Signal(2 * W)
        m.d.comb += ahead.eq(Cat(*(lanes[b][j] for j in range(2 * B) for b in range(8))))
        # the bytes held there, as a mask of 2B bytes in flip-flops built beside the view:
        # one gate after the shift, no comparison on the window's path. (``view_count``
        # equals ``count`` whenever a ``take_full`` can come, but the mask built from
        # ``count - B`` instead placed at 80.2 MHz, not 97.9: a shallower mask path lets
        # synthesis map the shift into wider, larger levels.)
        held = Signal(2 * B)
        held_full = kept(m, view_count - B + arrived, "view_count_full")
        held_read = count_kept = kept(m, count + arrived, "count_kept")
        m.d.sync += [view_count.eq(Mux(self.take_full, held_full, held_read)),
                     held.eq(Mux(self.take_full, Cat(*(held_full > j for j in range(2 * B))),
                                 Cat(*(held_read > j for j in range(2 * B)))))]
        ahead = Cat(*(Mux(held[j], ahead.word_select(j, 8), 0) for j in range(2 * B)))
        # both windows in flip-flops, chosen after them by a flip-flop: ``take_full`` reaches
        # one flip-flop, not every bit of the window
        settled = Signal(W)
        further = Signal(W)
        moved_full = Signal()
        m.d.sync += [settled.eq(ahead[:W]), further.eq(ahead[W:]), moved_full.eq(self.take_full)]
        m.d.comb += [window.eq(Mux(moved_full, further, settled)),
                     self.settled_window.eq(settled)]

        # ``ended`` is shown while settling too when nothing is left: a consumer that took a
        # message's last bytes sees its end in the next cycle
        def show(held, name):
            m.d.sync += [avail.eq(kept(m, Mux(stale, 0, Mux(held >= B, B, held)),
                                       f"avail_{name}")),
                         shown_ended.eq(kept(m, ended & Mux(stale, held == 0, held <= B),
                                             f"ended_{name}")),
                         stale.eq(0)]

        # Room after a move, without the arriving beat's byte count: a beat that is not its
        # message's last is full, and a last one ends the room. ``fill``, the bytes from the
        # read slot's start to the last one held, must stay within three slots: a take that
        # crosses into the next slot frees one, a full beat fills one.
        fill = Signal(range((self.SLOTS + 1) * B))
        m.d.comb += fill.eq(read[:nb] + count)
        within_two = kept(m, fill <= 2 * B, "fill_within_two")
        within_three = kept(m, fill <= 3 * B, "fill_within_three")
        crosses = kept(m, (read[:nb] + self.amount)[nb], "take_crosses")
        ended_after = Mux(accepted, s.tlast, ended)

        def room_after(crossed):
            return ~ended_after & Mux(accepted, Mux(crossed, within_three, within_two),
                                      crossed | within_three)

        # each move's next position and count on a kept wire: the late ``take`` and ``flush``
        # choose between them instead of an operand of one shared adder
        read_full = kept(m, read + B, "read_full")
        read_taken = kept(m, read + self.amount, "read_taken")
        count_full = kept(m, count - B + arrived, "count_full")
        count_taken = kept(m, count - self.amount + arrived, "count_taken")
        emptied = kept(m, ended & (count == self.amount), "emptied")
        with m.If(dropping):
            m.d.sync += room.eq(1)
            with m.If(s.tvalid & s.tlast):
                m.d.sync += dropping.eq(0)
        with m.Elif(self.flush):
            # the next message starts at the slot of its first beat
            m.d.sync += [count.eq(0), read.eq(Cat(Const(0, nb), written)), ended.eq(0),
                         dropping.eq(~ended & ~(accepted & s.tlast)), room.eq(1),
                         avail.eq(0), shown_ended.eq(0), stale.eq(1)]
        with m.Elif(self.take_full):
            m.d.sync += [read.eq(read_full), count.eq(count_full), room.eq(room_after(1))]
            show((count - B)[:len(count)], "full")
        with m.Elif(self.take):
            m.d.sync += [read.eq(read_taken), count.eq(count_taken), avail.eq(0),
                         room.eq(room_after(crosses)), shown_ended.eq(emptied), stale.eq(1)]
        with m.Else():
            m.d.sync += [count.eq(count_kept), room.eq(room_after(0))]
            show(count, "kept")
        return m


def byte_unpacker_class(data_width, *, settling=False):
    """The byte unpacker to build at ``data_width``: above 64 bits at a power of two,
    :class:`SettlingByteUnpacker` if ``settling`` (for a consumer that decides from the
    window's bytes) else :class:`WideByteUnpacker` (where it is the smaller in LUT4 cells; in
    LUT6 cells it is about the same); else :class:`ByteUnpacker`."""
    if data_width > 64 and not data_width & (data_width - 1):
        return SettlingByteUnpacker if settling else WideByteUnpacker
    return ByteUnpacker
