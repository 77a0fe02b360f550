"""Responders on a :class:`~hdl.net.tx.FrameBuilder` request port: each answers one kind of
received frame (docs/network.md)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int
from .checksum import echo_reply_checksum
from .frames import ARP_REPLY, ARP_REQUEST, TCP_ACK, TCP_RST
from .rbcp import RbcpBusSignature, RbcpServer
from .rx import RX_FIELDS, FrameKind
from .tx import TX_REQUEST, TxRequestSignature

__all__ = ["ParsedFrameSignature", "ArpResponder", "IcmpEchoResponder", "RbcpResponder",
           "TcpResetResponder"]

#: bytes of the RBCP request and reply buffer (the longest request: 8 header + 255 data)
_RBCP_BUFFER = 2048


class ParsedFrameSignature(wiring.Signature):
    """What a :class:`~hdl.net.rx.FrameParser` tells its consumers, seen from the parser
    (``Out``); see its members of the same names.

    Parameters
    ----------
    lanes : int
        The parser's bytes per beat, 1 or 2.

    Members
    -------
    fields : Out(RX_FIELDS)
    kind : Out(FrameKind)
    payload_data, payload_valid, payload_keep, payload_offset : Out
    first : Out(1)
        The frame's first beat arrives (a consumer may claim a buffer for it).
    done, accept : Out(1)
        The verdict.
    """

    def __init__(self, lanes=1):
        self._lanes = check_int("lanes", lanes, 1, 2)
        super().__init__({
            "fields": Out(RX_FIELDS), "kind": Out(FrameKind),
            "payload_data": Out(8 * lanes), "payload_valid": Out(1),
            "payload_keep": Out(lanes), "payload_offset": Out(11),
            "first": Out(1), "done": Out(1), "accept": Out(1),
        })

    lanes = property(lambda self: self._lanes)

    def __eq__(self, other):
        return type(other) is type(self) and other._lanes == self._lanes

    def __hash__(self):
        return hash((type(self), self._lanes))

    @staticmethod
    def connect_parser(m, parser, port, rx, *, accept=None):
        """Drive ``port`` (an ``In(ParsedFrameSignature())``) from ``parser`` and the byte
        stream ``rx`` it parses; ``accept`` replaces the parser's verdict (to gate it)."""
        m.d.comb += [port.fields.eq(parser.fields), port.kind.eq(parser.kind),
                     port.payload_data.eq(parser.payload_data),
                     port.payload_valid.eq(parser.payload_valid),
                     port.payload_keep.eq(parser.payload_keep),
                     port.payload_offset.eq(parser.payload_offset),
                     port.first.eq(rx.valid & (rx.index == 0)),
                     port.done.eq(parser.done),
                     port.accept.eq(parser.accept if accept is None else accept)]


def _responder_members(lanes, tag_width, **more):
    """The members every responder has: the parsed frame in, the request to the frame
    builder out, ``busy``, and with a tag the port the request came in on and the answer goes
    out of."""
    members = {"frame": In(ParsedFrameSignature(lanes)), "tx": Out(TxRequestSignature(lanes)),
               "busy": Out(1), **more}
    if tag_width:
        members.update({"rx_tag": In(tag_width), "tx_tag": Out(tag_width)})
    return members


class ArpResponder(wiring.Component):
    """Answers an ARP request for this node's address (the parser accepts only those) with
    a reply to the requester's addresses.

    Parameters
    ----------
    tag_width : int
        Width of ``rx_tag``/``tx_tag`` (0: none): something the parent wants back with the
        reply, such as the port the request came in on.
    lanes : int
        The parser's and the builder's bytes per beat, 1 or 2.

    Members
    -------
    frame : In(ParsedFrameSignature(lanes))
    tx : Out(TxRequestSignature(lanes))
        To the builder.
    rx_tag : In(tag_width)
        Sampled at the verdict of a request that is answered ...
    tx_tag : Out(tag_width)
        ... and held while its reply is pending.
    busy : Out(1)
        A reply is pending: a request answered now would be dropped (count it as busy).
    """

    def __init__(self, *, tag_width=0, lanes=1):
        self._tag = check_int("tag_width", tag_width, 0, 8)
        super().__init__(_responder_members(lanes, tag_width))

    def elaborate(self, platform):
        m = Module()
        f, tx = self.frame, self.tx
        req = tx.request
        pending = Signal()
        m.d.comb += [self.busy.eq(pending), tx.valid.eq(pending),
                     req.kind.eq(FrameKind.ARP), req.arp_oper.eq(ARP_REPLY)]
        eth, ip = Signal(48), Signal(32)
        m.d.comb += [req.eth_dst.eq(eth), req.ip_dst.eq(ip)]
        with m.If(tx.ready):
            m.d.sync += pending.eq(0)
        with m.If(f.done & f.accept & (f.kind == FrameKind.ARP) &
                  (f.fields.arp_oper == ARP_REQUEST) & ~pending):
            m.d.sync += [pending.eq(1), eth.eq(f.fields.sender_mac), ip.eq(f.fields.sender_ip)]
            if self._tag:
                m.d.sync += self.tx_tag.eq(self.rx_tag)
        return m


