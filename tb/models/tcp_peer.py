"""A TCP peer model that acknowledges like Linux (RFC 9293, RFC 5681 receiver rules as the
kernel applies them): it sends a byte stream within the engine's window, acknowledges every
second full segment (or after ``ack_delay`` cycles, at once for out-of-order data), keeps
out-of-order segments, and retransmits from SND.UNA after ``rto`` cycles without progress.
It works on raw frame bytes (struct, no scapy in the data path) so long transfers stay fast.
Written from the RFCs, not from the RTL; used by the fuzz bench and the throughput bench.
"""

import struct

from scapy.utils import checksum

from hdl.net.frames import (
    ETHERTYPE_IPV4,
    IP_PROTO_TCP,
    IP_PROTO_UDP,
    IP_TTL,
    TCP_ACK,
    TCP_FIN,
    TCP_MSS,
    TCP_PSH,
    TCP_RST,
    TCP_SYN,
    ip_to_int,
    mac_to_int,
)

__all__ = ["TcpPeerModel", "parse_tcp_frame", "tcp_options_mss", "tcp_frame", "udp_frame",
           "fix_ip_checksum", "fix_tcp_checksum"]


def _mac(value):
    return value.to_bytes(6, "big")


def _ipv4_frame(src_mac, dst_mac, src_ip, dst_ip, proto, l4, ip_id):
    ip = struct.pack("!BBHHHBBHII", 0x45, 0, 20 + len(l4), ip_id, 0x4000, IP_TTL, proto, 0,
                     src_ip, dst_ip)
    ip = ip[:10] + struct.pack("!H", checksum(ip)) + ip[12:]
    return _mac(dst_mac) + _mac(src_mac) + struct.pack("!H", ETHERTYPE_IPV4) + ip + l4


def _l4_checksum(src_ip, dst_ip, proto, l4):
    return checksum(struct.pack("!IIBBH", src_ip, dst_ip, 0, proto, len(l4)) + l4)


def tcp_frame(src_mac, dst_mac, src_ip, dst_ip, sport, dport, seq, ack, flags, window,
              payload=b"", options=b"", ip_id=0):
    """An Ethernet/IPv4/TCP frame (no FCS) with correct checksums."""
    doff = (20 + len(options)) // 4
    tcp = struct.pack("!HHIIBBHHH", sport, dport, seq & 0xFFFFFFFF, ack & 0xFFFFFFFF,
                      doff << 4, flags, window, 0, 0) + options + payload
    csum = _l4_checksum(src_ip, dst_ip, IP_PROTO_TCP, tcp)
    tcp = tcp[:16] + struct.pack("!H", csum) + tcp[18:]
    return _ipv4_frame(src_mac, dst_mac, src_ip, dst_ip, IP_PROTO_TCP, tcp, ip_id)


def udp_frame(src_mac, dst_mac, src_ip, dst_ip, sport, dport, payload, ip_id=0):
    """An Ethernet/IPv4/UDP frame (no FCS) with its checksum (0 sent as 0xFFFF)."""
    udp = struct.pack("!HHHH", sport, dport, 8 + len(payload), 0) + bytes(payload)
    csum = _l4_checksum(src_ip, dst_ip, IP_PROTO_UDP, udp) or 0xFFFF
    return _ipv4_frame(src_mac, dst_mac, src_ip, dst_ip, IP_PROTO_UDP,
                       udp[:6] + struct.pack("!H", csum) + udp[8:], ip_id)


def fix_ip_checksum(frame):
    """Recompute the IPv4 header checksum of ``frame`` (a bytearray, 20-byte header) in
    place, after a mutation."""
    frame[24:26] = b"\x00\x00"
    frame[24:26] = checksum(bytes(frame[14:34])).to_bytes(2, "big")


def fix_tcp_checksum(frame):
    """Recompute the TCP checksum of ``frame`` over its IP payload in place."""
    total = int.from_bytes(frame[16:18], "big")
    seg = bytearray(frame[34:14 + total])
    seg[16:18] = b"\x00\x00"
    src, dst = struct.unpack("!II", frame[26:34])
    frame[50:52] = _l4_checksum(src, dst, IP_PROTO_TCP, bytes(seg)).to_bytes(2, "big")


def parse_tcp_frame(frame):
    """``dict`` of the TCP segment in ``frame`` (no FCS), or ``None`` if it is not one;
    checksums are verified (a bad one raises ``AssertionError``)."""
    if len(frame) < 54 or struct.unpack("!H", frame[12:14])[0] != ETHERTYPE_IPV4:
        return None
    ihl = (frame[14] & 0xF) * 4
    if frame[23] != IP_PROTO_TCP:
        return None
    total = struct.unpack("!H", frame[16:18])[0]
    ip = frame[14:14 + ihl]
    assert checksum(ip) == 0, "engine sent a bad IPv4 header checksum"
    seg = frame[14 + ihl:14 + total]
    src_ip, dst_ip = struct.unpack("!II", frame[26:34])
    pseudo = struct.pack("!IIBBH", src_ip, dst_ip, 0, IP_PROTO_TCP, len(seg))
    assert checksum(pseudo + seg) == 0, "engine sent a bad TCP checksum"
    sport, dport, seq, ack, off, flags, window = struct.unpack("!HHIIBBH", seg[:16])
    doff = (off >> 4) * 4
    return dict(dst_mac=int.from_bytes(frame[0:6], "big"),
                src_mac=int.from_bytes(frame[6:12], "big"), src_ip=src_ip, dst_ip=dst_ip,
                sport=sport, dport=dport, seq=seq, ack=ack, flags=flags, window=window,
                options=seg[20:doff], payload=seg[doff:])


