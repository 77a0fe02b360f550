"""Transmit-side frame builder: Ethernet, ARP, IPv4, ICMP, UDP and TCP headers with their
checksums, then the payload read from the requester's buffer (docs/network.md)."""

from amaranth.hdl import Array, Cat, Const, Module, Mux, Signal
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int
from ..stream import AXIStreamSignature
from .checksum import ones_complement_add
from .frames import (
    ARP_LENGTH, ARP_REQUEST, ETH_HEADER, ETHERTYPE_ARP, ETHERTYPE_IPV4, IP_CSUM_OFFSET,
    IP_PROTO_ICMP, IP_PROTO_TCP, IP_PROTO_UDP, IP_SRC_OFFSET, IP_TTL, IP_TTL_OFFSET, IP_VERSION,
    L4_OFFSET, MIN_HEADER_WORDS, TCP_CSUM_OFFSET, TCP_MSS, TCP_OPT_MSS, TCP_OPT_MSS_LENGTH,
    TCP_WINDOW_OFFSET, UDP_CSUM_OFFSET, UDP_LENGTH_OFFSET,
)
from .rx import FrameKind

__all__ = ["TX_REQUEST", "TxRequestSignature", "FrameBuilder"]

#: Cycles after a grant in which the checksum words known from the request are summed (the
#: MAC's preamble, 8 cycles, hides them; the first byte they could collide with is byte 14)
PRESUM_CYCLES = 5

