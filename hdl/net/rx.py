"""Receive-side frame parser: Ethernet, ARP, IPv4, ICMP, UDP and TCP headers and checksums,
checked on the fly at one or two bytes per cycle (docs/network.md)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import data, enum, wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int
from .checksum import ones_complement_add
from .frames import (
    ARP_HEADER_FIELDS,
    ARP_OFFSET,
    ARP_REPLY,
    ARP_REQUEST,
    ARP_SHA_OFFSET,
    ARP_SPA_OFFSET,
    DROP_REASONS,
    ETH_HEADER,
    ETH_HEADER_FIELDS,
    ETH_SRC_OFFSET,
    ETHERTYPE_ARP,
    ETHERTYPE_IPV4,
    ICMP_ECHO_REQUEST,
    ICMP_HEADER_FIELDS,
    IP_OFFSET,
    IP_PROTO_ICMP,
    IP_PROTO_OFFSET,
    IP_PROTO_TCP,
    IP_PROTO_UDP,
    IP_SRC_OFFSET,
    IP_VERSION,
    IPV4_HEADER_FIELDS,
    L4_OFFSET,
    MIN_HEADER_WORDS,
    TCP_FLAGS,
    TCP_HEADER_FIELDS,
    TCP_OPT_MSS,
    TCP_OPT_MSS_LENGTH,
    UDP_HEADER_FIELDS,
)
from .mac import RxBeatSignature

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
#: the beats at which the pseudo-header's protocol and L4 length are summed: in the L4 header
#: of a frame of at least 64 bytes, after the addresses
_PSEUDO_PROTO = L4_OFFSET
_PSEUDO_LENGTH = L4_OFFSET + 2
assert all(UDP_HEADER_FIELDS[port] == TCP_HEADER_FIELDS[port] for port in ("src_port", "dst_port"))


def _span(table, first, last):
    """Bytes from the start of field ``first`` to the end of field ``last`` of ``table``."""
    return table[last][0] + table[last][1] - table[first][0]


def _ipv4_version_ihl_ok(value):
    """The first IPv4 header byte names version 4 and a header of 20 bytes or more."""
    return (value[4:8] == IP_VERSION) & (value[0:4] >= MIN_HEADER_WORDS)


def _options_step(st, byte, active):
    """One byte through the TCP options parser (RFC 9293 §3.2): ``st`` and the result are
    dicts of ``state``, ``left``, ``is_mss``, ``mss_high``, ``mss``, ``has_mss``, ``bad``.
    Only MSS (length 4) is used; everything else is skipped by length. A length below 2 is
    malformed: parsing stops."""
    kind, length, body = st["state"] == _OPT_KIND, st["state"] == _OPT_LENGTH, \
        st["state"] == _OPT_BODY
    go = active
    nxt = dict(st)
    # KIND: End of list stops, NOP stays, any other kind waits for its length
    kind_next = Mux(byte == 0, OPTIONS_WAIT, Mux(byte == 1, _OPT_KIND, _OPT_LENGTH))
    # LENGTH: below 2 is malformed, 2 has no body
    length_next = Mux(byte < 2, OPTIONS_WAIT, Mux(byte == 2, _OPT_KIND, _OPT_BODY))
    body_ends = st["left"] == 1
    nxt["state"] = Mux(go & kind, kind_next, Mux(go & length, length_next,
                       Mux(go & body & body_ends, _OPT_KIND, st["state"])))
    nxt["is_mss"] = Mux(go & kind, byte == TCP_OPT_MSS,
                        Mux(go & length, st["is_mss"] & (byte == TCP_OPT_MSS_LENGTH),
                            st["is_mss"]))
    nxt["left"] = Mux(go & length, (byte - 2)[:8], Mux(go & body, (st["left"] - 1)[:8],
                                                         st["left"]))
    nxt["mss_high"] = Mux(go & body, byte, st["mss_high"])
    take_mss = go & body & body_ends & st["is_mss"]
    nxt["mss"] = Mux(take_mss, Cat(byte, st["mss_high"]), st["mss"])
    nxt["has_mss"] = st["has_mss"] | take_mss
    nxt["bad"] = st["bad"] | (go & length & (byte < 2))
    return nxt


#: the TCP option walker's states
OPTIONS_WAIT, _OPT_KIND, _OPT_LENGTH, _OPT_BODY = range(4)


class FrameParser(wiring.Component):
    """Parse a received frame's headers while it arrives; after its last byte tell whether
    it is for this node and well formed, and what it is.

    Members
    -------
    rx : In(RxBeatSignature(lanes))
        Beats and end status from a :class:`GmiiRx` (1 lane) or an :class:`RxBeatBridge`
        (2 lanes).
    local_mac, local_ip : In(48), In(32)
        This node's addresses.
    fields : Out(RX_FIELDS)
        Header fields, captured in place (``payload_len`` a cycle after the last header byte
        it follows: valid during the payload and at ``done``).
    payload_data, payload_valid, payload_keep, payload_offset : Out
        The L4 payload as it passes: the whole ICMP message, the UDP data, the TCP data
        (after the options). ``payload_data`` holds bytes ``payload_offset`` ..
        ``payload_offset + lanes - 1`` of it (offset counts from 0 without a gap, a multiple
        of ``lanes``), ``payload_keep`` which of them are payload (contiguous from lane 0).
        Bytes beyond the IP total length (Ethernet padding, FCS) are not payload, nor are
        any bytes of an ARP frame, of an IPv4 header shorter than 20 bytes or of a TCP
        segment whose data offset is below 5 (tb/test_net_formal.py proves these rules).
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
    lanes : int
        Bytes per beat, 1 or 2. Every header this parser reads starts at an even offset
        (Ethernet's 14 bytes, IPv4 and TCP headers in 4-byte words), so with 2 lanes each
        field sits in a fixed lane and each payload starts in lane 0.
    groups : sequence of (int, int)
        The MAC and IPv4 address of each multicast group whose UDP datagrams are accepted
        (a FinEmbP node's group); none by default.
    limited_broadcast : bool
        Accept UDP datagrams to 255.255.255.255 in broadcast frames (a node without an
        address, as DHCP clients).
    """

    def __init__(self, *, lanes=1, groups=(), limited_broadcast=False):
        self._lanes = check_int("lanes", lanes, 1, 2)
        # (MAC, IP) of multicast groups whose UDP datagrams are accepted, as ints
        self._groups = tuple((int(mac), int(ip)) for mac, ip in groups)
        self._limited_broadcast = bool(limited_broadcast)
        super().__init__({
            "rx": In(RxBeatSignature(lanes)),
            "local_mac": In(48), "local_ip": In(32),
            "fields": Out(RX_FIELDS),
            "payload_data": Out(8 * lanes), "payload_valid": Out(1),
            "payload_keep": Out(lanes), "payload_offset": Out(11),
            "kind": Out(FrameKind),
            "done": Out(1), "accept": Out(1), "reason": Out(range(len(DROP_REASONS))),
            "arp_seen": Out(1), "options_malformed": Out(1),
            **({"group": Out(1)} if groups or limited_broadcast else {}),
        })

    lanes = property(lambda self: self._lanes)

    def elaborate(self, platform):
        m = Module()
        L = self._lanes
        f = self.fields
        rx = self.rx
        i = rx.index
        v = rx.valid
        lane = [rx.data[8 * k:8 * k + 8] for k in range(L)]

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

        def at(offset, index=i, valid=v):
            """The beat holding byte ``offset`` (of the frame, or of ``index``'s header) is
            here; the byte is in lane ``offset % L``."""
            return valid & (index == offset - offset % L)

        def byte_at(offset):
            return lane[offset % L]

        def word(k, index=i):
            """The beat's 16-bit contribution to a checksum: lane ``k``'s byte in the high or
            low half of its word (by the byte's own index)."""
            if L == 2:
                return Cat(Const(0, 8), lane[k]) if k == 0 else Cat(lane[k], Const(0, 8))
            return Mux(index[0], Cat(lane[0], Const(0, 8)), Cat(Const(0, 8), lane[0]))

        def beat_word(include_second=1, index=i):
            if L == 2:
                return Cat(Mux(include_second, lane[1], 0), lane[0])
            return word(0, index)

        j = Signal(11)
        m.d.comb += j.eq(i - l4_off)
        lv = Signal()                   # the beat's first byte is in the L4 part
        m.d.comb += lv.eq(v & (i >= l4_off) & (i < ip_end) & (i >= 18))
        # with 2 lanes the second byte is in the L4 part unless the datagram ends before it
        second_in = (i + 1 < ip_end) if L == 2 else Const(0)

        with m.If(v & (i == 0)):
            m.d.sync += [l4_off.eq(2047), pl_start.eq(2047),
                         ip_acc.eq(0), l4_acc.eq(0), pseudo_acc.eq(0),
                         f.ip_len.eq(0xFFFF), f.doff.eq(0)]

        # destination MAC: this node's, broadcast, or a group's
        dst_group = Signal(max(len(self._groups), 1))
        targets = [(dst_mine, self.local_mac), (dst_bcast, Const(0xFFFFFFFFFFFF, 48))]
        targets += [(dst_group[g], Const(gmac, 48)) for g, (gmac, _) in enumerate(self._groups)]
        for start in range(0, 6, L):
            for flag, address in targets:
                same = Cat(*(lane[k] == address.word_select(5 - (start + k), 8)
                             for k in range(L) if start + k < 6)).all()
                with m.If(at(start)):
                    m.d.sync += flag.eq(same if start == 0 else flag & same)

        def capture(field, offset, nbytes, index=i, valid=v, when=1):
            """Write bytes ``offset`` .. ``offset + nbytes - 1`` into ``field`` (big-endian)
            as they pass."""
            for k in range(nbytes):
                with m.If(at(offset + k, index, valid) & when):
                    m.d.sync += field.word_select(nbytes - 1 - k, 8).eq(byte_at(offset + k))

        def capture_field(field, header, table, name, index=i, valid=v):
            """Capture ``table[name]`` of the header that starts at byte ``header``."""
            offset, nbytes = table[name]
            capture(field, header + offset, nbytes, index, valid)

        capture_field(ethertype, 0, ETH_HEADER_FIELDS, "ethertype")
        arp_frame = ethertype == ETHERTYPE_ARP
        # where an answer goes: the ARP sender's addresses of an ARP frame, else the Ethernet
        # and IPv4 sources (the ARP sender's come later and overwrite)
        capture(f.sender_mac, ETH_SRC_OFFSET, 6)
        capture(f.sender_mac, ARP_SHA_OFFSET, 6, when=arp_frame)
        capture(f.sender_ip, IP_SRC_OFFSET, 4, when=~arp_frame)
        capture(f.sender_ip, ARP_SPA_OFFSET, 4, when=arp_frame)
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
        version_ihl = IP_OFFSET + IPV4_HEADER_FIELDS["version_ihl"][0]
        vbyte = byte_at(version_ihl)
        with m.If(at(version_ihl) & (ethertype == ETHERTYPE_IPV4) & _ipv4_version_ihl_ok(vbyte)):
            m.d.sync += l4_off.eq(ETH_HEADER + Cat(Const(0, 2), vbyte[0:4]))
        with m.If(v & (i >= IP_OFFSET) & (i < l4_off)):
            m.d.sync += ip_acc.eq(ones_complement_add(ip_acc, beat_word()))
        # the pseudo-header (RFC 9293 §3.1): source and destination address as they pass,
        # then the protocol and the L4 length, at two beats of the L4 header that every
        # frame long enough to be accepted has
        addresses = IP_OFFSET + IPV4_HEADER_FIELDS["src"][0]
        with m.If(v & (i >= addresses) &
                  (i < addresses + _span(IPV4_HEADER_FIELDS, "src", "dst"))):
            m.d.sync += pseudo_acc.eq(ones_complement_add(pseudo_acc, beat_word()))
        with m.If(at(IP_PROTO_OFFSET + 1)):
            m.d.sync += f.l4_len.eq(f.ip_len - ihl4)
        with m.If(at(_PSEUDO_PROTO)):
            m.d.sync += pseudo_acc.eq(ones_complement_add(pseudo_acc, f.ip_proto))
        with m.If(at(_PSEUDO_LENGTH)):
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
        with m.If(at(IP_PROTO_OFFSET + 1)):
            with m.Switch(f.ip_proto):
                with m.Case(IP_PROTO_ICMP):
                    m.d.sync += pl_start.eq(0)
                with m.Case(IP_PROTO_UDP):
                    m.d.sync += pl_start.eq(8)

        # L4 headers, relative to the end of the IP header (a multiple of 4 bytes, so the
        # lanes stay those of a header at offset 0)
        with m.If(lv):
            m.d.sync += l4_acc.eq(ones_complement_add(l4_acc, beat_word(second_in, j)))
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
        doff_at = TCP_HEADER_FIELDS["data_offset"][0]
        doff_byte = byte_at(doff_at)
        with m.If(at(doff_at, j, lv)):
            m.d.sync += f.doff.eq(doff_byte[4:8])
            with m.If(is_tcp & (doff_byte[4:8] >= MIN_HEADER_WORDS)):
                m.d.sync += pl_start.eq(Cat(Const(0, 2), doff_byte[4:8]))

        # TCP options (RFC 9293 §3.2), one byte after the other through ``_options_step``,
        # lanes in order. A length below 2, or an option that runs past the data offset,
        # is malformed (docs/network.md): parsing stops, the segment is processed, the stack
        # counts it.
        self._options_state = Signal(2, name="opt_state")   # (the formal check reads it)
        opt = {"state": self._options_state, "left": Signal(8, name="opt_left"),
               "is_mss": Signal(name="opt_is_mss"), "mss_high": Signal(8, name="opt_mss_high"),
               "mss": f.mss, "has_mss": f.has_mss, "bad": Signal(name="opt_bad")}
        in_options = lv & is_tcp & (j < pl_start)       # pl_start and j are multiples of L
        st = dict(opt)
        for k in range(L):
            st = _options_step(st, lane[k], in_options & (Const(1) if k == 0 else second_in))
        with m.If(v & (i == 0)):
            m.d.sync += [opt["state"].eq(OPTIONS_WAIT), f.mss.eq(0), f.has_mss.eq(0),
                         opt["bad"].eq(0)]
        with m.Elif(at(_TCP_FIXED_HEADER - 1, j, lv) & is_tcp):
            m.d.sync += opt["state"].eq(_OPT_KIND)
        with m.Elif(in_options):
            m.d.sync += [opt[name].eq(value) for name, value in st.items()]
        # at the verdict an option still waiting for its length or body was cut by the end
        # of the header
        options_cut = (opt["state"] == _OPT_LENGTH) | (opt["state"] == _OPT_BODY)

        m.d.comb += [
            self.payload_data.eq(rx.data),
            self.payload_offset.eq(j - pl_start),
            self.payload_valid.eq(lv & (j >= pl_start)),
            self.payload_keep.eq(Cat(Const(1), second_in) if L == 2 else 1),
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
                     self.options_malformed.eq(~arp_frame & is_tcp & (opt["bad"] | options_cut))]
        if self._groups or self._limited_broadcast:
            m.d.sync += self.group.eq(group_ok)
        return m
