"""One TCP session: server or client, sliding window, retransmission, both directions
(spec net.md §1.3-§1.6, §2.1; RFC 9293, RFC 5681, RFC 6298)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import enum, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import check_int, check_power_of_two
from ..stream import AXIStreamSignature
from .checksum import ones_complement_add
from .frames import (
    ARP_REPLY, ARP_REQUEST, TCP_ACK, TCP_FIN, TCP_MSS, TCP_MSS_DEFAULT, TCP_PSH, TCP_RST,
    TCP_SYN,
)
from .rx import RX_FIELDS, FrameKind
from .tx import TxRequestSignature

__all__ = ["TcpState", "TcpError", "TcpSession", "TCP_COUNTERS"]


class TcpState(enum.Enum, shape=4):
    """Connection states (RFC 9293 §3.3.2) plus ARP resolution before a client's SYN; the
    value is the TCP_STATE register code (net.md §7.2)."""
    CLOSED = 0
    LISTEN = 1
    SYN_SENT = 2
    SYN_RECEIVED = 3
    ESTABLISHED = 4
    FIN_WAIT_1 = 5
    FIN_WAIT_2 = 6
    CLOSE_WAIT = 7
    CLOSING = 8
    LAST_ACK = 9
    TIME_WAIT = 10
    ARP = 11


class TcpError(enum.Enum, shape=4):
    """Sticky error codes (net.md §7.2 ERROR register)."""
    NONE = 0
    REFUSED = 1
    TIMEOUT = 2
    ARP = 3
    RESET = 6


#: Session counters, in the order of the ``counters`` output (net.md §7.2 "counters").
TCP_COUNTERS = ("bytes_tx", "bytes_rx", "segments_tx", "segments_rx", "rto", "fast_retransmit",
                "dup_acks", "rst_rx", "dropped_segments")


def _seq_lt(a, b):
    """a < b modulo 2**32 (RFC 9293 §3.4)."""
    return (a - b)[31]


def _seq_le(a, b):
    return ~_seq_lt(b, a)


class TcpSession(wiring.Component):
    """One TCP connection with a SiTCP-like user side.

    Transmit data goes into a block-RAM buffer of ``tx_depth`` bytes and is cut into segments
    as it arrives (at ``min(peer MSS, 1460)`` bytes, at ``tlast``, or after 16 idle cycles);
    each segment's checksum is summed while it is written, so a segment is sent at one byte
    per cycle straight from the buffer and resent unchanged until acknowledged. Received
    in-order data is written into a ``rx_depth``-byte ring while the frame arrives and
    committed when the frame's FCS and checksum are known good; the ring's free space is the
    advertised window. Out-of-order segments are dropped and answered with a duplicate ACK.

    Parameters
    ----------
    tx_depth, rx_depth : int
        Buffer sizes in bytes, powers of two in 2**11..2**16.
    descriptors : int
        Segments the transmit buffer may hold, a power of two in 4..256.
    iss_seed : int
        Initial value of the initial-sequence-number clock (tests start it near 2**32).

    Members
    -------
    seg_* : In
        From the :class:`FrameParser`: ``seg_fields`` (live header fields), ``seg_kind``,
        ``seg_payload_*`` (payload bytes as they arrive), ``seg_done`` and ``seg_accept``
        (the parser's verdict).
    claim : Out(1)
        The segment of the current verdict belongs to this session (else the stack answers
        with RST).
    tx : Out(TxRequestSignature())
        Frame requests to the :class:`FrameBuilder`.
    s_axis : In(AXIStreamSignature(8, keep=False))
        Bytes to send; ``tlast`` pushes the segment out at once. ``tready`` is high only in
        ESTABLISHED and CLOSE-WAIT, while there is buffer room.
    m_axis : Out(AXIStreamSignature(8, keep=False))
        Received bytes in order (``tlast`` is 0). Backpressure closes the receive window.
    open_req : In(1)
        Client (``active`` = 1): a rising level connects to ``remote_ip:remote_port``.
        Server: listen on ``local_port`` while high. Falling while connected: close (FIN
        after the buffered data).
    active : In(1)
        Client mode.
    local_port, remote_ip, remote_port : In
        Addresses; a client with ``local_port`` 0 takes ephemeral ports from 49152 up.
    open_ack : Out(1)
        The connection is up (ESTABLISHED .. LAST-ACK, SiTCP TCP_OPEN_ACK).
    close_req : Out(1)
        The peer has closed its direction (CLOSE-WAIT): drain, then ``close_ack``.
    close_ack : In(1)
        Answer to ``close_req``: send FIN after the buffered data.
    abort : In(1)
        Send RST and close now.
    error : Out(1)
        Pulse when the connection fails; ``error_code`` keeps the reason until the next
        connection (a server's next SYN, a client's next open).
    state : Out(TcpState)
    peer_ip, peer_port : Out
        The connected peer (a server learns it from the SYN).
    counters : Out(32 * len(TCP_COUNTERS))
        :data:`TCP_COUNTERS`, 32 bits each, wrapping.
    rto_cycles, msl_cycles, arp_retry_cycles : In(32)
        Initial retransmission timeout, maximum segment lifetime (TIME-WAIT is 2 MSL) and
        ARP retry interval, in clock cycles (registers of the stack).
    """

    def __init__(self, *, tx_depth=65536, rx_depth=65536, descriptors=64, iss_seed=0x1000):
        self._tx_depth = check_power_of_two("tx_depth", tx_depth, 2048, 65536)
        self._rx_depth = check_power_of_two("rx_depth", rx_depth, 2048, 65536)
        self._descriptors = check_power_of_two("descriptors", descriptors, 4, 256)
        self._iss_seed = check_int("iss_seed", iss_seed, 0, 2**32 - 1)
        super().__init__({
            "seg_fields": In(RX_FIELDS), "seg_kind": In(FrameKind),
            "seg_payload_data": In(8), "seg_payload_valid": In(1), "seg_payload_offset": In(11),
            "seg_done": In(1), "seg_accept": In(1),
            "claim": Out(1),
            "tx": Out(TxRequestSignature()),
            "s_axis": In(AXIStreamSignature(8, keep=False)),
            "m_axis": Out(AXIStreamSignature(8, keep=False)),
            "open_req": In(1), "active": In(1),
            "local_port": In(16), "remote_ip": In(32), "remote_port": In(16),
            "open_ack": Out(1), "close_req": Out(1), "close_ack": In(1), "abort": In(1),
            "error": Out(1), "error_code": Out(TcpError), "state": Out(TcpState),
            "peer_ip": Out(32), "peer_port": Out(16), "tx_fill": Out(17),
            "counters": Out(32 * len(TCP_COUNTERS)),
            "rto_cycles": In(32), "msl_cycles": In(32), "arp_retry_cycles": In(32),
        })

    def elaborate(self, platform):
        m = Module()
        S = TcpState
        f = self.seg_fields
        state = Signal(TcpState)
        m.d.comb += self.state.eq(state)
        txd, rxd, nd = self._tx_depth, self._rx_depth, self._descriptors
        tx_bits, rx_bits = txd.bit_length() - 1, rxd.bit_length() - 1

        counters = {name: Signal(32, name=f"cnt_{name}") for name in TCP_COUNTERS}
        m.d.comb += self.counters.eq(Cat(*(counters[name] for name in TCP_COUNTERS)))

        def count(name, amount=1):
            return counters[name].eq(counters[name] + amount)

        # ---- connection registers
        remote_mac = Signal(48)
        remote_ip = Signal(32)
        remote_port = Signal(16)
        local_port = Signal(16)
        ephemeral = Signal(16, init=49152)
        iss_clock = Signal(32, init=self._iss_seed)
        m.d.sync += iss_clock.eq(iss_clock + 1)
        iss = Signal(32)
        snd_una = Signal(32)
        snd_nxt = Signal(32)
        snd_max = Signal(32)
        snd_wnd = Signal(16)
        wl1 = Signal(32)
        wl2 = Signal(32)
        rcv_nxt = Signal(32)
        mss = Signal(11, init=TCP_MSS_DEFAULT)
        cwnd = Signal(17)
        ssthresh = Signal(17, init=65535)
        cwnd_acc = Signal(17)
        dupacks = Signal(2)
        m.d.comb += [self.peer_ip.eq(remote_ip), self.peer_port.eq(remote_port)]

        syn_due = Signal()
        arp_due = Signal()
        ack_now = Signal()          # send an ACK as soon as possible
        ack_owed = Signal()         # one in-order segment not yet acknowledged
        delack = Signal(12)
        rst_due = Signal()
        rst_seq = Signal(32)
        fin_queued = Signal()
        fin_sent = Signal()
        fin_acked = Signal()
        fin_seq = Signal(32)
        probe_due = Signal()
        armed = Signal(init=1)

        timer = Signal(32)
        timer_on = Signal()
        backoff = Signal(3)
        retries = Signal(4)
        rto = Signal(32)
        m.d.comb += rto.eq(self.rto_cycles << backoff)

        synchronized = ((state == S.ESTABLISHED) | (state == S.FIN_WAIT_1) |
                        (state == S.FIN_WAIT_2) | (state == S.CLOSE_WAIT) |
                        (state == S.CLOSING) | (state == S.LAST_ACK) | (state == S.TIME_WAIT))
        receiving = (state == S.ESTABLISHED) | (state == S.FIN_WAIT_1) | (state == S.FIN_WAIT_2)
        sending = (state == S.ESTABLISHED) | (state == S.CLOSE_WAIT)
        m.d.comb += [self.open_ack.eq(synchronized & (state != S.TIME_WAIT)),
                     self.close_req.eq(state == S.CLOSE_WAIT)]

        # ---- receive ring: written while a frame arrives, committed on a good verdict
        m.submodules.rx_mem = rx_mem = Memory(shape=8, depth=rxd, init=[])
        rx_w = rx_mem.write_port()
        rx_r = rx_mem.read_port(transparent_for=())
        rx_rptr = Signal(17)
        rx_commit = Signal(17)
        rx_spec = Signal(17)
        rx_written = Signal(11)
        rx_used = Signal(17)
        m.d.comb += rx_used.eq(rx_commit - rx_rptr)
        rx_free = Signal(17)
        m.d.comb += rx_free.eq(rxd - 1 - rx_used)
        window = Signal(16)
        m.d.comb += window.eq(Mux(rx_free > 65535, 65535, rx_free))
        adv_wnd = Signal(16)

        out_go = self.m_axis.tvalid & self.m_axis.tready
        m.d.comb += [
            self.m_axis.tvalid.eq(rx_rptr != rx_commit),
            self.m_axis.tdata.eq(rx_r.data),
            rx_r.addr.eq(Mux(out_go, rx_rptr + 1, rx_rptr)[:rx_bits]),
        ]
        with m.If(out_go):
            m.d.sync += rx_rptr.eq(rx_rptr + 1)

        tuple_match = ((f.sender_ip == remote_ip) & (f.src_port == remote_port) &
                       (f.dst_port == local_port))
        is_tcp = self.seg_kind == FrameKind.TCP
        wr_on = Signal()
        wr_skip = Signal(16)
        po = self.seg_payload_offset
        pv = self.seg_payload_valid
        ahead = Signal(32)
        m.d.comb += ahead.eq(rcv_nxt - f.seq)
        start_ok = (is_tcp & receiving & tuple_match & _seq_le(f.seq, rcv_nxt) &
                    (ahead[16:] == 0) & ~f.flags[2] & f.flags[4])
        first = pv & (po == 0)
        on = Mux(first, start_ok, wr_on)
        skip = Mux(first, ahead[:16], wr_skip)
        # pointer and sequence differences are taken modulo their width (the counters wrap)
        rx_spec_used = Signal(17)
        m.d.comb += rx_spec_used.eq(rx_spec - rx_rptr)
        room = rx_spec_used < rxd - 1
        wr_now = Signal()
        m.d.comb += wr_now.eq(pv & on & (po >= skip) & room)
        m.d.comb += [rx_w.addr.eq(rx_spec[:rx_bits]), rx_w.data.eq(self.seg_payload_data),
                     rx_w.en.eq(wr_now)]
        with m.If(first):
            m.d.sync += [wr_on.eq(start_ok), wr_skip.eq(ahead[:16])]
        with m.If(wr_now):
            m.d.sync += [rx_spec.eq(rx_spec + 1), rx_written.eq(rx_written + 1)]
        with m.Elif(pv & on & (po >= skip)):
            m.d.sync += wr_on.eq(0)         # no room: the rest would not be contiguous

        # ---- transmit buffer and segmenter
        m.submodules.tx_mem = tx_mem = Memory(shape=8, depth=txd, init=[])
        tx_w = tx_mem.write_port()
        tx_r = tx_mem.read_port(transparent_for=())
        m.d.comb += [tx_r.addr.eq(self.tx.rd_addr[:tx_bits]), self.tx.rd_data.eq(tx_r.data)]
        m.submodules.desc = desc = Memory(shape=32 + 11 + 16, depth=nd, init=[])
        d_w = desc.write_port()
        d_r = desc.read_port(domain="comb")
        d_a = desc.read_port(domain="comb")
        ptr_bits = nd.bit_length()
        d_wr = Signal(ptr_bits)
        d_snd = Signal(ptr_bits)
        d_ack = Signal(ptr_bits)
        m.d.comb += [d_r.addr.eq(d_snd[:-1]), d_a.addr.eq(d_ack[:-1])]
        snd_seq, snd_len, snd_sum = d_r.data[:32], d_r.data[32:43], d_r.data[43:59]
        ack_seq, ack_len = d_a.data[:32], d_a.data[32:43]

        wr_seq = Signal(32)         # sequence number of the next byte the user writes
        seg_start = Signal(32)
        seg_len = Signal(11)
        seg_sum = Signal(16)
        idle = Signal(5)
        oldest = Mux(d_ack != d_wr, ack_seq, Mux(seg_len != 0, seg_start, wr_seq))
        used = Signal(17)
        m.d.comb += [used.eq(wr_seq - oldest), self.tx_fill.eq(used)]
        ring_used = Signal(ptr_bits)
        m.d.comb += ring_used.eq(d_wr - d_ack)
        ring_room = ring_used < nd - 1
        m.d.comb += self.s_axis.tready.eq(sending & ~fin_queued & ring_room & (used < txd - 1))
        take = self.s_axis.tvalid & self.s_axis.tready
        m.d.comb += [tx_w.addr.eq(wr_seq[:tx_bits]), tx_w.data.eq(self.s_axis.tdata),
                     tx_w.en.eq(take)]
        byte_word = Mux(seg_len[0], Cat(self.s_axis.tdata, Const(0, 8)),
                        Cat(Const(0, 8), self.s_axis.tdata))
        new_sum = ones_complement_add(seg_sum, byte_word)
        close_seg = Signal()
        close_len = Signal(11)
        close_sum = Signal(16)
        with m.If(take):
            m.d.sync += [wr_seq.eq(wr_seq + 1), idle.eq(0), count("bytes_tx")]
            with m.If(seg_len == 0):
                m.d.sync += seg_start.eq(wr_seq)
            with m.If(self.s_axis.tlast | (seg_len + 1 >= mss)):
                m.d.comb += [close_seg.eq(1), close_len.eq(seg_len + 1), close_sum.eq(new_sum)]
                m.d.sync += [seg_len.eq(0), seg_sum.eq(0)]
            with m.Else():
                m.d.sync += [seg_len.eq(seg_len + 1), seg_sum.eq(new_sum)]
        with m.Elif(seg_len != 0):
            m.d.sync += idle.eq(idle + 1)
            with m.If((idle == 15) & (ring_used < nd)):
                m.d.comb += [close_seg.eq(1), close_len.eq(seg_len), close_sum.eq(seg_sum)]
                m.d.sync += [seg_len.eq(0), seg_sum.eq(0), idle.eq(0)]
        start_of_closed = Mux(seg_len == 0, wr_seq, seg_start)
        m.d.comb += [d_w.addr.eq(d_wr[:-1]), d_w.data.eq(Cat(start_of_closed, close_len, close_sum)),
                     d_w.en.eq(close_seg)]
        with m.If(close_seg):
            m.d.sync += d_wr.eq(d_wr + 1)

        # free acknowledged segments, one per cycle
        free_now = Signal()
        m.d.comb += free_now.eq((d_ack != d_wr) & _seq_le(ack_seq + ack_len, snd_una))
        d_ack_next = d_ack + free_now
        with m.If(free_now):
            m.d.sync += d_ack.eq(d_ack + 1)
            with m.If(d_snd == d_ack):
                m.d.sync += d_snd.eq(d_snd + 1)

        # ---- transmit requests
        req = self.tx.request
        pending = Signal()          # a request is offered to the builder
        flight = snd_max - snd_una
        wnd_limit = Mux(cwnd < snd_wnd, cwnd, snd_wnd)
        data_end = Signal(32)
        m.d.comb += data_end.eq(snd_seq + snd_len - snd_una)
        data_fits = data_end <= wnd_limit
        have_data = (d_snd != d_wr) & (synchronized | (state == S.SYN_RECEIVED))
        all_sent = (d_snd == d_wr) & (seg_len == 0)
        m.d.comb += self.tx.valid.eq(pending)
        kind_ = Signal(3)           # what the pending request is
        K_RST, K_ARP, K_SYN, K_DATA, K_FIN, K_PROBE, K_ACK = range(7)

        m.d.comb += [req.kind.eq(FrameKind.TCP), req.eth_dst.eq(remote_mac),
                     req.ip_dst.eq(remote_ip), req.src_port.eq(local_port),
                     req.dst_port.eq(remote_port), req.ack.eq(rcv_nxt), req.window.eq(window)]
        with m.Switch(kind_):
            with m.Case(K_RST):
                m.d.comb += [req.seq.eq(rst_seq), req.flags.eq(TCP_RST), req.window.eq(0)]
            with m.Case(K_ARP):
                m.d.comb += [req.kind.eq(FrameKind.ARP), req.arp_oper.eq(ARP_REQUEST),
                             req.eth_dst.eq(0xFFFFFFFFFFFF)]
            with m.Case(K_SYN):
                m.d.comb += [req.seq.eq(iss), req.mss.eq(1),
                             req.flags.eq(Mux(state == S.SYN_SENT, TCP_SYN, TCP_SYN | TCP_ACK))]
            with m.Case(K_DATA):
                m.d.comb += [req.seq.eq(snd_seq), req.flags.eq(TCP_ACK | TCP_PSH),
                             req.length.eq(snd_len), req.payload_sum.eq(snd_sum),
                             req.payload_addr.eq(snd_seq[:16])]
            with m.Case(K_FIN):
                m.d.comb += [req.seq.eq(fin_seq), req.flags.eq(TCP_FIN | TCP_ACK)]
            with m.Case(K_PROBE):
                m.d.comb += [req.seq.eq(snd_una - 1), req.flags.eq(TCP_ACK)]
            with m.Case(K_ACK):
                m.d.comb += [req.seq.eq(snd_nxt), req.flags.eq(TCP_ACK)]

        # choose the next request when none is pending
        fin_may = fin_queued & all_sent & (~fin_sent | (snd_nxt == fin_seq))
        with m.If(~pending):
            with m.If(rst_due):
                m.d.sync += [pending.eq(1), kind_.eq(K_RST)]
            with m.Elif(arp_due & (state == S.ARP)):
                m.d.sync += [pending.eq(1), kind_.eq(K_ARP)]
            with m.Elif(syn_due & ((state == S.SYN_SENT) | (state == S.SYN_RECEIVED))):
                m.d.sync += [pending.eq(1), kind_.eq(K_SYN)]
            with m.Elif(have_data & (state != S.SYN_RECEIVED) & data_fits):
                m.d.sync += [pending.eq(1), kind_.eq(K_DATA)]
            with m.Elif(fin_may & ((state == S.FIN_WAIT_1) | (state == S.LAST_ACK) |
                                   (state == S.CLOSING))):
                m.d.sync += [pending.eq(1), kind_.eq(K_FIN)]
            with m.Elif(probe_due):
                m.d.sync += [pending.eq(1), kind_.eq(K_PROBE)]
            with m.Elif(ack_now & synchronized):
                m.d.sync += [pending.eq(1), kind_.eq(K_ACK)]

        sent = pending & self.tx.ready
        with m.If(sent):
            m.d.sync += [pending.eq(0), count("segments_tx")]
            with m.If(kind_ != K_ARP):
                m.d.sync += adv_wnd.eq(window)
            with m.If((kind_ != K_RST) & (kind_ != K_ARP) & (kind_ != K_SYN)):
                m.d.sync += [ack_now.eq(0), ack_owed.eq(0), delack.eq(0)]
            with m.Switch(kind_):
                with m.Case(K_RST):
                    m.d.sync += rst_due.eq(0)
                with m.Case(K_ARP):
                    m.d.sync += [arp_due.eq(0), timer.eq(0), timer_on.eq(1)]
                with m.Case(K_SYN):
                    m.d.sync += [syn_due.eq(0), snd_nxt.eq(iss + 1), snd_max.eq(iss + 1),
                                 timer_on.eq(1), timer.eq(0)]
                with m.Case(K_DATA):
                    nxt = snd_seq + snd_len
                    m.d.sync += [snd_nxt.eq(nxt), d_snd.eq(d_snd + 1)]
                    with m.If(_seq_lt(snd_max, nxt)):
                        m.d.sync += snd_max.eq(nxt)
                    with m.If(~timer_on):
                        m.d.sync += [timer_on.eq(1), timer.eq(0)]
                with m.Case(K_FIN):
                    m.d.sync += [fin_sent.eq(1), snd_nxt.eq(fin_seq + 1)]
                    with m.If(_seq_lt(snd_max, fin_seq + 1)):
                        m.d.sync += snd_max.eq(fin_seq + 1)
                    with m.If(~timer_on):
                        m.d.sync += [timer_on.eq(1), timer.eq(0)]
                with m.Case(K_PROBE):
                    m.d.sync += probe_due.eq(0)

        # delayed ACK: at most 20 us (2500 cycles at 125 MHz)
        with m.If(ack_owed & ~ack_now):
            m.d.sync += delack.eq(delack + 1)
            with m.If(delack == 2500):
                m.d.sync += ack_now.eq(1)
        # window update once the user has made room (SWS avoidance, RFC 9293 §3.8.6.2.2)
        with m.If(receiving & (window >= adv_wnd + Mux(mss + mss < rxd // 2, mss + mss,
                                                          rxd // 2))):
            m.d.sync += ack_now.eq(1)

        # ---- timers
        with m.If(timer_on):
            m.d.sync += timer.eq(timer + 1)
        expired = timer_on & (timer >= rto)
        tw_expired = (state == S.TIME_WAIT) & (timer >= (self.msl_cycles << 1))
        nothing_out = snd_una == snd_max
        zero_wnd_wait = synchronized & nothing_out & (d_snd != d_wr) & ~data_fits
        with m.If(zero_wnd_wait & ~timer_on):
            m.d.sync += [timer_on.eq(1), timer.eq(0)]

        # ---- user controls
        with m.If(~self.open_req):
            m.d.sync += armed.eq(1)
        go_closed = Signal()
        with m.Switch(state):
            with m.Case(S.CLOSED):
                m.d.sync += [timer_on.eq(0), fin_queued.eq(0), fin_sent.eq(0), fin_acked.eq(0),
                             syn_due.eq(0), probe_due.eq(0), ack_now.eq(0), ack_owed.eq(0),
                             backoff.eq(0), retries.eq(0), dupacks.eq(0)]
                with m.If(self.open_req & ~self.active):
                    m.d.sync += [state.eq(S.LISTEN), local_port.eq(self.local_port)]
                with m.Elif(self.open_req & self.active & armed):
                    m.d.sync += [state.eq(S.ARP), arp_due.eq(1), armed.eq(0),
                                 remote_ip.eq(self.remote_ip), remote_port.eq(self.remote_port),
                                 local_port.eq(Mux(self.local_port != 0, self.local_port,
                                                   ephemeral)),
                                 ephemeral.eq(Mux(ephemeral == 65535, 49152, ephemeral + 1)),
                                 timer.eq(0), timer_on.eq(0), retries.eq(0),
                                 self.error_code.eq(TcpError.NONE)]
            with m.Case(S.LISTEN):
                with m.If(~self.open_req | self.active):
                    m.d.sync += state.eq(S.CLOSED)
        with m.If(synchronized & ~self.open_req & ((state == S.ESTABLISHED) |
                                                   (state == S.CLOSE_WAIT))):
            m.d.sync += fin_queued.eq(1)
        with m.If((state == S.CLOSE_WAIT) & self.close_ack):
            m.d.sync += fin_queued.eq(1)
        with m.If(fin_queued & ~fin_sent & all_sent & (fin_seq != wr_seq)):
            m.d.sync += fin_seq.eq(wr_seq)
        with m.If(fin_queued & all_sent & ~fin_sent):
            with m.If(state == S.ESTABLISHED):
                m.d.sync += [state.eq(S.FIN_WAIT_1), fin_seq.eq(wr_seq)]
            with m.If(state == S.CLOSE_WAIT):
                m.d.sync += [state.eq(S.LAST_ACK), fin_seq.eq(wr_seq)]

        # ---- segment arrival
        seg = self.seg_done & self.seg_accept & is_tcp
        flags = f.flags
        f_fin, f_syn, f_rst, f_ack = flags[0], flags[1], flags[2], flags[4]
        plen = f.payload_len

        def in_wnd(x):
            return (x - rcv_nxt)[:32] < window

        seg_seqlen = plen + f_fin
        acceptable = Mux(seg_seqlen == 0,
                         Mux(window == 0, f.seq == rcv_nxt, in_wnd(f.seq)),
                         (window != 0) & (in_wnd(f.seq) | in_wnd(f.seq + seg_seqlen - 1)))
        listen_hit = (state == S.LISTEN) & (f.dst_port == local_port) & f_syn & ~f_rst & ~f_ack
        conn_hit = (state != S.CLOSED) & (state != S.LISTEN) & (state != S.ARP) & tuple_match
        m.d.comb += self.claim.eq(listen_hit | conn_hit)
        new_ack = _seq_lt(snd_una, f.ack) & _seq_le(f.ack, snd_max)
        too_new = _seq_lt(snd_max, f.ack)
        committed = Signal(11)
        m.d.comb += committed.eq(rx_written)
        commit = Signal()

        def abort_to(code):
            return [state.eq(Mux(~self.active & self.open_req & (state == S.SYN_RECEIVED),
                                 S.LISTEN, S.CLOSED)),
                    self.error_code.eq(code), self.error.eq(1)]

        m.d.sync += self.error.eq(0)
        with m.If(seg & conn_hit):
            m.d.sync += count("segments_rx")
        with m.If(seg & listen_hit):
            m.d.sync += rx_rptr.eq(rx_commit)      # a new connection starts with no old bytes
            m.d.sync += [state.eq(S.SYN_RECEIVED), remote_mac.eq(f.sender_mac),
                         remote_ip.eq(f.sender_ip), remote_port.eq(f.src_port),
                         rcv_nxt.eq(f.seq + 1), mss.eq(self._mss(f)), snd_wnd.eq(f.window),
                         wl1.eq(f.seq), wl2.eq(0), iss.eq(iss_clock), snd_una.eq(iss_clock),
                         snd_nxt.eq(iss_clock), snd_max.eq(iss_clock), wr_seq.eq(iss_clock + 1),
                         syn_due.eq(1), retries.eq(0), backoff.eq(0), timer.eq(0),
                         cwnd.eq(3 * TCP_MSS), ssthresh.eq(65535), dupacks.eq(0),
                         self.error_code.eq(TcpError.NONE)]
        with m.Elif(seg & conn_hit & (state == S.SYN_SENT)):
            with m.If(f_ack & (f.ack != iss + 1)):
                with m.If(~f_rst):
                    m.d.sync += [rst_due.eq(1), rst_seq.eq(f.ack)]
            with m.Elif(f_rst):
                with m.If(f_ack):
                    m.d.sync += abort_to(TcpError.REFUSED)
                    m.d.sync += count("rst_rx")
            with m.Elif(f_syn):
                m.d.sync += [rcv_nxt.eq(f.seq + 1), mss.eq(self._mss(f)), snd_wnd.eq(f.window),
                             wl1.eq(f.seq), wl2.eq(f.ack), ack_now.eq(1)]
                with m.If(f_ack):
                    m.d.sync += [state.eq(S.ESTABLISHED), snd_una.eq(f.ack), timer_on.eq(0),
                                 retries.eq(0), backoff.eq(0)]
                with m.Else():
                    m.d.sync += [state.eq(S.SYN_RECEIVED), syn_due.eq(1)]
        with m.Elif(seg & conn_hit):
            with m.If(f_syn & (state == S.SYN_RECEIVED) & (f.seq + 1 == rcv_nxt)):
                m.d.sync += syn_due.eq(1)               # our SYN-ACK was lost: resend it
            with m.Elif(~acceptable):
                with m.If(~f_rst):
                    m.d.sync += [ack_now.eq(1), count("dropped_segments")]
            with m.Elif(f_rst):
                m.d.sync += count("rst_rx")
                with m.If(f.seq == rcv_nxt):
                    m.d.sync += abort_to(TcpError.RESET)
                with m.Else():
                    m.d.sync += ack_now.eq(1)           # challenge ACK (RFC 5961 §3)
            with m.Elif(f_syn):
                m.d.sync += ack_now.eq(1)               # challenge ACK (RFC 5961 §4)
            with m.Elif(~f_ack):
                pass
            with m.Elif(state == S.SYN_RECEIVED):
                with m.If(f.ack == iss + 1):
                    m.d.sync += [state.eq(S.ESTABLISHED), snd_una.eq(f.ack), timer_on.eq(0),
                                 retries.eq(0), backoff.eq(0), snd_wnd.eq(f.window),
                                 wl1.eq(f.seq), wl2.eq(f.ack)]
                    m.d.comb += commit.eq(1)
                with m.Else():
                    m.d.sync += [rst_due.eq(1), rst_seq.eq(f.ack)]
            with m.Elif(too_new):
                m.d.sync += ack_now.eq(1)
            with m.Else():
                m.d.comb += commit.eq(1)
                with m.If(new_ack):
                    acked = (f.ack - snd_una)[:32]
                    m.d.sync += [snd_una.eq(f.ack), retries.eq(0), backoff.eq(0), timer.eq(0),
                                 timer_on.eq(f.ack != snd_max), dupacks.eq(0)]
                    with m.If(_seq_lt(snd_nxt, f.ack)):
                        m.d.sync += snd_nxt.eq(f.ack)
                    with m.If(cwnd < ssthresh):
                        m.d.sync += cwnd.eq(cwnd + Mux(acked[16:] != 0, mss,
                                                       Mux(acked[:16] < mss, acked[:16], mss)))
                    with m.Elif(cwnd_acc + acked[:17] >= cwnd):
                        m.d.sync += [cwnd_acc.eq(0), cwnd.eq(Mux(cwnd[16], cwnd, cwnd + mss))]
                    with m.Else():
                        m.d.sync += cwnd_acc.eq(cwnd_acc + acked[:17])
                    with m.If(fin_sent & (f.ack == fin_seq + 1)):
                        m.d.sync += fin_acked.eq(1)
                        with m.Switch(state):
                            with m.Case(S.FIN_WAIT_1):
                                m.d.sync += state.eq(S.FIN_WAIT_2)
                            with m.Case(S.CLOSING):
                                m.d.sync += [state.eq(S.TIME_WAIT), timer.eq(0),
                                             timer_on.eq(1)]
                            with m.Case(S.LAST_ACK):
                                m.d.comb += go_closed.eq(1)
                with m.Elif((f.ack == snd_una) & (plen == 0) & ~f_fin & ~nothing_out &
                            (f.window == snd_wnd)):
                    m.d.sync += [dupacks.eq(Mux(dupacks == 3, 3, dupacks + 1)), count("dup_acks")]
                    with m.If(dupacks == 2):
                        # fast retransmit (RFC 5681 §3.2), go-back-N from SND.UNA
                        half = flight[1:18]
                        m.d.sync += [d_snd.eq(d_ack_next), snd_nxt.eq(snd_una),
                                     ssthresh.eq(Mux(half < 2 * TCP_MSS, 2 * TCP_MSS, half)),
                                     cwnd.eq(Mux(half < 2 * TCP_MSS, 2 * TCP_MSS, half) + 3 * mss),
                                     count("fast_retransmit"), timer.eq(0)]
                        with m.If(fin_sent & ~fin_acked):
                            m.d.sync += fin_sent.eq(0)
                    with m.If(dupacks == 3):
                        m.d.sync += cwnd.eq(cwnd + mss)
                with m.If(_seq_lt(wl1, f.seq) | ((wl1 == f.seq) & _seq_le(wl2, f.ack))):
                    m.d.sync += [snd_wnd.eq(f.window), wl1.eq(f.seq), wl2.eq(f.ack)]
                # data and FIN
                with m.If(plen != 0):
                    with m.If((committed == plen) & (f.seq == rcv_nxt)):
                        with m.If(ack_owed | f.flags[3]):
                            m.d.sync += ack_now.eq(1)
                        with m.Else():
                            m.d.sync += [ack_owed.eq(1), delack.eq(0)]
                    with m.Else():
                        m.d.sync += ack_now.eq(1)
                end = f.seq + plen
                with m.If(f_fin & (end == rcv_nxt + committed)):
                    m.d.sync += [rcv_nxt.eq(rcv_nxt + committed + 1), ack_now.eq(1)]
                    with m.Switch(state):
                        with m.Case(S.ESTABLISHED):
                            m.d.sync += state.eq(S.CLOSE_WAIT)
                        with m.Case(S.FIN_WAIT_1):
                            with m.If(fin_sent & (f.ack == fin_seq + 1)):
                                m.d.sync += [state.eq(S.TIME_WAIT), timer.eq(0), timer_on.eq(1)]
                            with m.Else():
                                m.d.sync += state.eq(S.CLOSING)
                        with m.Case(S.FIN_WAIT_2):
                            m.d.sync += [state.eq(S.TIME_WAIT), timer.eq(0), timer_on.eq(1)]
                        with m.Case(S.TIME_WAIT):
                            m.d.sync += timer.eq(0)
                with m.Elif(committed != 0):
                    m.d.sync += rcv_nxt.eq(rcv_nxt + committed)

        # commit or roll back the bytes written while the frame arrived
        with m.If(self.seg_done):
            m.d.sync += rx_written.eq(0)
            with m.If(seg & conn_hit & commit & receiving):
                m.d.sync += [rx_commit.eq(rx_spec), count("bytes_rx", committed)]
            with m.Else():
                m.d.sync += rx_spec.eq(rx_commit)

        # ARP resolution for a client
        with m.If(self.seg_done & self.seg_accept & (self.seg_kind == FrameKind.ARP) &
                  (state == S.ARP) & (f.sender_ip == remote_ip) &
                  ((f.arp_oper == ARP_REPLY) | (f.arp_oper == ARP_REQUEST))):
            m.d.sync += rx_rptr.eq(rx_commit)
            m.d.sync += [remote_mac.eq(f.sender_mac), state.eq(S.SYN_SENT), syn_due.eq(1),
                         iss.eq(iss_clock), snd_una.eq(iss_clock), snd_nxt.eq(iss_clock),
                         snd_max.eq(iss_clock), wr_seq.eq(iss_clock + 1), timer.eq(0),
                         timer_on.eq(0), retries.eq(0), backoff.eq(0), cwnd.eq(3 * TCP_MSS),
                         ssthresh.eq(65535), snd_wnd.eq(0), wl1.eq(0), wl2.eq(0)]

        # retransmission timeout (RFC 6298 with a fixed initial RTO, doubled per expiry)
        with m.If(state == S.ARP):
            with m.If(timer_on & (timer >= self.arp_retry_cycles)):
                m.d.sync += [retries.eq(retries + 1), timer.eq(0), arp_due.eq(1)]
                with m.If(retries == 3):
                    m.d.sync += [state.eq(S.CLOSED), self.error_code.eq(TcpError.ARP),
                                 self.error.eq(1)]
        with m.Elif(tw_expired):
            m.d.comb += go_closed.eq(1)
        with m.Elif(expired & (state != S.TIME_WAIT)):
            m.d.sync += [timer.eq(0), backoff.eq(Mux(backoff == 5, 5, backoff + 1))]
            with m.If(zero_wnd_wait):
                m.d.sync += probe_due.eq(1)             # persist timer: keep probing
            with m.Elif(retries == 7):
                m.d.sync += [rst_due.eq(synchronized), rst_seq.eq(snd_nxt)]
                m.d.sync += abort_to(TcpError.TIMEOUT)
            with m.Else():
                half = flight[1:18]
                m.d.sync += [retries.eq(retries + 1), count("rto"), d_snd.eq(d_ack_next),
                             snd_nxt.eq(snd_una), cwnd.eq(mss), dupacks.eq(0),
                             ssthresh.eq(Mux(half < 2 * TCP_MSS, 2 * TCP_MSS, half))]
                with m.If((state == S.SYN_SENT) | (state == S.SYN_RECEIVED)):
                    m.d.sync += syn_due.eq(1)
                with m.If(fin_sent & ~fin_acked):
                    m.d.sync += fin_sent.eq(0)
                with m.If(nothing_out):
                    m.d.sync += timer_on.eq(0)

        with m.If(self.abort & synchronized):
            m.d.sync += [rst_due.eq(1), rst_seq.eq(snd_nxt), state.eq(S.CLOSED)]
        with m.If(go_closed):
            m.d.sync += [state.eq(S.CLOSED), timer_on.eq(0)]
        with m.If(state == S.CLOSED):
            m.d.sync += [d_snd.eq(d_wr), d_ack.eq(d_wr), seg_len.eq(0), seg_sum.eq(0),
                         snd_wnd.eq(0)]
        return m

    @staticmethod
    def _mss(f):
        peer = Mux(f.has_mss, f.mss, TCP_MSS_DEFAULT)
        return Mux(peer < TCP_MSS, peer, TCP_MSS)[:11]
