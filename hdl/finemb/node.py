"""A FinEmbP fieldbus node in gateware: two Ethernet ports in a line, layer-2 forwarding
between them, and the node's own FinEmbP client, ARP and ICMP answers (docs/finemb.md)."""

from amaranth.hdl import Array, ClockDomain, Const, DomainRenamer, Module, Mux, ResetSignal, Signal
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer, PulseSynchronizer
from amaranth.lib.wiring import In, Out

from hdl.dds.arbiter import TopicArbiter
from hdl.net.counters import EventCounters
from hdl.net.frames import DROP_REASONS, ip_to_int, mac_to_int
from hdl.net.mac import GMII_HZ, GmiiRx, GmiiSignature, GmiiTx, TxBeatBridge
from hdl.net.queue import FrameQueue, FrameStreamBridge, FrameStreamSignature, FrameToRxBeats
from hdl.net.responders import ArpResponder, IcmpEchoResponder, ParsedFrameSignature
from hdl.net.rx import FrameKind, FrameParser
from hdl.net.tx import FrameBuilder

from ..params import ParameterError, check_int
from .client import CLIENT_EVENTS, CLOCK_HZ, FinembClient
from .descriptor import IoDescriptor
from .page import PageAppSignature, PageBuffer
from .protocol import FINEMB_PORT, GROUP_IP, GROUP_MAC, IP_TTL_FINEMB, NodeState

__all__ = ["FinembNode", "NODE_COUNTERS", "NODE_CLOCKS_HZ"]

#: the node's counters, in the order of ``counter_index``
NODE_COUNTERS = (("rx_frames0", "rx_frames1", "rx_bad0", "rx_bad1", "forwarded0", "forwarded1",
                  "forward_dropped0", "forward_dropped1", "consume_dropped", "delivered") +
                 DROP_REASONS + CLIENT_EVENTS + ("arp_replies", "icmp_replies",
                                                 "icmp_dropped"))
#: the counters of events on the GMII clock (forwarding), taken to the core clock
_GMII_EVENTS = ("rx_frames0", "rx_frames1", "rx_bad0", "rx_bad1", "forwarded0", "forwarded1",
                "forward_dropped0", "forward_dropped1", "consume_dropped")
#: bytes the node's protocol side moves per cycle of its core clock
LANES = 2
#: idle core cycles after each frame into the parser, so that two of its verdicts, and of
#: the answers they start, are at least this many cycles and a beat apart
PARSER_GAP = 16
#: the counters whose events can come every cycle: the GMII side's (a pulse synchroniser
#: passes one per core cycle) and the cycle watchdog's (it can fire a few cycles after each
#: ISEND_REQ when the master sets a tiny cycle period); every other counter counts a
#: verdict of the parser or a frame built, at most one per PARSER_GAP + 1 cycles
_EVERY_CYCLE = _GMII_EVENTS + ("missed_cycles",)
#: the node's clock ports and the frequencies its timers and benches assume: the core clock
#: (``sync``) and the GMII clock of both ports, asynchronous to each other
NODE_CLOCKS_HZ = {"aclk": CLOCK_HZ, "gmii_clk": GMII_HZ}


