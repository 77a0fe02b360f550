"""The connection state machine of a TCP session (docs/network.md "TCP session"; RFC 9293,
RFC 5961, RFC 6298)."""

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from ...params import check_int, check_power_of_two
from ..frames import TCP_FLAGS, TCP_MSS, TCP_MSS_DEFAULT, TCP_MSS_MIN
from ..mac import GMII_HZ
from ..rx import RX_FIELDS, FrameKind
from .codes import TcpError, TcpRequest, TcpState
from .sequence_engine import ARRIVAL_FLAGS, SEQUENCE_INTENT
from .timer import TimerMode

__all__ = ["CONNECTION_EVENTS", "DELAYED_ACK_US", "TcpConnection", "user_control_members"]

#: the longest an in-order segment waits for its acknowledgement (docs/network.md)
DELAYED_ACK_US = 20

#: Events the connection counts (fields of the session's counters).
CONNECTION_EVENTS = data.StructLayout({
    "bytes_rx": 11, "segments_rx": 1, "rto": 1, "fast_retransmit": 1, "dup_acks": 1,
    "rst_rx": 1, "dropped_segments": 1})


def user_control_members():
    """The user's controls of a connection, as :class:`~hdl.net.tcp.TcpSession` has them
    (its docstring says what each means); the connection owns them and the session passes
    them through."""
    return {
        "open_req": In(1), "active": In(1),
        "local_port": In(16), "remote_ip": In(32), "remote_port": In(16),
        "default_port": In(16),
        "open_ack": Out(1), "close_req": Out(1), "close_ack": In(1), "abort": In(1),
        "error": Out(1), "error_code": Out(TcpError), "state": Out(TcpState),
        "peer_ip": Out(32), "peer_port": Out(16),
    }


