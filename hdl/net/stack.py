"""The network engine: GMII MAC, ARP, IPv4, ICMP echo, RBCP over UDP and N TCP sessions on
one MAC and IP address (docs/network.md)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int
from ..stream import AXIStreamSignature, StreamDownsizer, StreamUpsizer
from .checksum import echo_reply_checksum
from .counters import EventCounters
from .frames import (
    ARP_REPLY, ARP_REQUEST, DEFAULT_IP, DEFAULT_MAC, DEFAULT_RBCP_PORT, DEFAULT_TCP_PORT,
    DROP_REASONS, TCP_ACK, TCP_RST, ip_to_int, mac_to_int,
)
from .mac import GmiiRx, GmiiTx
from .rbcp import RbcpBusSignature, RbcpServer
from .rx import FrameKind, FrameParser
from .tcp import TCP_COUNTERS, TcpError, TcpSession, TcpState
from .tx import FrameBuilder

__all__ = ["NetStack", "TcpUserSignature", "STACK_COUNTERS", "GLOBAL_BASE", "GLOBAL_REGS",
           "global_register",
           "GLOBAL_OFFSETS"]

#: Stack counters, in the order of their read addresses (``counter_index``, RBCP): every
#: received frame ends in exactly one of ``delivered`` and the drop reasons;
#: ``tcp_bad_options`` counts TCP segments that passed every check and had malformed
#: options (processed all the same, docs/network.md).
STACK_COUNTERS = ("frames_in", "delivered") + DROP_REASONS + ("frames_out", "tcp_bad_options")

#: RBCP base of the stack's own registers (docs/network.md "global block")
GLOBAL_BASE = 0xFFFF0000
#: offset -> (name, bytes, writable) of the global block; multi-byte values big-endian
GLOBAL_REGS = {
    0x00: ("mac", 6, True),
    0x08: ("ip", 4, True),
    0x0C: ("rto_cycles", 4, True),
    0x10: ("msl_cycles", 4, True),
    0x14: ("rbcp_port", 2, True),
    0x18: ("arp_retry_cycles", 4, True),
    0x1C: ("tcp_port", 2, True),
    0x40: ("counters", 4 * len(STACK_COUNTERS), False),
}
#: name -> offset of the global block's registers
GLOBAL_OFFSETS = {name: offset for offset, (name, _, _) in GLOBAL_REGS.items()}


def global_register(name):
    """``(RBCP address, bytes)`` of the global block's register ``name``."""
    offset = GLOBAL_OFFSETS[name]
    return GLOBAL_BASE + offset, GLOBAL_REGS[offset][1]

_CLOCK_HZ = 125_000_000


class TcpUserSignature(wiring.Signature):
    """One TCP session's user side (``Out`` = towards the user), after SiTCP's interface
    (docs/network.md); see :class:`TcpSession` for each member's meaning.

    Parameters
    ----------
    data_width : int
        Width of the ``tx`` and ``rx`` streams: 8 (SiTCP's byte streams, no ``tkeep``) or a
        wider multiple of 8 up to 1024, with ``tkeep`` (see :class:`NetStack`).
    """

    def __init__(self, data_width=8):
        check_int("data_width", data_width, 8, 1024, multiple_of=8)
        self._data_width = data_width
        keep = data_width > 8
        super().__init__({
            "tx": In(AXIStreamSignature(data_width, keep=keep)),
            "rx": Out(AXIStreamSignature(data_width, keep=keep)),
            "open_req": In(1), "active": In(1), "local_port": In(16), "remote_ip": In(32),
            "remote_port": In(16), "open_ack": Out(1), "close_req": Out(1),
            "close_ack": In(1), "abort": In(1), "error": Out(1), "error_code": Out(TcpError),
            "state": Out(TcpState), "peer_ip": Out(32), "peer_port": Out(16),
            "tx_fill": Out(17),
            "counter_index": In(range(len(TCP_COUNTERS))), "counter_value": Out(32),
            "counters_clear": In(1),
        })

    data_width = property(lambda self: self._data_width)

    def __eq__(self, other):
        return type(other) is type(self) and other._data_width == self._data_width

    def __hash__(self):
        return hash((type(self), self._data_width))


