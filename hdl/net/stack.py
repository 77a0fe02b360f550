"""The network engine: GMII MAC, ARP, IPv4, ICMP echo, RBCP over UDP and N TCP sessions on
one MAC and IP address (docs/network.md)."""

from amaranth.hdl import Cat, ClockDomain, Const, DomainRenamer, Module, ResetSignal
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int
from ..stream import AXIStreamSignature, StreamDownsizer, StreamRepacker, StreamUpsizer
from .counters import EventCounters
from .frames import (
    ARP_REQUEST,
    DEFAULT_IP,
    DEFAULT_MAC,
    DEFAULT_RBCP_PORT,
    DEFAULT_TCP_PORT,
    DROP_REASONS,
    ip_to_int,
    mac_to_int,
)
from .mac import DEFAULT_CLOCK_HZ, GMII_HZ, GmiiRx, GmiiTx, RxBeatBridge, TxBeatBridge
from .rbcp import RbcpBusSignature
from .registers import (
    GLOBAL_BASE,
    GLOBAL_OFFSETS,
    GLOBAL_REGS,
    STACK_COUNTERS,
    GlobalRegisters,
    global_register,
)
from .responders import (
    ArpResponder,
    IcmpEchoResponder,
    ParsedFrameSignature,
    RbcpResponder,
    TcpResetResponder,
)
from .rx import FrameKind, FrameParser
from .tcp import TCP_COUNTERS, TcpError, TcpSession, TcpState
from .tx import FrameBuilder

__all__ = ["NetStack", "TcpUserSignature", "STACK_COUNTERS", "GLOBAL_BASE", "GLOBAL_REGS",
           "global_register", "GLOBAL_OFFSETS"]

