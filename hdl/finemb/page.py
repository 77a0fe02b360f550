"""The page buffer between a FinEmbP node's communication side and its application, with
page flipping (docs/finemb.md)."""

from amaranth.hdl import Array, Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from hdl.net.checksum import ones_complement_add

from ..params import check_int
from .descriptor import MAX_PAGE_BYTES

__all__ = ["PageAppSignature", "PageBuffer"]


class PageAppSignature(wiring.Signature):
    """The application's side of a :class:`PageBuffer` (``Out`` = from the buffer).

    Members
    -------
    out_pending : Out(1)
        A complete output page arrived that has not been claimed yet (``NEW_OUT``).
    out_claim : In(1)
        Pulse: take the newest complete output page (master -> node) for reading ...
    out_claimed : Out(1)
        ... a page is held (after the claim; none before the first page arrived) ...
    out_new : Out(1)
        ... and it had not been claimed before (``NEW_OUT``).
    out_raddr : In(range(page_out_bytes))
    out_rdata : Out(8)
        Byte ``out_raddr`` of the held page, one cycle later.
    out_release : In(1)
        Pulse: done with the held page.
    in_we, in_waddr, in_wdata : In
        Write a byte of the next input page (node -> master); taken only while ``in_ready``.
    in_commit : In(1)
        Pulse (while ``in_ready``): the input page is complete; it becomes the page the next
        ISEND_RES carries.
    in_ready : Out(1)
        Writes and a commit are taken: the back page is not being sent, and the last commit
        has been summed.
    overrun : Out(1)
        Sticky: an output page arrived while the application held the only page it could go
        to, and was dropped.
    clear_overrun : In(1)
        Pulse: clear ``overrun``.
    """

    def __init__(self, page_out_bytes, page_in_bytes):
        self._sizes = (page_out_bytes, page_in_bytes)
        super().__init__({
            "out_pending": Out(1),
            "out_claim": In(1), "out_claimed": Out(1), "out_new": Out(1),
            "out_raddr": In(range(max(page_out_bytes, 2))), "out_rdata": Out(8),
            "out_release": In(1),
            "in_we": In(1), "in_waddr": In(range(max(page_in_bytes, 2))), "in_wdata": In(8),
            "in_commit": In(1), "in_ready": Out(1),
            "overrun": Out(1), "clear_overrun": In(1),
        })

    def __eq__(self, other):
        return type(other) is type(self) and other._sizes == self._sizes

    def __hash__(self):
        return hash((type(self), self._sizes))


