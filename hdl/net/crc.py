"""Ethernet FCS: CRC-32 over up to ``W`` bytes per cycle (docs/network.md)."""

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int

__all__ = ["Crc32", "CRC32_POLY_REFLECTED", "CRC32_RESIDUE", "crc32_byte_matrix"]

#: IEEE 802.3 polynomial 0x04C11DB7, bit-reflected (bytes are fed LSB first)
CRC32_POLY_REFLECTED = 0xEDB88320
#: the register after a good frame including its FCS (0x2144DF1C once complemented)
CRC32_RESIDUE = 0xDEBB20E3


def _step_byte(crc, byte):
    crc ^= byte
    for _ in range(8):
        crc = (crc >> 1) ^ (CRC32_POLY_REFLECTED if crc & 1 else 0)
    return crc


def crc32_byte_matrix(nbytes):
    """For the register after ``nbytes`` bytes: ``rows[i] = (crc_mask, data_mask)``, the bits
    of the old register and of the data (byte k in bits 8k..8k+7) whose XOR is new bit i.
    The CRC is linear over GF(2), so the columns are the responses to single bits."""
    def advance(crc, data):
        for k in range(nbytes):
            crc = _step_byte(crc, (data >> (8 * k)) & 0xFF)
        return crc
    rows = [[0, 0] for _ in range(32)]
    for b in range(32):
        out = advance(1 << b, 0)
        for i in range(32):
            if out >> i & 1:
                rows[i][0] |= 1 << b
    for b in range(8 * nbytes):
        out = advance(0, 1 << b)
        for i in range(32):
            if out >> i & 1:
                rows[i][1] |= 1 << b
    return rows


class Crc32(wiring.Component):
    """CRC-32 of a byte stream, ``zlib.crc32`` semantics, up to ``data_bytes`` per cycle.

    Parameters
    ----------
    data_bytes : int
        Bytes per beat, 1..16 (1 for GMII).

    Members
    -------
    data : In(8 * data_bytes)
        Byte k in bits ``8k..8k+7``.
    valid : In(1)
        Fold ``count`` bytes of ``data`` (the low ones) into the register this cycle.
    count : In(range(1, data_bytes + 1))
        Bytes of ``data`` that are valid (ignored with one byte per beat).
    clear : In(1)
        Reset the register to all ones (start of a frame); wins over ``valid``.
    crc : Out(32)
        ``zlib.crc32`` of the bytes folded in since ``clear``: the complemented register,
        sent low byte first as the FCS.
    residue_ok : Out(1)
        The bytes so far end in their own correct FCS (register ==
        :data:`CRC32_RESIDUE`).
    """

    def __init__(self, data_bytes=1):
        self._n = check_int("data_bytes", data_bytes, 1, 16)
        super().__init__({
            "data": In(8 * data_bytes),
            "valid": In(1),
            "count": In(range(1, data_bytes + 1)),
            "clear": In(1),
            "crc": Out(32),
            "residue_ok": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        reg = Signal(32, init=0xFFFFFFFF)
        m.d.comb += [self.crc.eq(~reg), self.residue_ok.eq(reg == CRC32_RESIDUE)]

        def fold(nbytes):
            rows = crc32_byte_matrix(nbytes)
            bits = []
            for crc_mask, data_mask in rows:
                terms = [reg[b] for b in range(32) if crc_mask >> b & 1]
                terms += [self.data[b] for b in range(8 * nbytes) if data_mask >> b & 1]
                value = terms[0]
                for t in terms[1:]:
                    value = value ^ t
                bits.append(value)
            return Cat(*bits)

        nxt = fold(self._n)
        for k in range(self._n - 1, 0, -1):
            nxt = Mux(self.count == k, fold(k), nxt)
        with m.If(self.clear):
            m.d.sync += reg.eq(0xFFFFFFFF)
        with m.Elif(self.valid):
            m.d.sync += reg.eq(nxt)
        return m
