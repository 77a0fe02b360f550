"""The receive ring of a TCP session: bytes written while a segment arrives, kept only when
the segment turns out good (docs/network.md "TCP session")."""

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ...params import check_power_of_two
from ...stream import AXIStreamSignature

__all__ = ["TcpReceiveRing"]


class TcpReceiveRing(wiring.Component):
    """A byte ring with a speculative write pointer.

    A segment's payload is written while its frame arrives, before its Ethernet FCS and TCP
    checksum are known. The bytes become readable on ``commit`` and are dropped on
    ``rollback``. Three pointers (17 bits, wrapping) hold the state: read, committed and
    speculative; the ring's free space is the receive window.

    Parameters
    ----------
    depth : int
        Bytes, a power of two in 2**11..2**16 (one byte stays unused, so that a full ring is
        told apart from an empty one).

    Members
    -------
    payload_data, payload_valid, payload_offset : In(8), In(1), In(11)
        The TCP payload of the arriving frame, one byte per cycle (the frame parser's
        ``payload_*``); ``payload_offset`` counts from the payload's first byte.
    accept : In(1)
        Sampled with the payload byte at offset 0: this segment may be written (it belongs
        to the connection, starts at or before RCV.NXT, and is not a RST).
    skip : In(16)
        Sampled with the byte at offset 0: how many of the segment's first bytes were already
        received (RCV.NXT - SEG.SEQ); they are not written again.
    written : Out(11)
        Bytes of the current segment written so far. When the ring fills, writing stops for
        the rest of the segment: what follows would not be contiguous.
    frame_end : In(1)
        The parser's verdict on the frame: ``written`` starts from zero for the next one.
    commit : In(1)
        The written bytes become readable (``commit`` wins over ``rollback``).
    rollback : In(1)
        The written bytes are dropped.
    discard : In(1)
        The committed bytes not yet read are dropped (a new connection starts empty).
    window : Out(16)
        Free bytes, at most 65535: the window to advertise.
    m_axis : Out(AXIStreamSignature(8, keep=False))
        Committed bytes in order; ``tlast`` is 0. Backpressure only fills the ring (and so
        closes the window).
    """

    def __init__(self, depth=65536):
        self._depth = check_power_of_two("depth", depth, 2048, 65536)
        super().__init__({
            "payload_data": In(8), "payload_valid": In(1), "payload_offset": In(11),
            "accept": In(1), "skip": In(16), "written": Out(11),
            "frame_end": In(1), "commit": In(1), "rollback": In(1), "discard": In(1),
            "window": Out(16),
            "m_axis": Out(AXIStreamSignature(8, keep=False)),
        })

    def elaborate(self, platform):
        m = Module()
        depth = self._depth
        bits = depth.bit_length() - 1
        m.submodules.memory = memory = Memory(shape=8, depth=depth, init=[])
        wr = memory.write_port()
        rd = memory.read_port(transparent_for=())

        read = Signal(17)
        committed = Signal(17)
        speculative = Signal(17)
        # pointer differences are taken modulo 2**17 (the pointers wrap)
        used = Signal(17)
        free = Signal(17)
        m.d.comb += [used.eq(committed - read), free.eq(depth - 1 - used),
                     self.window.eq(Mux(free > 65535, 65535, free))]

        out_go = self.m_axis.tvalid & self.m_axis.tready
        m.d.comb += [
            self.m_axis.tvalid.eq(read != committed),
            self.m_axis.tdata.eq(rd.data),
            rd.addr.eq(Mux(out_go, read + 1, read)[:bits]),
        ]
        with m.If(out_go):
            m.d.sync += read.eq(read + 1)
        with m.If(self.discard):
            m.d.sync += read.eq(committed)

        writing = Signal()
        skipping = Signal(16)
        offset = self.payload_offset
        first = self.payload_valid & (offset == 0)
        on = Mux(first, self.accept, writing)
        skip = Mux(first, self.skip, skipping)
        in_use = Signal(17)
        m.d.comb += in_use.eq(speculative - read)
        room = in_use < depth - 1
        wanted = self.payload_valid & on & (offset >= skip)
        write_now = wanted & room
        m.d.comb += [wr.addr.eq(speculative[:bits]), wr.data.eq(self.payload_data),
                     wr.en.eq(write_now)]
        with m.If(first):
            m.d.sync += [writing.eq(self.accept), skipping.eq(self.skip)]
        with m.If(write_now):
            m.d.sync += [speculative.eq(speculative + 1), self.written.eq(self.written + 1)]
        with m.Elif(wanted):
            m.d.sync += writing.eq(0)
        with m.If(self.frame_end):
            m.d.sync += self.written.eq(0)
        with m.If(self.commit):
            m.d.sync += committed.eq(speculative)
        with m.Elif(self.rollback):
            m.d.sync += speculative.eq(committed)
        return m