def tcp_options_mss(options):
    """Walk a TCP header's option bytes as a minimal receiver does (RFC 9293 §3.2,
    docs/network.md): EOL ends the list, NOP is one byte, every other option is skipped by its
    length; MSS is taken from a kind-2 option of length 4. Return ``(mss or None,
    malformed)``, where ``malformed`` says that a length below 2 or an option running past
    the end stopped the walk (an MSS before that point is kept)."""
    mss, at = None, 0
    while at < len(options):
        kind = options[at]
        if kind == 0:
            break
        if kind == 1:
            at += 1
            continue
        if at + 1 >= len(options) or options[at + 1] < 2 or at + options[at + 1] > len(options):
            return mss, True
        length = options[at + 1]
        if kind == 2 and length == 4:
            mss = struct.unpack("!H", options[at + 2:at + 4])[0]
        at += length
    return mss, False


def _lt(a, b):
    return ((a - b) & 0xFFFFFFFF) >= 0x80000000


class TcpPeerModel:
    """One connection's peer. Call :meth:`on_frame` for each frame the engine sends and
    :meth:`poll` regularly with the current cycle; both return frames to send to the engine.

    Parameters
    ----------
    mac, ip, port : peer addresses.
    engine_mac, engine_ip, engine_port : the engine's.
    isn : int
        Our initial sequence number.
    window : int
        Receive window we announce (no window scaling: at most 65535).
    ack_every : int
        Full-size segments per ACK (Linux: 2).
    ack_delay : int
        Cycles before a delayed ACK.
    rto : int
        Cycles without progress before resending from SND.UNA.
    ack_latency : int
        Cycles between deciding to acknowledge and the ACK leaving (host turnaround,
        interrupt moderation).
    delay_from_last : bool
        The delayed-ACK timer restarts with every segment (an ACK only after a burst, as the
        seed paper's capture shows), instead of running from the first unacknowledged one.
    """

    def __init__(self, *, mac, ip, port, engine_mac, engine_ip, engine_port, isn=1000,
                 window=65535, ack_every=2, ack_delay=2500, rto=200_000, mss=TCP_MSS,
                 ack_latency=0, delay_from_last=False):
        self.mac, self.ip, self.port = mac_to_int(mac), ip_to_int(ip), port
        self.emac, self.eip, self.eport = mac_to_int(engine_mac), ip_to_int(engine_ip), \
            engine_port
        self.iss = isn
        self.snd_una = self.snd_nxt = isn
        self.rcv_nxt = None
        self.window = window
        self.ack_every, self.ack_delay, self.rto, self.mss = ack_every, ack_delay, rto, mss
        self.send_data = bytearray()       # bytes queued to send (index 0 = ISN + 1)
        self.received = bytearray()
        self.ooo = {}                      # seq -> payload held out of order
        self.peer_window = 0
        self.peer_mss = 536
        self.established = False
        self.fin_received = False
        self.unacked_segments = 0
        self.ack_due_at = None
        self.last_progress = 0
        self.retransmissions = 0
        self.acks_sent = 0
        self.segments_received = 0
        self.rst_received = 0
        self.ip_id = 0
        self.ack_latency = ack_latency
        self.delay_from_last = delay_from_last
        self.scheduled = []                # cycles at which decided ACKs leave the host
        self.listening = False

    # ---- frames
    def _frame(self, flags, seq, payload=b"", options=b""):
        self.ip_id = (self.ip_id + 1) & 0xFFFF
        return tcp_frame(self.mac, self.emac, self.ip, self.eip, self.port, self.eport, seq,
                         self.rcv_nxt or 0, flags, min(self.window, 65535), payload, options,
                         self.ip_id)

    def syn(self):
        """Our SYN (with MSS, as Linux sends it with more options the engine ignores)."""
        opts = struct.pack("!BBH", 2, 4, self.mss) + b"\x01\x03\x03\x07"
        self.snd_nxt = self.iss + 1
        return self._frame(TCP_SYN, self.iss, options=opts)

    def ack_frame(self):
        self.unacked_segments = 0
        self.ack_due_at = None
        self.acks_sent += 1
        return self._frame(TCP_ACK, self.snd_nxt)

    def listen(self):
        """Accept the engine's SYN (passive open) instead of sending one."""
        self.listening = True

    def _ack(self, cycle):
        """An ACK now, or one built ``ack_latency`` cycles later (with the numbers then)."""
        if not self.ack_latency:
            return [self.ack_frame()]
        self.unacked_segments = 0
        self.ack_due_at = None
        self.scheduled.append(cycle + self.ack_latency)
        return []

    def queue(self, data):
        self.send_data += data

    @property
    def bytes_acked(self):
        return (self.snd_una - self.iss - 1) & 0xFFFFFFFF

    # ---- engine -> peer
    def on_frame(self, frame, cycle):
        seg = parse_tcp_frame(frame)
        if seg is None or seg["dport"] != self.port or (self.eport and
                                                         seg["sport"] != self.eport):
            return []
        flags = seg["flags"]
        out = []
        if flags & TCP_RST:
            self.rst_received += 1
            return []
        if flags & TCP_SYN:
            opts = seg["options"]
            if len(opts) >= 4 and opts[0] == 2:
                self.peer_mss = struct.unpack("!H", opts[2:4])[0]
            self.rcv_nxt = (seg["seq"] + 1) & 0xFFFFFFFF
            if self.listening and not flags & TCP_ACK:
                self.eport = seg["sport"]          # a client's port is only known now
                self.peer_window = seg["window"]
                self.snd_nxt = self.iss + 1
                opts = struct.pack("!BBH", 2, 4, self.mss)
                return [self._frame(TCP_SYN | TCP_ACK, self.iss, options=opts)]
            if flags & TCP_ACK and seg["ack"] == (self.iss + 1) & 0xFFFFFFFF:
                self.snd_una = seg["ack"]
                self.established = True
                self.peer_window = seg["window"]
                out.append(self.ack_frame())
            return out
        if flags & TCP_ACK and self.rcv_nxt is not None:
            ack = seg["ack"]
            if _lt(self.snd_una, ack) and not _lt(self.snd_nxt, ack):
                self.snd_una = ack
                self.last_progress = cycle
            self.peer_window = seg["window"]
            if not self.established and ack == (self.iss + 1) & 0xFFFFFFFF:
                self.established = True
        payload = seg["payload"]
        if payload or flags & TCP_FIN:
            self.segments_received += 1
            seq = seg["seq"]
            if seq == self.rcv_nxt:
                self.received += payload
                self.rcv_nxt = (self.rcv_nxt + len(payload)) & 0xFFFFFFFF
                while self.rcv_nxt in self.ooo:
                    held = self.ooo.pop(self.rcv_nxt)
                    self.received += held
                    self.rcv_nxt = (self.rcv_nxt + len(held)) & 0xFFFFFFFF
                if flags & TCP_FIN:
                    self.rcv_nxt = (self.rcv_nxt + 1) & 0xFFFFFFFF
                    self.fin_received = True
                    out += self._ack(cycle)
                    return out
                self.unacked_segments += 1
                if self.unacked_segments >= self.ack_every or self.ooo:
                    out += self._ack(cycle)
                elif self.ack_due_at is None or self.delay_from_last:
                    self.ack_due_at = cycle + self.ack_delay
            else:
                if _lt(self.rcv_nxt, seq):
                    self.ooo.setdefault(seq, payload)
                out += self._ack(cycle)            # duplicate or out of order: at once
        return out

    # ---- peer -> engine
    def poll(self, cycle, *, max_frames=2):
        """Frames to send now: a due delayed ACK, a retransmission after ``rto``, then new
        data up to the engine's window."""
        out = []
        if self.scheduled and self.scheduled[0] <= cycle:
            while self.scheduled and self.scheduled[0] <= cycle:
                self.scheduled.pop(0)
            out.append(self.ack_frame())
        if self.ack_due_at is not None and cycle >= self.ack_due_at:
            out += self._ack(cycle)
        if not self.established:
            return out
        in_flight = (self.snd_nxt - self.snd_una) & 0xFFFFFFFF
        if in_flight and cycle - self.last_progress > self.rto:
            self.snd_nxt = self.snd_una
            self.last_progress = cycle
            self.retransmissions += 1
        mss = min(self.mss, self.peer_mss)
        while len(out) < max_frames:
            offset = (self.snd_nxt - self.iss - 1) & 0xFFFFFFFF
            if offset >= len(self.send_data):
                break
            in_flight = (self.snd_nxt - self.snd_una) & 0xFFFFFFFF
            room = self.peer_window - in_flight
            n = min(mss, len(self.send_data) - offset)
            if room < n:
                break
            payload = bytes(self.send_data[offset:offset + n])
            flags = TCP_ACK | (TCP_PSH if offset + n == len(self.send_data) else 0)
            out.append(self._frame(flags, self.snd_nxt, payload))
            if not in_flight:
                self.last_progress = cycle
            self.snd_nxt = (self.snd_nxt + n) & 0xFFFFFFFF
            self.unacked_segments = 0
            self.ack_due_at = None
        return out
