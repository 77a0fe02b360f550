"""Message FIFO with ROS KEEP_LAST history: fixed message slots, the oldest waiting one dropped."""

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import check_int, check_power_of_two
from .signature import check_stream_signature

__all__ = ["MessageFIFO"]


class MessageFIFO(wiring.Component):
    """Keeps the newest ``slots`` messages of a stream (DDS history KEEP_LAST).

    The memory is divided into ``slots`` message slots of ``slot_depth`` beats. A message is
    offered on ``m_axis`` only once its ``tlast`` beat is stored. ``s_axis.tready`` is always
    high: when a new message starts and no slot is free, the oldest complete message that has
    not begun delivery is dropped and its slot reused. The message being delivered on
    ``m_axis`` is never dropped (AXI4-Stream forbids withdrawing an offered beat). A message
    longer than ``slot_depth`` beats is dropped whole. Every drop counts once in :attr:`drops`.

    Parameters
    ----------
    signature : AXIStreamSignature
        Stream format of both ports.
    slots : int
        Message slots, a power of two in 2..64: one may be in delivery, one being written,
        the rest hold complete messages waiting.
    slot_depth : int
        Beats per slot (the longest message kept), a power of two in 1..2**20.
    counter_width : int
        Width of :attr:`drops`.

    Members
    -------
    s_axis : In(signature)
        Input messages.
    m_axis : Out(signature)
        Output messages, whole, in arrival order, some possibly missing (never parts of one).
        Back-to-back messages leave no idle cycle between them.
    waiting : Out(range(slots + 1))
        Complete messages stored and not yet begun.
    drops : Out(counter_width)
        Messages dropped since reset (wraps).
    """

    def __init__(self, signature, slots, slot_depth, *, counter_width=32):
        check_stream_signature(signature)
        check_power_of_two("slots", slots, 2, 64)
        check_power_of_two("slot_depth", slot_depth, 1, 1 << 20)
        check_int("counter_width", counter_width, 1, 64)
        self._stream = signature
        self._slots = slots
        self._slot_depth = slot_depth
        super().__init__({
            "s_axis": In(signature),
            "m_axis": Out(signature),
            "waiting": Out(range(slots + 1)),
            "drops": Out(counter_width),
        })

    def elaborate(self, platform):
        m = Module()
        sig = self._stream
        k, depth = self._slots, self._slot_depth
        kw = k.bit_length() - 1
        s, o = self.s_axis, self.m_axis

        m.submodules.storage = storage = Memory(shape=sig.payload_width, depth=k * depth,
                                                init=[])
        w_port = storage.write_port()
        r_port = storage.read_port(domain="sync", transparent_for=())
        m.submodules.lengths = lengths = Memory(shape=range(depth + 1), depth=k, init=[])
        len_w = lengths.write_port()
        len_r = lengths.read_port(domain="comb")
        m.submodules.order = order = Memory(shape=range(k), depth=k, init=[])
        ord_w = order.write_port()
        ord_r = order.read_port(domain="comb")

        # Queue of complete messages (slot numbers), oldest at the head.
        q_head = Signal(kw + 1)
        q_tail = Signal(kw + 1)
        m.d.comb += [
            self.waiting.eq(q_tail - q_head),
            ord_r.addr.eq(q_head[:kw]),
            ord_w.addr.eq(q_tail[:kw]),
        ]
        oldest = ord_r.data
        free = Signal(k, init=(1 << k) - 1)
        take = Signal(k)     # slots the writer claims this cycle
        release_w = Signal(k)  # slot given up by the writer (message too long)
        release_r = Signal(k)  # slot whose last beat the reader fetched
        m.d.sync += free.eq((free | release_w | release_r) & ~take)
        pop = Signal()
        with m.If(pop):
            m.d.sync += q_head.eq(q_head + 1)
        with m.If(ord_w.en):
            m.d.sync += q_tail.eq(q_tail + 1)

        # Writer.
        w_active = Signal()
        w_slot = Signal(range(k))
        w_off = Signal(range(depth + 1))
        discarding = Signal()
        # A slot whose last beat the reader fetches this cycle may be rewritten at once: the
        # read port is not transparent, so that fetch still returns the old beat.
        # Only a message already in delivery is bypassed (it depends on registers alone).
        free_now = Signal(k)
        release_bypass = Signal(k)
        m.d.comb += free_now.eq(free | release_bypass)
        lowest_free = Signal(range(k))
        for i in reversed(range(k)):
            with m.If(free_now[i]):
                m.d.comb += lowest_free.eq(i)
        slot = Signal(range(k))
        offset = Signal(range(depth + 1))
        m.d.comb += [
            s.tready.eq(1),
            w_port.addr.eq(Cat(offset[:max(depth.bit_length() - 1, 0)], slot)
                           if depth > 1 else slot),
            w_port.data.eq(sig.pack(s)),
            len_w.addr.eq(slot),
            len_w.data.eq(offset + 1),
            ord_w.data.eq(slot),
        ]
        drop_pop = Signal()

        def store(at_slot, at_offset):
            m.d.comb += [slot.eq(at_slot), offset.eq(at_offset), w_port.en.eq(1)]
            with m.If(s.tlast):
                m.d.comb += [len_w.en.eq(1), ord_w.en.eq(1)]
                m.d.sync += w_active.eq(0)
            with m.Else():
                m.d.sync += [w_active.eq(1), w_slot.eq(at_slot), w_off.eq(at_offset + 1)]

        with m.If(s.tvalid):
            with m.If(discarding):
                m.d.sync += discarding.eq(~s.tlast)
            with m.Elif(~w_active):
                with m.If(free_now.any()):
                    m.d.comb += take.eq(1 << lowest_free)
                    store(lowest_free, 0)
                with m.Else():
                    # Room for the newest: give up the oldest waiting message.
                    m.d.comb += [drop_pop.eq(1), pop.eq(1)]
                    m.d.sync += self.drops.eq(self.drops + 1)
                    store(oldest, 0)
            with m.Elif(w_off == depth):
                m.d.comb += release_w.eq(1 << w_slot)
                m.d.sync += [w_active.eq(0), discarding.eq(~s.tlast),
                             self.drops.eq(self.drops + 1)]
            with m.Else():
                store(w_slot, w_off)

        # Reader: fetch the slot in delivery into the output register. A message starts (and
        # its first beat is fetched) in the cycle it is popped, or, back to back, in the cycle
        # after the previous message's last fetch.
        r_active = Signal()
        r_slot = Signal(range(k))
        r_off = Signal(range(depth + 1))
        r_len = Signal(range(depth + 1))
        start_now = Signal()
        cur_slot = Signal(range(k))
        cur_off = Signal(range(depth + 1))
        cur_len = Signal(range(depth + 1))
        rd_en = Signal()
        fetch_last = Signal()
        m.d.comb += [
            len_r.addr.eq(oldest),
            start_now.eq(~r_active & (self.waiting != 0) & ~drop_pop),
            cur_slot.eq(Mux(start_now, oldest, r_slot)),
            cur_off.eq(Mux(start_now, 0, r_off)),
            cur_len.eq(Mux(start_now, len_r.data, r_len)),
            rd_en.eq((r_active | start_now) & (~o.tvalid | o.tready)),
            fetch_last.eq(rd_en & (cur_off + 1 == cur_len)),
            r_port.addr.eq(Cat(cur_off[:max(depth.bit_length() - 1, 0)], cur_slot)
                           if depth > 1 else cur_slot),
            r_port.en.eq(rd_en),
        ]
        m.d.comb += sig.unpack(o, r_port.data)
        with m.If(r_active & (~o.tvalid | o.tready) & (r_off + 1 == r_len)):
            m.d.comb += release_bypass.eq(1 << r_slot)
        with m.If(rd_en):
            m.d.sync += o.tvalid.eq(1)
            m.d.comb += release_r.eq(Mux(fetch_last, 1 << cur_slot, 0))
        with m.Elif(o.tready):
            m.d.sync += o.tvalid.eq(0)
        with m.If(start_now):
            m.d.comb += pop.eq(1)
            m.d.sync += [r_slot.eq(oldest), r_len.eq(len_r.data), r_off.eq(rd_en),
                         r_active.eq(~fetch_last)]
        with m.Elif(r_active & fetch_last & (self.waiting != 0) & ~drop_pop):
            m.d.comb += pop.eq(1)
            m.d.sync += [r_slot.eq(oldest), r_len.eq(len_r.data), r_off.eq(0)]
        with m.Elif(rd_en):
            m.d.sync += [r_off.eq(r_off + 1), r_active.eq(~fetch_last)]
        return m
