"""Receive-side frame parser: Ethernet, ARP, IPv4, ICMP, UDP and TCP headers and checksums,
checked on the fly at one byte per cycle (docs/network.md)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import data, enum, wiring
from amaranth.lib.wiring import In, Out

from .checksum import ones_complement_add
from .frames import (
    ARP_REPLY, ARP_REQUEST, ARP_SHA_OFFSET, ARP_SPA_OFFSET, DROP_REASONS, ETH_SRC_OFFSET,
    IP_SRC_OFFSET, ETH_HEADER, ETHERTYPE_ARP, ETHERTYPE_IPV4, ICMP_ECHO_REQUEST,
    IP_PROTO_ICMP, IP_PROTO_TCP, IP_PROTO_UDP, IP_VERSION, MIN_HEADER_WORDS, TCP_OPT_MSS,
    TCP_OPT_MSS_LENGTH, ARP_HEADER_FIELDS, ARP_OFFSET, ETH_HEADER_FIELDS, ICMP_HEADER_FIELDS,
    IP_OFFSET, IP_PROTO_OFFSET, IPV4_HEADER_FIELDS, TCP_FLAGS, TCP_HEADER_FIELDS,
    UDP_HEADER_FIELDS,
)
from .mac import RxByteSignature

__all__ = ["RX_FIELDS", "FrameKind", "DROP_CODE", "FrameParser"]

#: Header fields of the frame being received, valid from the byte that completes them until
#: the next frame's bytes overwrite them (at least 4 cycles after ``done``). ``sender_mac``
#: and ``sender_ip`` are where an answer goes: the ARP sender hardware and protocol addresses
#: of an ARP frame, else the Ethernet and IPv4 source addresses (one register each, so the
#: stack and the sessions need no selection between the two).
RX_FIELDS = data.StructLayout({
    "sender_mac": 48, "sender_ip": 32,
    "arp_oper": 16, "arp_tpa": 32,
    "ip_dst": 32, "ip_proto": 8, "ip_len": 16, "l4_len": 16,
    "src_port": 16, "dst_port": 16, "udp_len": 16, "udp_csum": 16,
    "seq": 32, "ack": 32, "flags": TCP_FLAGS, "window": 16, "doff": 4, "mss": 16, "has_mss": 1,
    "icmp_type": 8, "icmp_code": 8, "icmp_csum": 16,
    "payload_len": 16,
})


class FrameKind(enum.Enum, shape=2):
    ARP = 0
    ICMP = 1
    UDP = 2
    TCP = 3


#: drop reason -> code of the ``reason`` output
DROP_CODE = {name: code for code, name in enumerate(DROP_REASONS)}


#: the TCP header without options: options start after it
_TCP_FIXED_HEADER = sum(TCP_HEADER_FIELDS["urgent"])
assert all(UDP_HEADER_FIELDS[port] == TCP_HEADER_FIELDS[port] for port in ("src_port", "dst_port"))


def _span(table, first, last):
    """Bytes from the start of field ``first`` to the end of field ``last`` of ``table``."""
    return table[last][0] + table[last][1] - table[first][0]


def _shift_in(field, byte):
    return field.eq(Cat(byte, field[:-8]))


def _ipv4_version_ihl_ok(value):
    """The first IPv4 header byte names version 4 and a header of 20 bytes or more."""
    return (value[4:8] == IP_VERSION) & (value[0:4] >= MIN_HEADER_WORDS)


class FrameParser(wiring.Component):
    """Parse a received frame's headers while it arrives; after its last byte tell whether
    it is for this node and well formed, and what it is.

    Members
    -------
    rx : In(RxByteSignature())
        Bytes and end status from :class:`GmiiRx`.
    local_mac, local_ip : In(48), In(32)
        This node's addresses.
    fields : Out(RX_FIELDS)
        Header fields, captured in place (``payload_len`` a cycle after the last header byte
        it follows: valid during the payload and at ``done``).
    payload_data, payload_valid, payload_offset : Out
        The L4 payload's bytes as they pass: the whole ICMP message, the UDP data, the TCP
        data (after the options); ``payload_offset`` counts from 0 without a gap. Bytes beyond
        the IP total length (Ethernet padding, FCS) are not payload, nor are any bytes of an
        ARP frame, of an IPv4 header shorter than 20 bytes or of a TCP segment whose data
        offset is below 5 (tb/test_net_formal.py proves these rules).
    kind : Out(FrameKind)
        What the frame is, from its EtherType and IP protocol (a register, a cycle after
        them: valid during the payload).
    done : Out(1)
        One-cycle pulse after the frame: ``accept``, ``reason`` and ``kind`` are valid.
    accept : Out(1)
        The frame passed every check: an ARP request or reply for ``local_ip``, an ICMP echo
        request, a UDP datagram or a TCP segment to ``local_ip`` with correct checksums.
    reason : Out(range(len(DROP_REASONS)))
        Why it was dropped, when ``accept`` is low (docs/network.md counters).
    group : Out(1), with ``groups`` or ``limited_broadcast``
        With ``done``: the frame was sent to a multicast group or to the IPv4 limited
        broadcast address (accepted only as UDP, see the parameters).
    arp_seen : Out(1)
        With ``done``: the frame was a well-formed ARP request or reply for this MAC or
        broadcast, whatever its target address (RFC 826 refreshes a known sender's entry
        before it looks at the target; ``fields.sender_*`` are its sender's addresses).
    options_malformed : Out(1)
        With ``done``: the frame was a TCP segment whose options were malformed (a length
        below 2, or an option running past the data offset, docs/network.md). Options are parsed
        up to there (an MSS option before it counts); the verdict does not change.

    Parameters
    ----------
    groups : sequence of (int, int)
        The MAC and IPv4 address of each multicast group whose UDP datagrams are accepted
        (a FinEmbP node's group); none by default.
    limited_broadcast : bool
        Accept UDP datagrams to 255.255.255.255 in broadcast frames (a node without an
        address, as DHCP clients).
    """

    def __init__(self, *, groups=(), limited_broadcast=False):
        # (MAC, IP) of multicast groups whose UDP datagrams are accepted, as ints
        self._groups = tuple((int(mac), int(ip)) for mac, ip in groups)
        self._limited_broadcast = bool(limited_broadcast)
        super().__init__({
            "rx": In(RxByteSignature()),
            "local_mac": In(48), "local_ip": In(32),
            "fields": Out(RX_FIELDS),
            "payload_data": Out(8), "payload_valid": Out(1), "payload_offset": Out(11),
            "kind": Out(FrameKind),
            "done": Out(1), "accept": Out(1), "reason": Out(range(len(DROP_REASONS))),
            "arp_seen": Out(1), "options_malformed": Out(1),
            **({"group": Out(1)} if groups or limited_broadcast else {}),
        })

    def elaborate(self, platform):
        m = Module()
        f = self.fields
        rx = self.rx
        i = rx.index
        byte = rx.data
        v = rx.valid

        dst_mine = Signal()
        dst_bcast = Signal()
        ethertype = Signal(16)
        arp_fixed = Signal(48)          # htype, ptype, hlen, plen
        ver_ihl = Signal(8)
        frag = Signal(16)
        ip_acc = Signal(16)
        l4_acc = Signal(16)
        pseudo_acc = Signal(16)
        l4_off = Signal(11, init=2047)
        pl_start = Signal(11, init=2047)
        tcp_csum = Signal(16)
        ihl4 = Cat(Const(0, 2), ver_ihl[0:4])
        ip_end = Signal(17)             # an IP total length up to 65535 must not wrap
        m.d.comb += ip_end.eq(ETH_HEADER + f.ip_len)

        j = Signal(11)
        m.d.comb += j.eq(i - l4_off)
        in_l4 = Signal()
        m.d.comb += in_l4.eq((i >= l4_off) & (i < ip_end) & (i >= 18))
        word = Mux(i[0], Cat(byte, Const(0, 8)), Cat(Const(0, 8), byte))

        with m.If(v & (i == 0)):
            m.d.sync += [dst_mine.eq(1), dst_bcast.eq(1), l4_off.eq(2047), pl_start.eq(2047),
                         ip_acc.eq(0), l4_acc.eq(0), pseudo_acc.eq(0), f.has_mss.eq(0),
                         f.ip_len.eq(0xFFFF), f.doff.eq(0), f.mss.eq(0)]
        dst_group = Signal(max(len(self._groups), 1))
        with m.If(v & (i < 6)):
            for g, (gmac, _) in enumerate(self._groups):
                gbyte = Const(gmac, 48).word_select((5 - i[:3]).as_unsigned()[:3], 8)
                with m.If(byte != gbyte):
                    m.d.sync += dst_group[g].eq(0)
                with m.If(i == 0):
                    m.d.sync += dst_group[g].eq(byte == (gmac >> 40))
        with m.If(v & (i < 6)):
            own = self.local_mac.word_select((5 - i[:3]).as_unsigned()[:3], 8)
            with m.If(byte != own):
                m.d.sync += dst_mine.eq(0)
            with m.If(byte != 0xFF):
                m.d.sync += dst_bcast.eq(0)
            with m.If(i == 0):
                m.d.sync += [dst_mine.eq(byte == self.local_mac[40:48]),
                             dst_bcast.eq(byte == 0xFF)]

        def capture(field, offset, nbytes, index=i, valid=v):
            with m.If(valid & (index >= offset) & (index < offset + nbytes)):
                m.d.sync += _shift_in(field, byte)

        def capture_field(field, header, table, name, index=i, valid=v):
            """Capture ``table[name]`` of the header that starts at byte ``header``."""
            offset, nbytes = table[name]
            capture(field, header + offset, nbytes, index, valid)

        capture_field(ethertype, 0, ETH_HEADER_FIELDS, "ethertype")
        arp_frame = ethertype == ETHERTYPE_ARP
        def within(offset, nbytes):
            return (i >= offset) & (i < offset + nbytes)

        with m.If(v & (within(ETH_SRC_OFFSET, 6) |
                       (arp_frame & (i >= ARP_SHA_OFFSET) & (i < ARP_SHA_OFFSET + 6)))):
            m.d.sync += _shift_in(f.sender_mac, byte)
        with m.If(v & Mux(arp_frame, within(ARP_SPA_OFFSET, 4), within(IP_SRC_OFFSET, 4))):
            m.d.sync += _shift_in(f.sender_ip, byte)
        # ARP (RFC 826): htype, ptype, hlen and plen in one register
        capture(arp_fixed, ARP_OFFSET, _span(ARP_HEADER_FIELDS, "htype", "plen"))
        capture_field(f.arp_oper, ARP_OFFSET, ARP_HEADER_FIELDS, "oper")
        capture_field(f.arp_tpa, ARP_OFFSET, ARP_HEADER_FIELDS, "tpa")
        # IPv4 (RFC 791)
        capture_field(ver_ihl, IP_OFFSET, IPV4_HEADER_FIELDS, "version_ihl")
        capture_field(f.ip_len, IP_OFFSET, IPV4_HEADER_FIELDS, "total_length")
        capture_field(frag, IP_OFFSET, IPV4_HEADER_FIELDS, "flags_fragment")
        capture_field(f.ip_proto, IP_OFFSET, IPV4_HEADER_FIELDS, "protocol")
        capture_field(f.ip_dst, IP_OFFSET, IPV4_HEADER_FIELDS, "dst")
        # only an IPv4 header of 20 bytes or more has an L4 part: no other frame's bytes
        # become payload (the verdict drops those frames; their bytes must not reach a
        # consumer before it)
        with m.If(v & (i == IP_OFFSET + IPV4_HEADER_FIELDS["version_ihl"][0]) &
                  (ethertype == ETHERTYPE_IPV4) & _ipv4_version_ihl_ok(byte)):
            m.d.sync += l4_off.eq(ETH_HEADER + Cat(Const(0, 2), byte[0:4]))
        with m.If(v & (i >= 14) & (i < l4_off)):
            m.d.sync += ip_acc.eq(ones_complement_add(ip_acc, word))
        # the pseudo-header (RFC 9293 §3.1): source and destination address as they pass,
        # then the protocol and the L4 length in the two cycles after the protocol byte
        addresses = IP_OFFSET + IPV4_HEADER_FIELDS["src"][0]
        with m.If(v & (i >= addresses) &
                  (i < addresses + _span(IPV4_HEADER_FIELDS, "src", "dst"))):
            m.d.sync += pseudo_acc.eq(ones_complement_add(pseudo_acc, word))
        with m.If(v & (i == IP_PROTO_OFFSET + 1)):
            m.d.sync += [pseudo_acc.eq(ones_complement_add(pseudo_acc, f.ip_proto)),
                         f.l4_len.eq(f.ip_len - ihl4)]
        with m.If(v & (i == IP_PROTO_OFFSET + 2)):
            m.d.sync += pseudo_acc.eq(ones_complement_add(pseudo_acc, f.l4_len))

        # ``kind`` and ``payload_len`` from flip-flops, a cycle after the header bytes they
        # follow (ethertype, protocol, lengths, TCP data offset): all of those arrive at
        # least eight bytes before the payload and the verdict, where they are used, and
        # the verdict's consumers start at registers
        kind = self.kind
        with m.Switch(ethertype):
            with m.Case(ETHERTYPE_ARP):
                m.d.sync += kind.eq(FrameKind.ARP)
            with m.Default():
                with m.Switch(f.ip_proto):
                    with m.Case(IP_PROTO_ICMP):
                        m.d.sync += kind.eq(FrameKind.ICMP)
                    with m.Case(IP_PROTO_UDP):
                        m.d.sync += kind.eq(FrameKind.UDP)
                    with m.Default():
                        m.d.sync += kind.eq(FrameKind.TCP)
        with m.If(v & (i == IP_PROTO_OFFSET + 1)):
            with m.Switch(f.ip_proto):
                with m.Case(IP_PROTO_ICMP):
                    m.d.sync += pl_start.eq(0)
                with m.Case(IP_PROTO_UDP):
                    m.d.sync += pl_start.eq(8)

        # L4 headers, relative to the end of the IP header
        lv = v & in_l4
        with m.If(lv):
            m.d.sync += l4_acc.eq(ones_complement_add(l4_acc, word))
        for field, table, name in (
                (f.icmp_type, ICMP_HEADER_FIELDS, "type"),
                (f.icmp_code, ICMP_HEADER_FIELDS, "code"),
                (f.icmp_csum, ICMP_HEADER_FIELDS, "checksum"),
                (f.src_port, TCP_HEADER_FIELDS, "src_port"),      # UDP's are at the same place
                (f.dst_port, TCP_HEADER_FIELDS, "dst_port"),
                (f.udp_len, UDP_HEADER_FIELDS, "length"),
                (f.udp_csum, UDP_HEADER_FIELDS, "checksum"),
                (f.seq, TCP_HEADER_FIELDS, "seq"),
                (f.ack, TCP_HEADER_FIELDS, "ack"),
                (f.flags.as_value(), TCP_HEADER_FIELDS, "flags"),
                (f.window, TCP_HEADER_FIELDS, "window"),
                (tcp_csum, TCP_HEADER_FIELDS, "checksum")):
            capture_field(field, 0, table, name, j, lv)
        is_tcp = f.ip_proto == IP_PROTO_TCP
        with m.If(lv & (j == TCP_HEADER_FIELDS["data_offset"][0])):
            m.d.sync += f.doff.eq(byte[4:8])
            with m.If(is_tcp & (byte[4:8] >= MIN_HEADER_WORDS)):
                m.d.sync += pl_start.eq(Cat(Const(0, 2), byte[4:8]))

        # TCP options (RFC 9293 §3.2): only MSS (length 4) is used; everything else is
        # skipped by length. A length below 2, or an option that runs past the data offset,
        # is malformed (docs/network.md): parsing stops, the segment is processed, the stack
        # counts it.
        opt_is_mss = Signal()
        opt_left = Signal(8)
        opt_mss = Signal(8)
        opt_bad = Signal()
        with m.If(v & (i == 0)):
            m.d.sync += opt_bad.eq(0)
        with m.FSM(name="options") as options:
            with m.State("WAIT"):
                with m.If(lv & is_tcp & (j == _TCP_FIXED_HEADER - 1)):
                    m.next = "KIND"
            with m.State("KIND"):
                with m.If(v & (i == 0)):
                    m.next = "WAIT"
                with m.Elif(lv & (j < pl_start)):
                    m.d.sync += opt_is_mss.eq(byte == TCP_OPT_MSS)
                    with m.If(byte == 0):
                        m.next = "WAIT"
                    with m.Elif(byte != 1):
                        m.next = "LENGTH"
            with m.State("LENGTH"):
                with m.If(v & (i == 0)):
                    m.next = "WAIT"
                with m.Elif(lv & (j < pl_start)):
                    m.d.sync += [opt_left.eq(byte - 2),
                                 opt_is_mss.eq(opt_is_mss & (byte == TCP_OPT_MSS_LENGTH))]
                    with m.If(byte < 2):
                        m.d.sync += opt_bad.eq(1)
                        m.next = "WAIT"
                    with m.Elif(byte == 2):
                        m.next = "KIND"
                    with m.Else():
                        m.next = "BODY"
            with m.State("BODY"):
                with m.If(v & (i == 0)):
                    m.next = "WAIT"
                with m.Elif(lv & (j < pl_start)):
                    m.d.sync += [opt_left.eq(opt_left - 1), opt_mss.eq(byte)]
                    with m.If(opt_left == 1):
                        m.next = "KIND"
                        with m.If(opt_is_mss):
                            m.d.sync += [f.mss.eq(Cat(byte, opt_mss)), f.has_mss.eq(1)]
        # at the verdict an option still waiting for its length or body was cut by the end
        # of the header
        options_cut = options.ongoing("LENGTH") | options.ongoing("BODY")

        m.d.comb += [
            self.payload_data.eq(byte),
            self.payload_offset.eq(j - pl_start),
            self.payload_valid.eq(lv & (j >= pl_start)),
        ]

        # verdict, one cycle after the end pulse
        frame_bytes = rx.index - 4
        l4_sum = ones_complement_add(l4_acc, pseudo_acc)
        arp_well_formed = ((arp_fixed == 0x000108000604) &
                           ((f.arp_oper == ARP_REQUEST) | (f.arp_oper == ARP_REPLY)))
        arp_ok = arp_well_formed & (f.arp_tpa == self.local_ip)
        ip_ok = (_ipv4_version_ihl_ok(ver_ihl) & (f.ip_len >= ihl4) &
                 (ip_end <= frame_bytes) & (ip_acc == 0xFFFF))
        proto_ok = Signal()
        l4_ok = Signal()
        with m.Switch(f.ip_proto):
            with m.Case(IP_PROTO_ICMP):
                m.d.comb += [proto_ok.eq((f.icmp_type == ICMP_ECHO_REQUEST) & (f.icmp_code == 0)),
                             l4_ok.eq((l4_acc == 0xFFFF) & (f.l4_len >= 8))]
            with m.Case(IP_PROTO_UDP):
                m.d.comb += [proto_ok.eq(1),
                             l4_ok.eq((f.udp_len == f.l4_len) & (f.l4_len >= 8) &
                                      ((f.udp_csum == 0) | (l4_sum == 0xFFFF)))]
            with m.Case(IP_PROTO_TCP):
                m.d.comb += [proto_ok.eq(1),
                             l4_ok.eq((f.doff >= MIN_HEADER_WORDS) &
                                      (Cat(Const(0, 2), f.doff) <= f.l4_len) &
                                      (l4_sum == 0xFFFF))]
        with m.Switch(f.ip_proto):
            with m.Case(IP_PROTO_ICMP):
                m.d.sync += f.payload_len.eq(f.l4_len)
            with m.Case(IP_PROTO_UDP):
                m.d.sync += f.payload_len.eq(f.l4_len - 8)
            with m.Default():
                m.d.sync += f.payload_len.eq(f.l4_len - Cat(Const(0, 2), f.doff))

        # a group's (or the limited broadcast's) datagrams: UDP only, in a frame to that
        # group's MAC (or to broadcast)
        group_ok = Signal()
        is_udp = f.ip_proto == IP_PROTO_UDP
        for g, (_, gip) in enumerate(self._groups):
            with m.If(is_udp & dst_group[g] & (f.ip_dst == gip)):
                m.d.comb += group_ok.eq(1)
        if self._limited_broadcast:
            with m.If(is_udp & dst_bcast & (f.ip_dst == 0xFFFFFFFF)):
                m.d.comb += group_ok.eq(1)
        reason = Signal(range(len(DROP_REASONS)))
        accept = Signal()
        with m.If(rx.err_size):
            m.d.comb += reason.eq(DROP_CODE["size"])
        with m.Elif(rx.err_rx_er):
            m.d.comb += reason.eq(DROP_CODE["rx_er"])
        with m.Elif(~rx.ok):
            m.d.comb += reason.eq(DROP_CODE["fcs"])
        with m.Elif(~(dst_mine | dst_bcast | (dst_group.any() if self._groups else 0))):
            m.d.comb += reason.eq(DROP_CODE["not_mine"])
        with m.Elif(ethertype == ETHERTYPE_ARP):
            with m.If(arp_ok):
                m.d.comb += accept.eq(1)
            with m.Else():
                m.d.comb += reason.eq(DROP_CODE["not_mine"])
        with m.Elif(ethertype != ETHERTYPE_IPV4):
            m.d.comb += reason.eq(DROP_CODE["not_mine"])
        with m.Elif(~ip_ok):
            m.d.comb += reason.eq(DROP_CODE["ip_header"])
        with m.Elif(frag[13] | (frag[0:13] != 0)):
            m.d.comb += reason.eq(DROP_CODE["fragment"])
        with m.Elif((f.ip_dst != self.local_ip) &
                    (~group_ok if self._groups or self._limited_broadcast else 1)):
            m.d.comb += reason.eq(DROP_CODE["not_mine"])
        with m.Elif(~proto_ok):
            m.d.comb += reason.eq(DROP_CODE["protocol"])
        with m.Elif(~l4_ok):
            m.d.comb += reason.eq(DROP_CODE["l4_checksum"])
        with m.Else():
            m.d.comb += accept.eq(1)
        m.d.sync += [self.done.eq(rx.end), self.accept.eq(accept), self.reason.eq(reason),
                     self.arp_seen.eq(~rx.err_size & ~rx.err_rx_er & rx.ok &
                                      (dst_mine | dst_bcast) & arp_frame & arp_well_formed),
                     self.options_malformed.eq(~arp_frame & is_tcp & (opt_bad | options_cut))]
        if self._groups or self._limited_broadcast:
            m.d.sync += self.group.eq(group_ok)
        return m
