"""Which frame a TCP session asks for next, and what it says (docs/network.md "TCP
session")."""

from amaranth.hdl import Module, Mux
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..frames import ARP_REQUEST, TCP_ACK, TCP_FIN, TCP_PSH, TCP_RST, TCP_SYN
from ..rx import FrameKind
from ..tx import TX_REQUEST
from .codes import TcpRequest

__all__ = ["TcpRequestScheduler"]

_DUE = ("rst", "arp", "syn", "data", "fin", "probe", "ack")
assert tuple(r.name.lower() for r in TcpRequest) == _DUE


class TcpRequestScheduler(wiring.Component):
    """Offer the frame builder one request at a time, chosen among the due ones by priority.

    The priority is the order of :class:`TcpRequest`: RST, ARP request, SYN (or SYN-ACK),
    data, FIN, zero-window probe, ACK. A request is chosen only when the sequence engine can
    write its sequence number in the same cycle (``choose``), and is withdrawn when the
    engine starts a program (``withdraw``): what the program changes may change the request. A
    data request is also withdrawn when its segment is acknowledged (and freed) while it
    waits: sending it would step the send pointer past the write pointer.

    Members
    -------
    <kind>_due : In(1)
        One per :class:`TcpRequest`: that frame is due (the connection has checked the
        state and, for data, the windows).
    next_due, next_kind : Out(1), Out(TcpRequest)
        The request that ``choose`` would take.
    choose : In(1)
        Take ``next_kind`` as the pending request.
    hold : In(1)
        Hide the pending request from the builder this cycle (the engine runs a program).
    withdraw : In(1)
        Drop the pending request (it is chosen again when still due).
    unsent : In(1)
        The transmit ring has a segment to send (else a pending data request is stale).
    pending : Out(1)
    kind : Out(TcpRequest)
        The pending request.
    sent : Out(1)
        The builder took the pending request this cycle.
    valid, request, ready : Out(1), Out(TX_REQUEST), In(1)
        The frame builder's request port (:class:`~hdl.net.tx.TxRequestSignature`).
    remote_mac, remote_ip, local_port, remote_port : In
        The connection's addresses.
    ack, window, ctl_seq : In(32), In(16), In(32)
        RCV.NXT, the receive window, and the sequence number of a request without data.
    data_seq, data_len, data_sum : In(32), In(11), In(16)
        The data segment to send (the transmit ring's next descriptor).
    syn_only : In(1)
        The SYN is a client's (SYN-SENT), not a SYN-ACK.
    """

    def __init__(self):
        members = {f"{name}_due": In(1) for name in _DUE}
        members.update({
            "next_due": Out(1), "next_kind": Out(TcpRequest),
            "choose": In(1), "hold": In(1), "withdraw": In(1), "unsent": In(1),
            "pending": Out(1), "kind": Out(TcpRequest), "sent": Out(1),
            "valid": Out(1), "request": Out(TX_REQUEST), "ready": In(1),
            "remote_mac": In(48), "remote_ip": In(32), "local_port": In(16),
            "remote_port": In(16),
            "ack": In(32), "window": In(16), "ctl_seq": In(32),
            "data_seq": In(32), "data_len": In(11), "data_sum": In(16),
            "syn_only": In(1),
        })
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        R = TcpRequest
        with m.If(self.rst_due):
            m.d.comb += [self.next_due.eq(1), self.next_kind.eq(R.RST)]
        for kind in list(R)[1:]:
            with m.Elif(getattr(self, f"{kind.name.lower()}_due")):
                m.d.comb += [self.next_due.eq(1), self.next_kind.eq(kind)]

        stale = self.pending & (self.kind == R.DATA) & ~self.unsent
        m.d.comb += [self.valid.eq(self.pending & ~self.hold & ~stale),
                     self.sent.eq(self.valid & self.ready)]
        with m.If(self.choose):
            m.d.sync += [self.pending.eq(1), self.kind.eq(self.next_kind)]
        with m.If(stale | self.withdraw | self.sent):
            m.d.sync += self.pending.eq(0)

        req = self.request
        m.d.comb += [req.kind.eq(FrameKind.TCP), req.eth_dst.eq(self.remote_mac),
                     req.ip_dst.eq(self.remote_ip), req.src_port.eq(self.local_port),
                     req.dst_port.eq(self.remote_port), req.ack.eq(self.ack),
                     req.window.eq(self.window),
                     req.seq.eq(Mux(self.kind == R.DATA, self.data_seq, self.ctl_seq))]
        with m.Switch(self.kind):
            with m.Case(R.RST):
                m.d.comb += [req.flags.eq(TCP_RST), req.window.eq(0)]
            with m.Case(R.ARP):
                m.d.comb += [req.kind.eq(FrameKind.ARP), req.arp_oper.eq(ARP_REQUEST),
                             req.eth_dst.eq(0xFFFFFFFFFFFF)]
            with m.Case(R.SYN):
                m.d.comb += [req.mss.eq(1),
                             req.flags.eq(Mux(self.syn_only, TCP_SYN, TCP_SYN | TCP_ACK))]
            with m.Case(R.DATA):
                m.d.comb += [req.flags.eq(TCP_ACK | TCP_PSH), req.length.eq(self.data_len),
                             req.payload_sum.eq(self.data_sum),
                             req.payload_addr.eq(self.data_seq[:16])]
            with m.Case(R.FIN):
                m.d.comb += req.flags.eq(TCP_FIN | TCP_ACK)
            with m.Case(R.PROBE, R.ACK):
                m.d.comb += req.flags.eq(TCP_ACK)
        return m
