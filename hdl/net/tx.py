"""Transmit-side frame builder: Ethernet, ARP, IPv4, ICMP, UDP and TCP headers with their
checksums, then the payload read from the requester's buffer, one or two bytes per cycle
(docs/network.md)."""

from amaranth.hdl import Array, Cat, Const, Module, Mux, Signal
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int
from ..stream import AXIStreamSignature
from .checksum import ones_complement_add
from .frames import (
    ARP_LENGTH,
    ARP_REQUEST,
    ETH_HEADER,
    ETHERTYPE_ARP,
    ETHERTYPE_IPV4,
    IP_CSUM_OFFSET,
    IP_PROTO_ICMP,
    IP_PROTO_TCP,
    IP_PROTO_UDP,
    IP_TTL,
    IP_VERSION,
    L4_OFFSET,
    MIN_HEADER_WORDS,
    TCP_CSUM_OFFSET,
    TCP_MSS,
    TCP_OPT_MSS,
    TCP_OPT_MSS_LENGTH,
    UDP_CSUM_OFFSET,
)
from .rx import FrameKind

__all__ = ["TX_REQUEST", "TxRequestSignature", "FrameBuilder"]

#: The MSS option of a SYN or SYN-ACK, as sent (after the 20-byte TCP header)
MSS_OPTION = (TCP_OPT_MSS, TCP_OPT_MSS_LENGTH, TCP_MSS >> 8, TCP_MSS & 0xFF)

#: What a requester asks the builder to send.
TX_REQUEST = data.StructLayout({
    "kind": FrameKind,
    "eth_dst": 48,
    "ip_dst": 32,          # ARP: target protocol address
    "arp_oper": 2,
    "src_port": 16, "dst_port": 16,
    "seq": 32, "ack": 32, "flags": 8, "window": 16,
    "mss": 1,              # TCP: add the MSS option (SYN, SYN-ACK)
    "length": 11,          # payload bytes (ICMP: the whole message)
    "payload_sum": 16,     # one's complement sum of the payload (UDP, TCP)
    "payload_addr": 16,    # first payload byte in the requester's buffer
})


class TxRequestSignature(wiring.Signature):
    """A requester's port on the :class:`FrameBuilder` (``Out`` = requester side).

    Parameters
    ----------
    lanes : int
        Bytes the builder reads per cycle (its frames' bytes per beat), 1 or 2.

    Members
    -------
    valid : Out(1)
        ``request`` describes a frame to send; hold until ``ready``.
    request : Out(TX_REQUEST)
    ready : In(1)
        The builder took the request this cycle (the requester may change it from the next).
    rd_addr : In(16)
        The builder reads payload bytes ``rd_addr`` .. ``rd_addr + lanes - 1`` of the
        requester's buffer (``rd_addr`` is ``payload_addr`` plus a multiple of ``lanes``) ...
    rd_data : Out(8 * lanes)
        ... which the requester returns one cycle later, byte ``rd_addr`` in bits 0..7 (a
        synchronous block-RAM port).
    done : In(1)
        One-cycle pulse: the frame's last payload byte has been read; the buffer is free.
    """

    def __init__(self, lanes=1):
        self._lanes = check_int("lanes", lanes, 1, 2)
        super().__init__({
            "valid": Out(1), "request": Out(TX_REQUEST), "ready": In(1),
            "rd_addr": In(16), "rd_data": Out(8 * lanes), "done": In(1),
        })

    lanes = property(lambda self: self._lanes)

    def __eq__(self, other):
        return type(other) is type(self) and other._lanes == self._lanes

    def __hash__(self):
        return hash((type(self), self._lanes))


