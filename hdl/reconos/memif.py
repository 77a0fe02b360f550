"""The MEMIF request path between the slots and memory: request formats and the arbiter
(docs/reconos.md).

Behind the arbiter a MEMIF request is no longer a word sequence but three streams:

* ``req``: one beat per request (:func:`request_layout`): read/write, byte length, address,
  the tag of the requester (slot index; the MMU uses ``num_hwts``) and a ``bad`` flag;
* ``wdata``: the data words of write requests, in request order;
* ``rdata``: the data words of read requests, in request order, each with its tag.

A request carries ``ceil(length / W)`` data words. Only requests that ReconOS can emit
(length a non-zero multiple of W, at most 256 B, not crossing a 256-B boundary) reach memory;
the memory controller answers any other one without touching memory (:class:`MemStatus`
``BAD_REQUEST``), so no length hangs the path (ReconROS defect 6, docs/reconos.md).
"""

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int
from .fifo import FifoReadSignature, FifoWriteSignature
from .protocol import MemifOp, arch as get_arch

__all__ = ["request_layout", "wdata_layout", "rdata_layout", "tag_width", "request_words", "MemifArbiter"]


def tag_width(num_hwts):
    """Bits of a requester tag: slots ``0..num_hwts-1`` and the MMU (``num_hwts``)."""
    return max(1, num_hwts.bit_length())


def request_layout(arch, num_hwts):
    a = get_arch(arch)
    return data.StructLayout({
        "write": 1,
        "length": a.length_bits,
        "addr": a.word_bits,
        "tag": tag_width(num_hwts),
        "bad": 1,
    })


def wdata_layout(arch):
    return data.StructLayout({"data": get_arch(arch).word_bits, "null": 1})


def rdata_layout(arch, num_hwts):
    return data.StructLayout({"data": get_arch(arch).word_bits, "tag": tag_width(num_hwts)})


