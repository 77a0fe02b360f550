"""AXI4 and AXI4-Lite as Amaranth signatures (AMBA AXI and ACE, ARM IHI 0022), with the
responses, burst types and a minimal register target shared by the rosgate control blocks."""

import enum

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int

__all__ = ["AXIResp", "AXIBurst", "AXI4LiteSignature", "AXI4Signature", "AXI4LiteTarget"]


class AXIResp(enum.IntEnum):
    OKAY = 0
    EXOKAY = 1
    SLVERR = 2
    DECERR = 3


class AXIBurst(enum.IntEnum):
    FIXED = 0
    INCR = 1
    WRAP = 2


class AXI4LiteSignature(wiring.Signature):
    """AXI4-Lite, seen from the manager (``Out``); flip it for a subordinate.

    Parameters
    ----------
    addr_width : int
        Width of ``awaddr``/``araddr`` (1..64).
    data_width : int
        32 or 64.

    Members
    -------
    aw*, w*, b*, ar*, r* :
        The five channels with their AMBA names; each transfers in a cycle with ``xVALID``
        and ``xREADY`` both high. ``awprot``/``arprot`` are present for interface inference and
        ignored by rosgate subordinates.
    """

    def __init__(self, addr_width, data_width):
        check_int("addr_width", addr_width, 1, 64)
        if data_width not in (32, 64):
            raise ValueError(f"AXI4-Lite data_width must be 32 or 64, not {data_width!r}")
        self.addr_width = addr_width
        self.data_width = data_width
        super().__init__({
            "awaddr": Out(addr_width), "awprot": Out(3), "awvalid": Out(1), "awready": In(1),
            "wdata": Out(data_width), "wstrb": Out(data_width // 8), "wvalid": Out(1),
            "wready": In(1),
            "bresp": In(2), "bvalid": In(1), "bready": Out(1),
            "araddr": Out(addr_width), "arprot": Out(3), "arvalid": Out(1), "arready": In(1),
            "rdata": In(data_width), "rresp": In(2), "rvalid": In(1), "rready": Out(1),
        })


class AXI4Signature(wiring.Signature):
    """AXI4 with bursts, seen from the manager (``Out``); flip it for a subordinate.

    Parameters
    ----------
    addr_width : int
        Width of ``awaddr``/``araddr``.
    data_width : int
        Width of ``wdata``/``rdata``: 32, 64, 128, 256, 512 or 1024.
    id_width, user_width : int
        Widths of the ID and AxUSER members (1..16 and 0..16; 0 omits ``awuser``/``aruser``).

    Members
    -------
    aw*, w*, b*, ar*, r* :
        The five channels with their AMBA names (``awlen`` 8 bits, ``awsize`` 3, ``awburst``
        2, ``awlock`` 1, ``awcache`` 4, ``awprot`` 3, ``awqos`` 4; ``wlast``/``rlast`` end a
        burst). Every channel transfers in a cycle with ``xVALID`` and ``xREADY`` both high.
    """

    def __init__(self, addr_width, data_width, *, id_width=1, user_width=0):
        check_int("addr_width", addr_width, 12, 64)
        if data_width not in (32, 64, 128, 256, 512, 1024):
            raise ValueError(f"AXI4 data_width must be a power of two in 32..1024, "
                             f"not {data_width!r}")
        check_int("id_width", id_width, 1, 16)
        check_int("user_width", user_width, 0, 16)
        self.addr_width = addr_width
        self.data_width = data_width
        self.id_width = id_width
        self.user_width = user_width
        members = {}
        for ch in ("aw", "ar"):
            members.update({
                f"{ch}id": Out(id_width), f"{ch}addr": Out(addr_width), f"{ch}len": Out(8),
                f"{ch}size": Out(3), f"{ch}burst": Out(2), f"{ch}lock": Out(1),
                f"{ch}cache": Out(4), f"{ch}prot": Out(3), f"{ch}qos": Out(4),
            })
            if user_width:
                members[f"{ch}user"] = Out(user_width)
            members[f"{ch}valid"] = Out(1)
            members[f"{ch}ready"] = In(1)
            if ch == "aw":
                members.update({
                    "wdata": Out(data_width), "wstrb": Out(data_width // 8), "wlast": Out(1),
                    "wvalid": Out(1), "wready": In(1),
                    "bid": In(id_width), "bresp": In(2), "bvalid": In(1), "bready": Out(1),
                })
        members.update({
            "rid": In(id_width), "rdata": In(data_width), "rresp": In(2), "rlast": In(1),
            "rvalid": In(1), "rready": Out(1),
        })
        super().__init__(members)


class AXI4LiteTarget(wiring.Component):
    """An AXI4-Lite subordinate that turns each transfer into a one-cycle register access.

    One transfer is in flight at a time; a write waits for both AW and W. Reads have priority
    over writes when both arrive in the same cycle. The register block decodes the word index
    (``addr >> log2(data_width/8)``) and answers in the same cycle.

    Parameters
    ----------
    addr_width, data_width : int
        Of the bus (see :class:`AXI4LiteSignature`).

    Members
    -------
    bus : In(AXI4LiteSignature)
        The subordinate port.
    read_en : Out(1)
        One-cycle pulse: a read of word ``read_index`` happens now; ``read_data`` is sampled
        in this cycle. Side effects of a read (a FIFO pop, a clear) happen exactly then.
    read_addr, read_index : Out(addr_width)
        Byte address and word index of the read.
    read_data : In(data_width)
        Value of the word; meaningful in the ``read_en`` cycle.
    read_error : In(1)
        Sampled with ``read_data``: answer SLVERR (an index no register decodes).
    write_en : Out(1)
        One-cycle pulse: write ``write_data`` (bytes enabled by ``write_strb``) to word
        ``write_index``.
    write_addr, write_index, write_data, write_strb : Out
    write_error : In(1)
        Sampled in the ``write_en`` cycle: answer SLVERR.
    """

    def __init__(self, addr_width, data_width):
        self._bus = AXI4LiteSignature(addr_width, data_width)
        super().__init__({
            "bus": In(self._bus),
            "read_en": Out(1), "read_addr": Out(addr_width), "read_index": Out(addr_width),
            "read_data": In(data_width),
            "read_error": In(1),
            "write_en": Out(1), "write_addr": Out(addr_width), "write_index": Out(addr_width),
            "write_data": Out(data_width),
            "write_strb": Out(data_width // 8), "write_error": In(1),
        })

    def elaborate(self, platform):
        m = Module()
        bus = self.bus
        shift = (self._bus.data_width // 8).bit_length() - 1
        have_aw = Signal()
        have_w = Signal()
        waddr = Signal.like(bus.awaddr)

        m.d.comb += [
            self.read_addr.eq(bus.araddr),
            self.read_index.eq(bus.araddr >> shift),
            self.write_addr.eq(waddr),
            self.write_index.eq(waddr >> shift),
        ]
        with m.FSM():
            with m.State("IDLE"):
                m.d.comb += bus.arready.eq(1)
                with m.If(bus.arvalid):
                    m.d.comb += self.read_en.eq(1)
                    m.d.sync += [
                        bus.rdata.eq(self.read_data),
                        bus.rresp.eq(Mux(self.read_error, int(AXIResp.SLVERR), int(AXIResp.OKAY))),
                        bus.rvalid.eq(1),
                    ]
                    m.next = "READ_RESP"
                with m.Else():
                    m.d.comb += [bus.awready.eq(~have_aw), bus.wready.eq(~have_w)]
                    with m.If(bus.awvalid & ~have_aw):
                        m.d.sync += [waddr.eq(bus.awaddr), have_aw.eq(1)]
                    with m.If(bus.wvalid & ~have_w):
                        m.d.sync += [self.write_data.eq(bus.wdata),
                                     self.write_strb.eq(bus.wstrb), have_w.eq(1)]
                    with m.If((have_aw | bus.awvalid) & (have_w | bus.wvalid)):
                        m.next = "WRITE"
            with m.State("WRITE"):
                m.d.comb += self.write_en.eq(1)
                m.d.sync += [
                    have_aw.eq(0), have_w.eq(0),
                    bus.bresp.eq(Mux(self.write_error, int(AXIResp.SLVERR), int(AXIResp.OKAY))),
                    bus.bvalid.eq(1),
                ]
                m.next = "WRITE_RESP"
            with m.State("WRITE_RESP"):
                with m.If(bus.bready):
                    m.d.sync += bus.bvalid.eq(0)
                    m.next = "IDLE"
            with m.State("READ_RESP"):
                with m.If(bus.rready):
                    m.d.sync += bus.rvalid.eq(0)
                    m.next = "IDLE"
        return m

