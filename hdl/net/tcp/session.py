"""One TCP session: server or client, sliding window, retransmission, both directions
(docs/network.md "TCP session"; RFC 9293, RFC 5681, RFC 6298)."""

from amaranth.hdl import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ...params import ParameterError, check_int, check_power_of_two
from ...stream import AXIStreamSignature
from ..counters import EventCounters
from ..mac import GMII_HZ
from ..rx import RX_FIELDS, FrameKind
from ..tx import TxRequestSignature
from .codes import TCP_COUNTERS, TcpRequest, TcpState
from .congestion import TcpCongestionControl
from .connection import TcpConnection, user_control_members
from .receive_ring import TcpReceiveRing
from .scheduler import TcpRequestScheduler
from .sequence_engine import TcpSequenceEngine
from .timer import TcpTimer
from .transmit_buffer import TcpTransmitBuffer

__all__ = ["TcpSession"]


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
    lanes : int
        Bytes per beat of the parser's payload, the builder's reads and ``s_axis``, 1 or 2.
    read_lanes : int
        Bytes per beat of ``m_axis``: 1 or ``lanes`` (default; see
        :class:`~hdl.net.tcp.receive_ring.TcpReceiveRing`).
    descriptors : int
        Segments the transmit buffer may hold, a power of two in 4..256.
    iss_seed : int
        Initial value of the initial-sequence-number clock (tests start it near 2**32).

    Members
    -------
    seg_* : In
        From the :class:`FrameParser`: ``seg_fields`` (live header fields), ``seg_kind``,
        ``seg_payload_*`` (payload beats as they arrive), ``seg_done``, ``seg_accept`` (the
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
    tx : Out(TxRequestSignature(lanes))
        Frame requests to the :class:`FrameBuilder`.
    s_axis : In(AXIStreamSignature(8 * lanes, keep=lanes > 1))
        Bytes to send (``tkeep`` contiguous from lane 0); ``tlast`` pushes the segment out at
        once. ``tready`` is high only in ESTABLISHED and CLOSE-WAIT, while there is buffer
        room.
    m_axis : Out(AXIStreamSignature(8 * read_lanes, keep=read_lanes > 1))
        Received bytes in order, up to ``read_lanes`` per beat (``tlast`` is 0).
        Backpressure closes the receive window.
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
    def check_parameters(*, tx_depth=65536, rx_depth=65536, descriptors=64, iss_seed=0x1000,
                         lanes=1, read_lanes=None, clock_hz=GMII_HZ):
        """The parameters, validated (:class:`~hdl.params.ParameterError` names a bad one);
        for containers that build their sessions later, in ``elaborate``."""
        lanes = check_int("lanes", lanes, 1, 2)
        read_lanes = lanes if read_lanes is None else read_lanes
        if read_lanes not in (1, lanes):
            raise ParameterError("read_lanes", read_lanes, f"1 or lanes ({lanes})")
        return dict(tx_depth=check_power_of_two("tx_depth", tx_depth, 2048, 65536),
                    rx_depth=check_power_of_two("rx_depth", rx_depth, 2048, 65536),
                    descriptors=check_power_of_two("descriptors", descriptors, 4, 256),
                    iss_seed=check_int("iss_seed", iss_seed, 0, 2**32 - 1),
                    lanes=lanes, read_lanes=read_lanes,
                    clock_hz=check_int("clock_hz", clock_hz, 1_000_000, 1_000_000_000))

    def __init__(self, *, tx_depth=65536, rx_depth=65536, descriptors=64, iss_seed=0x1000,
                 lanes=1, read_lanes=None, clock_hz=GMII_HZ):
        params = self.check_parameters(tx_depth=tx_depth, rx_depth=rx_depth,
                                       descriptors=descriptors, iss_seed=iss_seed, lanes=lanes,
                                       read_lanes=read_lanes, clock_hz=clock_hz)
        self._tx_depth, self._rx_depth = params["tx_depth"], params["rx_depth"]
        self._descriptors, self._iss_seed = params["descriptors"], params["iss_seed"]
        self._lanes, self._clock_hz = params["lanes"], params["clock_hz"]
        self._read_lanes = params["read_lanes"]
        L, R = self._lanes, self._read_lanes
        super().__init__({
            "seg_fields": In(RX_FIELDS), "seg_kind": In(FrameKind),
            "seg_payload_data": In(8 * L), "seg_payload_valid": In(1),
            "seg_payload_keep": In(L), "seg_payload_offset": In(11),
            "seg_done": In(1), "seg_accept": In(1), "seg_arp": In(1),
            "conn_match": Out(1), "listen_match": Out(1), "port_listening": Out(1),
            "listen_block": In(1),
            "tx": Out(TxRequestSignature(L)),
            "s_axis": In(AXIStreamSignature(8 * L, keep=L > 1)),
            "m_axis": Out(AXIStreamSignature(8 * R, keep=R > 1)),
            **user_control_members(),
            "tx_fill": Out(17),
            "counter_index": In(range(len(TCP_COUNTERS))), "counter_value": Out(32),
            "counters_clear": In(1),
            "rto_cycles": In(32), "msl_cycles": In(32), "arp_retry_cycles": In(32),
        })

    def elaborate(self, platform):
        m = Module()
        L = self._lanes
        m.submodules.ring = ring = TcpReceiveRing(self._rx_depth, lanes=L,
                                                  read_lanes=self._read_lanes)
        m.submodules.tx_buffer = buffer = TcpTransmitBuffer(depth=self._tx_depth,
                                                            descriptors=self._descriptors,
                                                            lanes=L)
        m.submodules.engine = engine = TcpSequenceEngine(iss_seed=self._iss_seed)
        m.submodules.scheduler = scheduler = TcpRequestScheduler()
        m.submodules.timer = timer = TcpTimer()
        m.submodules.congestion = congestion = TcpCongestionControl(
            descriptors=self._descriptors)
        m.submodules.connection = conn = TcpConnection(rx_depth=self._rx_depth,
                                                       descriptors=self._descriptors,
                                                       clock_hz=self._clock_hz)

        # parser and user side
        m.d.comb += [
            conn.seg_fields.eq(self.seg_fields), conn.seg_kind.eq(self.seg_kind),
            conn.seg_done.eq(self.seg_done), conn.seg_accept.eq(self.seg_accept),
            conn.seg_arp.eq(self.seg_arp), conn.listen_block.eq(self.listen_block),
            self.conn_match.eq(conn.conn_match), self.listen_match.eq(conn.listen_match),
            self.port_listening.eq(conn.port_listening),
            ring.payload_data.eq(self.seg_payload_data),
            ring.payload_valid.eq(self.seg_payload_valid),
            ring.payload_keep.eq(self.seg_payload_keep),
            ring.payload_offset.eq(self.seg_payload_offset),
            ring.frame_end.eq(self.seg_done),
        ]
        for name, member in user_control_members().items():
            if member.flow == wiring.In:
                m.d.comb += getattr(conn, name).eq(getattr(self, name))
            else:
                m.d.comb += getattr(self, name).eq(getattr(conn, name))
        wiring.connect(m, ring.m_axis, wiring.flipped(self.m_axis))
        wiring.connect(m, wiring.flipped(self.s_axis), buffer.s_axis)

        # receive ring
        m.d.comb += [ring.accept.eq(conn.ring_accept), ring.skip.eq(conn.ring_skip),
                     ring.commit.eq(conn.ring_commit), ring.rollback.eq(conn.ring_rollback),
                     ring.discard.eq(conn.ring_discard),
                     conn.ring_written.eq(ring.written), conn.window.eq(ring.window)]

        # transmit buffer
        sent_data = scheduler.sent & (scheduler.kind == TcpRequest.DATA)
        m.d.comb += [
            buffer.accept.eq(conn.tx_accept), buffer.mss.eq(conn.mss),
            buffer.snd_una.eq(engine.snd_una), buffer.advance.eq(sent_data),
            buffer.rewind.eq(conn.tx_rewind), buffer.reset.eq(conn.tx_reset),
            buffer.load.eq(engine.wr_seq_load), buffer.load_value.eq(engine.wr_seq_value),
            buffer.rd_addr.eq(self.tx.rd_addr), self.tx.rd_data.eq(buffer.rd_data),
            self.tx_fill.eq(buffer.fill),
            conn.tx_unsent.eq(buffer.unsent), conn.tx_all_sent.eq(buffer.all_sent),
            conn.tx_in_flight.eq(buffer.in_flight), conn.tx_next_seq.eq(buffer.next_seq),
            conn.tx_next_len.eq(buffer.next_len), conn.wr_seq.eq(buffer.wr_seq),
        ]

        # sequence engine
        m.d.comb += [
            engine.sent.eq(scheduler.sent), engine.sent_kind.eq(scheduler.kind),
            engine.sent_seq.eq(buffer.next_seq), engine.sent_len.eq(buffer.next_len),
            engine.rewind.eq(conn.engine_rewind),
            engine.request_due.eq(scheduler.next_due),
            engine.request_kind.eq(scheduler.next_kind),
            engine.request_pending.eq(scheduler.pending),
            engine.rst_at_nxt.eq(conn.rst_at_nxt),
            engine.arrive.eq(conn.engine_arrive), engine.initialise.eq(conn.engine_initialise),
            engine.listen.eq(conn.engine_listen),
            engine.seg_seq.eq(conn.seg_seq), engine.seg_ack.eq(conn.seg_ack),
            engine.seg_len.eq(conn.seg_len), engine.seg_fin.eq(conn.seg_fin),
            engine.seg_written.eq(conn.seg_written), engine.window.eq(ring.window),
            engine.intent.eq(conn.intent), engine.rcv_add.eq(conn.rcv_add),
            engine.wr_seq.eq(buffer.wr_seq),
            conn.flags.eq(engine.flags), conn.deciding.eq(engine.deciding),
            conn.snd_una.eq(engine.snd_una), conn.snd_nxt.eq(engine.snd_nxt),
            conn.snd_max.eq(engine.snd_max), conn.rcv_nxt.eq(engine.rcv_nxt),
            conn.engine_busy.eq(engine.busy), conn.arrival_pending.eq(engine.arrival_pending),
            conn.init_pending.eq(engine.init_pending),
        ]

        # request scheduler and frame builder
        for request in TcpRequest:
            due = f"{request.name.lower()}_due"
            m.d.comb += getattr(scheduler, due).eq(getattr(conn, due))
        m.d.comb += [
            scheduler.choose.eq(engine.choose), scheduler.hold.eq(engine.busy),
            scheduler.withdraw.eq(engine.busy | conn.engine_rewind),
            scheduler.unsent.eq(buffer.unsent),
            scheduler.remote_mac.eq(conn.peer_mac), scheduler.remote_ip.eq(conn.peer_ip),
            scheduler.local_port.eq(conn.bound_port), scheduler.remote_port.eq(conn.peer_port),
            scheduler.ack.eq(engine.rcv_nxt), scheduler.window.eq(ring.window),
            scheduler.ctl_seq.eq(engine.ctl_seq),
            scheduler.data_seq.eq(buffer.next_seq), scheduler.data_len.eq(buffer.next_len),
            scheduler.data_sum.eq(buffer.next_sum),
            scheduler.syn_only.eq(conn.state == TcpState.SYN_SENT),
            self.tx.valid.eq(scheduler.valid), self.tx.request.eq(scheduler.request),
            scheduler.ready.eq(self.tx.ready),
            conn.sent.eq(scheduler.sent), conn.sent_kind.eq(scheduler.kind),
        ]

        # timer and congestion control
        m.d.comb += [
            timer.mode.eq(conn.timer_mode), timer.rto_cycles.eq(self.rto_cycles),
            timer.msl_cycles.eq(self.msl_cycles), timer.arp_retry_cycles.eq(self.arp_retry_cycles),
            timer.stop.eq(conn.timer_stop), timer.restart.eq(conn.timer_restart),
            timer.start.eq(conn.timer_start), timer.zero.eq(conn.timer_zero),
            timer.back_off.eq(conn.back_off), timer.backoff_reset.eq(conn.backoff_reset),
            conn.timer_done.eq(timer.done), conn.timer_expired.eq(timer.expired),
            congestion.in_flight.eq(buffer.in_flight), congestion.reset.eq(conn.cc_reset),
            congestion.new_ack.eq(conn.cc_new_ack), congestion.dup_ack.eq(conn.cc_dup_ack),
            congestion.timeout.eq(conn.cc_timeout),
            conn.cwnd.eq(congestion.cwnd), conn.fast_retransmit.eq(congestion.fast_retransmit),
        ]

        # counters: the events are registered
        m.submodules.counters = counters = EventCounters(
            TCP_COUNTERS, amounts={"bytes_rx": 11, "bytes_tx": len(buffer.taken)})
        events = Signal(counters.events.shape())
        m.d.sync += [events.eq(0), events.bytes_tx.eq(buffer.taken),
                     events.segments_tx.eq(scheduler.sent)]
        for name in ("bytes_rx", "segments_rx", "rto", "fast_retransmit", "dup_acks",
                     "rst_rx", "dropped_segments"):
            m.d.sync += events[name].eq(getattr(conn.events, name))
        m.d.comb += [counters.events.eq(events), counters.clear.eq(self.counters_clear),
                     counters.rd_addr[0].eq(self.counter_index),
                     self.counter_value.eq(counters.rd_data[0])]
        return m