class FinembNode(wiring.Component):
    """A FinEmbP node: two GMII ports (a line topology), forwarding, the client, the page
    buffer and its application side.

    Forwarding (per port, a frame received on one port): to this node's own MAC, consumed
    only; broadcast or FinEmbP's multicast group, consumed and forwarded to the other port;
    anything else, forwarded only. A frame never goes back out of the port it came in on.
    The decision is made after the destination address: the frame then starts on the other
    port right away (cut-through, about 19 cycles from its first byte in to its first byte
    out) or, when that port is sending, as soon as it is free (store-and-forward from a
    2 KiB queue; a queue that cannot take a frame drops it and counts it). A frame whose FCS
    turns out bad after it was forwarded is ended with TX_ER, so the next receiver drops it.

    Consumed frames from both ports go, a whole frame at a time, through one
    :class:`~hdl.net.rx.FrameParser` (this node's address, FinEmbP's group, the limited
    broadcast of a node without address) to the :class:`~hdl.finemb.client.FinembClient`,
    an :class:`~hdl.net.responders.ArpResponder` and an
    :class:`~hdl.net.responders.IcmpEchoResponder` (both answer only once the node has an
    address). Every answer leaves by the port its request came in on.

    Clocks: the ports' receivers and transmitters, the forwarding and the queues run on the
    GMII clock ``gmii_clk`` (125 MHz, both ports: a board clocks the two PHYs from one
    reference); the parser, the client, the responders, the frame builder, the page buffer
    and the application run two bytes wide on ``sync`` at half that rate
    (:class:`~hdl.net.queue.FrameStreamBridge` and :class:`~hdl.net.mac.TxBeatBridge`
    cross between them), as the network engine's protocol side does.

    Parameters
    ----------
    descriptor : IoDescriptor
        The application's ports.
    mac : str
        The node's MAC address.
    serial : int
        Serial number in ID_RES.
    app_deadline : int
        See :class:`~hdl.finemb.client.FinembClient`.
    queue_bytes : int
        Bytes of each forwarding and consuming queue (a power of two, at least 2048: a whole
        frame).
    registered_queues : bool
        The queues' outputs through register slices
        (:class:`~hdl.net.queue.FrameQueue` ``registered``): a cycle more from a frame in to
        it forwarded or consumed, for the GMII clock with real pins (a board's node).

    Members
    -------
    gmii_clk : In(1)
        The ports' 125 MHz clock.
    port0, port1 : Out(GmiiSignature())
        The two Ethernet ports.
    app : Out(PageAppSignature)
        The application's side of the page buffer.
    state : Out(NodeState)
    node_id : Out(16)
    local_ip : Out(32)
    soc : Out(1)
        Pulse: a start of cycle arrived.
    counter_index : In(range(len(NODE_COUNTERS)))
    counter_value : Out(32)
        The counter of :data:`NODE_COUNTERS` that ``counter_index`` named in the cycle
        before (wrapping, cleared by reset; the counters are in block RAM).
    """

    def __init__(self, descriptor, *, mac="02:00:00:00:46:01", serial=0, app_deadline=256,
                 queue_bytes=2048, registered_queues=False):
        if not isinstance(descriptor, IoDescriptor):
            raise ParameterError("descriptor", descriptor, "an IoDescriptor")
        try:
            self._mac = mac_to_int(mac)
        except ValueError as e:
            raise ParameterError("mac", mac, "a MAC address like 02:00:00:00:46:01") from e
        if self._mac >> 40 & 1:
            raise ParameterError("mac", mac, "a unicast MAC address (first byte even)")
        self._desc = descriptor
        self._serial = check_int("serial", serial, 0, (1 << 32) - 1)
        self._deadline = check_int("app_deadline", app_deadline, 0, 4095)
        self._queue = check_int("queue_bytes", queue_bytes, 2048, 65536)
        self._registered = bool(registered_queues)
        super().__init__({
            "gmii_clk": In(1), "port0": Out(GmiiSignature()), "port1": Out(GmiiSignature()),
            "app": Out(PageAppSignature(descriptor.page_out_bytes, descriptor.page_in_bytes)),
            "state": Out(NodeState), "node_id": Out(16), "local_ip": Out(32), "soc": Out(1),
            "counter_index": In(range(len(NODE_COUNTERS))), "counter_value": Out(32),
        })

    descriptor = property(lambda self: self._desc)
    mac = property(lambda self: self._mac)

    def elaborate(self, platform):
        m = Module()
        mac = Const(self._mac, 48)
        group_mac = Const(mac_to_int(GROUP_MAC), 48)
        ports = [self.port0, self.port1]
        m.submodules.counters = counters = EventCounters(
            NODE_COUNTERS, block_ram=True,
            spacing={name: PARSER_GAP + 1 for name in NODE_COUNTERS if name not in _EVERY_CYCLE})
        m.d.comb += [counters.rd_addr[0].eq(self.counter_index),
                     self.counter_value.eq(counters.rd_data[0])]
        ev = counters.events

        # the GMII side: its own clock, the core's reset taken into it through flip-flops
        m.domains += (cd := ClockDomain("gmii", local=True))
        m.d.comb += cd.clk.eq(self.gmii_clk)
        m.submodules.gmii_reset = FFSynchronizer(ResetSignal("sync"), cd.rst, o_domain="gmii",
                                                 init=1)
        gmii = DomainRenamer("gmii")
        g = m.d.gmii
        gev = {}                  # events on the GMII clock, each taken to sync below
        for name in _GMII_EVENTS:
            gev[name] = Signal(name=f"gmii_{name}")
            m.submodules[f"{name}_sync"] = sync = PulseSynchronizer("gmii", "sync")
            m.d.comb += [sync.i.eq(gev[name]), ev[name].eq(sync.o)]

        rxs, txs, fwd, consume = [], [], [], []
        for k, port in enumerate(ports):
            m.submodules[f"rx{k}"] = rx = gmii(GmiiRx())
            m.submodules[f"tx{k}"] = tx = gmii(GmiiTx(raw=True))
            m.submodules[f"forward{k}"] = fq = gmii(    # k -> the other
                FrameQueue(self._queue, registered=self._registered))
            m.submodules[f"consume{k}"] = cq = gmii(
                FrameQueue(self._queue, registered=self._registered))
            m.d.comb += [rx.gmii_rxd.eq(port.rxd), rx.gmii_rx_dv.eq(port.rx_dv),
                         rx.gmii_rx_er.eq(port.rx_er),
                         port.txd.eq(tx.gmii_txd), port.tx_en.eq(tx.gmii_tx_en),
                         port.tx_er.eq(tx.gmii_tx_er)]
            wiring.connect(m, rx.rx, fq.rx, cq.rx)
            # the destination address decides, with the byte after its last (a frame that
            # ends with its address is not kept); the decision is registered from the last
            # address byte's comparisons, so the queues' read enables start at flip-flops
            own, bcast, group = Signal(name=f"own{k}"), Signal(name=f"bcast{k}"), \
                Signal(name=f"group{k}")
            decided, to_forward, to_consume = (Signal(name=f"{n}{k}") for n in
                                               ("decided", "to_forward", "to_consume"))
            r = rx.rx
            g += decided.eq(0)
            with m.If(r.valid & (r.index < 6)):
                sel = (5 - r.index[:3]).as_unsigned()[:3]
                is_own = r.data == mac.word_select(sel, 8)
                is_bcast = r.data == 0xFF
                is_group = r.data == group_mac.word_select(sel, 8)
                first = r.index == 0
                own_now = is_own & (first | own)
                bcast_now = is_bcast & (first | bcast)
                group_now = is_group & (first | group)
                g += [own.eq(own_now), bcast.eq(bcast_now), group.eq(group_now)]
                with m.If(r.index == 5):
                    g += [decided.eq(1), to_forward.eq(~own_now),
                          to_consume.eq(own_now | bcast_now | group_now)]
            decide = decided & r.valid
            m.d.comb += [fq.decide.eq(decide), fq.keep.eq(to_forward),
                         cq.decide.eq(decide), cq.keep.eq(to_consume)]
            m.d.comb += [gev[f"rx_frames{k}"].eq(r.end), gev[f"rx_bad{k}"].eq(r.end & ~r.ok),
                         gev[f"forward_dropped{k}"].eq(fq.overflow)]
            rxs.append(rx)
            txs.append(tx)
            fwd.append(fq)
            consume.append(cq)
        # forwarding: port k's frames leave by the other port
        for k in range(2):
            wiring.connect(m, fwd[k].m_axis, txs[1 - k].r_axis)
            r = txs[1 - k].r_axis
            m.d.comb += gev[f"forwarded{k}"].eq(r.tvalid & r.tready & r.tlast)
        m.d.comb += gev["consume_dropped"].eq(consume[0].overflow | consume[1].overflow)

        # ---- consumed frames: to the core clock, then one at a time through the parser
        m.submodules.consume_arbiter = arb = TopicArbiter(FrameStreamSignature(LANES), 2)
        for k in range(2):
            m.submodules[f"consume{k}_bridge"] = bridge = FrameStreamBridge(gmii_domain="gmii")
            wiring.connect(m, consume[k].m_axis, bridge.s_axis)
            wiring.connect(m, bridge.m_axis, arb.s_axis[k])
        m.submodules.to_parser = to_parser = FrameToRxBeats(lanes=LANES, gap=PARSER_GAP)
        wiring.connect(m, arb.m_axis, to_parser.s_axis)
        m.submodules.parser = parser = FrameParser(
            lanes=LANES, groups=[(mac_to_int(GROUP_MAC), ip_to_int(GROUP_IP))],
            limited_broadcast=True)
        wiring.connect(m, to_parser.rx, parser.rx)
        rx_port = Signal()        # the port of the frame being parsed
        with m.If(to_parser.rx.valid & (to_parser.rx.index == 0)):
            m.d.sync += rx_port.eq(arb.grant)

        m.submodules.client = client = FinembClient(
            mac=self._mac, descriptor=self._desc, serial=self._serial,
            app_deadline=self._deadline, lanes=LANES)
        m.submodules.arp = arp = ArpResponder(tag_width=1, lanes=LANES)
        m.submodules.icmp = icmp = IcmpEchoResponder(buffer_bytes=2048, tag_width=1,
                                                     lanes=LANES)
        local_ip = client.local_ip
        m.d.comb += [parser.local_mac.eq(mac), parser.local_ip.eq(local_ip),
                     self.local_ip.eq(local_ip), self.state.eq(client.state),
                     self.node_id.eq(client.node_id), self.soc.eq(client.soc)]
        # ARP and ICMP are answered only on an assigned address
        has_ip = local_ip != 0
        frames = [("client", client.frame, 1), ("arp", arp.frame, has_ip),
                  ("icmp", icmp.frame, has_ip)]
        for _, port, enable in frames:
            ParsedFrameSignature.connect_parser(m, parser, port, to_parser.rx,
                                                accept=parser.accept & enable)
        for responder in (client, arp, icmp):
            m.d.comb += responder.rx_tag.eq(rx_port)

        # ---- the page buffer
        m.submodules.pages = pages = PageBuffer(self._desc.page_out_bytes,
                                                self._desc.page_in_bytes, lanes=LANES)
        m.d.comb += [pages.out_begin.eq(client.page_out_begin),
                     client.page_out_accept.eq(pages.out_accept),
                     pages.out_we.eq(client.page_out_we), pages.out_waddr.eq(client.page_out_waddr),
                     pages.out_wdata.eq(client.page_out_wdata),
                     pages.out_commit.eq(client.page_out_commit),
                     pages.in_claim.eq(client.page_in_claim),
                     client.page_in_held.eq(pages.in_held), client.page_in_sum.eq(pages.in_sum),
                     pages.in_raddr.eq(client.page_in_raddr),
                     client.page_in_rdata.eq(pages.in_rdata),
                     pages.in_release.eq(client.page_in_release),
                     client.page_in_ready.eq(pages.app.in_ready),
                     client.app_commit.eq(self.app.in_commit & pages.app.in_ready)]
        wiring.connect(m, wiring.flipped(self.app), pages.app)

        # ---- answers: one builder, each frame out of its request's port
        m.submodules.builder = builder = FrameBuilder(
            3, lanes=LANES, ttl=IP_TTL_FINEMB, kinds=(FrameKind.ARP, FrameKind.ICMP,
                                                       FrameKind.UDP))
        wiring.connect(m, arp.tx, builder.req_0)
        wiring.connect(m, icmp.tx, builder.req_1)
        wiring.connect(m, client.tx, builder.req_2)
        m.d.comb += [builder.local_mac.eq(mac), builder.local_ip.eq(local_ip)]
        tags = Array([arp.tx_tag, icmp.tx_tag, client.tx_tag])
        out_port = Signal()
        m.d.comb += out_port.eq(tags[builder.grant])
        b = builder.m_axis
        bridges = []
        for k in range(2):
            m.submodules[f"tx{k}_bridge"] = bridge = TxBeatBridge(gmii_domain="gmii")
            wiring.connect(m, bridge.gmii, txs[k].s_axis)
            s = bridge.s_axis
            m.d.comb += [s.tdata.eq(b.tdata), s.tkeep.eq(b.tkeep), s.tlast.eq(b.tlast),
                         s.tvalid.eq(b.tvalid & (out_port == k))]
            bridges.append(bridge)
        m.d.comb += b.tready.eq(Mux(out_port, bridges[1].s_axis.tready,
                                    bridges[0].s_axis.tready))

        # ---- counters
        # the node serves ARP, ICMP echo and FinEmbP's UDP port: any other UDP port or TCP
        # segment the parser accepts is dropped here (no ICMP unreachable, no RST)
        arp_icmp = (parser.kind == FrameKind.ARP) | (parser.kind == FrameKind.ICMP)
        served = ((arp_icmp & has_ip) |
                  ((parser.kind == FrameKind.UDP) & (parser.fields.dst_port == FINEMB_PORT)))
        with m.If(parser.done):
            with m.If(parser.accept & served):
                m.d.comb += ev.delivered.eq(1)
            with m.Elif(parser.accept & arp_icmp):
                m.d.comb += ev.not_mine.eq(1)         # for 0.0.0.0: no address yet
            with m.Elif(parser.accept):
                m.d.comb += ev.no_port.eq(1)
            with m.Else():
                with m.Switch(parser.reason):
                    for i, name in enumerate(DROP_REASONS):
                        with m.Case(i):
                            m.d.comb += ev[name].eq(1)
        for name in CLIENT_EVENTS:
            m.d.comb += ev[name].eq(client.events[name])
        m.d.comb += [ev.arp_replies.eq(builder.req_0.ready & builder.req_0.valid),
                     ev.icmp_replies.eq(builder.req_1.ready & builder.req_1.valid),
                     ev.icmp_dropped.eq(icmp.dropped)]
        return m
