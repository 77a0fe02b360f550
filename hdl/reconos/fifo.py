"""ReconOS FIFO interfaces and the OSIF/MEMIF FIFO (docs/reconos.md)."""

from amaranth.hdl import DomainRenamer, Elaboratable, Module, ResetInserter, Signal
from amaranth.lib import wiring
from amaranth.lib.fifo import AsyncFIFO
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import check_int, check_power_of_two

__all__ = ["FifoWriteSignature", "FifoReadSignature", "ReconosFifo", "OSIF_FIFO_DEPTH",
           "MEMIF_FIFO_DEPTH"]

#: ReconROS block-design depths: ``C_FIFO_ADDR_WIDTH`` 3 (OSIF) and 7 (MEMIF).
OSIF_FIFO_DEPTH = 8
MEMIF_FIFO_DEPTH = 128


class FifoWriteSignature(wiring.Signature):
    """The write side of a ReconOS FIFO (bus definition ``FIFO_M``/``FIFO64_M``), seen from
    the writer.

    Members
    -------
    data : Out(width)
        The word to push.
    we : Out(1)
        Push ``data`` in a cycle where ``full`` is low. A writer may hold ``we`` high across
        consecutive words; each is taken in a cycle with ``full`` low (valid/ready with
        valid = ``we``, ready = ``~full``).
    full : In(1)
        The FIFO cannot take a word in this cycle.
    """

    def __init__(self, width):
        check_int("width", width, 1, 1024)
        self.width = width
        super().__init__({"data": Out(width), "we": Out(1), "full": In(1)})

    def __eq__(self, other):
        return type(other) is type(self) and other.width == self.width

    def __hash__(self):
        return hash((type(self), self.width))


class FifoReadSignature(wiring.Signature):
    """The read side of a ReconOS FIFO (``FIFO_S``/``FIFO64_S``), seen from the reader.

    Members
    -------
    data : In(width)
        The head word, valid while ``empty`` is low (first-word fall-through).
    empty : In(1)
        No word is available.
    re : Out(1)
        Pop the head word in a cycle where ``empty`` is low (valid = ``~empty``, ready =
        ``re``). ``re`` may depend combinationally on ``empty`` and ``data``.
    """

    def __init__(self, width):
        check_int("width", width, 1, 1024)
        self.width = width
        super().__init__({"data": In(width), "empty": In(1), "re": Out(1)})

    def __eq__(self, other):
        return type(other) is type(self) and other.width == self.width

    def __hash__(self):
        return hash((type(self), self.width))


class _SyncFifoCore(Elaboratable):
    """The synchronous ReconOS FIFO: distributed RAM read combinationally, with the ports of
    :class:`amaranth.lib.fifo.SyncFIFO` but ``w_rdy`` and ``r_rdy`` held in flip-flops.

    ``SyncFIFO`` derives both from its level by comparison, so a writer's decision and the
    RAM's write enables wait for that comparator; here they are computed a cycle ahead from
    the level and the cycle's push and pop.
    """

    def __init__(self, width, depth):
        self.width, self.depth = width, depth
        self.w_data = Signal(width)
        self.w_en = Signal()
        self.w_rdy = Signal(init=1)
        self.r_data = Signal(width)
        self.r_en = Signal()
        self.r_rdy = Signal()
        self.level = self.r_level = self.w_level = Signal(range(depth + 1))

    def elaborate(self, platform):
        m = Module()
        m.submodules.storage = storage = Memory(shape=self.width, depth=self.depth, init=[])
        w_port = storage.write_port()
        r_port = storage.read_port(domain="comb")
        w_ptr = Signal(range(self.depth))
        r_ptr = Signal(range(self.depth))
        push = Signal()
        pop = Signal()
        m.d.comb += [
            push.eq(self.w_en & self.w_rdy),
            pop.eq(self.r_en & self.r_rdy),
            w_port.addr.eq(w_ptr), w_port.data.eq(self.w_data), w_port.en.eq(push),
            r_port.addr.eq(r_ptr), self.r_data.eq(r_port.data),
        ]
        with m.If(push):
            m.d.sync += w_ptr.eq(w_ptr + 1)
        with m.If(pop):
            m.d.sync += r_ptr.eq(r_ptr + 1)
        with m.If(push & ~pop):
            m.d.sync += [self.level.eq(self.level + 1), self.r_rdy.eq(1),
                         self.w_rdy.eq(self.level != self.depth - 1)]
        with m.Elif(pop & ~push):
            m.d.sync += [self.level.eq(self.level - 1), self.w_rdy.eq(1),
                         self.r_rdy.eq(self.level != 1)]
        return m