class IcmpEchoResponder(wiring.Component):
    """Answers an ICMP echo request with its echo reply: the message is kept as it arrives,
    its type set to 0 and its checksum updated (RFC 1624), and sent back to the sender.

    A request that arrives while a reply is pending, or whose message is longer than the
    buffer, is not answered (``dropped`` pulses).

    Parameters
    ----------
    buffer_bytes : int
        The longest ICMP message answered (header and data), a power of two in 64..2048
        (2048 holds the largest unfragmented ping, 1480 bytes).
    tag_width, lanes : int
        As for :class:`ArpResponder`.

    Members
    -------
    frame : In(ParsedFrameSignature(lanes))
    tx : Out(TxRequestSignature(lanes))
    rx_tag, tx_tag :
        As for :class:`ArpResponder`.
    busy : Out(1)
        The buffer holds a reply.
    dropped : Out(1)
        Pulse with the verdict of an accepted echo request that is not answered.
    """

    def __init__(self, *, buffer_bytes=2048, tag_width=0, lanes=1):
        check_int("buffer_bytes", buffer_bytes, 64, 2048)
        if buffer_bytes & (buffer_bytes - 1):
            raise ParameterError("buffer_bytes", buffer_bytes, "a power of two in 64..2048")
        self._bytes = buffer_bytes
        self._tag = check_int("tag_width", tag_width, 0, 8)
        self._lanes = check_int("lanes", lanes, 1, 2)
        super().__init__(_responder_members(lanes, tag_width, dropped=Out(1)))

    def elaborate(self, platform):
        m = Module()
        f, tx = self.frame, self.tx
        req = tx.request
        L = self._lanes
        shift = L.bit_length() - 1
        aw = (self._bytes // L - 1).bit_length()
        m.submodules.buffer = mem = Memory(shape=8 * L, depth=self._bytes // L, init=[])
        wp = mem.write_port(granularity=8)
        rp = mem.read_port(transparent_for=())
        eth, ip = Signal(48), Signal(32)
        length = Signal(11)
        csum = Signal(16)
        claim = Signal()          # this frame's message goes into the buffer
        m.d.comb += [req.kind.eq(FrameKind.ICMP), req.eth_dst.eq(eth), req.ip_dst.eq(ip),
                     req.length.eq(length), rp.addr.eq(tx.rd_addr[shift:shift + aw]),
                     tx.rd_data.eq(rp.data)]
        # the reply's changes, as (buffer word, byte enables, data) writes: type 8 -> 0 at
        # byte 0, the checksum at bytes 2..3 (RFC 1624)
        edits = {}
        for offset, value in ((0, Const(0, 8)), (2, csum[8:]), (3, csum[:8])):
            word, byte = divmod(offset, L)
            edits.setdefault(word, {})[byte] = value
        edits = [(word, sum(1 << b for b in lanes),
                  Cat(*(lanes.get(b, Const(0, 8)) for b in range(L))))
                 for word, lanes in sorted(edits.items())]
        with m.FSM() as fsm:
            with m.State("IDLE"):
                with m.If(f.first):
                    m.d.sync += claim.eq(1)
                with m.If(f.payload_valid & claim & (f.kind == FrameKind.ICMP) &
                          (f.payload_offset < self._bytes)):
                    m.d.comb += [wp.addr.eq(f.payload_offset[shift:shift + aw]),
                                 wp.data.eq(f.payload_data), wp.en.eq(f.payload_keep)]
                with m.If(f.done):
                    m.d.sync += claim.eq(0)
                    with m.If(f.accept & (f.kind == FrameKind.ICMP)):
                        with m.If(claim & (f.fields.payload_len <= self._bytes)):
                            m.d.sync += [eth.eq(f.fields.sender_mac), ip.eq(f.fields.sender_ip),
                                         length.eq(f.fields.payload_len),
                                         csum.eq(f.fields.icmp_csum)]
                            if self._tag:
                                m.d.sync += self.tx_tag.eq(self.rx_tag)
                            m.next = "CHECKSUM"
                        with m.Else():
                            m.d.comb += self.dropped.eq(1)
            with m.State("CHECKSUM"):
                m.d.sync += csum.eq(echo_reply_checksum(csum))
                m.next = "EDIT_0"
            for k, (word, enables, value) in enumerate(edits):
                with m.State(f"EDIT_{k}"):
                    m.d.comb += [wp.addr.eq(word), wp.data.eq(value), wp.en.eq(enables)]
                    m.next = f"EDIT_{k + 1}" if k + 1 < len(edits) else "REQUEST"
            with m.State("REQUEST"):
                m.d.comb += tx.valid.eq(1)
                with m.If(tx.ready):
                    m.next = "SENDING"
            with m.State("SENDING"):
                with m.If(tx.done):
                    m.next = "IDLE"
        with m.If(~fsm.ongoing("IDLE") & f.done & f.accept & (f.kind == FrameKind.ICMP)):
            m.d.comb += self.dropped.eq(1)
        m.d.comb += self.busy.eq(~fsm.ongoing("IDLE"))
        return m


class RbcpResponder(wiring.Component):
    """Answers SiTCP's register protocol: a UDP datagram to ``port`` is kept as it arrives,
    executed by an :class:`~hdl.net.rbcp.RbcpServer` on ``bus``, and its reply (the buffer,
    rewritten) sent back to the sender's address and port.

    A datagram that arrives while a request is being executed or answered is not taken
    (``dropped`` pulses).

    Parameters
    ----------
    windows : list of (int, int)
        The bus windows, as :class:`~hdl.net.rbcp.RbcpServer`'s.
    lanes : int
        As for :class:`ArpResponder`.

    Members
    -------
    frame : In(ParsedFrameSignature(lanes))
    tx : Out(TxRequestSignature(lanes))
    port : In(16)
        The RBCP UDP port.
    bus : Out(RbcpBusSignature())
        The register bus.
    busy : Out(1)
        A request is being executed or answered.
    dropped : Out(1)
        Pulse with the verdict of an accepted datagram to ``port`` that is not taken.
    """

    def __init__(self, windows, *, lanes=1):
        self._server = RbcpServer(windows)
        self._lanes = check_int("lanes", lanes, 1, 2)
        super().__init__(_responder_members(lanes, 0, port=In(16), bus=Out(RbcpBusSignature()),
                                            dropped=Out(1)))

    def elaborate(self, platform):
        m = Module()
        f, tx = self.frame, self.tx
        req = tx.request
        L = self._lanes
        shift = L.bit_length() - 1
        m.submodules.server = server = self._server
        wiring.connect(m, server.bus, wiring.flipped(self.bus))
        m.submodules.buffer = mem = Memory(shape=8 * L, depth=_RBCP_BUFFER // L, init=[])
        wp = mem.write_port(granularity=8)
        rp = mem.read_port(transparent_for=())
        # the server works byte by byte: its byte's lane, one cycle later for a read
        server_lane = Signal(range(L)) if L > 1 else Const(0)
        if L > 1:
            m.d.sync += server_lane.eq(server.buf_addr[:shift])
        eth, ip, src_port, dst_port = Signal(48), Signal(32), Signal(16), Signal(16)
        length, total = Signal(11), Signal(16)
        claim = Signal()
        m.d.comb += [req.kind.eq(FrameKind.UDP), req.eth_dst.eq(eth), req.ip_dst.eq(ip),
                     req.src_port.eq(src_port), req.dst_port.eq(dst_port),
                     req.length.eq(length), req.payload_sum.eq(total),
                     tx.rd_data.eq(rp.data),
                     server.buf_rdata.eq(rp.data.word_select(server_lane, 8))]
        mine = f.accept & (f.kind == FrameKind.UDP) & (f.fields.dst_port == self.port)
        with m.FSM() as fsm:
            with m.State("IDLE"):
                with m.If(f.first):
                    m.d.sync += claim.eq(1)
                with m.If(f.payload_valid & claim & (f.kind == FrameKind.UDP)):
                    m.d.comb += [wp.addr.eq(f.payload_offset[shift:]), wp.data.eq(f.payload_data),
                                 wp.en.eq(f.payload_keep)]
                with m.If(f.done):
                    m.d.sync += claim.eq(0)
                    with m.If(mine & claim):
                        m.d.sync += [eth.eq(f.fields.sender_mac), ip.eq(f.fields.sender_ip),
                                     src_port.eq(f.fields.dst_port),
                                     dst_port.eq(f.fields.src_port)]
                        m.d.comb += [server.start.eq(1), server.length.eq(f.fields.payload_len)]
                        m.next = "EXECUTE"
                    with m.Elif(mine):
                        m.d.comb += self.dropped.eq(1)
            with m.State("EXECUTE"):
                m.d.comb += [rp.addr.eq(server.buf_addr[shift:]),
                             wp.addr.eq(server.buf_addr[shift:]),
                             wp.data.eq(Cat(*([server.buf_wdata] * L))),
                             wp.en.eq(Mux(server.buf_we, 1 << server.buf_addr[:shift], 0)
                                      if L > 1 else server.buf_we)]
                with m.If(server.done):
                    m.d.sync += [length.eq(server.reply_len), total.eq(server.reply_sum)]
                    with m.If(server.reply):
                        m.next = "REQUEST"
                    with m.Else():
                        m.next = "IDLE"
            with m.State("REQUEST"):
                m.d.comb += [tx.valid.eq(1), rp.addr.eq(tx.rd_addr[shift:11])]
                with m.If(tx.ready):
                    m.next = "SENDING"
            with m.State("SENDING"):
                m.d.comb += rp.addr.eq(tx.rd_addr[shift:11])
                with m.If(tx.done):
                    m.next = "IDLE"
        with m.If(~fsm.ongoing("IDLE") & f.done & mine):
            m.d.comb += self.dropped.eq(1)
        m.d.comb += self.busy.eq(~fsm.ongoing("IDLE"))
        return m


class TcpResetResponder(wiring.Component):
    """Answers a TCP segment that no session takes with RST (RFC 9293 §3.10.7.1): a segment
    with ACK gets ``<SEQ=SEG.ACK><CTL=RST>``, one without ``<SEQ=0><ACK=SEG.SEQ+SEG.LEN>
    <CTL=RST,ACK>``. A RST is never answered, nor a segment the sessions ``claimed`` or
    ``ignore`` (one to a listening port without SYN, ACK and RST: RFC 9293 §3.10.7.2 drops
    it), nor one that arrives while a RST is pending.

    Parameters
    ----------
    lanes : int
        As for :class:`ArpResponder`.

    Members
    -------
    frame : In(ParsedFrameSignature(lanes))
    tx : Out(TxRequestSignature(lanes))
    claimed, ignore : In(1)
        At the verdict: a session takes the segment; the segment is dropped silently.
    busy : Out(1)
        A RST is pending.
    """

    def __init__(self, *, lanes=1):
        super().__init__(_responder_members(lanes, 0, claimed=In(1), ignore=In(1)))

    def elaborate(self, platform):
        m = Module()
        f, tx = self.frame, self.tx
        fields = f.fields
        req = tx.request
        pending = Signal()
        answer = Signal(TX_REQUEST)
        m.d.comb += [self.busy.eq(pending), tx.valid.eq(pending), req.eq(answer),
                     req.kind.eq(FrameKind.TCP)]
        with m.If(tx.ready):
            m.d.sync += pending.eq(0)
        with m.If(f.done & f.accept & (f.kind == FrameKind.TCP) & ~self.claimed &
                  ~self.ignore & ~fields.flags.rst & ~pending):
            syn_fin = fields.flags.syn + fields.flags.fin
            m.d.sync += [pending.eq(1),
                         answer.eth_dst.eq(fields.sender_mac), answer.ip_dst.eq(fields.sender_ip),
                         answer.src_port.eq(fields.dst_port), answer.dst_port.eq(fields.src_port),
                         answer.seq.eq(Mux(fields.flags.ack, fields.ack, 0)),
                         answer.ack.eq(fields.seq + fields.payload_len + syn_fin),
                         answer.flags.eq(Mux(fields.flags.ack, TCP_RST, TCP_RST | TCP_ACK))]
        return m