class PageBuffer(wiring.Component):
    """Two output pages (master -> node) and two input pages (node -> master) in block RAM,
    flipped so that neither side ever sees a page that mixes two frames.

    Output direction. The communication side writes a received ISEND page into the page that
    is not the newest (``W = not FRONT``); only after the frame's last byte and a good UDP
    checksum does ``out_commit`` make it the newest (``FRONT = W``, one cycle). The
    application claims the newest page (``BUSY = FRONT``, one cycle) and reads it until it
    releases it. A frame that would have to be written into the page the application holds
    (the application kept a page for longer than a cycle) is refused at ``out_begin``: the
    frame is dropped and ``overrun`` set.

    Input direction, mirrored. The application writes the back page and commits; the buffer
    then sums the page (one byte per cycle, the UDP checksum's share) and makes it the newest.
    The communication side claims the newest page, with its sum, for an ISEND_RES and releases
    it once sent; the application waits (``in_ready`` low) rather than write the page being
    sent.

    Parameters
    ----------
    page_out_bytes, page_in_bytes : int
        Page sizes, 1..1024 bytes.
    lanes : int
        Bytes a communication-side write or read moves (the parser's and the builder's
        beat), 1 or 2; the application's side moves one. With 2 lanes each page is two
        byte banks.

    Members
    -------
    out_begin : In(1)
        Pulse: a new output page starts arriving ...
    out_accept : Out(1)
        ... and may be written (valid in the cycle of ``out_begin``; when low the frame is
        dropped and ``overrun`` is set).
    out_we, out_waddr, out_wdata : In(lanes), In, In(8 * lanes)
        Bytes ``out_waddr`` .. ``out_waddr + lanes - 1`` of the arriving page (``out_waddr`` a
        multiple of ``lanes``, bit ``k`` of ``out_we`` for byte ``k``; the first may come with
        ``out_begin``).
    out_commit : In(1)
        Pulse: the arriving page is complete and its frame good.
    in_claim : In(1)
        Pulse: hold the newest input page for sending ...
    in_held : Out(1)
        ... a page is held (zeros are sent before the application committed any) ...
    in_sum : Out(16)
        ... its bytes' one's complement sum (big-endian 16-bit words from byte 0).
    in_raddr : In(range(page_in_bytes))
    in_rdata : Out(8 * lanes)
        Bytes ``in_raddr`` .. ``in_raddr + lanes - 1`` of the held input page (``in_raddr`` a
        multiple of ``lanes``), one cycle later.
    in_release : In(1)
        Pulse: the held input page has been sent.
    app : Out(PageAppSignature(page_out_bytes, page_in_bytes))
        The application's side.
    """

    def __init__(self, page_out_bytes, page_in_bytes, *, lanes=1):
        self._out = check_int("page_out_bytes", page_out_bytes, 1, MAX_PAGE_BYTES)
        self._in = check_int("page_in_bytes", page_in_bytes, 1, MAX_PAGE_BYTES)
        self._lanes = L = check_int("lanes", lanes, 1, 2)
        super().__init__({
            "out_begin": In(1), "out_accept": Out(1),
            "out_we": In(L), "out_waddr": In(range(max(page_out_bytes, 2))),
            "out_wdata": In(8 * L), "out_commit": In(1),
            "in_claim": In(1), "in_held": Out(1), "in_sum": Out(16),
            "in_raddr": In(range(max(page_in_bytes, 2))), "in_rdata": Out(8 * L),
            "in_release": In(1),
            "app": Out(PageAppSignature(page_out_bytes, page_in_bytes)),
        })

    page_out_bytes = property(lambda self: self._out)
    page_in_bytes = property(lambda self: self._in)

    def elaborate(self, platform):
        m = Module()
        app = self.app
        po, pi = self._out, self._in
        L = self._lanes
        q = L.bit_length() - 1            # address bits of the byte within a beat
        sh_o, sh_i = max(po - 1, 1).bit_length(), max(pi - 1, 1).bit_length()

        def banks(name, sh):
            """A page pair as ``L`` byte banks: byte ``a`` of page ``p`` in bank ``a % L`` at
            ``(p, a // L)``."""
            out = []
            for b in range(L):
                m.submodules[f"{name}{b}"] = mem = Memory(shape=8, depth=(2 << sh) // L,
                                                          init=[])
                out.append(mem)
            return out

        def bank_address(addr, page, sh):
            return Cat(addr[q:sh], page)

        # ---- output pages: the comm side writes, the application reads
        out_mems = banks("out_mem", sh_o)
        front = Signal()          # the newest complete page ...
        front_valid = Signal()    # ... once one has arrived
        busy = Signal()           # the page the application holds ...
        busy_valid = Signal()     # ... if any
        target = Signal()         # the page being written
        writing = Signal()
        new = Signal()
        overrun = Signal()
        next_target = ~front
        blocked = busy_valid & (busy == next_target)
        m.d.comb += self.out_accept.eq(~blocked)
        with m.If(self.out_begin):
            m.d.sync += [target.eq(next_target), writing.eq(~blocked)]
            with m.If(blocked):
                m.d.sync += overrun.eq(1)
        # the first bytes may come with out_begin
        may_write = Mux(self.out_begin, ~blocked, writing)
        app_lane = Signal(range(L)) if L > 1 else Const(0)
        if L > 1:
            m.d.sync += app_lane.eq(app.out_raddr[:q])
        reads = []
        for b, mem in enumerate(out_mems):
            ow, orp = mem.write_port(), mem.read_port()
            m.d.comb += [ow.en.eq(self.out_we[b] & may_write),
                         ow.addr.eq(bank_address(self.out_waddr, Mux(self.out_begin, next_target,
                                                                     target), sh_o)),
                         ow.data.eq(self.out_wdata.word_select(b, 8)),
                         orp.addr.eq(bank_address(app.out_raddr, busy, sh_o))]
            reads.append(orp.data)
        with m.If(self.out_commit & writing):
            m.d.sync += [front.eq(target), front_valid.eq(1), writing.eq(0), new.eq(1)]
        with m.If(app.out_claim):
            m.d.sync += [busy.eq(front), busy_valid.eq(front_valid), app.out_new.eq(new),
                         new.eq(0)]
            with m.If(self.out_commit & writing):      # the commit of this cycle wins
                m.d.sync += [busy.eq(target), busy_valid.eq(1), app.out_new.eq(1)]
        with m.Elif(app.out_release):
            m.d.sync += busy_valid.eq(0)
        with m.If(app.clear_overrun):
            m.d.sync += overrun.eq(0)
        m.d.comb += [app.out_claimed.eq(busy_valid), app.overrun.eq(overrun),
                     app.out_pending.eq(new),
                     app.out_rdata.eq(Mux(busy_valid, Array(reads)[app_lane], 0))]

        # ---- input pages: the application writes, the comm side reads (and a summing pass)
        in_mems = banks("in_mem", sh_i)
        in_front = Signal()
        in_front_valid = Signal()
        sums = [Signal(16, name=f"in_sum{k}") for k in range(2)]
        held = Signal()
        held_valid = Signal()
        back = ~in_front
        summing = Signal()
        sum_idx = Signal(range(pi + 2))
        acc = Signal(16)
        m.d.comb += app.in_ready.eq(~summing & ~(held_valid & (held == back)))
        # the summing pass: one byte per cycle, read one cycle ahead
        sum_byte = Signal(range(pi + 2))
        m.d.sync += sum_byte.eq(sum_idx)
        sum_data, comm_data = [], []
        for b, mem in enumerate(in_mems):
            iw, irp, isp = mem.write_port(), mem.read_port(), mem.read_port()
            lane_hit = (app.in_waddr[:q] == b) if L > 1 else 1
            m.d.comb += [iw.en.eq(app.in_we & app.in_ready & lane_hit),
                         iw.addr.eq(bank_address(app.in_waddr, back, sh_i)),
                         iw.data.eq(app.in_wdata),
                         isp.addr.eq(bank_address(sum_idx, back, sh_i)),
                         irp.addr.eq(bank_address(self.in_raddr, held, sh_i))]
            sum_data.append(isp.data)
            comm_data.append(irp.data)
        sum_lane = sum_byte[:q] if L > 1 else Const(0)
        sum_value = Array(sum_data)[sum_lane]
        with m.If(app.in_commit & app.in_ready):
            m.d.sync += [summing.eq(1), sum_idx.eq(0), acc.eq(0)]
        with m.If(summing):
            m.d.sync += sum_idx.eq(sum_idx + 1)
            with m.If((sum_byte < pi) & (sum_idx != 0)):
                word = Mux(sum_byte[0], Cat(sum_value, Const(0, 8)), Cat(Const(0, 8), sum_value))
                m.d.sync += acc.eq(ones_complement_add(acc, word))
            with m.If(sum_byte == pi):
                m.d.sync += [summing.eq(0), in_front.eq(back), in_front_valid.eq(1)]
                for k in range(2):
                    with m.If(back == k):
                        m.d.sync += sums[k].eq(acc)
        with m.If(self.in_claim):
            m.d.sync += [held.eq(in_front), held_valid.eq(in_front_valid)]
        with m.Elif(self.in_release):
            m.d.sync += held_valid.eq(0)
        m.d.comb += [self.in_held.eq(held_valid),
                     self.in_sum.eq(Mux(held_valid, Mux(held, sums[1], sums[0]), 0)),
                     self.in_rdata.eq(Mux(held_valid, Cat(*comm_data), 0))]
        return m
