"""The MEMIF AXI4 memory controller (docs/reconos.md, with defects 6 and 9 fixed)."""

from amaranth.hdl import Array, Cat, Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ..bus import AXI4Signature, AXIBurst, AXIResp
from ..params import check_int
from .memif import rdata_layout, request_layout, request_words, wdata_layout
from .mmu import PAGE_BITS
from .protocol import MEMIF_CHUNK, MemStatus, arch as get_arch

__all__ = ["MemoryController", "ORDER_PAGE_BITS", "READS_IN_FLIGHT"]

#: Read bursts the controller keeps outstanding (AXI allows reads to overlap).
READS_IN_FLIGHT = 4
#: Page-number bits the read/write ordering compares: pages whose numbers agree in these
#: (256 MiB apart) are ordered as if they were one, which is never wrong, only slower
ORDER_PAGE_BITS = 16


class MemoryController(wiring.Component):
    """reconos_memif_memory_controller: one AXI4 INCR burst per MEMIF request.

    ``AxLEN = length/W - 1``, ``AxSIZE = log2 W``, ``AxBURST`` INCR, ``AxCACHE``/``AxPROT``/
    ``AxUSER`` from :class:`~hdl.reconos.protocol.Arch`, ``AxID``/``AxQOS``/``AxLOCK`` 0,
    ``WSTRB`` all ones (zero for ``null`` words).

    Ordering (ReconROS defect 9, docs/reconos.md): requests are taken in order; up to
    :data:`READS_IN_FLIGHT` read bursts overlap each other and one write, whose response the
    controller waits for before it takes the next write. AXI does not order a read and a
    write against each other, so the controller does, per 4 KiB page: a read of the page a
    write is in waits for that write's response (read after write), and a write to the page of
    an outstanding read waits until that read's data is in (write after read); pages are
    compared by the low :data:`ORDER_PAGE_BITS` bits of their numbers. Reads and writes of
    other pages run side by side: a streaming copy moves a read word and a write
    word in the same cycle. ``RREADY`` follows the ready of ``m_rdata``, i.e. the requester's
    FIFO space.

    Bad requests (length 0, not a multiple of W, over 256 B, crossing a 256-B boundary, or
    marked ``bad`` by the MMU) never reach AXI (defect 6: ReconOS hangs): a read returns
    ``ceil(length/W)`` zero words, a write drains its data words; ``error`` pulses
    ``BAD_REQUEST``. A SLVERR/DECERR response pulses the matching :class:`MemStatus` bit; the
    data still flows, so the requester never waits forever.

    Members
    -------
    s_req : In(stream.Signature(request_layout))
        Requests with physical addresses.
    s_wdata : In(stream.Signature(wdata_layout))
    m_rdata : Out(stream.Signature(rdata_layout))
    axi : Out(AXI4Signature(addr_bits, W*8, id_width=1, user_width=2))
    error : Out(len(MemStatus))
        One-cycle :class:`MemStatus` pulses, a cycle after the request or response that
        caused them.
    error_addr : Out(addr_bits)
        Address of the request that caused ``error`` (of a read's, when a read's and another
        request's error fall in the same cycle).
    busy : Out(1)
        A request is being executed or read data is outstanding.
    """

    def __init__(self, arch, num_hwts):
        self._arch = a = get_arch(arch)
        self._n = check_int("num_hwts", num_hwts, 1, 32)
        super().__init__({
            "s_req": In(stream.Signature(request_layout(a, num_hwts))),
            "s_wdata": In(stream.Signature(wdata_layout(a))),
            "m_rdata": Out(stream.Signature(rdata_layout(a, num_hwts))),
            "axi": Out(AXI4Signature(a.addr_bits, a.word_bits, id_width=1, user_width=2)),
            "error": Out(len(MemStatus)),
            "error_addr": Out(a.addr_bits),
            "busy": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        a = self._arch
        wb = a.word_bytes
        lb = a.length_bits
        axi = self.axi
        req = self.s_req.payload

        for ch in ("ar", "aw"):
            m.d.comb += [
                getattr(axi, f"{ch}size").eq(wb.bit_length() - 1),
                getattr(axi, f"{ch}burst").eq(AXIBurst.INCR),
                getattr(axi, f"{ch}cache").eq(a.axcache),
                getattr(axi, f"{ch}prot").eq(a.axprot),
                getattr(axi, f"{ch}user").eq(a.axuser),
            ]

        # the outstanding reads, in request order, in flip-flops: the write-after-read check
        # compares a write's page with every one of them
        track_layout = data.StructLayout({"tag": len(req.tag), "words": lb, "bad": 1,
                                          "addr": a.addr_bits})
        n = READS_IN_FLIGHT
        reads = Array(Signal(track_layout, name=f"read{i}") for i in range(n))
        pending = Signal(n)
        w_ptr, r_ptr = Signal(range(n)), Signal(range(n))
        track_w_rdy, track_r_rdy, track_push, track_pop = Signal(), Signal(), Signal(), Signal()
        push = Signal(track_layout)
        head = reads[r_ptr]
        m.d.comb += [track_w_rdy.eq(~pending.all()), track_r_rdy.eq(pending.any())]
        with m.If(track_push):
            m.d.sync += [reads[w_ptr].eq(push), w_ptr.eq(w_ptr + 1)]
        with m.If(track_pop):
            m.d.sync += r_ptr.eq(r_ptr + 1)
        for i in range(n):
            with m.If(track_push & (w_ptr == i)):
                m.d.sync += pending[i].eq(1)
            with m.Elif(track_pop & (r_ptr == i)):
                m.d.sync += pending[i].eq(0)

        def page(addr):
            return addr[PAGE_BITS:PAGE_BITS + ORDER_PAGE_BITS]

        write_open = Signal()       # a write from its request to its response
        w_addr = Signal(a.addr_bits)
        read_after_write = write_open & (page(w_addr) == page(req.addr))
        write_after_read = Signal()
        m.d.comb += write_after_read.eq(
            Cat(pending[i] & (page(reads[i].addr) == page(req.addr)) for i in range(n)).any())

        length = req.length
        cb = MEMIF_CHUNK.bit_length() - 1       # MEMIF_CHUNK is a power of two
        offset = req.addr[:cb]
        good = Signal()
        # "at most one chunk" as tests of the high bits, and the chunk-boundary test on the
        # chunk-wide bits only (a word-wide addition and comparison are carry chains in front
        # of the AXI address registers)
        within = (length[cb + 1:] == 0) & (~length[cb] | (length[:cb] == 0))
        m.d.comb += good.eq(~req.bad & (length != 0) & (length[:wb.bit_length() - 1] == 0) &
                            within & (offset + length[:cb + 1] <= MEMIF_CHUNK))
        words = Signal(lb)
        m.d.comb += words.eq(request_words(a, length))

        # ---- request side ----
        remaining = Signal(lb)
        with m.If(axi.arready):
            m.d.sync += axi.arvalid.eq(0)
        with m.If(axi.awready):
            m.d.sync += axi.awvalid.eq(0)

        req_error = Signal(len(MemStatus))
        req_error_addr = Signal(a.addr_bits)
        b_error = Signal(len(MemStatus))
        r_error = Signal(len(MemStatus))
        r_error_addr = Signal(a.addr_bits)
        # the addresses do not wait for the checks: each is the address an error of its kind
        # would name, and the register is only read with an error
        m.d.comb += [req_error_addr.eq(req.addr), r_error_addr.eq(head.addr)]
        # registered: the validity checks of a request stay out of the status registers' path
        m.d.sync += [
            self.error.eq(req_error | b_error | r_error),
            self.error_addr.eq(Mux(r_error.any(), r_error_addr,
                                   Mux(b_error.any(), w_addr, req_error_addr))),
        ]

        with m.FSM() as fsm:
            with m.State("IDLE"):
                with m.If(self.s_req.valid & ~req.write):
                    # A read: one AR (or, if bad, a zero-filled answer) per request.
                    with m.If(track_w_rdy & (~axi.arvalid | axi.arready) & ~read_after_write):
                        m.d.comb += [
                            self.s_req.ready.eq(1), track_push.eq(1),
                            push.tag.eq(req.tag), push.words.eq(words),
                            push.bad.eq(~good), push.addr.eq(req.addr),
                        ]
                        with m.If(good):
                            m.d.sync += [axi.araddr.eq(req.addr),
                                         axi.arlen.eq(words - 1), axi.arvalid.eq(1)]
                        with m.Elif(words != 0):
                            m.d.comb += req_error.eq(MemStatus.BAD_REQUEST)
                        with m.Else():
                            # length 0: nothing to answer
                            m.d.comb += [track_push.eq(0),
                                         req_error.eq(MemStatus.BAD_REQUEST)]
                with m.Elif(self.s_req.valid & ~write_open & ~write_after_read):
                    m.d.comb += self.s_req.ready.eq(1)
                    m.d.sync += [remaining.eq(words), w_addr.eq(req.addr)]
                    with m.If(good):
                        m.d.sync += [axi.awaddr.eq(req.addr), axi.awlen.eq(words - 1),
                                     axi.awvalid.eq(1), write_open.eq(1)]
                        m.next = "WRITE"
                    with m.Else():
                        m.d.comb += req_error.eq(MemStatus.BAD_REQUEST)
                        with m.If(words != 0):
                            m.next = "DRAIN"
            with m.State("WRITE"):
                # the write's data, then back to taking requests while its response comes
                m.d.comb += [
                    axi.wvalid.eq(self.s_wdata.valid),
                    axi.wdata.eq(self.s_wdata.payload.data),
                    axi.wstrb.eq(Mux(self.s_wdata.payload.null, 0, (1 << wb) - 1)),
                    axi.wlast.eq(remaining == 1),
                    self.s_wdata.ready.eq(axi.wready),
                ]
                with m.If(self.s_wdata.valid & axi.wready):
                    m.d.sync += remaining.eq(remaining - 1)
                    with m.If(remaining == 1):
                        m.next = "IDLE"
            with m.State("DRAIN"):
                m.d.comb += self.s_wdata.ready.eq(1)
                with m.If(self.s_wdata.valid):
                    m.d.sync += remaining.eq(remaining - 1)
                    with m.If(remaining == 1):
                        m.next = "IDLE"

        # ---- write response: taken whenever it comes after the write's data ----
        with m.If(write_open & fsm.ongoing("IDLE")):
            m.d.comb += axi.bready.eq(1)
            with m.If(axi.bvalid):
                m.d.sync += write_open.eq(0)
                with m.If(axi.bresp == AXIResp.SLVERR):
                    m.d.comb += b_error.eq(MemStatus.AXI_SLVERR)
                with m.Elif(axi.bresp == AXIResp.DECERR):
                    m.d.comb += b_error.eq(MemStatus.AXI_DECERR)

        # ---- read data side: bursts in request order ----
        count = Signal(lb)       # words of the head burst already delivered
        last_word = Signal()
        m.d.comb += [
            last_word.eq(count + 1 == head.words),
            self.m_rdata.payload.tag.eq(head.tag),
        ]
        with m.If(track_r_rdy):
            with m.If(head.bad):
                m.d.comb += [self.m_rdata.valid.eq(1), self.m_rdata.payload.data.eq(0)]
            with m.Else():
                m.d.comb += [self.m_rdata.valid.eq(axi.rvalid),
                             self.m_rdata.payload.data.eq(axi.rdata),
                             axi.rready.eq(self.m_rdata.ready)]
            with m.If(self.m_rdata.valid & self.m_rdata.ready):
                m.d.sync += count.eq(count + 1)
                with m.If(~head.bad & (axi.rresp == AXIResp.SLVERR)):
                    m.d.comb += r_error.eq(MemStatus.AXI_SLVERR)
                with m.If(~head.bad & (axi.rresp == AXIResp.DECERR)):
                    m.d.comb += r_error.eq(MemStatus.AXI_DECERR)
                with m.If(last_word):
                    m.d.sync += count.eq(0)
                    m.d.comb += track_pop.eq(1)

        m.d.comb += self.busy.eq(~fsm.ongoing("IDLE") | write_open | track_r_rdy | axi.arvalid)
        return m
