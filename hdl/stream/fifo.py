"""Stream FIFOs: synchronous (with packet mode and drop policies) and asynchronous."""

from amaranth.hdl import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.fifo import AsyncFIFOBuffered
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import check_choice, check_int, check_power_of_two
from .signature import check_stream_signature

__all__ = ["StreamFIFO", "AsyncStreamFIFO", "OVERFLOW_POLICIES"]


#: What a :class:`StreamFIFO` does with an input beat when it has no room for it.
OVERFLOW_POLICIES = ("block", "drop_new")

MAX_DEPTH = 1 << 20


class StreamFIFO(wiring.Component):
    """Synchronous AXI4-Stream FIFO with block-RAM storage.

    Storage is a :class:`~amaranth.lib.memory.Memory` with a synchronous read port (block RAM
    on FPGAs), followed by one output register, so ``m_axis`` is first-word-fall-through
    from flip-flops. A beat written into an empty FIFO appears on ``m_axis`` two cycles later.

    Parameters
    ----------
    signature : AXIStreamSignature
        Stream format of both ports.
    depth : int
        Memory entries (beats), a power of two in 2..2**20. One more beat may sit in the
        output register.
    packet : bool
        Store-and-forward: a message becomes visible on ``m_axis`` only once its ``tlast`` beat
        is stored. With ``overflow="block"``, a message longer than ``depth`` would deadlock, so
        when the memory is full of an incomplete message the FIFO commits it and passes the
        rest of that message through (cut-through) instead.
    overflow : str
        ``"block"`` (default): ``s_axis.tready`` falls while the memory is full; nothing is lost.
        ``"drop_new"``: ``s_axis.tready`` is always high; a message that does not fit is
        dropped whole (beats already stored are rolled back, the rest are discarded up to
        ``tlast``); it needs ``packet=True``. (Dropping the *oldest* message instead is
        :class:`MessageFIFO`'s job: a ring cannot drop a message whose first beat it already
        offers on ``m_axis``.)
    counter_width : int
        Width of :attr:`drops`.

    Members
    -------
    s_axis : In(signature)
        Input stream.
    m_axis : Out(signature)
        Output stream: the stored beats in order. Under a drop policy whole messages may be
        missing, never parts of one.
    level : Out(range(depth + 2))
        Beats held, including the output register and beats of an incomplete message.
    drops : Out(counter_width)
        Messages dropped since reset (wraps).
    """

    def __init__(self, signature, depth, *, packet=False, overflow="block", counter_width=32):
        check_stream_signature(signature)
        check_power_of_two("depth", depth, 2, MAX_DEPTH)
        check_choice("overflow", overflow, OVERFLOW_POLICIES)
        check_int("counter_width", counter_width, 1, 64)
        if overflow != "block" and not packet:
            raise ValueError(f"overflow={overflow!r} drops whole messages and needs packet=True")
        self._stream = signature
        self._depth = depth
        self._packet = bool(packet)
        self._overflow = overflow
        super().__init__({
            "s_axis": In(signature),
            "m_axis": Out(signature),
            "level": Out(range(depth + 2)),
            "drops": Out(counter_width),
        })

    depth = property(lambda self: self._depth)
    packet = property(lambda self: self._packet)
    overflow = property(lambda self: self._overflow)

    def elaborate(self, platform):
        m = Module()
        sig = self._stream
        depth = self._depth
        aw = depth.bit_length() - 1
        s, o = self.s_axis, self.m_axis

        m.submodules.storage = storage = Memory(shape=sig.payload_width, depth=depth, init=[])
        w_port = storage.write_port()
        r_port = storage.read_port(domain="sync", transparent_for=())

        # Pointers carry one wrap bit, so full and empty differ without a level counter.
        wp = Signal(aw + 1)  # next beat written
        rp = Signal(aw + 1)  # next beat read into the output register
        if self._packet:
            cp = Signal(aw + 1)  # end of the committed (readable) beats
        else:
            cp = wp
        used = Signal(aw + 1)
        avail = Signal(aw + 1)
        full = Signal()
        m.d.comb += [
            used.eq(wp - rp),
            avail.eq(cp - rp),
            full.eq(used == depth),
            self.level.eq(used + o.tvalid),
        ]

        # Read side: fetch into the output register whenever it is empty or being emptied.
        rd_en = Signal()
        m.d.comb += [
            rd_en.eq((~o.tvalid | o.tready) & (avail != 0)),
            r_port.addr.eq(rp[:aw]),
            r_port.en.eq(rd_en),
        ]
        m.d.comb += sig.unpack(o, r_port.data)
        with m.If(rd_en):
            m.d.sync += [rp.eq(rp + 1), o.tvalid.eq(1)]
        with m.Elif(o.tready):
            m.d.sync += o.tvalid.eq(0)

        # Write side.
        write = Signal()
        m.d.comb += [
            w_port.addr.eq(wp[:aw]),
            w_port.data.eq(sig.pack(s)),
            w_port.en.eq(write),
        ]
        with m.If(write):
            m.d.sync += wp.eq(wp + 1)

        if self._overflow == "block":
            m.d.comb += [s.tready.eq(~full), write.eq(s.tvalid & ~full)]
            if self._packet:
                cut_through = Signal()
                with m.If(write):
                    with m.If(s.tlast):
                        m.d.sync += [cp.eq(wp + 1), cut_through.eq(0)]
                    with m.Elif(cut_through):
                        m.d.sync += cp.eq(wp + 1)
                with m.Elif(full & (avail == 0)):
                    m.d.sync += [cp.eq(wp), cut_through.eq(1)]
            return m

        m.d.comb += s.tready.eq(1)
        discarding = Signal()
        beat = Signal()
        m.d.comb += beat.eq(s.tvalid & ~discarding)
        with m.If(s.tvalid & discarding & s.tlast):
            m.d.sync += discarding.eq(0)

        def drop_incoming():
            m.d.sync += [wp.eq(cp), discarding.eq(~s.tlast), self.drops.eq(self.drops + 1)]

        def commit():
            with m.If(s.tlast):
                m.d.sync += cp.eq(wp + 1)

        with m.If(beat):
            with m.If(~full):
                m.d.comb += write.eq(1)
                commit()
            with m.Else():
                drop_incoming()
        return m