#: the stack's own requesters on the frame builder, before the sessions'
RESPONDERS = ("arp", "icmp", "rbcp", "rst")



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
        interval in microseconds (defaults 200 ms, 1 s and 2 s; docs/network.md);
        registers at :data:`GLOBAL_BASE` change them at run time, in cycles of ``sync``.
    user_window : int
        Bytes of RBCP address space from 0 that the user bus decodes.
    iss_seed : int
        Initial-sequence-number clock at reset (tests use values near 2**32).
    user_width : int
        Width of the sessions' user streams: 8 (default, SiTCP's) or a wider multiple of 8
        (16..1024). A wider ``tx`` beat is sent byte 0 first, its ``tkeep`` contiguous from
        byte 0, ``tlast`` pushing out the segment as on the byte stream. A wider ``rx`` beat
        leaves when full or, partial and with ``tlast``, when the session has no further
        byte to deliver, so bytes never wait for later ones. Each direction moves up to
        ``lanes`` bytes per cycle, so with 2 lanes a byte-wide user side runs at half the
        line rate.
    lanes : int
        Bytes the engine moves per cycle. 1: GMII, the protocol logic and the user side on
        one clock (``sync``, 125 MHz: a fabric that closes the whole engine at the byte
        clock). 2: the protocol logic two bytes wide on ``sync`` at half the GMII clock
        (62.5 MHz: line rate both ways, as LiteEth runs its 32-bit core at 62.5 MHz), the
        GMII receiver and transmitter on their own clocks (``gmii_rx_clk``,
        ``gmii_tx_clk``), each crossing to ``sync`` through an asynchronous FIFO
        (:class:`~hdl.net.mac.RxBeatBridge`, :class:`~hdl.net.mac.TxBeatBridge`).
    clock_hz : int
        The ``sync`` clock, for the timers given in microseconds (default: 125 MHz with one
        lane, 62.5 MHz with two). With two lanes it must be at least half the GMII clock.

    Members
    -------
    gmii_txd, gmii_tx_en, gmii_tx_er : Out
        To the PHY (on ``gmii_tx_clk`` with 2 lanes).
    gmii_rxd, gmii_rx_dv, gmii_rx_er : In
        From the PHY (on ``gmii_rx_clk`` with 2 lanes, else on the core clock).
    gmii_rx_clk, gmii_tx_clk : In(1), with 2 lanes
        The PHY's receive clock and the 125 MHz transmit clock (GMII's RX_CLK and GTX_CLK).
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
                 iss_seed=0x1000, user_width=8, lanes=2, clock_hz=None):
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
        self._lanes = check_int("lanes", lanes, 1, 2)
        if clock_hz is None:
            clock_hz = DEFAULT_CLOCK_HZ[self._lanes]
        self._clock_hz = check_int("clock_hz", clock_hz, GMII_HZ // self._lanes, 1_000_000_000)
        per_us = self._clock_hz / 1_000_000
        self._rto = round(check_int("rto_us", rto_us, 1, 30_000_000) * per_us)
        self._msl = round(check_int("msl_us", msl_us, 1, 30_000_000) * per_us)
        self._arp_retry = round(check_int("arp_retry_us", arp_retry_us, 1, 30_000_000) * per_us)
        self._user_window = check_int("user_window", user_window, 1, GLOBAL_BASE)
        self._user_width = check_int("user_width", user_width, 8, 1024, multiple_of=8)
        # a byte-wide user reads the receive ring a byte at a time
        self._session_args = TcpSession.check_parameters(
            tx_depth=tx_depth, rx_depth=rx_depth, descriptors=descriptors, iss_seed=iss_seed,
            lanes=self._lanes, read_lanes=1 if user_width == 8 else None,
            clock_hz=self._clock_hz)
        members = {"gmii_txd": Out(8), "gmii_tx_en": Out(1), "gmii_tx_er": Out(1),
                   "gmii_rxd": In(8), "gmii_rx_dv": In(1), "gmii_rx_er": In(1)}
        if self._lanes == 2:
            members.update({"gmii_rx_clk": In(1), "gmii_tx_clk": In(1)})
        for k in range(sessions):
            members[f"tcp{k}"] = Out(TcpUserSignature(user_width))
        members.update({"rbcp": Out(RbcpBusSignature()), "local_mac": Out(48),
                        "local_ip": Out(32),
                        "counter_index": In(range(len(STACK_COUNTERS))),
                        "counter_value": Out(32)})
        super().__init__(members)

    lanes = property(lambda self: self._lanes)
    clock_hz = property(lambda self: self._clock_hz)

    def connect_gmii(self, m, port):
        """Drive this stack's GMII members from ``port`` (an ``Out(GmiiSignature(clocks=
        lanes == 2))`` of a parent) and ``port``'s outputs from them."""
        m.d.comb += [self.gmii_rxd.eq(port.rxd), self.gmii_rx_dv.eq(port.rx_dv),
                     self.gmii_rx_er.eq(port.rx_er), port.txd.eq(self.gmii_txd),
                     port.tx_en.eq(self.gmii_tx_en), port.tx_er.eq(self.gmii_tx_er)]
        if self._lanes == 2:
            m.d.comb += [self.gmii_rx_clk.eq(port.rx_clk), self.gmii_tx_clk.eq(port.tx_clk)]

    def elaborate(self, platform):
        m = Module()
        L = self._lanes
        mac_rx, mac_tx = GmiiRx(), GmiiTx()
        m.submodules.parser = parser = FrameParser(lanes=L)
        m.submodules.builder = builder = FrameBuilder(len(RESPONDERS) + self._sessions, lanes=L)
        if L == 1:
            m.submodules.mac_rx, m.submodules.mac_tx = mac_rx, mac_tx
            wiring.connect(m, mac_rx.rx, parser.rx)
            wiring.connect(m, builder.m_axis, mac_tx.s_axis)
            rx_beats = mac_rx.rx
        else:
            # GMII on the PHY's clocks, everything else two bytes wide on ``sync``
            for name, clock in (("gmii_rx", self.gmii_rx_clk), ("gmii_tx", self.gmii_tx_clk)):
                m.domains += (cd := ClockDomain(name, local=True))
                m.d.comb += cd.clk.eq(clock)
                # the core's reset, taken into the GMII clock through flip-flops (a
                # synchronous reset; the PHY's clocks run while it is held)
                m.submodules[f"{name}_reset"] = FFSynchronizer(ResetSignal("sync"), cd.rst,
                                                               o_domain=name, init=1)
            m.submodules.mac_rx = DomainRenamer("gmii_rx")(mac_rx)
            m.submodules.mac_tx = DomainRenamer("gmii_tx")(mac_tx)
            m.submodules.rx_bridge = rx_bridge = RxBeatBridge(gmii_domain="gmii_rx")
            m.submodules.tx_bridge = tx_bridge = TxBeatBridge(gmii_domain="gmii_tx")
            wiring.connect(m, mac_rx.rx, rx_bridge.gmii)
            wiring.connect(m, rx_bridge.rx, parser.rx)
            wiring.connect(m, builder.m_axis, tx_bridge.s_axis)
            wiring.connect(m, tx_bridge.gmii, mac_tx.s_axis)
            rx_beats = rx_bridge.rx
        m.submodules.registers = registers = GlobalRegisters({
            "mac": self._mac, "ip": self._ip, "rto_cycles": self._rto, "msl_cycles": self._msl,
            "rbcp_port": self._rbcp_port, "arp_retry_cycles": self._arp_retry,
            "tcp_port": self._tcp_port})
        m.d.comb += [mac_rx.gmii_rxd.eq(self.gmii_rxd), mac_rx.gmii_rx_dv.eq(self.gmii_rx_dv),
                     mac_rx.gmii_rx_er.eq(self.gmii_rx_er),
                     self.gmii_txd.eq(mac_tx.gmii_txd), self.gmii_tx_en.eq(mac_tx.gmii_tx_en),
                     self.gmii_tx_er.eq(mac_tx.gmii_tx_er)]
        m.d.comb += [self.local_mac.eq(registers.mac), self.local_ip.eq(registers.ip),
                     parser.local_mac.eq(registers.mac), parser.local_ip.eq(registers.ip),
                     builder.local_mac.eq(registers.mac), builder.local_ip.eq(registers.ip)]
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
                s.seg_payload_keep.eq(parser.payload_keep),
                s.seg_payload_offset.eq(parser.payload_offset),
                s.seg_done.eq(parser.done), s.seg_accept.eq(parser.accept),
                s.seg_arp.eq(parser.arp_seen),
                s.rto_cycles.eq(registers.rto_cycles), s.msl_cycles.eq(registers.msl_cycles),
                s.arp_retry_cycles.eq(registers.arp_retry_cycles),
                s.default_port.eq(registers.tcp_port),
            ]
            wiring.connect(m, s.tx, getattr(builder, f"req_{len(RESPONDERS) + k}"))
            self._connect_user(m, k, s, user)
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

        # ---- one responder per protocol, each on its own builder port
        m.submodules.arp = arp = ArpResponder(lanes=L)
        m.submodules.icmp = icmp = IcmpEchoResponder(buffer_bytes=2048, lanes=L)
        m.submodules.rbcp = rbcp = RbcpResponder([(0, self._user_window),
                                                  (GLOBAL_BASE, 0x10000)], lanes=L)
        m.submodules.tcp_reset = rst = TcpResetResponder(lanes=L)
        responders = {"arp": arp, "icmp": icmp, "rbcp": rbcp, "rst": rst}
        for k, name in enumerate(RESPONDERS):
            ParsedFrameSignature.connect_parser(m, parser, responders[name].frame, rx_beats)
            wiring.connect(m, responders[name].tx, getattr(builder, f"req_{k}"))
        m.d.comb += [rbcp.port.eq(registers.rbcp_port), rst.claimed.eq(claimed),
                     rst.ignore.eq(listen_drop)]
        wiring.connect(m, rbcp.bus, registers.bus)
        wiring.connect(m, registers.user, wiring.flipped(self.rbcp))

        # counters: read port 0 for RBCP, port 1 for user logic; each counts at most one
        # event per frame, and frames end at most every other cycle
        m.submodules.counters = counters = EventCounters(STACK_COUNTERS, readers=2, spacing=2)
        m.d.comb += [counters.rd_addr[0].eq(registers.counter_index),
                     registers.counter_value.eq(counters.rd_data[0]),
                     counters.rd_addr[1].eq(self.counter_index),
                     self.counter_value.eq(counters.rd_data[1])]
        out = builder.m_axis
        m.d.comb += counters.events.frames_out.eq(out.tvalid & out.tready & out.tlast)

        def bump(name):
            return counters.events[name].eq(1)

        # frame accounting: each frame ends in exactly one counter
        with m.If(parser.done):
            m.d.comb += bump("frames_in")
            with m.If(~parser.accept):
                with m.Switch(parser.reason):
                    for i, name in enumerate(DROP_REASONS):
                        with m.Case(i):
                            m.d.comb += bump(name)
            with m.Else():
                with m.Switch(parser.kind):
                    with m.Case(FrameKind.ARP):
                        with m.If((f.arp_oper == ARP_REQUEST) & arp.busy):
                            m.d.comb += bump("busy")
                        with m.Else():
                            m.d.comb += bump("delivered")
                    with m.Case(FrameKind.ICMP):
                        with m.If(icmp.dropped):
                            m.d.comb += bump("busy")
                        with m.Else():
                            m.d.comb += bump("delivered")
                    with m.Case(FrameKind.UDP):
                        with m.If(f.dst_port != registers.rbcp_port):
                            m.d.comb += bump("no_port")
                        with m.Elif(rbcp.dropped):
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

    def _connect_user(self, m, k, session, user):
        """Session ``k``'s streams to the user's width: bytes or ``lanes``-byte beats inside,
        ``user_width`` outside, at the inside's rate."""
        L, width = self._lanes, self._user_width
        if width == 8 * L:
            wiring.connect(m, wiring.flipped(user.tx), session.s_axis)
            if L == 1:
                wiring.connect(m, session.m_axis, wiring.flipped(user.rx))
            else:
                # the ring's beats as they are, a partial one (no further byte) with tlast
                r = session.m_axis
                m.d.comb += [user.rx.tdata.eq(r.tdata), user.rx.tkeep.eq(r.tkeep),
                             user.rx.tlast.eq(~r.tkeep[L - 1]), user.rx.tvalid.eq(r.tvalid),
                             r.tready.eq(user.rx.tready)]
            return
        if L == 1:
            tx, rx = StreamDownsizer(width), StreamUpsizer(width)
        elif width == 8:
            # a byte per beat each way: one-byte beats into the session, and the receive
            # ring read a byte at a time
            s = session.s_axis
            m.d.comb += [s.tdata.eq(user.tx.tdata), s.tkeep.eq(1), s.tlast.eq(user.tx.tlast),
                         s.tvalid.eq(user.tx.tvalid), user.tx.tready.eq(s.tready)]
            wiring.connect(m, session.m_axis, wiring.flipped(user.rx))
            return
        else:
            # beats regrouped into whole lanes-byte beats (partial only at tlast), received
            # bytes into user beats that never wait for bytes to come
            tx = StreamRepacker(width // 8, L)
            rx = StreamRepacker(L, width // 8, eager=True)
        m.submodules[f"tcp{k}_tx_width"] = tx
        m.submodules[f"tcp{k}_rx_width"] = rx
        wiring.connect(m, wiring.flipped(user.tx), tx.s_axis)
        wiring.connect(m, tx.m_axis, session.s_axis)
        wiring.connect(m, session.m_axis, rx.s_axis)
        wiring.connect(m, rx.m_axis, wiring.flipped(user.rx))
