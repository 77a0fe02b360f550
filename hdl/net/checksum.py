"""Internet checksum (RFC 1071) of a byte stream, as IPv4, ICMP, UDP and TCP use it (
docs/network.md)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..logic import adder_tree

__all__ = ["InternetChecksum", "ones_complement_add", "ones_complement_fold", "word_sum_tree",
           "echo_reply_checksum"]


def ones_complement_add(a, b):
    """16-bit one's complement sum of two 16-bit values (end-around carry)."""
    s = a + b
    return (s[:16] + s[16])[:16]


def word_sum_tree(words):
    """Plain binary sum of 16-bit ``words`` as a balanced adder tree (depth log2 of their
    number); :func:`ones_complement_fold` turns it into their one's complement sum."""
    return adder_tree(list(words) or [Const(0, 16)])


def ones_complement_fold(value):
    """The 16-bit one's complement sum of a binary sum of at most 16 words (up to 20 bits):
    two end-around folds. Zero only when ``value`` is, like a chain of
    :func:`ones_complement_add` over the same words."""
    once = value[:16] + value[16:]
    return (once[:16] + once[16:])[:16]


class InternetChecksum(wiring.Component):
    """One's complement sum of a byte stream taken as big-endian 16-bit words, one byte per
    cycle; an odd length is padded with a zero byte (RFC 1071).

    Members
    -------
    data : In(8)
        The next byte.
    valid : In(1)
        Add ``data`` this cycle.
    clear : In(1)
        Start a new sum (wins over ``valid``).
    preset : In(16)
        Value the sum starts from at ``clear`` (for example the pseudo-header sum).
    sum : Out(16)
        The one's complement sum so far (odd trailing byte as the high byte of a word).
    checksum : Out(16)
        ``~sum``: the value to put in a header; a received header with a correct checksum
        sums to 0xFFFF.
    """

    def __init__(self):
        super().__init__({
            "data": In(8),
            "valid": In(1),
            "clear": In(1),
            "preset": In(16),
            "sum": Out(16),
            "checksum": Out(16),
        })

    def elaborate(self, platform):
        m = Module()
        acc = Signal(16)
        low = Signal()           # the next byte is the low byte of a word
        word = Mux(low, Cat(self.data, Const(0, 8)), Cat(Const(0, 8), self.data))
        m.d.comb += [self.sum.eq(acc), self.checksum.eq(~acc)]
        with m.If(self.clear):
            m.d.sync += [acc.eq(self.preset), low.eq(0)]
        with m.Elif(self.valid):
            m.d.sync += [acc.eq(ones_complement_add(acc, word)), low.eq(~low)]
        return m


def echo_reply_checksum(request_checksum):
    """The ICMP checksum of the echo reply to a request with ``request_checksum``: only the
    type changes (8 -> 0), so the checksum is updated per RFC 1624 (HC' = ~(~HC + ~m + m'),
    m = 0x0800, m' = 0) instead of summed again."""
    return ~ones_complement_add(~request_checksum, 0xF7FF)