class TcpConnection(wiring.Component):
    """What a TCP session does with segments, user controls and time.

    It owns the connection state and addresses and decides everything else drives:
    which segments belong to it, whether an arrived one is acceptable and what it changes
    (it reads the sequence engine's comparisons in the engine's DECIDE cycle and gives its
    intent), which frames are due, what the timer measures, when received bytes are
    committed, when the congestion control sees a new or duplicate ACK, and when the
    connection ends. Server and client, simultaneous open, the RFC 9293 closing states,
    challenge ACKs (RFC 5961), delayed ACKs, window updates (SWS avoidance), zero-window
    probes and give-up after 8 retransmissions.

    Parameters
    ----------
    rx_depth : int
        Receive ring bytes (for the window-update threshold).
    descriptors : int
        Segments of the transmit buffer.
    clock_hz : int
        The clock, for the delayed ACK's :data:`DELAYED_ACK_US`.

    Members
    -------
    seg_fields, seg_kind, seg_done, seg_accept, seg_arp : In
        The frame parser's fields, kind and verdict (see :class:`~hdl.net.tcp.TcpSession`).
    conn_match, listen_match, port_listening, listen_block
        As :class:`~hdl.net.tcp.TcpSession`'s.
    open_req, active, local_port, remote_ip, remote_port, default_port, open_ack, close_req,
    close_ack, abort, error, error_code, state, peer_ip, peer_port
        The user controls, as :class:`~hdl.net.tcp.TcpSession`'s.
    peer_mac, bound_port : Out(48), Out(16)
        The peer's MAC address and the connection's own port.
    ring_accept, ring_skip, ring_commit, ring_rollback, ring_discard : Out
        To the :class:`~hdl.net.tcp.receive_ring.TcpReceiveRing`'s ``accept`` ... ``discard``.
    ring_written, window : In(11), In(16)
        From the receive ring.
    tx_accept, tx_rewind, tx_reset, mss : Out
        To the :class:`~hdl.net.tcp.transmit_buffer.TcpTransmitBuffer`'s ``accept``,
        ``rewind``, ``reset`` and ``mss``.
    tx_unsent, tx_all_sent, tx_in_flight, tx_next_seq, tx_next_len, wr_seq : In
        From the transmit buffer.
    engine_arrive, engine_initialise, engine_listen, engine_rewind, rst_at_nxt : Out(1)
    seg_seq, seg_ack, seg_len, seg_fin, seg_written : Out
        The latched segment, for the sequence engine.
    flags, deciding, intent, rcv_add
        The sequence engine's comparisons and DECIDE cycle, and the connection's intent.
    snd_una, snd_nxt, snd_max, rcv_nxt : In(32)
    engine_busy, arrival_pending, init_pending : In(1)
    <kind>_due : Out(1)
        To the :class:`~hdl.net.tcp.scheduler.TcpRequestScheduler`.
    sent, sent_kind : In(1), In(TcpRequest)
        The builder took a request.
    timer_mode, timer_stop, timer_restart, timer_start, timer_zero, back_off,
    backoff_reset : Out
        To the :class:`~hdl.net.tcp.timer.TcpTimer`.
    timer_done, timer_expired : In(1)
    cc_reset, cc_new_ack, cc_dup_ack, cc_timeout : Out(1)
        To the :class:`~hdl.net.tcp.congestion.TcpCongestionControl` ...
    cwnd, fast_retransmit : In
        ... and from it.
    events : Out(CONNECTION_EVENTS)
        Counted events, this cycle.
    """

    def __init__(self, *, rx_depth=65536, descriptors=64, clock_hz=GMII_HZ):
        self._rx_depth = check_power_of_two("rx_depth", rx_depth, 2048, 65536)
        self._descriptors = check_power_of_two("descriptors", descriptors, 4, 256)
        self._clock_hz = check_int("clock_hz", clock_hz, 1_000_000, 1_000_000_000)
        members = {
            "seg_fields": In(RX_FIELDS), "seg_kind": In(FrameKind), "seg_done": In(1),
            "seg_accept": In(1), "seg_arp": In(1),
            "conn_match": Out(1), "listen_match": Out(1), "port_listening": Out(1),
            "listen_block": In(1),
            **user_control_members(),
            "peer_mac": Out(48), "bound_port": Out(16),
            "ring_accept": Out(1), "ring_skip": Out(16), "ring_commit": Out(1),
            "ring_rollback": Out(1), "ring_discard": Out(1),
            "ring_written": In(11), "window": In(16),
            "tx_accept": Out(1), "tx_rewind": Out(1), "tx_reset": Out(1),
            "mss": Out(11, init=TCP_MSS_DEFAULT),
            "tx_unsent": In(1), "tx_all_sent": In(1), "tx_in_flight": In(range(descriptors)),
            "tx_next_seq": In(32), "tx_next_len": In(11), "wr_seq": In(32),
            "engine_arrive": Out(1), "engine_initialise": Out(1), "engine_listen": Out(1),
            "engine_rewind": Out(1), "rst_at_nxt": Out(1),
            "seg_seq": Out(32), "seg_ack": Out(32), "seg_len": Out(11), "seg_fin": Out(1),
            "seg_written": Out(11),
            "flags": In(ARRIVAL_FLAGS), "deciding": In(1),
            "intent": Out(SEQUENCE_INTENT), "rcv_add": Out(12),
            "snd_una": In(32), "snd_nxt": In(32), "snd_max": In(32), "rcv_nxt": In(32),
            "engine_busy": In(1), "arrival_pending": In(1), "init_pending": In(1),
            "sent": In(1), "sent_kind": In(TcpRequest),
            "timer_mode": Out(TimerMode), "timer_stop": Out(1), "timer_restart": Out(1),
            "timer_start": Out(1), "timer_zero": Out(1), "back_off": Out(1),
            "backoff_reset": Out(1), "timer_done": In(1), "timer_expired": In(1),
            "cc_reset": Out(1), "cc_new_ack": Out(1), "cc_dup_ack": Out(1),
            "cc_timeout": Out(1), "cwnd": In(range(descriptors)), "fast_retransmit": In(1),
            "events": Out(CONNECTION_EVENTS),
        }
        members.update({f"{r.name.lower()}_due": Out(1) for r in TcpRequest})
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        S, R = TcpState, TcpRequest
        f = self.seg_fields
        state = self.state
        rxd = self._rx_depth
        events = self.events

        remote_mac, remote_ip, remote_port = self.peer_mac, self.peer_ip, self.peer_port
        local_port = self.bound_port
        ephemeral = Signal(16, init=49152)
        snd_wnd = Signal(16)
        mss = self.mss
        retries = Signal(4)

        syn_due = Signal()
        arp_due = Signal()
        ack_now = Signal()          # send an ACK as soon as possible
        ack_owed = Signal()         # one in-order segment not yet acknowledged
        delack = Signal(range(DELAYED_ACK_US * self._clock_hz // 1_000_000 + 1))
        rst_due = Signal()
        rst_at_nxt = self.rst_at_nxt    # the pending RST carries SND.NXT (else ``ctl_seq``)
        fin_queued = Signal()
        fin_sent = Signal()
        fin_acked = Signal()
        probe_due = Signal()
        armed = Signal(init=1)

        # timer commands: the last one given in a cycle wins (``TcpTimer`` would give
        # ``stop`` priority; only one reaches it)
        def timer_stop():
            return [self.timer_stop.eq(1), self.timer_restart.eq(0), self.timer_start.eq(0)]

        def timer_restart():
            return [self.timer_restart.eq(1), self.timer_stop.eq(0)]

        def timer_start():
            return [self.timer_start.eq(1)]

        def timer_zero():
            return [self.timer_zero.eq(1)]

        synchronized = ((state == S.ESTABLISHED) | (state == S.FIN_WAIT_1) |
                        (state == S.FIN_WAIT_2) | (state == S.CLOSE_WAIT) |
                        (state == S.CLOSING) | (state == S.LAST_ACK) | (state == S.TIME_WAIT))
        receiving = (state == S.ESTABLISHED) | (state == S.FIN_WAIT_1) | (state == S.FIN_WAIT_2)
        sending = (state == S.ESTABLISHED) | (state == S.CLOSE_WAIT)
        m.d.comb += [self.open_ack.eq(synchronized & (state != S.TIME_WAIT)),
                     self.close_req.eq(state == S.CLOSE_WAIT),
                     self.tx_accept.eq(sending & ~fin_queued)]

        # ---- where an arriving payload goes
        tuple_match = ((f.sender_ip == remote_ip) & (f.src_port == remote_port) &
                       (f.dst_port == local_port))
        is_tcp = self.seg_kind == FrameKind.TCP
        ahead = Signal(18)
        m.d.comb += ahead.eq(self.rcv_nxt[:18] - f.seq[:18])
        m.d.comb += [self.ring_accept.eq(is_tcp & receiving & tuple_match & (ahead[16:] == 0) &
                                         ~f.flags.rst & f.flags.ack),
                     self.ring_skip.eq(ahead[:16])]

        # ---- which frame is due
        nothing_out = self.snd_una == self.snd_max
        # transmit-side sequence distances stay below 2**16: modulo 2**18, bit 17 the sign
        data_end = Signal(18)
        m.d.comb += data_end.eq((self.tx_next_seq + self.tx_next_len)[:18] - self.snd_una[:18])
        data_fits = (data_end <= snd_wnd) & (self.tx_in_flight < self.cwnd)
        have_data = self.tx_unsent & (synchronized | (state == S.SYN_RECEIVED))
        all_sent = self.tx_all_sent
        fin_may = fin_queued & all_sent & (~fin_sent | (self.snd_nxt == self.wr_seq))
        m.d.comb += [
            self.rst_due.eq(rst_due),
            self.arp_due.eq(arp_due & (state == S.ARP)),
            self.syn_due.eq(syn_due & ((state == S.SYN_SENT) | (state == S.SYN_RECEIVED))),
            self.data_due.eq(have_data & (state != S.SYN_RECEIVED) & data_fits),
            self.fin_due.eq(fin_may & ((state == S.FIN_WAIT_1) | (state == S.LAST_ACK) |
                                       (state == S.CLOSING))),
            self.probe_due.eq(probe_due),
            self.ack_due.eq(ack_now & synchronized),
        ]

        # ---- a frame left
        sent = self.sent
        kind = self.sent_kind
        adv_wnd = Signal(16)
        with m.If(sent):
            with m.If(kind != R.ARP):
                m.d.sync += adv_wnd.eq(self.window)
            with m.If((kind != R.RST) & (kind != R.ARP) & (kind != R.SYN)):
                m.d.sync += [ack_now.eq(0), ack_owed.eq(0), delack.eq(0)]
            with m.Switch(kind):
                with m.Case(R.RST):
                    m.d.sync += rst_due.eq(0)
                with m.Case(R.ARP):
                    m.d.sync += arp_due.eq(0)
                    m.d.comb += timer_restart()
                with m.Case(R.SYN):
                    m.d.sync += syn_due.eq(0)
                    m.d.comb += timer_restart()
                with m.Case(R.DATA):
                    m.d.comb += timer_start()
                with m.Case(R.FIN):
                    m.d.sync += fin_sent.eq(1)
                    m.d.comb += timer_start()
                with m.Case(R.PROBE):
                    m.d.sync += probe_due.eq(0)

        # delayed ACK: at most 20 us
        with m.If(ack_owed & ~ack_now):
            m.d.sync += delack.eq(delack + 1)
            with m.If(delack == DELAYED_ACK_US * self._clock_hz // 1_000_000):
                m.d.sync += ack_now.eq(1)
        # window update once the user has made room (SWS avoidance, RFC 9293 §3.8.6.2.2);
        # not in the cycle a segment leaves: ``adv_wnd`` takes its window only then
        with m.If(receiving & ~sent &
                  (self.window >= adv_wnd + Mux(mss + mss < rxd // 2, mss + mss, rxd // 2))):
            m.d.sync += ack_now.eq(1)

        # ---- timer
        with m.Switch(state):
            with m.Case(S.ARP):
                m.d.comb += self.timer_mode.eq(TimerMode.ARP)
            with m.Case(S.TIME_WAIT):
                m.d.comb += self.timer_mode.eq(TimerMode.TIME_WAIT)
            with m.Case(S.FIN_WAIT_2):
                m.d.comb += self.timer_mode.eq(TimerMode.FIN_WAIT_2)
            with m.Default():
                m.d.comb += self.timer_mode.eq(TimerMode.RETRANSMIT)
        expired = self.timer_expired
        tw_expired = (state == S.TIME_WAIT) & self.timer_done
        fw2_expired = (state == S.FIN_WAIT_2) & expired
        zero_wnd_wait = synchronized & nothing_out & self.tx_unsent & ~data_fits
        with m.If(zero_wnd_wait):
            m.d.comb += timer_start()

        # ---- user controls
        with m.If(~self.open_req):
            m.d.sync += armed.eq(1)
        go_closed = Signal()
        with m.Switch(state):
            with m.Case(S.CLOSED):
                m.d.sync += [fin_queued.eq(0), fin_sent.eq(0), fin_acked.eq(0),
                             syn_due.eq(0), probe_due.eq(0), ack_now.eq(0), ack_owed.eq(0),
                             retries.eq(0)]
                m.d.comb += [self.backoff_reset.eq(1), self.cc_reset.eq(1)] + timer_stop()
                # a pending RST leaves first: it carries the old connection's ports
                with m.If(self.open_req & ~self.active & ~rst_due):
                    m.d.sync += [state.eq(S.LISTEN),
                                 local_port.eq(Mux(self.local_port != 0, self.local_port,
                                                   self.default_port))]
                with m.Elif(self.open_req & self.active & armed & ~rst_due):
                    m.d.sync += [state.eq(S.ARP), arp_due.eq(1), armed.eq(0),
                                 remote_ip.eq(self.remote_ip), remote_port.eq(self.remote_port),
                                 local_port.eq(Mux(self.local_port != 0, self.local_port,
                                                   ephemeral)),
                                 ephemeral.eq(Mux(ephemeral == 65535, 49152, ephemeral + 1)),
                                 retries.eq(0), self.error_code.eq(TcpError.NONE)]
                    m.d.comb += timer_stop()
            with m.Case(S.LISTEN):
                with m.If(~self.open_req | self.active):
                    m.d.sync += state.eq(S.CLOSED)
        with m.If(synchronized & ~self.open_req & ((state == S.ESTABLISHED) |
                                                   (state == S.CLOSE_WAIT))):
            m.d.sync += fin_queued.eq(1)
        with m.If((state == S.CLOSE_WAIT) & self.close_ack):
            m.d.sync += fin_queued.eq(1)
        with m.If(fin_queued & all_sent & ~fin_sent):
            with m.If(state == S.ESTABLISHED):
                m.d.sync += state.eq(S.FIN_WAIT_1)
            with m.If(state == S.CLOSE_WAIT):
                m.d.sync += state.eq(S.LAST_ACK)

        # ---- segment arrival: the verdict's fields are latched; the sequence engine
        # compares them, then the outcome is decided (``deciding``)
        seg = self.seg_done & self.seg_accept & is_tcp
        port_listening = (state == S.LISTEN) & (f.dst_port == local_port)
        listen_match = port_listening & f.flags.syn & ~f.flags.rst & ~f.flags.ack
        listen_hit = listen_match & ~self.listen_block
        connected = (state != S.CLOSED) & (state != S.LISTEN) & (state != S.ARP)
        conn_hit = connected & tuple_match
        m.d.comb += [self.conn_match.eq(conn_hit), self.listen_match.eq(listen_match),
                     self.port_listening.eq(port_listening)]
        arp_from_peer = self.seg_done & self.seg_arp & (f.sender_ip == remote_ip)
        arp_hit = arp_from_peer & (state == S.ARP)
        # RFC 826: a known sender's hardware address is refreshed (gratuitous ARP after a
        # NIC change, a failover)
        with m.If(arp_from_peer & connected):
            m.d.sync += remote_mac.eq(f.sender_mac)

        s_flags = Signal(TCP_FLAGS)
        s_window = Signal(16)
        s_plen = self.seg_len
        s_committed = self.seg_written
        s_mss = Signal(11)
        s_listen = self.engine_listen   # the pending initialisation is a server's
        with m.If(seg & (conn_hit | listen_hit)):
            m.d.sync += [self.seg_seq.eq(f.seq), self.seg_ack.eq(f.ack), s_flags.eq(f.flags),
                         s_window.eq(f.window), s_plen.eq(f.payload_len),
                         s_committed.eq(self.ring_written), s_mss.eq(self._mss(f))]
        m.d.comb += self.seg_fin.eq(s_flags.fin)
        arriving = seg & conn_hit
        m.d.comb += self.engine_arrive.eq(arriving)
        with m.If(arriving):
            m.d.comb += events.segments_rx.eq(1)
            with m.If(state == S.FIN_WAIT_2):
                m.d.comb += timer_zero()        # an idle timeout: the peer is still there

        m.d.sync += self.error.eq(0)

        def abort_to(code):
            return [state.eq(Mux(~self.active & self.open_req & (state == S.SYN_RECEIVED),
                                 S.LISTEN, S.CLOSED)),
                    self.error_code.eq(code), self.error.eq(1)]

        def time_out():
            """Give up: RST at SND.NXT if the connection was synchronized, error TIMEOUT."""
            return [rst_due.eq(synchronized), rst_at_nxt.eq(1)] + abort_to(TcpError.TIMEOUT)

        initialise = [self.engine_initialise.eq(1), self.backoff_reset.eq(1),
                      self.cc_reset.eq(1)] + timer_zero()
        with m.If(seg & listen_hit):
            m.d.comb += self.ring_discard.eq(1)     # a new connection starts with no old bytes
            m.d.sync += [state.eq(S.SYN_RECEIVED), remote_mac.eq(f.sender_mac),
                         remote_ip.eq(f.sender_ip), remote_port.eq(f.src_port),
                         mss.eq(self._mss(f)), snd_wnd.eq(f.window), syn_due.eq(1),
                         s_listen.eq(1), self.error_code.eq(TcpError.NONE), retries.eq(0)]
            m.d.comb += initialise
        # ARP resolution for a client
        with m.If(arp_hit):
            m.d.comb += self.ring_discard.eq(1)
            m.d.sync += [remote_mac.eq(f.sender_mac), state.eq(S.SYN_SENT), syn_due.eq(1),
                         snd_wnd.eq(0), s_listen.eq(0), retries.eq(0)]
            m.d.comb += initialise + timer_stop()

        # ---- the outcome of a segment of the connection
        flag = self.flags
        intent = self.intent
        a_fin, a_syn, a_rst, a_ack = s_flags.fin, s_flags.syn, s_flags.rst, s_flags.ack
        seqlen = Signal(12)
        m.d.comb += seqlen.eq(s_plen + a_fin)
        acceptable = Mux(seqlen == 0,
                         Mux(self.window == 0, flag.seq_is_rcv_nxt, flag.seq_in_window),
                         (self.window != 0) & (flag.seq_in_window | flag.last_in_window))
        new_ack = flag.ack_after_snd_una & ~flag.ack_after_snd_max
        fin_acked_now = fin_sent & flag.ack_is_fin_plus_1
        decide = self.deciding
        commit = Signal()
        m.d.comb += self.rcv_add.eq(s_committed)
        with m.If(decide & (state == S.SYN_SENT)):
            with m.If(a_ack & ~flag.ack_is_snd_una_plus_1):
                with m.If(~a_rst):
                    m.d.sync += [rst_due.eq(1), rst_at_nxt.eq(0)]
                    m.d.comb += intent.rst.eq(1)
            with m.Elif(a_rst):
                with m.If(a_ack):
                    m.d.sync += abort_to(TcpError.REFUSED)
                    m.d.comb += events.rst_rx.eq(1)
            with m.Elif(a_syn):
                m.d.sync += [mss.eq(s_mss), snd_wnd.eq(s_window)]
                m.d.comb += [intent.rcv.eq(1), intent.rcv_syn.eq(1), intent.wl.eq(1)]
                with m.If(a_ack):
                    m.d.sync += [state.eq(S.ESTABLISHED), retries.eq(0), ack_now.eq(1)]
                    m.d.comb += [intent.una.eq(1), self.backoff_reset.eq(1)] + timer_stop()
                with m.Else():
                    # simultaneous open: the SYN-ACK acknowledges the peer's SYN
                    m.d.sync += [state.eq(S.SYN_RECEIVED), syn_due.eq(1)]
        with m.Elif(decide):
            with m.If(a_syn & (state == S.SYN_RECEIVED) & flag.seq_is_rcv_nxt_minus_1):
                m.d.sync += syn_due.eq(1)               # our SYN-ACK was lost: resend it
            with m.Elif(~acceptable):
                with m.If(~a_rst):
                    m.d.sync += ack_now.eq(1)
                    m.d.comb += events.dropped_segments.eq(1)
                with m.If(a_fin & (state == S.TIME_WAIT)):
                    # the peer's FIN again (it lies below RCV.NXT): acknowledge it and
                    # restart the 2 MSL (RFC 9293 §3.10.7.4)
                    m.d.comb += timer_zero()
            with m.Elif(a_rst):
                m.d.comb += events.rst_rx.eq(1)
                with m.If(flag.seq_is_rcv_nxt):
                    m.d.sync += abort_to(TcpError.RESET)
                with m.Else():
                    m.d.sync += ack_now.eq(1)           # challenge ACK (RFC 5961 §3)
            with m.Elif(a_syn):
                m.d.sync += ack_now.eq(1)               # challenge ACK (RFC 5961 §4)
            with m.Elif(~a_ack):
                pass
            with m.Elif(state == S.SYN_RECEIVED):
                with m.If(flag.ack_is_snd_una_plus_1):
                    m.d.sync += [state.eq(S.ESTABLISHED), retries.eq(0), snd_wnd.eq(s_window)]
                    m.d.comb += [intent.una.eq(1), intent.wl.eq(1), self.backoff_reset.eq(1),
                                 commit.eq(1)] + timer_stop()
                with m.Else():
                    m.d.sync += [rst_due.eq(1), rst_at_nxt.eq(0)]
                    m.d.comb += intent.rst.eq(1)
            with m.Elif(flag.ack_after_snd_max):
                m.d.sync += ack_now.eq(1)
            with m.Else():
                m.d.comb += commit.eq(1)
                with m.If(new_ack):
                    m.d.sync += retries.eq(0)
                    m.d.comb += [intent.una.eq(1), intent.nxt.eq(flag.ack_after_snd_nxt),
                                 self.backoff_reset.eq(1), self.cc_new_ack.eq(1)]
                    with m.If(flag.ack_is_snd_max):
                        m.d.comb += timer_stop()
                    with m.Else():
                        m.d.comb += timer_restart()
                    with m.If(fin_acked_now):
                        m.d.sync += fin_acked.eq(1)
                        with m.Switch(state):
                            with m.Case(S.FIN_WAIT_1):
                                m.d.sync += state.eq(S.FIN_WAIT_2)
                                m.d.comb += timer_restart()
                            with m.Case(S.CLOSING):
                                m.d.sync += state.eq(S.TIME_WAIT)
                                m.d.comb += timer_restart()
                            with m.Case(S.LAST_ACK):
                                m.d.comb += go_closed.eq(1)
                with m.Elif(flag.ack_is_snd_una & (s_plen == 0) & ~a_fin & ~nothing_out &
                            (s_window == snd_wnd)):
                    m.d.comb += [self.cc_dup_ack.eq(1), events.dup_acks.eq(1)]
                    with m.If(self.fast_retransmit):
                        # fast retransmit (RFC 5681 §3.2), go-back-N from SND.UNA
                        m.d.comb += [self.tx_rewind.eq(1), intent.retransmit.eq(1),
                                     events.fast_retransmit.eq(1)] + timer_zero()
                        with m.If(fin_sent & ~fin_acked):
                            m.d.sync += fin_sent.eq(0)
                with m.If(flag.seq_after_wl1 | (flag.seq_is_wl1 & flag.ack_not_before_wl2)):
                    m.d.sync += snd_wnd.eq(s_window)
                    m.d.comb += intent.wl.eq(1)
                # data and FIN
                with m.If(s_plen != 0):
                    with m.If((s_committed == s_plen) & flag.seq_is_rcv_nxt):
                        with m.If(ack_owed | s_flags.psh):
                            m.d.sync += ack_now.eq(1)
                        with m.Else():
                            m.d.sync += [ack_owed.eq(1), delack.eq(0)]
                    with m.Else():
                        m.d.sync += ack_now.eq(1)
                with m.If(a_fin & flag.fin_at_end):
                    m.d.sync += ack_now.eq(1)
                    m.d.comb += [intent.rcv.eq(1), self.rcv_add.eq(s_committed + 1)]
                    with m.Switch(state):
                        with m.Case(S.ESTABLISHED):
                            m.d.sync += state.eq(S.CLOSE_WAIT)
                        with m.Case(S.FIN_WAIT_1):
                            with m.If(fin_acked_now):
                                m.d.sync += state.eq(S.TIME_WAIT)
                                m.d.comb += timer_restart()
                            with m.Else():
                                m.d.sync += state.eq(S.CLOSING)
                        with m.Case(S.FIN_WAIT_2):
                            m.d.sync += state.eq(S.TIME_WAIT)
                            m.d.comb += timer_restart()
                with m.Elif(s_committed != 0):
                    m.d.comb += intent.rcv.eq(1)

        # commit or roll back the bytes written while the frame arrived: at the outcome for a
        # segment of the connection, at the verdict for any other frame (a runt's verdict
        # may fall between the two: it wrote nothing)
        committing = decide & commit & receiving
        m.d.comb += [
            self.ring_commit.eq(committing),
            self.ring_rollback.eq((decide & ~committing) |
                                  (self.seg_done & ~arriving & ~self.arrival_pending &
                                   ~self.engine_busy)),
        ]
        with m.If(committing):
            m.d.comb += events.bytes_rx.eq(s_committed)

        # retransmission timeout (RFC 6298 with a fixed initial RTO, doubled per expiry); a
        # timer acts only between segments: a segment being applied, or whose verdict comes
        # in this very cycle, is seen first (it may restart the timer: FIN-WAIT-2 ends only
        # after a silence). Any frame's verdict holds the timer for that cycle, so that the
        # segment's match with the connection stays off the timer's path into the engine.
        sent_op = sent & ((kind == R.SYN) | (kind == R.DATA) | (kind == R.FIN))
        timers_free = ~self.engine_busy & ~sent_op & ~self.arrival_pending & ~self.seg_done
        with m.If(state == S.ARP):
            with m.If(expired):
                m.d.sync += [retries.eq(retries + 1), arp_due.eq(1)]
                m.d.comb += timer_zero()
                with m.If(retries == 3):
                    m.d.sync += [state.eq(S.CLOSED), self.error_code.eq(TcpError.ARP),
                                 self.error.eq(1)]
        with m.Elif(tw_expired & timers_free):
            m.d.comb += go_closed.eq(1)
        with m.Elif(fw2_expired & timers_free):
            # the peer acknowledged our FIN and went silent: reset, as Linux does for an
            # orphaned FIN-WAIT-2 socket
            m.d.sync += time_out()
        with m.Elif(expired & (state != S.TIME_WAIT) & timers_free & ~self.init_pending):
            m.d.comb += [self.back_off.eq(1)] + timer_zero()
            with m.If(zero_wnd_wait):
                m.d.sync += probe_due.eq(1)             # persist timer: keep probing
            with m.Elif(retries == 7):
                m.d.sync += time_out()
            with m.Else():
                m.d.sync += retries.eq(retries + 1)
                m.d.comb += [events.rto.eq(1), self.tx_rewind.eq(1), self.cc_timeout.eq(1),
                             self.engine_rewind.eq(1)]
                with m.If((state == S.SYN_SENT) | (state == S.SYN_RECEIVED)):
                    m.d.sync += syn_due.eq(1)
                with m.If(fin_sent & ~fin_acked):
                    m.d.sync += fin_sent.eq(0)
                with m.If(nothing_out):
                    m.d.comb += timer_stop()

        with m.If(self.abort & synchronized):
            m.d.sync += [rst_due.eq(1), rst_at_nxt.eq(1), state.eq(S.CLOSED)]
        with m.If(go_closed):
            m.d.sync += state.eq(S.CLOSED)
            m.d.comb += timer_stop()
        with m.If(state == S.CLOSED):
            m.d.sync += snd_wnd.eq(0)
            m.d.comb += self.tx_reset.eq(1)
        return m

    @staticmethod
    def _mss(f):
        peer = Mux(f.has_mss, f.mss, TCP_MSS_DEFAULT)
        return Mux(peer < TCP_MSS_MIN, TCP_MSS_MIN, Mux(peer < TCP_MSS, peer, TCP_MSS))[:11]