class FrameBuilder(wiring.Component):
    """Serve requesters round-robin, one whole frame at a time, and stream each frame into
    the MAC at ``lanes`` bytes per cycle.

    The IPv4 and L4 checksums are sums of words the request and the builder's registers
    hold (addresses, lengths, ports, sequence numbers, the payload's sum), added one word
    per cycle while the first header bytes leave: both are ready before their checksum
    fields can leave (:func:`_serial_sum`). Once a frame
    has started its beats follow one per cycle for as long as ``m_axis`` takes them.

    Parameters
    ----------
    ports : int
        Number of requesters.
    lanes : int
        Bytes per beat, 1 or 2 (every header it sends is an even number of bytes, so each
        payload starts in lane 0).
    ttl : int
        The IPv4 time to live of every frame (64; a FinEmbP node sends 1: its frames stay in
        the layer-2 domain).
    kinds : iterable of FrameKind
        The kinds of frame the builder makes (all four unless given): the header tables and
        checksum words of the others are left out. A request of another kind is taken and
        ended (``ready``, then ``done`` in the next cycle) without a frame.

    Members
    -------
    req_<k> : In(TxRequestSignature(lanes))
        Requester ``k``.
    local_mac, local_ip : In(48), In(32)
        Source addresses.
    m_axis : Out(AXIStreamSignature(8 * lanes, keep=lanes > 1))
        Frames for :class:`GmiiTx` or a :class:`TxBeatBridge` (no preamble, padding or FCS);
        with 2 lanes a frame of odd length ends with ``tkeep`` 0b01.
    grant : Out(range(ports))
        The requester whose frame is on ``m_axis`` (a parent that sends frames to several
        ports picks the port by it).
    """

    def __init__(self, ports, *, lanes=1, ttl=IP_TTL, kinds=tuple(FrameKind)):
        self._ports = check_int("ports", ports, 1, 64)
        self._lanes = check_int("lanes", lanes, 1, 2)
        self._ttl = check_int("ttl", ttl, 1, 255)
        try:
            kinds = tuple(kinds)
        except TypeError:
            kinds = (kinds,)
        if not kinds or not all(isinstance(k, FrameKind) for k in kinds):
            raise ParameterError("kinds", kinds, "one or more FrameKind members")
        self._kinds = frozenset(kinds)
        members = {f"req_{k}": In(TxRequestSignature(lanes)) for k in range(ports)}
        members.update({"local_mac": In(48), "local_ip": In(32),
                        "m_axis": Out(AXIStreamSignature(8 * lanes, keep=lanes > 1)),
                        "grant": Out(range(max(ports, 2)))})
        super().__init__(members)

    lanes = property(lambda self: self._lanes)
    kinds = property(lambda self: self._kinds)

    def elaborate(self, platform):
        m = Module()
        n = self._ports
        L = self._lanes
        reqs = [getattr(self, f"req_{k}") for k in range(n)]
        r = Signal(TX_REQUEST)
        grant = Signal(range(max(n, 2)))
        m.d.comb += self.grant.eq(grant)
        busy = Signal()
        ip_id = Signal(16)

        def is_kind(kind):
            return r.kind == kind if kind in self._kinds else Const(0)
        is_arp, is_udp, is_tcp = (is_kind(k) for k in (FrameKind.ARP, FrameKind.UDP,
                                                        FrameKind.TCP))
        l4_header = Mux(is_tcp, Mux(r.mss, 24, 20), Mux(is_udp, 8, 0))
        l4_len = Signal(16)
        header = Signal(11)
        total = Signal(11)
        ip_total = Signal(16)
        m.d.comb += [
            l4_len.eq(l4_header + r.length),
            ip_total.eq(20 + l4_len),
            header.eq(Mux(is_arp, ETH_HEADER + ARP_LENGTH, L4_OFFSET + l4_header)),
            total.eq(Mux(is_arp, ETH_HEADER + ARP_LENGTH, L4_OFFSET + l4_len)),
        ]

        idx = Signal(11)                # the frame index of the current beat's first byte
        accept = self.m_axis.tvalid & self.m_axis.tready

        # Checksums: every word they cover is known at the grant
        src, dst = self.local_ip, r.ip_dst
        proto = Signal(8)
        m.d.comb += proto.eq(Mux(is_tcp, IP_PROTO_TCP, Mux(is_udp, IP_PROTO_UDP, IP_PROTO_ICMP)))
        data_offset = Mux(r.mss, MIN_HEADER_WORDS + 1, MIN_HEADER_WORDS)
        version_ihl = (IP_VERSION << 4) | MIN_HEADER_WORDS
        ip_words = [Const(version_ihl << 8, 16), ip_total, ip_id, Const(IP_DONT_FRAGMENT, 16),
                    Cat(proto, Const(self._ttl, 8)), src[16:], src[:16], dst[16:], dst[:16]]
        mss_words = [Const((MSS_OPTION[0] << 8) | MSS_OPTION[1], 16),
                     Const((MSS_OPTION[2] << 8) | MSS_OPTION[3], 16)]
        tcp_words = [r.seq[16:], r.seq[:16], r.ack[16:], r.ack[:16],
                     Cat(r.flags, Const(0, 4), data_offset), r.window] + \
            [Mux(r.mss, w, 0) for w in mss_words]
        l4_words = ([src[16:], src[:16], dst[16:], dst[:16], proto, l4_len,   # pseudo-header
                     r.src_port, r.dst_port, r.payload_sum, Mux(is_udp, l4_len, 0)] +
                    ([Mux(is_tcp, w, 0) for w in tcp_words]
                     if FrameKind.TCP in self._kinds else []))
        step = Signal(range(len(l4_words) + 1))
        ip_sum = _serial_sum(m, "ip_sum", ip_words, step)
        l4_sum = _serial_sum(m, "l4_sum", l4_words, step)
        with m.If(busy & (step < len(l4_words))):
            m.d.sync += step.eq(step + 1)
        ip_csum = ~ip_sum
        l4_csum = Signal(16)
        m.d.comb += l4_csum.eq(Mux(is_udp & (l4_sum == 0xFFFF), 0xFFFF, ~l4_sum))
        # the sums (one word a cycle from the first beat's cycle) are complete before their
        # checksum fields can leave: beat b leaves b cycles after the first at the earliest
        assert len(ip_words) <= IP_CSUM_OFFSET // L
        assert len(l4_words) <= min(UDP_CSUM_OFFSET, TCP_CSUM_OFFSET) // L

        # Header bytes: a table maps (frame kind, variant, beat) to one of a few byte sources
        # per lane, so the wide selection is made once for all kinds. The variant is the
        # MSS option of a TCP frame or an ARP request (whose target hardware address is 0).
        def be(value, nbytes):
            return [value.word_select(nbytes - 1 - q, 8) for q in range(nbytes)]

        eth_dst, local_mac = be(r.eth_dst, 6), be(self.local_mac, 6)
        local_ip, ip_dst = be(self.local_ip, 4), be(r.ip_dst, 4)
        ports = be(r.src_port, 2) + be(r.dst_port, 2)
        ip_fields = be(ip_total, 2) + be(ip_id, 2)
        ip_csum_bytes, l4_csum_bytes = be(ip_csum, 2), be(l4_csum, 2)
        l4_len_bytes = be(l4_len, 2)
        tcp_fields = (be(r.seq, 4) + be(r.ack, 4) + [Cat(Const(0, 4), data_offset), r.flags] +
                      be(r.window, 2))
        arp_oper = Cat(r.arp_oper, Const(0, 6))

        def ipv4(proto):
            return ([version_ihl, 0x00] + ip_fields +
                    [IP_DONT_FRAGMENT >> 8, IP_DONT_FRAGMENT & 0xFF, self._ttl, proto] +
                    ip_csum_bytes + local_ip + ip_dst)

        def frame(variant, kind):
            if kind == FrameKind.ARP:
                tha = [0] * 6 if variant else eth_dst
                return (eth_dst + local_mac + [ETHERTYPE_ARP >> 8, ETHERTYPE_ARP & 0xFF] +
                        [0x00, 0x01, 0x08, 0x00, 0x06, 0x04, 0x00, arp_oper] +
                        local_mac + local_ip + tha + ip_dst)
            eth = eth_dst + local_mac + [ETHERTYPE_IPV4 >> 8, ETHERTYPE_IPV4 & 0xFF]
            if kind == FrameKind.ICMP:
                return eth + ipv4(IP_PROTO_ICMP)
            if kind == FrameKind.UDP:
                return eth + ipv4(IP_PROTO_UDP) + ports + l4_len_bytes + l4_csum_bytes
            tcp = ports + tcp_fields + l4_csum_bytes + [0, 0]
            if variant:
                tcp += list(MSS_OPTION)
            return eth + ipv4(IP_PROTO_TCP) + tcp

        # one table for the IPv4 kinds (selected by is_udp/is_tcp), one for ARP (by
        # request/reply); beyond the header the bytes are payload
        shift = L.bit_length() - 1
        beat = idx[shift:shift + 6]
        layouts = tuple((kind, frame(kind == FrameKind.TCP, kind))
                        for kind in (FrameKind.ICMP, FrameKind.UDP, FrameKind.TCP)
                        if kind in self._kinds)
        arp_layouts = ((frame(0, FrameKind.ARP), frame(1, FrameKind.ARP))
                       if FrameKind.ARP in self._kinds else ())
        hdr = []
        for k in range(L):
            sources = []                    # distinct byte sources, in order of first use

            def source(value):
                for q, s in enumerate(sources):
                    if s is value or (isinstance(s, int) and isinstance(value, int) and
                                      s == value):
                        return q
                sources.append(value)
                return len(sources) - 1

            ip_code = Signal(range(64), name=f"ip_code{k}")
            arp_code = Signal(range(64), name=f"arp_code{k}")
            with m.Switch(Cat(beat, is_udp, is_tcp)):
                for q in range(64):
                    for kind, layout in layouts:
                        if q * L + k < len(layout):
                            pattern = (q | ((kind == FrameKind.UDP) << 6) |
                                       ((kind == FrameKind.TCP) << 7))
                            with m.Case(pattern):
                                m.d.comb += ip_code.eq(source(layout[q * L + k]))
            with m.Switch(Cat(beat, r.arp_oper == ARP_REQUEST)):
                for variant, layout in enumerate(arp_layouts):
                    for q in range(len(layout) // L):
                        with m.Case(q | (variant << 6)):
                            m.d.comb += arp_code.eq(source(layout[q * L + k]))
            assert len(sources) <= 64, len(sources)
            code = Mux(is_arp, arp_code, ip_code) if arp_layouts else ip_code
            byte = Signal(8, name=f"hdr_byte{k}")
            with m.Switch(code):
                for q, value in enumerate(sources):
                    with m.Case(q):
                        m.d.comb += byte.eq(value)
            hdr.append(byte)

        # payload reads: the address of the beat that will be current next cycle
        next_idx = Mux(accept, idx + L, idx)
        rd_addr = Signal(16)
        m.d.comb += rd_addr.eq(r.payload_addr + (next_idx - header))
        rd_data = Signal(8 * L)
        m.d.comb += rd_data.eq(Array(q.rd_data for q in reqs)[grant])
        for q in reqs:
            m.d.comb += q.rd_addr.eq(rd_addr)

        in_header = idx < header        # header lengths are even: both lanes agree
        # a request of a kind the builder does not make: taken, then ended without a frame
        partial = self._kinds != frozenset(FrameKind)
        skip = Signal() if partial else Const(0)
        m.d.comb += [
            self.m_axis.tvalid.eq(busy & ~skip if partial else busy),
            self.m_axis.tdata.eq(Mux(in_header, Cat(*hdr), rd_data)),
            self.m_axis.tlast.eq(idx + L >= total),
        ]
        if L > 1:
            m.d.comb += self.m_axis.tkeep.eq(Cat(Const(1), idx + 1 < total))

        # round-robin grant at frame boundaries
        with m.If(~busy):
            chosen = Signal(range(max(n, 2)))
            found = Signal()
            # the port after the last granted one goes first
            order = []
            for start in range(n):
                order.append([(start + 1 + o) % n for o in range(n)])
            with m.Switch(grant):
                for start in range(n):
                    with m.Case(start):
                        for cand in reversed(order[start]):
                            with m.If(reqs[cand].valid):
                                m.d.comb += [chosen.eq(cand), found.eq(1)]
            request = Array(q.request.as_value() for q in reqs)[chosen]
            if partial:
                chosen_kind = Signal(FrameKind)
                m.d.comb += chosen_kind.eq(Array(q.request.kind for q in reqs)[chosen])
            with m.If(found):
                m.d.sync += [busy.eq(1), grant.eq(chosen), idx.eq(0), step.eq(0),
                             ip_sum.eq(0), l4_sum.eq(0), r.eq(request)]
                if partial:
                    m.d.sync += skip.eq(~Cat(*(chosen_kind == k for k in self._kinds)).any())
                for cand in range(n):
                    with m.If(chosen == cand):
                        m.d.comb += reqs[cand].ready.eq(1)
        if partial:
            with m.Elif(skip):
                m.d.sync += [busy.eq(0), skip.eq(0)]
                for cand in range(n):
                    with m.If(grant == cand):
                        m.d.comb += reqs[cand].done.eq(1)
        with m.Elif(accept):
            m.d.sync += idx.eq(idx + L)
            with m.If(self.m_axis.tlast):
                m.d.sync += [busy.eq(0), ip_id.eq(ip_id + Mux(is_arp, 0, 1))]
                for cand in range(n):
                    with m.If(grant == cand):
                        m.d.comb += reqs[cand].done.eq(1)
        return m


#: the IPv4 flags and fragment offset of every frame sent: Don't Fragment
IP_DONT_FRAGMENT = 0x4000


def _serial_sum(m, name, words, step):
    """A register that adds ``words[step]`` (one's complement) in each cycle while ``step``
    is below their number; its parent clears it and ``step`` at a grant and advances
    ``step``."""
    acc = Signal(16, name=name)
    with m.If(step < len(words)):
        m.d.sync += acc.eq(ones_complement_add(acc, Array(words)[step]))
    return acc
