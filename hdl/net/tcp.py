"""One TCP session: server or client, sliding window, retransmission, both directions
(docs/network.md; RFC 9293, RFC 5681, RFC 6298)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import enum, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import check_int, check_power_of_two
from ..stream import AXIStreamSignature
from .checksum import ones_complement_add
from .counters import EventCounters
from .frames import (
    ARP_REQUEST, TCP_ACK, TCP_FIN, TCP_MSS, TCP_MSS_DEFAULT, TCP_MSS_MIN, TCP_PSH, TCP_RST,
    TCP_SYN,
)
from .rx import RX_FIELDS, FrameKind
from .tx import TxRequestSignature

__all__ = ["TcpState", "TcpError", "TcpSession", "TCP_COUNTERS"]


class TcpState(enum.Enum, shape=4):
    """Connection states (RFC 9293 §3.3.2) plus ARP resolution before a client's SYN; the
    value is the TCP_STATE register code (docs/network.md)."""
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
    """Sticky error codes (docs/network.md ERROR register)."""
    NONE = 0
    REFUSED = 1
    TIMEOUT = 2
    ARP = 3
    RESET = 6


#: Initial congestion window in segments (docs/network.md: 3 x 1460 bytes)
INITIAL_WINDOW = 3
#: Back-offs of the retransmission timeout: it doubles per expiry up to 2**5 times the RTO
MAX_BACKOFF = 5
#: FIN-WAIT-2 ends after 2**6 MSL without a segment from the peer (64 s at the default MSL of
#: 1 s; docs/network.md proposes 60 s)
FIN_WAIT_2_SCALE = 6

#: Session counters, in the order of the ``counters`` output (docs/network.md "counters").
TCP_COUNTERS = ("bytes_tx", "bytes_rx", "segments_tx", "segments_rx", "rto", "fast_retransmit",
                "dup_acks", "rst_rx", "dropped_segments")


class TcpSession(wiring.Component):
    """One TCP connection with a SiTCP-like user side.

    Transmit data goes into a block-RAM buffer of ``tx_depth`` bytes and is cut into segments
    as it arrives (at ``min(max(peer MSS, 48), 1460)`` bytes, at ``tlast``, or after 16 idle
    cycles); each segment's checksum is summed while it is written, so a segment is sent at
    one byte per cycle straight from the buffer and resent unchanged until acknowledged.
    Received in-order data is written into a ``rx_depth``-byte ring while the frame arrives and
    committed when the frame's FCS and checksum are known good; the ring's free space is the
    advertised window. Out-of-order segments are dropped and answered with a duplicate ACK.

    The 32-bit sequence numbers (SND.UNA, SND.NXT, SND.MAX, RCV.NXT, SND.WL1, SND.WL2) are
    written only by a sequence engine with one adder: a received segment's fields are latched
    at the verdict, compared with them one per cycle, and the outcome is applied 10 cycles
    later, the new sequence numbers over the next 4 (the next segment's payload cannot start
    within 54 cycles). A request's sequence number is the sending segment's descriptor, or
    for a segment without data one register the engine writes when the request is chosen;
    an engine program withdraws a pending request (it is chosen again afterwards) and no
    retransmission timer fires while it runs, so what it compared stays true.

    Congestion control (RFC 5681) counts segments, as Linux does: the initial window is
    3 segments, slow start adds one per new ACK, congestion avoidance one per window; a
    timeout or a third duplicate ACK halves the segments in flight. The retransmission
    timeout doubles per expiry (up to 32 times ``rto_cycles``).

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
        ``seg_payload_*`` (payload bytes as they arrive), ``seg_done``, ``seg_accept`` (the
        parser's verdict) and ``seg_arp`` (an ARP frame from anyone to anyone: one from the
        peer's IP resolves it for a client and refreshes its MAC on a live connection,
        docs/network.md).
    conn_match, listen_match : Out(1)
        The segment of the current verdict matches the connection; it is a SYN to the
        listening port (whatever ``listen_block``). A segment that no session matches is
        answered by the stack with RST.
    port_listening : Out(1)
        The session listens on the current segment's destination port (whatever its flags):
        the stack drops a segment to it without SYN, ACK and RST silently (RFC 9293
        §3.10.7.2).
    listen_block : In(1)
        Another session takes this SYN (its connection, or a lower-numbered listener on the
        same port): do not accept it.
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
        Addresses; a client with ``local_port`` 0 takes ephemeral ports from 49152 up, a
        server with ``local_port`` 0 listens on ``default_port`` (both taken at the open).
    default_port : In(16)
        The server port of ``local_port`` 0 (SiTCP's TCP port, 24 by default).
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
    counter_index : In(range(len(TCP_COUNTERS)))
        One of :data:`TCP_COUNTERS` ...
    counter_value : Out(32)
        ... and its value in the same cycle (32 bits, wrapping; it shows an event within
        ``len(TCP_COUNTERS) + 1`` cycles).
    counters_clear : In(1)
        Set the counters to zero (they show it within ``len(TCP_COUNTERS)`` cycles).
    rto_cycles, msl_cycles, arp_retry_cycles : In(32)
        Initial retransmission timeout, maximum segment lifetime and ARP retry interval, in
        clock cycles (registers of the stack). TIME-WAIT lasts 2 MSL; FIN-WAIT-2 ends after
        64 MSL without a segment from the peer, with RST and ``error_code`` TIMEOUT.
    """

    @staticmethod
    def check_parameters(*, tx_depth=65536, rx_depth=65536, descriptors=64, iss_seed=0x1000):
        """The parameters, validated (:class:`~hdl.params.ParameterError` names a bad one);
        for containers that build their sessions later, in ``elaborate``."""
        return dict(tx_depth=check_power_of_two("tx_depth", tx_depth, 2048, 65536),
                    rx_depth=check_power_of_two("rx_depth", rx_depth, 2048, 65536),
                    descriptors=check_power_of_two("descriptors", descriptors, 4, 256),
                    iss_seed=check_int("iss_seed", iss_seed, 0, 2**32 - 1))

    def __init__(self, *, tx_depth=65536, rx_depth=65536, descriptors=64, iss_seed=0x1000):
        params = self.check_parameters(tx_depth=tx_depth, rx_depth=rx_depth,
                                       descriptors=descriptors, iss_seed=iss_seed)
        self._tx_depth, self._rx_depth = params["tx_depth"], params["rx_depth"]
        self._descriptors, self._iss_seed = params["descriptors"], params["iss_seed"]
        super().__init__({
            "seg_fields": In(RX_FIELDS), "seg_kind": In(FrameKind),
            "seg_payload_data": In(8), "seg_payload_valid": In(1), "seg_payload_offset": In(11),
            "seg_done": In(1), "seg_accept": In(1), "seg_arp": In(1),
            "conn_match": Out(1), "listen_match": Out(1), "port_listening": Out(1),
            "listen_block": In(1),
            "tx": Out(TxRequestSignature()),
            "s_axis": In(AXIStreamSignature(8, keep=False)),
            "m_axis": Out(AXIStreamSignature(8, keep=False)),
            "open_req": In(1), "active": In(1),
            "local_port": In(16), "remote_ip": In(32), "remote_port": In(16),
            "default_port": In(16),
            "open_ack": Out(1), "close_req": Out(1), "close_ack": In(1), "abort": In(1),
            "error": Out(1), "error_code": Out(TcpError), "state": Out(TcpState),
            "peer_ip": Out(32), "peer_port": Out(16), "tx_fill": Out(17),
            "counter_index": In(range(len(TCP_COUNTERS))), "counter_value": Out(32),
            "counters_clear": In(1),
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

        # counters: the events are registered (``count`` is used among sync statements)
        m.submodules.counters = counters = EventCounters(TCP_COUNTERS,
                                                         amounts={"bytes_rx": 11})
        events = Signal(counters.events.shape())
        m.d.sync += events.eq(0)
        m.d.comb += [counters.events.eq(events), counters.clear.eq(self.counters_clear),
                     counters.rd_addr[0].eq(self.counter_index),
                     self.counter_value.eq(counters.rd_data[0])]

        def count(name, amount=1):
            return events[name].eq(amount)

        # ---- connection registers
        remote_mac = Signal(48)
        remote_ip = Signal(32)
        remote_port = Signal(16)
        local_port = Signal(16)
        ephemeral = Signal(16, init=49152)
        iss_clock = Signal(32, init=self._iss_seed)
        m.d.sync += iss_clock.eq(iss_clock + 1)
        snd_wnd = Signal(16)
        mss = Signal(11, init=TCP_MSS_DEFAULT)
        # congestion control counts segments, as Linux does: the descriptor ring already
        # knows how many are in flight, so the window needs no byte arithmetic
        cwnd = Signal(range(nd), init=INITIAL_WINDOW)
        ssthresh = Signal(range(nd), init=nd - 1)
        cwnd_acc = Signal(range(nd))
        dupacks = Signal(2)
        m.d.comb += [self.peer_ip.eq(remote_ip), self.peer_port.eq(remote_port)]

        # Sequence-space registers are written only from the sequence engine's write bus
        # (below). SND.UNA holds the ISS until the SYN is acknowledged; the FIN's sequence
        # number is the write pointer, which stops when the FIN is queued; ``ctl_seq`` is
        # the sequence number of the pending request when it carries no data (written when
        # the request is chosen, or for a RST answering a segment, by that segment's outcome).
        seq_names = ("snd_una", "snd_nxt", "snd_max", "rcv_nxt", "wl1", "wl2", "ctl_seq")
        seq = {name: Signal(32, name=name) for name in seq_names}
        snd_una, snd_nxt, snd_max, rcv_nxt = (seq[n] for n in seq_names[:4])
        wl1, wl2, ctl_seq = seq["wl1"], seq["wl2"], seq["ctl_seq"]
        wbus = Signal(32)
        write = {name: Signal(name=f"write_{name}") for name in seq_names + ("wr_seq",)}

        syn_due = Signal()
        arp_due = Signal()
        ack_now = Signal()          # send an ACK as soon as possible
        ack_owed = Signal()         # one in-order segment not yet acknowledged
        delack = Signal(12)
        rst_due = Signal()
        rst_at_nxt = Signal()       # the pending RST carries SND.NXT (else ``ctl_seq``)
        fin_queued = Signal()
        fin_sent = Signal()
        fin_acked = Signal()
        probe_due = Signal()
        armed = Signal(init=1)

        # The timer counts ticks of 2**scale cycles: the retransmission timeout doubles per
        # back-off without a shifter, TIME-WAIT lasts 2 MSL.
        timer = Signal(32)
        timer_on = Signal()
        backoff = Signal(range(MAX_BACKOFF + 1))
        retries = Signal(4)
        prescaler = Signal(FIN_WAIT_2_SCALE)
        m.d.sync += prescaler.eq(prescaler + 1)
        scale = Signal(range(FIN_WAIT_2_SCALE + 1))
        tick = Signal()
        m.d.comb += tick.eq(Cat(*(prescaler[b] | (scale <= b)
                                  for b in range(FIN_WAIT_2_SCALE))).all())

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
        ahead = Signal(18)
        m.d.comb += ahead.eq(rcv_nxt[:18] - f.seq[:18])
        start_ok = (is_tcp & receiving & tuple_match & (ahead[16:] == 0) & ~f.flags[2] &
                    f.flags[4])
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
        with m.If(write["wr_seq"]):
            m.d.sync += wr_seq.eq(wbus)
        start_of_closed = Mux(seg_len == 0, wr_seq, seg_start)
        m.d.comb += [d_w.addr.eq(d_wr[:-1]), d_w.data.eq(Cat(start_of_closed, close_len, close_sum)),
                     d_w.en.eq(close_seg)]
        with m.If(close_seg):
            m.d.sync += d_wr.eq(d_wr + 1)

        # Distances between sequence numbers of the transmit side stay below the buffer size
        # (2**16), so they are taken modulo 2**18 and their bit 17 is the sign.
        def distance(a, b, c=0):
            d = Signal(18)
            m.d.comb += d.eq(a[:18] - b[:18] - c)
            return d

        # free acknowledged segments, one per cycle
        free_now = Signal()
        m.d.comb += free_now.eq((d_ack != d_wr) & ~distance(snd_una, ack_seq, ack_len)[17])
        d_ack_next = d_ack + free_now
        with m.If(free_now):
            m.d.sync += d_ack.eq(d_ack + 1)
            with m.If(d_snd == d_ack):
                m.d.sync += d_snd.eq(d_snd + 1)

        # ---- transmit requests
        req = self.tx.request
        pending = Signal()          # a request is offered to the builder
        busy = Signal()             # the sequence engine runs a program (requests withdrawn)
        in_flight = Signal(range(nd))          # segments sent and not yet freed
        m.d.comb += in_flight.eq(d_snd - d_ack)
        half_flight = in_flight[1:]
        reduced = Mux(half_flight < 2, 2, half_flight)      # ssthresh after a loss
        # the window never exceeds the ring: it holds nd - 1 segments
        cwnd_grown = Mux(cwnd == nd - 1, cwnd, cwnd + 1)
        inflated = Signal(range(nd + 3))
        m.d.comb += inflated.eq(reduced + 3)
        # (with 8 or more descriptors ssthresh + 3 always fits, and the comparison would be
        # constant)
        most_inflated = max(2, (nd - 1) // 2) + 3
        cwnd_inflated = (Mux(inflated > nd - 1, nd - 1, inflated) if most_inflated > nd - 1
                         else inflated)
        data_fits = ((distance(snd_seq + snd_len, snd_una) <= snd_wnd) &
                     (in_flight < cwnd))
        have_data = (d_snd != d_wr) & (synchronized | (state == S.SYN_RECEIVED))
        all_sent = (d_snd == d_wr) & (seg_len == 0)
        kind_ = Signal(3)           # what the pending request is
        K_RST, K_ARP, K_SYN, K_DATA, K_FIN, K_PROBE, K_ACK = range(7)
        # A data request whose segment was acknowledged (and freed) while it waited for the
        # builder is withdrawn: sending it would step the send pointer past the write
        # pointer, and the segment written next would never leave.
        stale_data = pending & (kind_ == K_DATA) & (d_snd == d_wr)
        m.d.comb += self.tx.valid.eq(pending & ~busy & ~stale_data)

        m.d.comb += [req.kind.eq(FrameKind.TCP), req.eth_dst.eq(remote_mac),
                     req.ip_dst.eq(remote_ip), req.src_port.eq(local_port),
                     req.dst_port.eq(remote_port), req.ack.eq(rcv_nxt), req.window.eq(window),
                     req.seq.eq(Mux(kind_ == K_DATA, snd_seq, ctl_seq))]
        with m.Switch(kind_):
            with m.Case(K_RST):
                m.d.comb += [req.flags.eq(TCP_RST), req.window.eq(0)]
            with m.Case(K_ARP):
                m.d.comb += [req.kind.eq(FrameKind.ARP), req.arp_oper.eq(ARP_REQUEST),
                             req.eth_dst.eq(0xFFFFFFFFFFFF)]
            with m.Case(K_SYN):
                m.d.comb += [req.mss.eq(1),
                             req.flags.eq(Mux(state == S.SYN_SENT, TCP_SYN, TCP_SYN | TCP_ACK))]
            with m.Case(K_DATA):
                m.d.comb += [req.flags.eq(TCP_ACK | TCP_PSH),
                             req.length.eq(snd_len), req.payload_sum.eq(snd_sum),
                             req.payload_addr.eq(snd_seq[:16])]
            with m.Case(K_FIN):
                m.d.comb += req.flags.eq(TCP_FIN | TCP_ACK)
            with m.Case(K_PROBE, K_ACK):
                m.d.comb += req.flags.eq(TCP_ACK)

        # the next request, chosen when none is pending and the sequence engine is free to
        # write its sequence number (a program withdraws a pending request: what it changes
        # may change the request)
        fin_may = fin_queued & all_sent & (~fin_sent | (snd_nxt == wr_seq))
        next_kind = Signal(3)
        next_due = Signal()
        with m.If(rst_due):
            m.d.comb += [next_due.eq(1), next_kind.eq(K_RST)]
        with m.Elif(arp_due & (state == S.ARP)):
            m.d.comb += [next_due.eq(1), next_kind.eq(K_ARP)]
        with m.Elif(syn_due & ((state == S.SYN_SENT) | (state == S.SYN_RECEIVED))):
            m.d.comb += [next_due.eq(1), next_kind.eq(K_SYN)]
        with m.Elif(have_data & (state != S.SYN_RECEIVED) & data_fits):
            m.d.comb += [next_due.eq(1), next_kind.eq(K_DATA)]
        with m.Elif(fin_may & ((state == S.FIN_WAIT_1) | (state == S.LAST_ACK) |
                               (state == S.CLOSING))):
            m.d.comb += [next_due.eq(1), next_kind.eq(K_FIN)]
        with m.Elif(probe_due):
            m.d.comb += [next_due.eq(1), next_kind.eq(K_PROBE)]
        with m.Elif(ack_now & synchronized):
            m.d.comb += [next_due.eq(1), next_kind.eq(K_ACK)]
        choose = Signal()
        with m.If(choose):
            m.d.sync += [pending.eq(1), kind_.eq(next_kind)]

        sent = self.tx.valid & self.tx.ready
        withdraw = Signal()
        with m.If(stale_data | withdraw):
            m.d.sync += pending.eq(0)
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
                    m.d.sync += [syn_due.eq(0), timer_on.eq(1), timer.eq(0)]
                with m.Case(K_DATA):
                    m.d.sync += d_snd.eq(d_snd + 1)
                    with m.If(~timer_on):
                        m.d.sync += [timer_on.eq(1), timer.eq(0)]
                with m.Case(K_FIN):
                    m.d.sync += fin_sent.eq(1)
                    with m.If(~timer_on):
                        m.d.sync += [timer_on.eq(1), timer.eq(0)]
                with m.Case(K_PROBE):
                    m.d.sync += probe_due.eq(0)

        # delayed ACK: at most 20 us (2500 cycles at 125 MHz)
        with m.If(ack_owed & ~ack_now):
            m.d.sync += delack.eq(delack + 1)
            with m.If(delack == 2500):
                m.d.sync += ack_now.eq(1)
        # window update once the user has made room (SWS avoidance, RFC 9293 §3.8.6.2.2);
        # not in the cycle a segment leaves: ``adv_wnd`` takes its window only then
        with m.If(receiving & ~sent & (window >= adv_wnd + Mux(mss + mss < rxd // 2, mss + mss,
                                                                 rxd // 2))):
            m.d.sync += ack_now.eq(1)

        # ---- timers
        with m.If(timer_on & tick):
            m.d.sync += timer.eq(timer + 1)
        limit = Signal(32)
        msl_timed = (state == S.TIME_WAIT) | (state == S.FIN_WAIT_2)
        m.d.sync += limit.eq(Mux(state == S.ARP, self.arp_retry_cycles,
                                 Mux(msl_timed, self.msl_cycles, self.rto_cycles)))
        # the tick follows the state at once: a registered scale let the first cycle of
        # FIN-WAIT-2 or TIME-WAIT count at the previous state's rate (a tick early)
        m.d.comb += scale.eq(Mux(state == S.TIME_WAIT, 1,
                                 Mux(state == S.FIN_WAIT_2, FIN_WAIT_2_SCALE,
                                     Mux(state == S.ARP, 0, backoff))))
        timer_done = timer >= limit
        expired = timer_on & timer_done
        tw_expired = (state == S.TIME_WAIT) & timer_done
        fw2_expired = (state == S.FIN_WAIT_2) & expired
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
        with m.If(fin_queued & all_sent & ~fin_sent):
            with m.If(state == S.ESTABLISHED):
                m.d.sync += state.eq(S.FIN_WAIT_1)
            with m.If(state == S.CLOSE_WAIT):
                m.d.sync += state.eq(S.LAST_ACK)

        # ---- segment arrival: the verdict's fields are latched; the sequence engine
        # compares them and applies the outcome (DECIDE) and the new sequence numbers
        seg = self.seg_done & self.seg_accept & is_tcp
        port_listening = (state == S.LISTEN) & (f.dst_port == local_port)
        listen_match = port_listening & f.flags[1] & ~f.flags[2] & ~f.flags[4]
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

        s_seq = Signal(32)
        s_ack = Signal(32)
        s_flags = Signal(8)
        s_window = Signal(16)
        s_plen = Signal(11)
        s_committed = Signal(11)
        s_mss = Signal(11)
        s_listen = Signal()         # the pending initialisation is a server's (from a SYN)
        arrival_pending = Signal()
        init_pending = Signal()
        with m.If(seg & (conn_hit | listen_hit)):
            m.d.sync += [s_seq.eq(f.seq), s_ack.eq(f.ack), s_flags.eq(f.flags),
                         s_window.eq(f.window), s_plen.eq(f.payload_len),
                         s_committed.eq(rx_written), s_mss.eq(self._mss(f))]
        arriving = seg & conn_hit
        with m.If(arriving):
            m.d.sync += [arrival_pending.eq(1), count("segments_rx")]
            with m.If(state == S.FIN_WAIT_2):
                m.d.sync += timer.eq(0)         # an idle timeout: the peer is still there

        m.d.sync += self.error.eq(0)

        def abort_to(code):
            return [state.eq(Mux(~self.active & self.open_req & (state == S.SYN_RECEIVED),
                                 S.LISTEN, S.CLOSED)),
                    self.error_code.eq(code), self.error.eq(1)]

        def time_out():
            """Give up: RST at SND.NXT if the connection was synchronized, error TIMEOUT."""
            return [rst_due.eq(synchronized), rst_at_nxt.eq(1)] + abort_to(TcpError.TIMEOUT)

        def initialise():
            return [init_pending.eq(1), timer.eq(0), retries.eq(0), backoff.eq(0),
                    cwnd.eq(INITIAL_WINDOW), ssthresh.eq(nd - 1), cwnd_acc.eq(0),
                    dupacks.eq(0)]

        with m.If(seg & listen_hit):
            m.d.sync += rx_rptr.eq(rx_commit)      # a new connection starts with no old bytes
            m.d.sync += [state.eq(S.SYN_RECEIVED), remote_mac.eq(f.sender_mac),
                         remote_ip.eq(f.sender_ip), remote_port.eq(f.src_port),
                         mss.eq(self._mss(f)), snd_wnd.eq(f.window), syn_due.eq(1),
                         s_listen.eq(1), self.error_code.eq(TcpError.NONE)] + initialise()
        # ARP resolution for a client
        with m.If(arp_hit):
            m.d.sync += rx_rptr.eq(rx_commit)
            m.d.sync += [remote_mac.eq(f.sender_mac), state.eq(S.SYN_SENT), syn_due.eq(1),
                         timer_on.eq(0), snd_wnd.eq(0), s_listen.eq(0)] + initialise()

        # the sequence engine: one adder, result = a + b (+ carry), or a - b (- 1)
        alu_a = Signal(32)
        alu_b = Signal(32)
        alu_sub = Signal()
        alu_minus_1 = Signal()
        alu = Signal(32)
        m.d.comb += [alu.eq(alu_a + Mux(alu_sub, ~alu_b, alu_b) + (alu_sub & ~alu_minus_1)),
                     wbus.eq(alu)]
        alu_zero = alu == 0
        alu_positive = ~alu[31] & ~alu_zero
        alu_in_window = (alu[16:] == 0) & (alu[:16] < window)
        flag = {name: Signal(name=f"arrival_{name}") for name in (
            "seq_is_rcv_nxt", "seq_is_rcv_nxt_minus_1", "seq_in_window", "ack_is_snd_una",
            "ack_after_snd_una", "ack_is_snd_una_plus_1", "ack_after_snd_max",
            "ack_is_fin_plus_1", "seq_after_wl1", "seq_is_wl1", "ack_not_before_wl2",
            "ack_after_snd_nxt", "last_in_window", "fin_at_end", "snd_max_behind",
            "ack_is_snd_max")}
        d = Signal(32)              # SEG.SEQ - RCV.NXT
        seg_seqlen = Signal(12)
        m.d.comb += seg_seqlen.eq(s_plen + s_flags[0])
        a_fin, a_syn, a_rst, a_ack = s_flags[0], s_flags[1], s_flags[2], s_flags[4]

        # operands: one of a few wide registers, or a small signed value
        small_a = Signal(signed(13))
        small_b = Signal(signed(13))
        a_sources = {"small": small_a, "snd_seq": snd_seq, "iss_clock": iss_clock,
                     "s_seq": s_seq, "s_ack": s_ack, "snd_nxt": snd_nxt, "d": d}
        b_sources = {"small": small_b, "snd_una": snd_una, "snd_nxt": snd_nxt,
                     "snd_max": snd_max, "rcv_nxt": rcv_nxt, "wr_seq": wr_seq, "wl1": wl1,
                     "wl2": wl2}
        a_sel = Signal(range(len(a_sources)))
        b_sel = Signal(range(len(b_sources)))
        for sel, target, sources in ((a_sel, alu_a, a_sources), (b_sel, alu_b, b_sources)):
            with m.Switch(sel):
                for k, value in enumerate(sources.values()):
                    with m.Case(k):
                        m.d.comb += target.eq(value)

        def op(a, b, *, sub=False, minus_1=False, writes=(), results=()):
            """Drive the adder this cycle with ``a`` and ``b`` (names of wide sources, or small
            values); store ``results`` and write ``writes`` (names of sequence registers, or
            (name, condition)) from its output."""
            for operand, sel, small, sources in ((a, a_sel, small_a, a_sources),
                                                 (b, b_sel, small_b, b_sources)):
                if isinstance(operand, str):
                    m.d.comb += sel.eq(list(sources).index(operand))
                else:
                    m.d.comb += [sel.eq(0), small.eq(operand)]
            m.d.comb += [alu_sub.eq(sub), alu_minus_1.eq(minus_1)]
            for w in writes:
                name, cond = (w, 1) if isinstance(w, str) else w
                m.d.comb += write[name].eq(cond)
            m.d.sync += list(results)

        intent = {name: Signal(name=f"intent_{name}") for name in (
            "una", "nxt", "wl", "rst", "rcv", "rcv_syn", "retransmit")}
        rcv_add = Signal(12)        # bytes (and FIN) RCV.NXT advances by
        commit = Signal()
        # engine work outside programs, in an idle cycle: a sent frame's SND.NXT, a
        # retransmission timeout's SND.NXT, a zero-window probe's sequence number
        sent_op = Signal()
        m.d.comb += sent_op.eq(sent & ((kind_ == K_SYN) | (kind_ == K_DATA) | (kind_ == K_FIN)))
        rto_op = Signal()

        with m.FSM(name="sequence_engine") as engine:
            with m.State("IDLE"):
                with m.If(sent_op):
                    with m.Switch(kind_):
                        with m.Case(K_SYN):
                            op(1, "snd_una", writes=("snd_nxt",))
                        with m.Case(K_DATA):
                            op("snd_seq", snd_len, writes=("snd_nxt",))
                        with m.Case(K_FIN):
                            op(1, "wr_seq", writes=("snd_nxt",))
                with m.Elif(rto_op):
                    op(0, "snd_una", writes=("snd_nxt",))
                with m.Elif(~pending & next_due & ~arrival_pending & ~init_pending):
                    m.d.comb += choose.eq(1)
                    with m.Switch(next_kind):
                        with m.Case(K_RST):
                            with m.If(rst_at_nxt):
                                op(0, "snd_nxt", writes=("ctl_seq",))
                        with m.Case(K_SYN):
                            op(0, "snd_una", writes=("ctl_seq",))
                        with m.Case(K_FIN):
                            op(0, "wr_seq", writes=("ctl_seq",))
                        with m.Case(K_PROBE):
                            op(-1, "snd_una", writes=("ctl_seq",))
                        with m.Case(K_ACK):
                            op(0, "snd_nxt", writes=("ctl_seq",))
                with m.If(sent_op):
                    m.next = "MAX_COMPARE"
                with m.Elif(arrival_pending):
                    m.d.sync += arrival_pending.eq(0)
                    m.next = "COMPARE_RCV_NXT"
                with m.Elif(init_pending):
                    m.d.sync += init_pending.eq(0)
                    m.next = "INIT_ISS"
            # SND.MAX follows SND.NXT forward
            with m.State("MAX_COMPARE"):
                op("snd_nxt", "snd_max", sub=True, results=[flag["snd_max_behind"].eq(alu_positive)])
                m.next = "MAX_WRITE"
            with m.State("MAX_WRITE"):
                op(0, "snd_nxt", writes=[("snd_max", flag["snd_max_behind"])])
                m.next = "IDLE"
            # a new connection's sequence numbers
            with m.State("INIT_ISS"):
                op("iss_clock", 0, writes=("snd_una", "snd_nxt", "snd_max"))
                m.next = "INIT_WR_SEQ"
            with m.State("INIT_WR_SEQ"):
                op(1, "snd_una", writes=("wr_seq",))
                m.next = "INIT_RCV_NXT"
            with m.State("INIT_RCV_NXT"):
                op("s_seq", 1, writes=[("rcv_nxt", s_listen)])
                m.next = "INIT_WL1"
            with m.State("INIT_WL1"):
                with m.If(s_listen):
                    op("s_seq", 0, writes=("wl1",))
                with m.Else():
                    op(0, 0, writes=("wl1",))
                m.next = "INIT_WL2"
            with m.State("INIT_WL2"):
                op(0, 0, writes=("wl2",))
                m.next = "IDLE"
            # a segment of the connection: its comparisons, one per cycle ...
            compares = [
                ("COMPARE_RCV_NXT", "s_seq", "rcv_nxt", False, [
                    d.eq(alu), flag["seq_is_rcv_nxt"].eq(alu_zero),
                    flag["seq_is_rcv_nxt_minus_1"].eq(alu == 0xFFFFFFFF),
                    flag["seq_in_window"].eq(alu_in_window)]),
                ("COMPARE_SND_UNA", "s_ack", "snd_una", False, [
                    flag["ack_is_snd_una"].eq(alu_zero),
                    flag["ack_after_snd_una"].eq(alu_positive),
                    flag["ack_is_snd_una_plus_1"].eq(alu == 1)]),
                ("COMPARE_SND_MAX", "s_ack", "snd_max", False, [
                    flag["ack_after_snd_max"].eq(alu_positive),
                    flag["ack_is_snd_max"].eq(alu_zero)]),
                ("COMPARE_FIN", "s_ack", "wr_seq", True, [
                    flag["ack_is_fin_plus_1"].eq(alu_zero)]),
                ("COMPARE_WL1", "s_seq", "wl1", False, [
                    flag["seq_after_wl1"].eq(alu_positive), flag["seq_is_wl1"].eq(alu_zero)]),
                ("COMPARE_WL2", "s_ack", "wl2", False, [
                    flag["ack_not_before_wl2"].eq(~alu[31])]),
                ("COMPARE_SND_NXT", "s_ack", "snd_nxt", False, [
                    flag["ack_after_snd_nxt"].eq(alu_positive)]),
            ]
            for k, (name, a, b, minus_1, results) in enumerate(compares):
                with m.State(name):
                    op(a, b, sub=True, minus_1=minus_1, results=results)
                    m.next = compares[k + 1][0] if k + 1 < len(compares) else "LAST_IN_WINDOW"
            with m.State("LAST_IN_WINDOW"):
                op("d", seg_seqlen - 1,
                   results=[flag["last_in_window"].eq(alu_in_window)])
                m.next = "FIN_AT_END"
            with m.State("FIN_AT_END"):
                op("d", s_plen - s_committed, results=[flag["fin_at_end"].eq(alu_zero)])
                m.next = "DECIDE"
            # ... the outcome (below) ...
            with m.State("DECIDE"):
                m.next = "WRITE_ACK"
            # ... and the new sequence numbers
            with m.State("WRITE_ACK"):
                op("s_ack", 0, writes=[("snd_una", intent["una"]), ("snd_nxt", intent["nxt"]),
                                     ("wl2", intent["wl"]), ("ctl_seq", intent["rst"])])
                m.next = "WRITE_SEQ"
            with m.State("WRITE_SEQ"):
                op("s_seq", 0, writes=[("wl1", intent["wl"])])
                m.next = "WRITE_RCV_NXT"
            with m.State("WRITE_RCV_NXT"):
                with m.If(intent["rcv_syn"]):
                    op("s_seq", 1, writes=[("rcv_nxt", intent["rcv"])])
                with m.Else():
                    op(rcv_add, "rcv_nxt", writes=[("rcv_nxt", intent["rcv"])])
                m.next = "WRITE_RETRANSMIT"
            with m.State("WRITE_RETRANSMIT"):
                op(0, "snd_una", writes=[("snd_nxt", intent["retransmit"])])
                m.next = "IDLE"
        m.d.comb += [busy.eq(~engine.ongoing("IDLE")), withdraw.eq(busy | rto_op)]
        for name, reg in seq.items():
            with m.If(write[name]):
                m.d.sync += reg.eq(wbus)
        # a timer may act only between segments: a segment being applied, or arriving in
        # this very cycle, is seen first (it may restart the timer: FIN-WAIT-2 ends only
        # after a silence)
        timers_free = engine.ongoing("IDLE") & ~sent_op & ~arrival_pending & ~arriving

        # the outcome of a segment of the connection
        acceptable = Mux(seg_seqlen == 0,
                         Mux(window == 0, flag["seq_is_rcv_nxt"], flag["seq_in_window"]),
                         (window != 0) & (flag["seq_in_window"] | flag["last_in_window"]))
        new_ack = flag["ack_after_snd_una"] & ~flag["ack_after_snd_max"]
        fin_acked_now = fin_sent & flag["ack_is_fin_plus_1"]
        decide = engine.ongoing("DECIDE")
        with m.If(decide):
            m.d.sync += [intent[name].eq(0) for name in intent]
            m.d.sync += rcv_add.eq(s_committed)
        with m.If(decide & (state == S.SYN_SENT)):
            with m.If(a_ack & ~flag["ack_is_snd_una_plus_1"]):
                with m.If(~a_rst):
                    m.d.sync += [rst_due.eq(1), rst_at_nxt.eq(0), intent["rst"].eq(1)]
            with m.Elif(a_rst):
                with m.If(a_ack):
                    m.d.sync += abort_to(TcpError.REFUSED)
                    m.d.sync += count("rst_rx")
            with m.Elif(a_syn):
                m.d.sync += [intent["rcv"].eq(1), intent["rcv_syn"].eq(1), mss.eq(s_mss),
                             snd_wnd.eq(s_window), intent["wl"].eq(1)]
                with m.If(a_ack):
                    m.d.sync += [state.eq(S.ESTABLISHED), intent["una"].eq(1), timer_on.eq(0),
                                 retries.eq(0), backoff.eq(0), ack_now.eq(1)]
                with m.Else():
                    # simultaneous open: the SYN-ACK acknowledges the peer's SYN
                    m.d.sync += [state.eq(S.SYN_RECEIVED), syn_due.eq(1)]
        with m.Elif(decide):
            with m.If(a_syn & (state == S.SYN_RECEIVED) & flag["seq_is_rcv_nxt_minus_1"]):
                m.d.sync += syn_due.eq(1)               # our SYN-ACK was lost: resend it
            with m.Elif(~acceptable):
                with m.If(~a_rst):
                    m.d.sync += [ack_now.eq(1), count("dropped_segments")]
                with m.If(a_fin & (state == S.TIME_WAIT)):
                    # the peer's FIN again (it lies below RCV.NXT): acknowledge it and
                    # restart the 2 MSL (RFC 9293 §3.10.7.4)
                    m.d.sync += timer.eq(0)
            with m.Elif(a_rst):
                m.d.sync += count("rst_rx")
                with m.If(flag["seq_is_rcv_nxt"]):
                    m.d.sync += abort_to(TcpError.RESET)
                with m.Else():
                    m.d.sync += ack_now.eq(1)           # challenge ACK (RFC 5961 §3)
            with m.Elif(a_syn):
                m.d.sync += ack_now.eq(1)               # challenge ACK (RFC 5961 §4)
            with m.Elif(~a_ack):
                pass
            with m.Elif(state == S.SYN_RECEIVED):
                with m.If(flag["ack_is_snd_una_plus_1"]):
                    m.d.sync += [state.eq(S.ESTABLISHED), intent["una"].eq(1), timer_on.eq(0),
                                 retries.eq(0), backoff.eq(0), snd_wnd.eq(s_window),
                                 intent["wl"].eq(1)]
                    m.d.comb += commit.eq(1)
                with m.Else():
                    m.d.sync += [rst_due.eq(1), rst_at_nxt.eq(0), intent["rst"].eq(1)]
            with m.Elif(flag["ack_after_snd_max"]):
                m.d.sync += ack_now.eq(1)
            with m.Else():
                m.d.comb += commit.eq(1)
                with m.If(new_ack):
                    m.d.sync += [intent["una"].eq(1), retries.eq(0), backoff.eq(0), timer.eq(0),
                                 timer_on.eq(~flag["ack_is_snd_max"]),
                                 dupacks.eq(0), intent["nxt"].eq(flag["ack_after_snd_nxt"])]
                    # slow start: one segment per ACK; congestion avoidance: one per window
                    with m.If(cwnd < ssthresh):
                        m.d.sync += cwnd.eq(cwnd_grown)
                    with m.Elif(cwnd_acc + 1 >= cwnd):
                        m.d.sync += [cwnd_acc.eq(0), cwnd.eq(cwnd_grown)]
                    with m.Else():
                        m.d.sync += cwnd_acc.eq(cwnd_acc + 1)
                    with m.If(fin_acked_now):
                        m.d.sync += fin_acked.eq(1)
                        with m.Switch(state):
                            with m.Case(S.FIN_WAIT_1):
                                m.d.sync += [state.eq(S.FIN_WAIT_2), timer.eq(0),
                                             timer_on.eq(1)]
                            with m.Case(S.CLOSING):
                                m.d.sync += [state.eq(S.TIME_WAIT), timer.eq(0),
                                             timer_on.eq(1)]
                            with m.Case(S.LAST_ACK):
                                m.d.comb += go_closed.eq(1)
                with m.Elif(flag["ack_is_snd_una"] & (s_plen == 0) & ~a_fin & ~nothing_out &
                            (s_window == snd_wnd)):
                    m.d.sync += [dupacks.eq(Mux(dupacks == 3, 3, dupacks + 1)), count("dup_acks")]
                    with m.If(dupacks == 2):
                        # fast retransmit (RFC 5681 §3.2), go-back-N from SND.UNA
                        m.d.sync += [d_snd.eq(d_ack_next), intent["retransmit"].eq(1),
                                     ssthresh.eq(reduced), cwnd.eq(cwnd_inflated),
                                     count("fast_retransmit"), timer.eq(0)]
                        with m.If(fin_sent & ~fin_acked):
                            m.d.sync += fin_sent.eq(0)
                    with m.If(dupacks == 3):
                        m.d.sync += cwnd.eq(cwnd_grown)
                with m.If(flag["seq_after_wl1"] |
                          (flag["seq_is_wl1"] & flag["ack_not_before_wl2"])):
                    m.d.sync += [snd_wnd.eq(s_window), intent["wl"].eq(1)]
                # data and FIN
                with m.If(s_plen != 0):
                    with m.If((s_committed == s_plen) & flag["seq_is_rcv_nxt"]):
                        with m.If(ack_owed | s_flags[3]):
                            m.d.sync += ack_now.eq(1)
                        with m.Else():
                            m.d.sync += [ack_owed.eq(1), delack.eq(0)]
                    with m.Else():
                        m.d.sync += ack_now.eq(1)
                with m.If(a_fin & flag["fin_at_end"]):
                    m.d.sync += [intent["rcv"].eq(1), rcv_add.eq(s_committed + 1),
                                 ack_now.eq(1)]
                    with m.Switch(state):
                        with m.Case(S.ESTABLISHED):
                            m.d.sync += state.eq(S.CLOSE_WAIT)
                        with m.Case(S.FIN_WAIT_1):
                            with m.If(fin_acked_now):
                                m.d.sync += [state.eq(S.TIME_WAIT), timer.eq(0), timer_on.eq(1)]
                            with m.Else():
                                m.d.sync += state.eq(S.CLOSING)
                        with m.Case(S.FIN_WAIT_2):
                            m.d.sync += [state.eq(S.TIME_WAIT), timer.eq(0), timer_on.eq(1)]
                with m.Elif(s_committed != 0):
                    m.d.sync += intent["rcv"].eq(1)

        # commit or roll back the bytes written while the frame arrived: at the outcome for a
        # segment of the connection, at the verdict for any other frame (a runt's verdict
        # may fall between the two: it wrote nothing)
        with m.If(self.seg_done):
            m.d.sync += rx_written.eq(0)
            with m.If(~(seg & conn_hit) & ~arrival_pending & ~busy):
                m.d.sync += rx_spec.eq(rx_commit)
        with m.If(decide):
            with m.If(commit & receiving):
                m.d.sync += [rx_commit.eq(rx_spec), count("bytes_rx", s_committed)]
            with m.Else():
                m.d.sync += rx_spec.eq(rx_commit)

        # retransmission timeout (RFC 6298 with a fixed initial RTO, doubled per expiry)
        with m.If(state == S.ARP):
            with m.If(timer_on & timer_done):
                m.d.sync += [retries.eq(retries + 1), timer.eq(0), arp_due.eq(1)]
                with m.If(retries == 3):
                    m.d.sync += [state.eq(S.CLOSED), self.error_code.eq(TcpError.ARP),
                                 self.error.eq(1)]
        with m.Elif(tw_expired & timers_free):
            m.d.comb += go_closed.eq(1)
        with m.Elif(fw2_expired & timers_free):
            # the peer acknowledged our FIN and went silent: reset, as Linux does for an
            # orphaned FIN-WAIT-2 socket
            m.d.sync += time_out()
        with m.Elif(expired & (state != S.TIME_WAIT) & timers_free & ~init_pending):
            m.d.sync += [timer.eq(0),
                         backoff.eq(Mux(backoff == MAX_BACKOFF, MAX_BACKOFF, backoff + 1))]
            with m.If(zero_wnd_wait):
                m.d.sync += probe_due.eq(1)             # persist timer: keep probing
            with m.Elif(retries == 7):
                m.d.sync += time_out()
            with m.Else():
                m.d.sync += [retries.eq(retries + 1), count("rto"), d_snd.eq(d_ack_next),
                             cwnd.eq(1), cwnd_acc.eq(0), dupacks.eq(0), ssthresh.eq(reduced)]
                m.d.comb += rto_op.eq(1)
                with m.If((state == S.SYN_SENT) | (state == S.SYN_RECEIVED)):
                    m.d.sync += syn_due.eq(1)
                with m.If(fin_sent & ~fin_acked):
                    m.d.sync += fin_sent.eq(0)
                with m.If(nothing_out):
                    m.d.sync += timer_on.eq(0)

        with m.If(self.abort & synchronized):
            m.d.sync += [rst_due.eq(1), rst_at_nxt.eq(1), state.eq(S.CLOSED)]
        with m.If(go_closed):
            m.d.sync += [state.eq(S.CLOSED), timer_on.eq(0)]
        with m.If(state == S.CLOSED):
            m.d.sync += [d_snd.eq(d_wr), d_ack.eq(d_wr), seg_len.eq(0), seg_sum.eq(0),
                         snd_wnd.eq(0)]
        return m

    @staticmethod
    def _mss(f):
        peer = Mux(f.has_mss, f.mss, TCP_MSS_DEFAULT)
        return Mux(peer < TCP_MSS_MIN, TCP_MSS_MIN, Mux(peer < TCP_MSS, peer, TCP_MSS))[:11]
