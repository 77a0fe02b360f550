"""A byte buffer as ``lanes`` block-RAM banks, so that ``lanes`` consecutive bytes from any
address are read or written in one cycle (the TCP session's buffers, docs/network.md)."""

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ...params import check_int, check_power_of_two

__all__ = ["ByteBanks"]


class ByteBanks(wiring.Component):
    """``depth`` bytes, byte ``p`` in bank ``p % lanes`` at ``p // lanes``.

    Parameters
    ----------
    depth : int
        Bytes, a power of two in 2**11..2**16.
    lanes : int
        Bytes a write or read moves, 1 or 2.

    Members
    -------
    wr_addr : In(16)
        The write's first byte address (low bits of a sequence number or ring pointer).
    wr_data : In(8 * lanes)
        Bytes for ``wr_addr`` .. ``wr_addr + lanes - 1``, the first in bits 0..7.
    wr_en : In(lanes)
        Which of them to write (bit ``k``: byte ``wr_addr + k``).
    rd_addr : In(16)
        The read's first byte address ...
    rd_data : Out(8 * lanes)
        ... and bytes ``rd_addr`` .. ``rd_addr + lanes - 1`` one cycle later (a read does not
        see a write of the same cycle).
    """

    def __init__(self, depth, *, lanes=1):
        self._depth = check_power_of_two("depth", depth, 2048, 65536)
        self._lanes = check_int("lanes", lanes, 1, 2)
        super().__init__({"wr_addr": In(16), "wr_data": In(8 * lanes), "wr_en": In(lanes),
                          "rd_addr": In(16), "rd_data": Out(8 * lanes)})

    def elaborate(self, platform):
        m = Module()
        L, bits = self._lanes, self._depth.bit_length() - 1
        if L == 1:
            m.submodules.bank0 = mem = Memory(shape=8, depth=self._depth, init=[])
            wr, rd = mem.write_port(), mem.read_port(transparent_for=())
            m.d.comb += [wr.addr.eq(self.wr_addr[:bits]), wr.data.eq(self.wr_data),
                         wr.en.eq(self.wr_en), rd.addr.eq(self.rd_addr[:bits]),
                         self.rd_data.eq(rd.data)]
            return m
        banks = []
        for b in range(2):
            m.submodules[f"bank{b}"] = mem = Memory(shape=8, depth=self._depth // 2, init=[])
            banks.append((mem.write_port(), mem.read_port(transparent_for=())))
        # byte k of an access at ``a`` is at ``a + k``: in bank (a + k) % 2, at (a + k) // 2;
        # bank 0 holds the byte at or after ``a`` with an even address: (a + 1) // 2
        wa, ra = self.wr_addr[:bits], self.rd_addr[:bits]
        odd_w = wa[0]
        lane = [self.wr_data[:8], self.wr_data[8:]]
        for b, (wr, rd) in enumerate(banks):
            first = odd_w if b == 1 else ~odd_w       # this bank holds the access's byte 0
            m.d.comb += [
                wr.addr.eq(((wa + 1) if b == 0 else wa)[1:]),
                wr.data.eq(Mux(first, lane[0], lane[1])),
                wr.en.eq(Mux(first, self.wr_en[0], self.wr_en[1])),
                rd.addr.eq(((ra + 1) if b == 0 else ra)[1:]),
            ]
        odd_r = Signal()
        m.d.sync += odd_r.eq(ra[0])
        d0, d1 = banks[0][1].data, banks[1][1].data
        m.d.comb += self.rd_data.eq(Mux(odd_r, Cat(d1, d0), Cat(d0, d1)))
        return m
