"""Transmit-side frame builder: Ethernet, ARP, IPv4, ICMP, UDP and TCP headers with their
checksums, then the payload read from the requester's buffer (spec net.md §1.1-§1.3)."""

from amaranth.hdl import Array, Cat, Const, Module, Mux, Signal
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from ..stream import AXIStreamSignature
from .checksum import ones_complement_add
from .frames import (
    ETHERTYPE_ARP, ETHERTYPE_IPV4, IP_PROTO_ICMP, IP_PROTO_TCP, IP_PROTO_UDP, IP_TTL, TCP_MSS,
    TCP_OPT_MSS,
)
from .rx import FrameKind

__all__ = ["TX_REQUEST", "TxRequestSignature", "FrameBuilder"]

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

    The IPv4 and L4 checksums are summed one 16-bit word per cycle from the latched request
    while the MAC sends the preamble and the first header bytes: they are complete 26 cycles
    after the grant, before the MAC takes header byte 24 (which is at least 32 cycles).

    Parameters
    ----------
    ports : int
        Number of requesters.

    Members
    -------
    req_<k> : In(TxRequestSignature())
        Requester ``k``.
    local_mac, local_ip : In(48), In(32)
        Source addresses.
    m_axis : Out(AXIStreamSignature(8, keep=False))
        Frames for :class:`GmiiTx` (no preamble, padding or FCS).
    """

    def __init__(self, ports):
        self._ports = ports
        members = {f"req_{k}": In(TxRequestSignature()) for k in range(ports)}
        members.update({"local_mac": In(48), "local_ip": In(32),
                        "m_axis": Out(AXIStreamSignature(8, keep=False))})
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        n = self._ports
        reqs = [getattr(self, f"req_{k}") for k in range(n)]
        r = Signal(TX_REQUEST)
        grant = Signal(range(max(n, 2)))
        busy = Signal()
        ip_id = Signal(16)

        is_arp = r.kind == FrameKind.ARP
        is_udp = r.kind == FrameKind.UDP
        is_tcp = r.kind == FrameKind.TCP
        l4_header = Mux(is_tcp, Mux(r.mss, 24, 20), Mux(is_udp, 8, 0))
        l4_len = Signal(16)
        header = Signal(11)
        total = Signal(11)
        m.d.comb += [
            l4_len.eq(l4_header + r.length),
            header.eq(Mux(is_arp, 42, 34 + l4_header)),
            total.eq(Mux(is_arp, 42, 34 + l4_len)),
        ]
        proto = Signal(8)
        m.d.comb += proto.eq(Mux(is_tcp, IP_PROTO_TCP, Mux(is_udp, IP_PROTO_UDP, IP_PROTO_ICMP)))
        ip_total = 20 + l4_len
        src, dst = self.local_ip, r.ip_dst
        data_offset = Signal(4)
        m.d.comb += data_offset.eq(Mux(r.mss, 6, 5))
        tcp_flags_word = Cat(r.flags, Const(0, 4), data_offset)

        # checksums, one word per cycle
        ip_words = [0x4500, ip_total, ip_id, 0x4000, Cat(proto, Const(IP_TTL, 8)),
                    src[16:], src[:16], dst[16:], dst[:16]]
        l4_words = [src[16:], src[:16], dst[16:], dst[:16], proto, l4_len,
                    r.src_port, r.dst_port,
                    Mux(is_tcp, r.seq[16:], l4_len), Mux(is_tcp, r.seq[:16], 0),
                    Mux(is_tcp, r.ack[16:], 0), Mux(is_tcp, r.ack[:16], 0),
                    Mux(is_tcp, tcp_flags_word, 0), Mux(is_tcp, r.window, 0),
                    Mux(is_tcp & r.mss, (TCP_OPT_MSS << 8) | 4, 0),
                    Mux(is_tcp & r.mss, TCP_MSS, 0),
                    r.payload_sum]
        ip_acc = Signal(16)
        l4_acc = Signal(16)
        k = Signal(range(32))
        with m.If(busy & (k < len(l4_words))):
            m.d.sync += k.eq(k + 1)
            m.d.sync += l4_acc.eq(ones_complement_add(l4_acc, Array(l4_words)[k]))
            with m.If(k < len(ip_words)):
                m.d.sync += ip_acc.eq(ones_complement_add(ip_acc, Array(ip_words)[k]))
        ip_csum = ~ip_acc
        l4_csum = Signal(16)
        m.d.comb += l4_csum.eq(Mux(is_udp & (l4_acc == 0xFFFF), 0xFFFF, ~l4_acc))

        # header bytes
        def be(value, nbytes):
            return [value.word_select(nbytes - 1 - q, 8) if not isinstance(value, int)
                    else (value >> (8 * (nbytes - 1 - q))) & 0xFF for q in range(nbytes)]

        eth = be(r.eth_dst, 6) + be(self.local_mac, 6)
        ethertype = Mux(is_arp, ETHERTYPE_ARP, ETHERTYPE_IPV4)
        eth += be(ethertype, 2)
        tha = Mux(r.arp_oper == 1, 0, r.eth_dst)
        arp = be(0x0001080006040000, 8)[:7] + [Cat(r.arp_oper, Const(0, 6))]
        arp += be(self.local_mac, 6) + be(self.local_ip, 4) + be(tha, 6) + be(r.ip_dst, 4)
        ip = [0x45, 0x00] + be(ip_total, 2) + be(ip_id, 2) + [0x40, 0x00, IP_TTL, proto]
        ip += be(ip_csum, 2) + be(src, 4) + be(dst, 4)
        udp = be(r.src_port, 2) + be(r.dst_port, 2) + be(l4_len, 2) + be(l4_csum, 2)
        tcp = be(r.src_port, 2) + be(r.dst_port, 2) + be(r.seq, 4) + be(r.ack, 4)
        tcp += be(tcp_flags_word, 2) + be(r.window, 2) + be(l4_csum, 2) + [0, 0]
        tcp += [TCP_OPT_MSS, 4] + be(Const(TCP_MSS, 16), 2)

        idx = Signal(11)
        hdr_byte = Signal(8)
        with m.Switch(idx):
            for q in range(58):
                with m.Case(q):
                    if q < 14:
                        m.d.comb += hdr_byte.eq(eth[q])
                    else:
                        a = q - 14
                        ip_b = ip[a] if a < 20 else Mux(is_tcp, tcp[a - 20] if a - 20 < 24 else 0,
                                                        udp[a - 20] if a - 20 < 8 else 0)
                        arp_b = arp[a] if a < 28 else 0
                        m.d.comb += hdr_byte.eq(Mux(is_arp, arp_b, ip_b))

        # payload reads: the address of the byte that will be current next cycle
        accept = self.m_axis.tvalid & self.m_axis.tready
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
