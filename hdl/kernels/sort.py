"""Sorting a block of unsigned integers (the ReconROS sort node, docs/reconos.md)."""

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import check_int, check_power_of_two
from ..stream import AXIStreamSignature

__all__ = ["MergeSorter"]


class MergeSorter(wiring.Component):
    """Sorts blocks of up to ``block_size`` unsigned integers into ascending order.

    A block streams in, is merged in ``log2(block_size)`` passes between the two halves of a
    block RAM (one element per cycle; the heads of the next pair of runs are read during the
    last cycle of a pair, so there is no gap) and the last pass streams out. The comparison
    of the two heads never feeds a memory address (each run's port reads the element after
    its head), which keeps the loop short enough for 100 MHz. ``(log2(block_size) + 1) *
    block_size + 3`` cycles per block from its first beat in to its last beat out when
    neither side stalls; 2048 elements: 24,579 cycles.

    Parameters
    ----------
    block_size : int
        Power of two in 2..4096: the largest block.
    width : int
        Element width in bits, a multiple of 8 in 8..64. Default 32.

    Members
    -------
    i : In(AXIStreamSignature(width, keep=False))
        The unsorted block, one element per beat, ``tlast`` on the last.
    o : Out(AXIStreamSignature(width, keep=False))
        The sorted block: ``length`` elements, ascending, ``tlast`` on the last.
    length : In(range(block_size + 1))
        Elements per block, sampled at the first beat of a block; 0 means ``block_size``.
    err_short : Out(1)
        One-cycle pulse (registered): a block ended (``tlast``) before ``length`` elements. The
        block is
        padded with all-ones elements to ``length`` (so they sort to the end).
    err_long : Out(1)
        One-cycle pulse: a block had more than ``length`` elements. The extra beats are
        dropped up to ``tlast``.
    progress : Out(range(log2(block_size) + 1))
        Merge passes finished on the current block (0 while loading, all when streaming out).
    busy : Out(1)
        A block has been accepted and is not yet fully streamed out.
    """

    def __init__(self, block_size, *, width=32):
        self._block_size = check_power_of_two("block_size", block_size, 2, 4096)
        self._width = check_int("width", width, 8, 64, multiple_of=8)
        self._passes = block_size.bit_length() - 1
        sig = AXIStreamSignature(width, keep=False)
        super().__init__({
            "i": In(sig),
            "o": Out(sig),
            "length": In(range(block_size + 1)),
            "err_short": Out(1),
            "err_long": Out(1),
            "progress": Out(range(self._passes + 1)),
            "busy": Out(1),
        })

    block_size = property(lambda self: self._block_size)
    width = property(lambda self: self._width)
    passes = property(lambda self: self._passes)

    def elaborate(self, platform):
        m = Module()
        n, w, passes = self._block_size, self._width, self._passes
        ab = passes                      # address bits
        # the two buffers A and B are the halves of one memory (address bit ab): the pass
        # chooses its half in the read address, not in a multiplexer after the data
        m.submodules.mem = mem = Memory(shape=w, depth=2 * n, init=[])
        wr = mem.write_port()
        rx, ry = mem.read_port(), mem.read_port()

        length = Signal(range(n + 1))
        count = Signal(range(n + 1))        # elements stored
        run = Signal(range(n + 1))          # run width of this pass
        i, j, k = (Signal(range(2 * n + 1), name=nm) for nm in ("i", "j", "k"))
        # the current pair's bounds, kept in registers so that no adder lies between the
        # counters and the read addresses: x_end = base + run, y_end = base + 2 run (also
        # the next pair's base), y_last = y_end - 1, next_j = y_end + run (the next pair's
        # second run), last_pair = (y_end == n). Each is updated from registers at a pair
        # boundary, with one adder
        x_end, y_end, y_last, next_j = (Signal(range(2 * n + 1), name=nm)
                                        for nm in ("x_end", "y_end", "y_last", "next_j"))
        last_pair = Signal()
        p = Signal(range(passes + 1))
        src = Signal()                      # memory read in this pass: 0 = A, 1 = B
        ovalid, olast = Signal(), Signal()
        m.d.comb += [self.progress.eq(p), src.eq(p[0])]

        def write(sel, addr, value):
            m.d.comb += [wr.en.eq(1), wr.addr.eq(Cat(addr[:ab], sel)), wr.data.eq(value)]

        # heads of the two runs being merged (see MERGE)
        held_x, held_y = Signal(w), Signal(w)
        fresh_x, fresh_y = Signal(), Signal()

        m.d.sync += [self.err_short.eq(0), self.err_long.eq(0)]
        with m.FSM():
            with m.State("LOAD"):
                m.d.comb += self.i.tready.eq(1)
                with m.If(self.i.tvalid):
                    lim = Signal(range(n + 1))
                    m.d.comb += lim.eq(Mux(count == 0, Mux(self.length == 0, n, self.length),
                                           length))
                    with m.If(count == 0):
                        m.d.sync += length.eq(lim)
                    with m.If(count < lim):
                        write(0, count, self.i.tdata)
                        m.d.sync += count.eq(count + 1)
                    with m.If(self.i.tlast):
                        m.d.sync += [self.err_short.eq(count + 1 < lim),
                                     self.err_long.eq(count >= lim)]
                        m.d.sync += p.eq(0)
                        m.next = "PAD"
                with m.If(count != 0):
                    m.d.comb += self.busy.eq(1)
            with m.State("PAD"):
                m.d.comb += self.busy.eq(1)
                with m.If(count == n):
                    m.next = "PRIME"
                with m.Else():
                    write(0, count, (1 << w) - 1)
                    m.d.sync += count.eq(count + 1)
            with m.State("PRIME"):
                m.d.comb += self.busy.eq(1)
                m.d.comb += [rx.addr.eq(0), ry.addr.eq(1)]
                m.d.sync += [i.eq(0), j.eq(1), k.eq(0), run.eq(1),
                             x_end.eq(1), y_end.eq(2), y_last.eq(1), next_j.eq(3),
                             last_pair.eq(n == 2), fresh_x.eq(1), fresh_y.eq(1)]
                m.next = "MERGE"
            with m.State("MERGE"):
                # one element per cycle. Each run's memory port always reads the element after
                # its head, so the comparison never feeds a read address: a head is the port's
                # data right after it was taken (fresh) and a register otherwise. The heads of
                # the next pair (or pass) are read in the last cycle of a pair, so pairs and
                # passes follow without a gap; the last pass streams out instead of writing
                m.d.comb += self.busy.eq(1)
                final = p == passes - 1
                with m.If(final):
                    m.d.comb += self.progress.eq(passes)
                hx, hy = Signal(w), Signal(w)
                m.d.comb += [hx.eq(Mux(fresh_x, rx.data, held_x)),
                             hy.eq(Mux(fresh_y, ry.data, held_y))]
                x_ok = i != x_end
                y_ok = j != y_end
                take_x = Signal()
                m.d.comb += take_x.eq(x_ok & (~y_ok | (hx <= hy)))
                value = Mux(take_x, hx, hy)
                step = Signal()
                m.d.comb += step.eq(~final | ~ovalid | self.o.tready)
                rd_i, rd_j = Signal.like(i), Signal.like(j)
                rd_half = Signal()
                m.d.comb += [rd_i.eq(i + 1), rd_j.eq(j + 1), rd_half.eq(src)]
                m.d.sync += [held_x.eq(hx), held_y.eq(hy), fresh_x.eq(0), fresh_y.eq(0)]
                with m.If(step):
                    with m.If(final):
                        m.d.sync += [ovalid.eq(1), olast.eq(k == length - 1),
                                     self.o.tdata.eq(value)]
                        with m.If(k == length - 1):
                            m.next = "DRAIN"
                    with m.Else():
                        write(~src, k, value)
                    # the increments run beside the comparison, which only selects
                    with m.If(take_x):
                        m.d.sync += i.eq(i + 1)
                    with m.Else():
                        m.d.sync += j.eq(j + 1)
                    m.d.sync += [k.eq(k + 1), fresh_x.eq(take_x), fresh_y.eq(~take_x)]
                    with m.If(k == y_last):
                        m.d.sync += [fresh_x.eq(1), fresh_y.eq(1)]
                        with m.If(last_pair):
                            r2 = run << 1
                            m.d.comb += [rd_i.eq(0), rd_j.eq(r2), rd_half.eq(~src)]
                            m.d.sync += [p.eq(p + 1), run.eq(r2), i.eq(0), j.eq(r2), k.eq(0),
                                         x_end.eq(r2), y_end.eq(r2 << 1),
                                         y_last.eq((r2 << 1) - 1),
                                         next_j.eq((r2 << 1) + r2),
                                         last_pair.eq((r2 << 1) == n)]
                        with m.Else():
                            m.d.comb += [rd_i.eq(y_end), rd_j.eq(next_j)]
                            m.d.sync += [i.eq(y_end), j.eq(next_j),
                                         x_end.eq(next_j), y_end.eq(y_end + 2 * run),
                                         y_last.eq(y_last + 2 * run),
                                         next_j.eq(next_j + 2 * run),
                                         last_pair.eq(y_end + 2 * run == n)]
                m.d.comb += [rx.addr.eq(Cat(rd_i[:ab], rd_half)),
                             ry.addr.eq(Cat(rd_j[:ab], rd_half))]
            with m.State("DRAIN"):
                m.d.comb += [self.busy.eq(1), self.progress.eq(passes)]
                with m.If(self.o.tready):
                    m.d.sync += ovalid.eq(0)
                    m.d.sync += [count.eq(0), p.eq(0)]
                    m.next = "LOAD"
        m.d.comb += [self.o.tvalid.eq(ovalid), self.o.tlast.eq(olast)]
        # read ports not driven above keep reading (en defaults to 1)
        return m