class AsyncStreamFIFO(wiring.Component):
    """AXI4-Stream FIFO between two clock domains.

    Built on :class:`amaranth.lib.fifo.AsyncFIFOBuffered`: Gray-coded pointers cross the domains
    through two-flip-flop synchronizers; the output is registered. ``s_axis`` belongs to
    ``w_domain`` and ``m_axis`` to ``r_domain``.

    Parameters
    ----------
    signature : AXIStreamSignature
        Stream format of both ports.
    depth : int
        Entries, a power of two in 4..2**20 (one more is held in the output register).
    w_domain, r_domain : str
        Clock domains of the write (``s_axis``) and read (``m_axis``) sides.

    Members
    -------
    s_axis : In(signature)
        Input stream, clocked by ``w_domain``.
    m_axis : Out(signature)
        Output stream, clocked by ``r_domain``; the same beats in the same order.
    """

    def __init__(self, signature, depth, *, w_domain="write", r_domain="read"):
        check_stream_signature(signature)
        check_power_of_two("depth", depth, 4, MAX_DEPTH)
        self._stream = signature
        self._depth = depth
        self._w_domain = w_domain
        self._r_domain = r_domain
        super().__init__({"s_axis": In(signature), "m_axis": Out(signature)})

    def elaborate(self, platform):
        m = Module()
        sig = self._stream
        m.submodules.fifo = fifo = AsyncFIFOBuffered(
            width=sig.payload_width, depth=self._depth + 1,
            w_domain=self._w_domain, r_domain=self._r_domain)
        m.d.comb += [
            fifo.w_data.eq(sig.pack(self.s_axis)),
            fifo.w_en.eq(self.s_axis.tvalid),
            self.s_axis.tready.eq(fifo.w_rdy),
            self.m_axis.tvalid.eq(fifo.r_rdy),
            fifo.r_en.eq(self.m_axis.tready),
        ]
        m.d.comb += sig.unpack(self.m_axis, fifo.r_data)
        return m