class NetStack(wiring.Component):
    """A SiTCP-class network engine for one GMII port.

    Received frames are parsed on the fly (:class:`FrameParser`); ARP requests for the local
    IP, ICMP echo requests and RBCP requests are answered through one reply slot (a frame that
    needs the slot while it is busy is dropped and counted as ``busy``); TCP segments go to
    the session whose connection or listening port they match (a SYN for a port several
    sessions listen on to the lowest-numbered one), others are answered with RST
    (RFC 9293 §3.10.7.1). Frames leave through a round-robin :class:`FrameBuilder`.

    Parameters
    ----------
    mac, ip : str
        Default addresses (``"02:00:c0:a8:0a:10"``, ``"192.168.10.16"``); RBCP registers at
        :data:`GLOBAL_BASE` change them at run time.
    rbcp_port : int
        UDP port of RBCP (4660).
    tcp_port : int
        The port a server session with ``local_port`` 0 listens on (SiTCP's 24); a register
        at :data:`GLOBAL_BASE` changes it for the next listen. Several sessions may listen on
        one port: a SYN goes to the session whose connection it matches (a retransmitted
        SYN), else to the lowest-numbered listener, so N sessions serve N connections.
    sessions : int
        TCP sessions, 1..8.
    tx_depth, rx_depth : int
        Per-session buffer bytes (see :class:`TcpSession`).
    descriptors : int
        Segments a session's transmit buffer may hold (see :class:`TcpSession`); the
        congestion window never exceeds one less.
    rto_us, msl_us, arp_retry_us : int
        Initial retransmission timeout, maximum segment lifetime and a client's ARP retry
        interval in microseconds at 125 MHz (defaults 200 ms, 1 s and 2 s; docs/network.md);
        registers at :data:`GLOBAL_BASE` change them at run time.
    user_window : int
        Bytes of RBCP address space from 0 that the user bus decodes.
    iss_seed : int
        Initial-sequence-number clock at reset (tests use values near 2**32).
    user_width : int
        Width of the sessions' user streams: 8 (default, SiTCP's) or a wider multiple of 8
        (16..1024). A wider ``tx`` beat is sent byte 0 first, its ``tkeep`` contiguous from
        byte 0, ``tlast`` pushing out the segment as on the byte stream. A wider ``rx`` beat
        leaves when full or, partial and with ``tlast``, when the session has no further
        byte to deliver, so bytes never wait for later ones. Both directions keep one byte
        per cycle (:class:`~hdl.stream.StreamDownsizer`, :class:`~hdl.stream.StreamUpsizer`).

    Members
    -------
    gmii_txd, gmii_tx_en, gmii_tx_er : Out
        To the PHY.
    gmii_rxd, gmii_rx_dv, gmii_rx_er : In
        From the PHY (on the core clock).
    tcp<k> : Out(TcpUserSignature(user_width))
        Session ``k``.
    rbcp : Out(RbcpBusSignature())
        Register bus for user logic: addresses below ``user_window``.
    local_mac, local_ip : Out
        The addresses in use.
    counter_index : In(range(len(STACK_COUNTERS)))
        A counter of :data:`STACK_COUNTERS` for user logic (a status display) ...
    counter_value : Out(32)
        ... and its value in the same cycle. Counters are 32 bits, wrapping, cleared by
        reset; an event shows within ``len(STACK_COUNTERS)`` cycles.
    """

    def __init__(self, *, mac=DEFAULT_MAC, ip=DEFAULT_IP, rbcp_port=DEFAULT_RBCP_PORT,
                 tcp_port=DEFAULT_TCP_PORT,
                 sessions=1, tx_depth=65536, rx_depth=65536, descriptors=64, rto_us=200_000,
                 msl_us=1_000_000, arp_retry_us=2_000_000, user_window=0x10000,
                 iss_seed=0x1000, user_width=8):
        try:
            self._mac = mac_to_int(mac)
        except ValueError as e:
            raise ParameterError("mac", mac, "a MAC address like 02:00:c0:a8:0a:10") from e
        try:
            self._ip = ip_to_int(ip)
        except ValueError as e:
            raise ParameterError("ip", ip, "an IPv4 address like 192.168.10.16") from e
        self._rbcp_port = check_int("rbcp_port", rbcp_port, 1, 65535)
        self._tcp_port = check_int("tcp_port", tcp_port, 1, 65535)
        self._sessions = check_int("sessions", sessions, 1, 8)
        self._rto = check_int("rto_us", rto_us, 1, 30_000_000) * (_CLOCK_HZ // 1_000_000)
        self._msl = check_int("msl_us", msl_us, 1, 30_000_000) * (_CLOCK_HZ // 1_000_000)
        self._arp_retry = (check_int("arp_retry_us", arp_retry_us, 1, 30_000_000) *
                           (_CLOCK_HZ // 1_000_000))
        self._user_window = check_int("user_window", user_window, 1, GLOBAL_BASE)
        self._session_args = TcpSession.check_parameters(
            tx_depth=tx_depth, rx_depth=rx_depth, descriptors=descriptors, iss_seed=iss_seed)
        self._user_width = check_int("user_width", user_width, 8, 1024, multiple_of=8)
        members = {"gmii_txd": Out(8), "gmii_tx_en": Out(1), "gmii_tx_er": Out(1),
                   "gmii_rxd": In(8), "gmii_rx_dv": In(1), "gmii_rx_er": In(1)}
        for k in range(sessions):
            members[f"tcp{k}"] = Out(TcpUserSignature(user_width))
        members.update({"rbcp": Out(RbcpBusSignature()), "local_mac": Out(48),
                        "local_ip": Out(32),
                        "counter_index": In(range(len(STACK_COUNTERS))),
                        "counter_value": Out(32)})
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        m.submodules.mac_rx = mac_rx = GmiiRx()
        m.submodules.mac_tx = mac_tx = GmiiTx()
        m.submodules.parser = parser = FrameParser()
        m.submodules.builder = builder = FrameBuilder(1 + self._sessions)
        m.submodules.rbcp_server = server = RbcpServer([(0, self._user_window),
                                                       (GLOBAL_BASE, 0x10000)])
        m.d.comb += [mac_rx.gmii_rxd.eq(self.gmii_rxd), mac_rx.gmii_rx_dv.eq(self.gmii_rx_dv),
                     mac_rx.gmii_rx_er.eq(self.gmii_rx_er),
                     self.gmii_txd.eq(mac_tx.gmii_txd), self.gmii_tx_en.eq(mac_tx.gmii_tx_en),
                     self.gmii_tx_er.eq(mac_tx.gmii_tx_er)]
        wiring.connect(m, mac_rx.rx, parser.rx)
        wiring.connect(m, builder.m_axis, mac_tx.s_axis)

        local_mac = Signal(48, init=self._mac)
        local_ip = Signal(32, init=self._ip)
        rto = Signal(32, init=self._rto)
        msl = Signal(32, init=self._msl)
        rbcp_port = Signal(16, init=self._rbcp_port)
        tcp_port = Signal(16, init=self._tcp_port)
        arp_retry = Signal(32, init=self._arp_retry)
        m.d.comb += [self.local_mac.eq(local_mac), self.local_ip.eq(local_ip),
                     parser.local_mac.eq(local_mac), parser.local_ip.eq(local_ip),
                     builder.local_mac.eq(local_mac), builder.local_ip.eq(local_ip)]
        f = parser.fields

        # ---- TCP sessions
        sessions = []
        for k in range(self._sessions):
            s = TcpSession(**self._session_args)
            m.submodules[f"tcp{k}"] = s
            sessions.append(s)
            user = getattr(self, f"tcp{k}")
            m.d.comb += [
                s.seg_fields.eq(f), s.seg_kind.eq(parser.kind),
                s.seg_payload_data.eq(parser.payload_data),
                s.seg_payload_valid.eq(parser.payload_valid),
                s.seg_payload_offset.eq(parser.payload_offset),
                s.seg_done.eq(parser.done), s.seg_accept.eq(parser.accept),
                s.seg_arp.eq(parser.arp_seen),
                s.rto_cycles.eq(rto), s.msl_cycles.eq(msl),
                s.arp_retry_cycles.eq(arp_retry), s.default_port.eq(tcp_port),
            ]
            wiring.connect(m, s.tx, getattr(builder, f"req_{k + 1}"))
            if self._user_width == 8:
                wiring.connect(m, wiring.flipped(user.tx), s.s_axis)
                wiring.connect(m, s.m_axis, wiring.flipped(user.rx))
            else:
                m.submodules[f"tcp{k}_tx_downsizer"] = down = StreamDownsizer(self._user_width)
                m.submodules[f"tcp{k}_rx_upsizer"] = up = StreamUpsizer(self._user_width)
                wiring.connect(m, wiring.flipped(user.tx), down.s_axis)
                wiring.connect(m, down.m_axis, s.s_axis)
                wiring.connect(m, s.m_axis, up.s_axis)
                wiring.connect(m, up.m_axis, wiring.flipped(user.rx))
            for name in ("open_req", "active", "local_port", "remote_ip", "remote_port",
                         "close_ack", "abort", "counter_index", "counters_clear"):
                m.d.comb += getattr(s, name).eq(getattr(user, name))
            for name in ("open_ack", "close_req", "error", "error_code", "state", "peer_ip",
                         "peer_port", "tx_fill", "counter_value"):
                m.d.comb += getattr(user, name).eq(getattr(s, name))
        # a SYN goes to the session whose connection it matches, else to the lowest-numbered
        # session listening on its port
        for k, s in enumerate(sessions):
            others = [o.conn_match for o in sessions if o is not s]
            lower = [o.listen_match for o in sessions[:k]]
            m.d.comb += s.listen_block.eq(Cat(Const(0, 1), *others, *lower).any())
        # a segment is claimed when any session matches it: a blocked listener's SYN is
        # taken by the session that blocks it
        claimed = Cat(*(Cat(s.conn_match, s.listen_match) for s in sessions)).any()
        # RFC 9293 §3.10.7.2: in LISTEN, a segment with neither SYN, ACK nor RST (a NULL, FIN
        # or Xmas probe) is dropped without an answer
        listen_drop = (Cat(*(s.port_listening for s in sessions)).any() & ~claimed &
                       ~f.flags.syn & ~f.flags.rst & ~f.flags.ack)

        # ---- reply slot: ARP replies, ICMP echo replies, RBCP replies, RST
        m.submodules.reply_mem = mem = Memory(shape=8, depth=2048, init=[])
        wp = mem.write_port()
        rp = mem.read_port(transparent_for=())
        port = builder.req_0
        req = port.request
        r_kind = Signal(FrameKind)
        r_eth = Signal(48)
        r_ip = Signal(32)
        r_sport = Signal(16)
        r_dport = Signal(16)
        r_seq = Signal(32)
        r_ack = Signal(32)
        r_flags = Signal(8)
        r_len = Signal(11)
        r_sum = Signal(16)
        m.d.comb += [req.kind.eq(r_kind), req.eth_dst.eq(r_eth), req.ip_dst.eq(r_ip),
                     req.arp_oper.eq(ARP_REPLY), req.src_port.eq(r_sport),
                     req.dst_port.eq(r_dport), req.seq.eq(r_seq), req.ack.eq(r_ack),
                     req.flags.eq(r_flags), req.length.eq(r_len), req.payload_sum.eq(r_sum),
                     port.rd_data.eq(rp.data)]
        m.d.comb += [rp.addr.eq(server.buf_addr), server.buf_rdata.eq(rp.data)]
        claim = Signal()              # the reply buffer takes this frame's payload
        icmp_csum = Signal(16)

        # global registers on the RBCP bus
        bus = server.bus
        in_global = bus.addr[16:] == (GLOBAL_BASE >> 16)
        global_rd = Signal(8)
        m.d.comb += [self.rbcp.act.eq(bus.act), self.rbcp.addr.eq(bus.addr),
                     self.rbcp.wd.eq(bus.wd), self.rbcp.we.eq(bus.we & ~in_global),
                     self.rbcp.re.eq(bus.re & ~in_global)]
        global_ack = Signal()
        m.d.sync += global_ack.eq((bus.we | bus.re) & in_global)
        m.d.comb += [bus.ack.eq(Mux(in_global, global_ack, self.rbcp.ack)),
                     bus.rd.eq(Mux(in_global, global_rd, self.rbcp.rd))]

        # counters: read port 0 for RBCP, port 1 for user logic; each counts at most one
        # event per frame, and frames end at most every other cycle
        m.submodules.counters = counters = EventCounters(STACK_COUNTERS, readers=2, spacing=2)
        m.d.comb += [counters.rd_addr[1].eq(self.counter_index),
                     self.counter_value.eq(counters.rd_data[1])]
        m.d.comb += counters.events.frames_out.eq(
            mac_tx.s_axis.tvalid & mac_tx.s_axis.tready & mac_tx.s_axis.tlast)

        global_values = {"mac": local_mac, "ip": local_ip, "rto_cycles": rto,
                         "msl_cycles": msl, "rbcp_port": rbcp_port,
                         "arp_retry_cycles": arp_retry, "tcp_port": tcp_port}
        offset = bus.addr[:16]
        # the counter index is offset bits 2..5: the block is 64-byte aligned
        assert GLOBAL_OFFSETS["counters"] % 64 == 0 and len(STACK_COUNTERS) <= 16
        m.d.comb += counters.rd_addr[0].eq(offset[2:6])
        with m.Switch(offset):
            for base, (name, size, writable) in GLOBAL_REGS.items():
                if name == "counters":
                    # big-endian 32-bit words, the first counter first
                    with m.Case(*range(base, base + size)):
                        m.d.sync += global_rd.eq(counters.rd_data[0].word_select(~offset[:2], 8))
                    continue
                value = global_values[name]
                for b in range(size):
                    with m.Case(base + b):
                        sel = value.word_select(size - 1 - b, 8)
                        m.d.sync += global_rd.eq(sel)
                        if writable:
                            with m.If(bus.we & in_global):
                                m.d.sync += sel.eq(bus.wd)
            with m.Default():
                m.d.sync += global_rd.eq(0)

        def bump(name):
            return counters.events[name].eq(1)

        verdict = parser.done
        with m.FSM() as reply_fsm:
            with m.State("IDLE"):
                with m.If(mac_rx.rx.valid & (mac_rx.rx.index == 0)):
                    m.d.sync += claim.eq(1)
                with m.If(parser.payload_valid & claim &
                          ((parser.kind == FrameKind.ICMP) | (parser.kind == FrameKind.UDP))):
                    m.d.comb += [wp.addr.eq(parser.payload_offset), wp.data.eq(parser.payload_data),
                                 wp.en.eq(1)]
                with m.If(verdict & parser.accept):
                    with m.Switch(parser.kind):
                        with m.Case(FrameKind.ARP):
                            with m.If(f.arp_oper == ARP_REQUEST):
                                m.d.sync += [r_kind.eq(FrameKind.ARP), r_eth.eq(f.sender_mac),
                                             r_ip.eq(f.sender_ip)]
                                m.next = "REQUEST"
                        with m.Case(FrameKind.ICMP):
                            with m.If(claim):
                                m.d.sync += [r_kind.eq(FrameKind.ICMP), r_eth.eq(f.sender_mac),
                                             r_ip.eq(f.sender_ip), r_len.eq(f.payload_len),
                                             icmp_csum.eq(f.icmp_csum)]
                                m.next = "ICMP_TYPE"
                        with m.Case(FrameKind.UDP):
                            with m.If(claim & (f.dst_port == rbcp_port)):
                                m.d.sync += [r_kind.eq(FrameKind.UDP), r_eth.eq(f.sender_mac),
                                             r_ip.eq(f.sender_ip), r_sport.eq(f.dst_port),
                                             r_dport.eq(f.src_port)]
                                m.d.comb += [server.start.eq(1),
                                             server.length.eq(f.payload_len)]
                                m.next = "RBCP"
                        with m.Case(FrameKind.TCP):
                            with m.If(~claimed & ~f.flags.rst & ~listen_drop):
                                syn_fin = f.flags.syn + f.flags.fin
                                m.d.sync += [r_kind.eq(FrameKind.TCP), r_eth.eq(f.sender_mac),
                                             r_ip.eq(f.sender_ip), r_sport.eq(f.dst_port),
                                             r_dport.eq(f.src_port), r_len.eq(0), r_sum.eq(0),
                                             r_seq.eq(Mux(f.flags.ack, f.ack, 0)),
                                             r_ack.eq(f.seq + f.payload_len + syn_fin),
                                             r_flags.eq(Mux(f.flags.ack, TCP_RST,
                                                            TCP_RST | TCP_ACK))]
                                m.next = "REQUEST"
                with m.If(verdict):
                    m.d.sync += claim.eq(0)
            with m.State("ICMP_TYPE"):
                # echo reply: type 8 -> 0
                m.d.comb += [wp.addr.eq(0), wp.data.eq(0), wp.en.eq(1)]
                m.d.sync += icmp_csum.eq(echo_reply_checksum(icmp_csum))
                m.next = "ICMP_CSUM_HI"
            with m.State("ICMP_CSUM_HI"):
                m.d.comb += [wp.addr.eq(2), wp.data.eq(icmp_csum[8:]), wp.en.eq(1)]
                m.next = "ICMP_CSUM_LO"
            with m.State("ICMP_CSUM_LO"):
                m.d.comb += [wp.addr.eq(3), wp.data.eq(icmp_csum[:8]), wp.en.eq(1)]
                m.next = "REQUEST"
            with m.State("RBCP"):
                m.d.comb += [wp.addr.eq(server.buf_addr), wp.data.eq(server.buf_wdata),
                             wp.en.eq(server.buf_we)]
                with m.If(server.done):
                    m.d.sync += [r_len.eq(server.reply_len), r_sum.eq(server.reply_sum)]
                    with m.If(server.reply):
                        m.next = "REQUEST"
                    with m.Else():
                        m.next = "IDLE"
            with m.State("REQUEST"):
                m.d.comb += [port.valid.eq(1), rp.addr.eq(port.rd_addr[:11])]
                with m.If(port.ready):
                    m.next = "SENDING"
            with m.State("SENDING"):
                m.d.comb += rp.addr.eq(port.rd_addr[:11])
                with m.If(port.done):
                    m.next = "IDLE"

        # frame accounting: each frame ends in exactly one counter
        busy_slot = Signal()
        m.d.comb += busy_slot.eq(~reply_fsm.ongoing("IDLE"))
        with m.If(verdict):
            m.d.comb += bump("frames_in")
            with m.If(~parser.accept):
                with m.Switch(parser.reason):
                    for i, name in enumerate(DROP_REASONS):
                        with m.Case(i):
                            m.d.comb += bump(name)
            with m.Else():
                with m.Switch(parser.kind):
                    with m.Case(FrameKind.ARP):
                        with m.If((f.arp_oper == ARP_REQUEST) & busy_slot):
                            m.d.comb += bump("busy")
                        with m.Else():
                            m.d.comb += bump("delivered")
                    with m.Case(FrameKind.ICMP):
                        with m.If(busy_slot | ~claim):
                            m.d.comb += bump("busy")
                        with m.Else():
                            m.d.comb += bump("delivered")
                    with m.Case(FrameKind.UDP):
                        with m.If(f.dst_port != rbcp_port):
                            m.d.comb += bump("no_port")
                        with m.Elif(busy_slot | ~claim):
                            m.d.comb += bump("busy")
                        with m.Else():
                            m.d.comb += bump("delivered")
                    with m.Case(FrameKind.TCP):
                        with m.If(claimed):
                            m.d.comb += bump("delivered")
                        with m.Elif(listen_drop):
                            m.d.comb += bump("listen_no_syn")
                        with m.Else():
                            m.d.comb += bump("no_port")
                        with m.If(parser.options_malformed):
                            m.d.comb += bump("tcp_bad_options")
        return m