class ReconosFifo(wiring.Component):
    """A first-word-fall-through FIFO with ReconOS ports (``reconos_fifo(64)_sync/_async``).

    Storage is distributed RAM read combinationally, as in ReconOS: a word pushed in cycle t
    is at the read side in cycle t+1 (synchronous version). In the synchronous version
    ``full`` and ``empty`` come straight from flip-flops.

    Parameters
    ----------
    width : int
        Word width (32 for r32, 64 for r64).
    depth : int
        Entries, a power of two in 2..4096.
    w_domain, r_domain : str
        Clock domains of the write and read side. Different names give the clock-crossing
        version (Gray-coded pointers, :class:`amaranth.lib.fifo.AsyncFIFO`).

    Members
    -------
    w : In(FifoWriteSignature(width))
        Write side.
    r : In(FifoReadSignature(width))
        Read side.
    rst : In(1)
        Synchronous reset of the FIFO contents, in ``w_domain`` (the slot's ``HWT_Rst`` for
        the slot's FIFOs). With two domains the read side follows after synchronisation.
    has_data : Out(1)
        ``~r.empty`` (``FIFO_Has_Data``, the OSIF interrupt input), in ``r_domain``.
    r_fill : Out(range(depth + 1))
        Words available to the reader (``Fill``), in ``r_domain``.
    w_free : Out(range(depth + 1))
        Words the writer may still push (``Remm``), in ``w_domain``.
    """

    def __init__(self, width, depth, *, w_domain="sync", r_domain="sync"):
        check_int("width", width, 1, 1024)
        check_power_of_two("depth", depth, 2, 4096)
        self._width = width
        self._depth = depth
        self._w_domain = w_domain
        self._r_domain = r_domain
        super().__init__({
            "w": In(FifoWriteSignature(width)),
            "r": In(FifoReadSignature(width)),
            "rst": In(1),
            "has_data": Out(1),
            "r_fill": Out(range(depth + 1)),
            "w_free": Out(range(depth + 1)),
        })

    depth = property(lambda self: self._depth)

    def elaborate(self, platform):
        m = Module()
        if self._w_domain == self._r_domain:
            fifo = ResetInserter({"sync": self.rst})(_SyncFifoCore(self._width, self._depth))
            if self._w_domain != "sync":
                fifo = DomainRenamer(self._w_domain)(fifo)
        else:
            fifo = AsyncFIFO(width=self._width, depth=self._depth,
                             r_domain=self._r_domain, w_domain=self._w_domain)
            fifo = ResetInserter({self._w_domain: self.rst})(fifo)
        m.submodules.fifo = fifo
        m.d.comb += [
            fifo.w_data.eq(self.w.data),
            fifo.w_en.eq(self.w.we),
            self.w.full.eq(~fifo.w_rdy),
            self.r.data.eq(fifo.r_data),
            self.r.empty.eq(~fifo.r_rdy),
            fifo.r_en.eq(self.r.re),
            self.has_data.eq(fifo.r_rdy),
            self.r_fill.eq(fifo.r_level),
            self.w_free.eq(self._depth - fifo.w_level),
        ]
        return m