def request_words(arch, length):
    """Data words of a request of ``length`` bytes: ``ceil(length / W)`` (an expression or an
    int)."""
    wb = get_arch(arch).word_bytes
    shift = wb.bit_length() - 1
    if isinstance(length, int):
        return -(-length // wb)
    return (length + (wb - 1)) >> shift


class MemifArbiter(wiring.Component):
    """reconos_memif_arbiter: N slots onto one request path, round robin per request.

    A slot requests when its hwt2mem FIFO is not empty. Among requesting slots not yet served
    in the current round the lowest index wins; when no unserved slot requests, a new round
    starts (ReconOS' masking). The grant is held while the request's command, address and
    (for a write) data words are forwarded, so words of two requests never interleave. Read
    data comes back on ``rdata`` in request order and is delivered to the slot named by its
    tag, so the next request may be forwarded while an earlier read's data is still coming
    (ReconOS holds the grant until then).

    Parameters
    ----------
    arch : str
        ``"r32"`` or ``"r64"``.
    num_hwts : int
        Slots, 1..32.

    Members
    -------
    hwt2mem : Out(FifoReadSignature(W*8)).array(num_hwts)
        Read side of each slot's hwt2mem FIFO: word 0 ``op << (8W-8) | length``, word 1 the
        virtual address, then the data words of a write.
    mem2hwt : Out(FifoWriteSignature(W*8)).array(num_hwts)
        Write side of each slot's mem2hwt FIFO.
    req : Out(stream.Signature(request_layout))
        Requests, tagged with the slot index.
    wdata : Out(stream.Signature(wdata_layout))
        Write data; ``null`` words carry no byte strobes.
    rdata : In(stream.Signature(rdata_layout))
        Read data for the slots; ``ready`` when the tagged slot's mem2hwt has room.
    grant : Out(num_hwts)
        One-hot: the slot whose words are being forwarded.
    slot_reset : In(num_hwts)
        The slots' ``HWT_Rst`` (their FIFOs are cleared). A reset slot's request is abandoned:
        before its address word nothing is forwarded; during its write data the remaining
        words are sent as ``null`` words. Read data for a reset slot is still taken (and lost
        in the cleared FIFO), so the path never stalls on it.
    """

    def __init__(self, arch, num_hwts):
        self._arch = get_arch(arch)
        self._n = check_int("num_hwts", num_hwts, 1, 32)
        w = self._arch.word_bits
        super().__init__({
            "hwt2mem": Out(FifoReadSignature(w)).array(num_hwts),
            "mem2hwt": Out(FifoWriteSignature(w)).array(num_hwts),
            "req": Out(stream.Signature(request_layout(self._arch, num_hwts))),
            "wdata": Out(stream.Signature(wdata_layout(self._arch))),
            "rdata": In(stream.Signature(rdata_layout(self._arch, num_hwts))),
            "grant": Out(num_hwts),
            "slot_reset": In(num_hwts),
        })

    def elaborate(self, platform):
        m = Module()
        a, n = self._arch, self._n
        lb = a.length_bits

        req_bits = Signal(n)
        mask = Signal(n, init=(1 << n) - 1)
        masked = Signal(n)
        winner = Signal(n)
        for i in range(n):
            m.d.comb += req_bits[i].eq(~self.hwt2mem[i].empty)
        m.d.comb += masked.eq(req_bits & mask)
        pick = Signal(n)
        m.d.comb += pick.eq(Mux(masked.any(), masked, req_bits))
        m.d.comb += winner.eq(pick & (~pick + 1))

        slot = Signal(range(max(n, 2)))
        head = Signal(a.word_bits)
        head_valid = Signal()
        pop = Signal()
        winner_head = Signal(a.word_bits)
        pop_winner = Signal()
        for i in range(n):
            with m.If(slot == i):
                m.d.comb += [head.eq(self.hwt2mem[i].data), head_valid.eq(~self.hwt2mem[i].empty)]
            with m.If(winner[i]):
                m.d.comb += winner_head.eq(self.hwt2mem[i].data)
            m.d.comb += self.hwt2mem[i].re.eq(Mux(pop_winner, winner[i], pop & (slot == i)))

        cmd = Signal(a.word_bits)
        words = Signal(lb)
        # A slot reset while its write data is being forwarded: the rest of the burst goes
        # out as null words (no byte strobes), so memory is untouched and nothing hangs.
        granted_reset = Signal()
        m.d.comb += granted_reset.eq((self.slot_reset & self.grant).any())
        m.d.comb += [self.wdata.payload.data.eq(Mux(granted_reset, 0, head)),
                     self.wdata.payload.null.eq(granted_reset)]

        with m.FSM():
            with m.State("ARBITRATE"):
                # The winner's command word is taken in the arbitration cycle.
                with m.If(winner.any()):
                    m.d.comb += pop_winner.eq(1)
                    for i in range(n):
                        with m.If(winner[i]):
                            m.d.sync += slot.eq(i)
                    m.d.sync += [self.grant.eq(winner), cmd.eq(winner_head),
                                 mask.eq(Mux(masked.any(), mask, (1 << n) - 1) & ~winner)]
                    m.next = "ADDR"
            with m.State("ADDR"):
                op = cmd[lb:]
                length = cmd[:lb]
                with m.If(granted_reset):
                    m.d.sync += self.grant.eq(0)
                    m.next = "ARBITRATE"
                m.d.comb += [
                    self.req.valid.eq(head_valid & ~granted_reset),
                    self.req.payload.write.eq(op == MemifOp.WRITE),
                    self.req.payload.length.eq(length),
                    self.req.payload.addr.eq(head),
                    self.req.payload.tag.eq(slot),
                    self.req.payload.bad.eq(0),
                    pop.eq(self.req.ready),
                ]
                with m.If(head_valid & self.req.ready & ~granted_reset):
                    m.d.sync += words.eq(request_words(a, length))
                    with m.If((op == MemifOp.WRITE) & (length != 0)):
                        m.next = "WRITE_DATA"
                    with m.Else():
                        m.d.sync += self.grant.eq(0)
                        m.next = "ARBITRATE"
            with m.State("WRITE_DATA"):
                m.d.comb += [self.wdata.valid.eq(head_valid | granted_reset),
                             pop.eq(self.wdata.ready & ~granted_reset)]
                with m.If((head_valid | granted_reset) & self.wdata.ready):
                    m.d.sync += words.eq(words - 1)
                    with m.If(words == 1):
                        m.d.sync += self.grant.eq(0)
                        m.next = "ARBITRATE"

        # Read data: to the tagged slot, when it has room.
        for i in range(n):
            m.d.comb += [
                self.mem2hwt[i].data.eq(self.rdata.payload.data),
                self.mem2hwt[i].we.eq(self.rdata.valid & (self.rdata.payload.tag == i) &
                                      ~self.slot_reset[i]),
            ]
            with m.If(self.rdata.payload.tag == i):
                m.d.comb += self.rdata.ready.eq(~self.mem2hwt[i].full | self.slot_reset[i])
        return m