# a byte added to its checksum the cycle after it left must leave two bytes before the
# checksum field: the fields from there to the checksum are summed from the request
assert all(csum - summed_from >= 2 for csum, summed_from in (
    (IP_CSUM_OFFSET, IP_TTL_OFFSET), (UDP_CSUM_OFFSET, UDP_LENGTH_OFFSET),
    (TCP_CSUM_OFFSET, TCP_WINDOW_OFFSET)))

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

    Members
    -------
    valid : Out(1)
        ``request`` describes a frame to send; hold until ``ready``.
    request : Out(TX_REQUEST)
    ready : In(1)
        The builder took the request this cycle (the requester may change it from the next).
    rd_addr : In(16)
        The builder reads payload byte ``rd_addr`` of the requester's buffer ...
    rd_data : Out(8)
        ... which the requester returns one cycle later (a synchronous block-RAM port).
    done : In(1)
        One-cycle pulse: the frame's last payload byte has been read; the buffer is free.
    """

    def __init__(self):
        super().__init__({
            "valid": Out(1), "request": Out(TX_REQUEST), "ready": In(1),
            "rd_addr": In(16), "rd_data": Out(8), "done": In(1),
        })


class FrameBuilder(wiring.Component):
    """Serve requesters round-robin, one whole frame at a time, and stream each frame into
    the MAC at one byte per cycle.

    The IPv4 and L4 checksums are summed from the header bytes as they leave, except the
    words that follow the checksum field, which are summed while the MAC sends the preamble.

    Parameters
    ----------
    ports : int
        Number of requesters.
    ttl : int
        The IPv4 time to live of every frame (64; a FinEmbP node sends 1: its frames stay in
        the layer-2 domain).

    Members
    -------
    req_<k> : In(TxRequestSignature())
        Requester ``k``.
    local_mac, local_ip : In(48), In(32)
        Source addresses.
    m_axis : Out(AXIStreamSignature(8, keep=False))
        Frames for :class:`GmiiTx` (no preamble, padding or FCS).
    grant : Out(range(ports))
        The requester whose frame is on ``m_axis`` (a parent that sends frames to several
        ports picks the port by it).
    """

    def __init__(self, ports, *, ttl=IP_TTL):
        self._ports = check_int("ports", ports, 1, 64)
        self._ttl = check_int("ttl", ttl, 1, 255)
        members = {f"req_{k}": In(TxRequestSignature()) for k in range(ports)}
        members.update({"local_mac": In(48), "local_ip": In(32),
                        "m_axis": Out(AXIStreamSignature(8, keep=False)),
                        "grant": Out(range(max(ports, 2)))})
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        n = self._ports
        reqs = [getattr(self, f"req_{k}") for k in range(n)]
        r = Signal(TX_REQUEST)
        grant = Signal(range(max(n, 2)))
        m.d.comb += self.grant.eq(grant)
        busy = Signal()
        ip_id = Signal(16)

        is_arp = r.kind == FrameKind.ARP
        is_udp = r.kind == FrameKind.UDP
        is_tcp = r.kind == FrameKind.TCP
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

        idx = Signal(11)
        accept = self.m_axis.tvalid & self.m_axis.tready
        hdr_byte = Signal(8)

        # Checksums. Before the MAC takes the first byte (it sends 8 preamble bytes first),
        # the words known from the request are summed, one per cycle: for the IPv4 header
        # the addresses, TTL and protocol; for TCP or UDP the pseudo-header's length and
        # protocol, the payload's sum, the MSS option and the UDP length or TCP window.
        # Every other covered byte is added the cycle after it left (a register apart from
        # the byte's selection): IPv4 bytes 14..21, TCP/UDP bytes 26 up to the length or
        # window field, which all leave at least two cycles before their checksum field.
        ip_acc = Signal(16)
        l4_acc = Signal(16)
        k = Signal(range(PRESUM_CYCLES + 1))
        src, dst = self.local_ip, r.ip_dst
        proto = Signal(8)
        m.d.comb += proto.eq(Mux(is_tcp, IP_PROTO_TCP, Mux(is_udp, IP_PROTO_UDP, IP_PROTO_ICMP)))
        ip_pre = Array([src[16:], src[:16], dst[16:], dst[:16], Cat(proto, Const(self._ttl, 8))])
        l4_pre = Array([l4_len, r.payload_sum,
                        Mux(is_tcp & r.mss, sum(MSS_OPTION[q] << 8 * (1 - q % 2)
                                                for q in range(len(MSS_OPTION))), 0),
                        proto, Mux(is_tcp, r.window, l4_len)])
        with m.If(busy & (k < PRESUM_CYCLES)):
            m.d.sync += [k.eq(k + 1), ip_acc.eq(ones_complement_add(ip_acc, ip_pre[k])),
                         l4_acc.eq(ones_complement_add(l4_acc, l4_pre[k]))]
        left_word = Signal(16)        # the byte that left last, in its half of a word ...
        left_ip = Signal()            # ... which the IPv4 checksum covers
        left_l4 = Signal()            # ... which the TCP or UDP checksum covers
        l4_summed_end = Mux(is_tcp, TCP_WINDOW_OFFSET, UDP_LENGTH_OFFSET)
        m.d.sync += [
            left_word.eq(Mux(idx[0], Cat(hdr_byte, Const(0, 8)), Cat(Const(0, 8), hdr_byte))),
            left_ip.eq(accept & (idx >= ETH_HEADER) & (idx < IP_TTL_OFFSET)),
            left_l4.eq(accept & (idx >= IP_SRC_OFFSET) & (idx < l4_summed_end)),
        ]
        with m.If(left_ip):
            m.d.sync += ip_acc.eq(ones_complement_add(ip_acc, left_word))
        with m.If(left_l4):
            m.d.sync += l4_acc.eq(ones_complement_add(l4_acc, left_word))
        ip_csum = ~ip_acc
        l4_csum = Signal(16)
        m.d.comb += l4_csum.eq(Mux(is_udp & (l4_acc == 0xFFFF), 0xFFFF, ~l4_acc))

        # Header bytes: a table maps (frame kind, variant, index) to one of a few byte
        # sources, so the wide selection is made once for all kinds. The variant is the
        # MSS option of a TCP frame or an ARP request (whose target hardware address is 0).
        def be(value, nbytes):
            return [value.word_select(nbytes - 1 - q, 8) for q in range(nbytes)]

        data_offset = Mux(r.mss, MIN_HEADER_WORDS + 1, MIN_HEADER_WORDS)
        sources = []                        # distinct byte sources, in order of first use

        def source(value):
            for q, s in enumerate(sources):
                if s is value or (isinstance(s, int) and isinstance(value, int) and s == value):
                    return q
            sources.append(value)
            return len(sources) - 1

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
            version_ihl = (IP_VERSION << 4) | MIN_HEADER_WORDS
            return ([version_ihl, 0x00] + ip_fields + [0x40, 0x00, self._ttl, proto] +
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
        # request/reply); beyond the header the byte is payload
        code = Signal(range(64))
        ip_code = Signal(range(64))
        arp_code = Signal(range(64))
        layouts = ((FrameKind.ICMP, frame(0, FrameKind.ICMP)),
                   (FrameKind.UDP, frame(0, FrameKind.UDP)),
                   (FrameKind.TCP, frame(1, FrameKind.TCP)))
        with m.Switch(Cat(idx[:6], is_udp, is_tcp)):
            for q in range(64):
                for kind, layout in layouts:
                    if q < len(layout):
                        pattern = (q | ((kind == FrameKind.UDP) << 6) |
                                   ((kind == FrameKind.TCP) << 7))
                        with m.Case(pattern):
                            m.d.comb += ip_code.eq(source(layout[q]))
        with m.Switch(Cat(idx[:6], r.arp_oper == ARP_REQUEST)):
            for v in (0, 1):
                for q, value in enumerate(frame(v, FrameKind.ARP)):
                    with m.Case(q | (v << 6)):
                        m.d.comb += arp_code.eq(source(value))
        m.d.comb += code.eq(Mux(is_arp, arp_code, ip_code))
        assert len(sources) <= 64, len(sources)
        with m.Switch(code):
            for q, value in enumerate(sources):
                with m.Case(q):
                    m.d.comb += hdr_byte.eq(value)

        # payload reads: the address of the byte that will be current next cycle
        next_idx = Mux(accept, idx + 1, idx)
        rd_addr = Signal(16)
        m.d.comb += rd_addr.eq(r.payload_addr + (next_idx - header))
        rd_data = Signal(8)
        m.d.comb += rd_data.eq(Array(q.rd_data for q in reqs)[grant])
        for q in reqs:
            m.d.comb += q.rd_addr.eq(rd_addr)

        m.d.comb += [
            self.m_axis.tvalid.eq(busy),
            self.m_axis.tdata.eq(Mux(idx < header, hdr_byte, rd_data)),
            self.m_axis.tlast.eq(idx == total - 1),
        ]

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
            with m.If(found):
                m.d.sync += [busy.eq(1), grant.eq(chosen), idx.eq(0), k.eq(0), ip_acc.eq(0),
                             l4_acc.eq(0), r.eq(Array(q.request.as_value() for q in reqs)[chosen])]
                for cand in range(n):
                    with m.If(chosen == cand):
                        m.d.comb += reqs[cand].ready.eq(1)
        with m.Elif(accept):
            m.d.sync += idx.eq(idx + 1)
            with m.If(self.m_axis.tlast):
                m.d.sync += [busy.eq(0), ip_id.eq(ip_id + Mux(is_arp, 0, 1))]
                for cand in range(n):
                    with m.If(grant == cand):
                        m.d.comb += reqs[cand].done.eq(1)
        return m
