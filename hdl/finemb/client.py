"""The FinEmbP client state machine of a node: init -> preop -> op (-> reinit), its answers
to the master, and the process data pages (docs/finemb.md)."""

from amaranth.hdl import Array, Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from hdl.net.checksum import ones_complement_add
from hdl.net.frames import ip_to_int, mac_to_int
from hdl.net.mac import DEFAULT_CLOCK_HZ
from hdl.net.responders import ParsedFrameSignature
from hdl.net.rx import FrameKind
from hdl.net.tx import TxRequestSignature

from ..params import ParameterError, check_int
from .descriptor import IoDescriptor
from .protocol import (
    BROADCAST_IP, BROADCAST_MAC, FINEMB_PORT, HEADER, MAGIC, NODE_ALL, STATE_SHIFT, VENDOR_ROSGATE,
    VERSION, Flag, MsgType, NodeState, ReinitReason,
)

__all__ = ["FinembClient", "CLIENT_EVENTS", "CLOCK_HZ"]

#: the node's core clock: half the GMII byte clock, two bytes per cycle
CLOCK_HZ = DEFAULT_CLOCK_HZ[2]

#: what the client counts (the node's counters include these)
CLIENT_EVENTS = ("finemb_rx", "bad_header", "other_node", "bad_page", "overrun", "id_conflict",
                 "missed_cycles", "late_app", "responses", "response_busy")

#: the longest IO descriptor chunk one IODESC_RES carries
IODESC_CHUNK = 256
_BODY = 16      # body bytes the client keeps of a request (the longest fixed request body)


class FinembClient(wiring.Component):
    """A node's FinEmbP client: follows the master's requests, keeps the node's state and
    address, writes received output pages into the :class:`~hdl.finemb.page.PageBuffer` and
    answers with the node's input page, its identity, address or IO descriptor.

    States (:class:`~hdl.finemb.protocol.NodeState`):

    * **INIT**, no address (source IP 0.0.0.0): ID_REQ is answered with ID_RES (broadcast);
      ADDR_REQ for this node's MAC sets the address and node id (ADDR_RES) -> PREOP.
    * **PREOP**: IODESC_REQ is answered with the requested part of the IO descriptor; the
      first ISEND_REQ -> OP.
    * **OP**: each ISEND_REQ for this node with a page of the right size is written into the
      output page, flipped once its UDP checksum is known to be good, and answered with
      ISEND_RES carrying the newest input page, sent once the application commits its next
      input page or ``app_deadline`` cycles after the flip, whichever comes first. Three
      cycle periods (from the SoC) without an SoC -> REINIT (counted as ``missed_cycles``).
    * **REINIT**: the address is kept; ADDR_REQ and IODESC_REQ are answered again; the next
      ISEND_REQ -> OP, its answer still reporting REINIT (the one after it reports OP).
      REINIT for this node enters it; REINIT for every node with reason MASTER_RESTART
      returns every node to INIT (a master that starts again re-initialises the network
      without a power cycle).

    An ADDR_REQ that gives this node's id to another MAC makes the node give up its address
    (INIT, ``id_conflict``): two nodes never keep one id. A request with a bad magic,
    version or length field is dropped (``bad_header``); an ISEND page of the wrong size is
    answered with the ERROR flag and not written (``bad_page``). Every response carries the
    node's state in flags bits 8-9.

    Parameters
    ----------
    mac : int
        The node's MAC address.
    descriptor : IoDescriptor
        The application's ports (page sizes; the descriptor bytes it sends).
    serial : int
        Serial number reported in ID_RES.
    app_deadline : int
        Cycles an ISEND_RES waits for the application's next input page, 0..4095.
    lanes : int
        Bytes per beat of the parser and the frame builder, 1 or 2.
    clock_hz : int
        The client's clock, for the SoC's cycle period given in nanoseconds (a clock period
        of a power of two nanoseconds: 8, 16, ...).

    Members
    -------
    frame : In(ParsedFrameSignature(lanes))
        The frames the node consumes, from its parser.
    rx_tag : In(1)
        The port the current frame came in on ...
    tx_tag : Out(1)
        ... and the port of the pending response (the request's).
    tx : Out(TxRequestSignature(lanes))
        Responses, to the frame builder.
    local_ip : Out(32)
        The node's address (0.0.0.0 until assigned).
    page_* : the :class:`~hdl.finemb.page.PageBuffer` ports (see there: ``lanes`` bytes
        a write or read; ``page_in_ready`` is the buffer's ``app.in_ready``: low while it
        sums a committed input page)
    app_commit : In(1)
        The application committed an input page (the buffer's ``app.in_commit``).
    state : Out(NodeState)
    node_id : Out(16)
        0xFFFF until assigned.
    soc : Out(1)
        Pulse: a start of cycle arrived (the application may align to it).
    events : Out(StructLayout)
        One pulse per :data:`CLIENT_EVENTS` counter.
    """

    def __init__(self, *, mac, descriptor, serial=0, app_deadline=256, lanes=1,
                 clock_hz=CLOCK_HZ):
        if not isinstance(descriptor, IoDescriptor):
            raise ParameterError("descriptor", descriptor, "an IoDescriptor")
        self._mac = check_int("mac", mac, 0, (1 << 48) - 1)
        self._desc = descriptor
        self._serial = check_int("serial", serial, 0, (1 << 32) - 1)
        self._deadline = check_int("app_deadline", app_deadline, 0, 4095)
        self._lanes = L = check_int("lanes", lanes, 1, 2)
        ns = 1_000_000_000 // check_int("clock_hz", clock_hz, 1_000_000, 1_000_000_000)
        if ns * clock_hz != 1_000_000_000 or ns & (ns - 1):
            raise ParameterError("clock_hz", clock_hz,
                                 "a clock whose period is a power of two nanoseconds")
        self._ns_shift = ns.bit_length() - 1
        po, pi = descriptor.page_out_bytes, descriptor.page_in_bytes
        from amaranth.lib import data
        super().__init__({
            "frame": In(ParsedFrameSignature(L)),
            "rx_tag": In(1), "tx_tag": Out(1),
            "tx": Out(TxRequestSignature(L)),
            "local_ip": Out(32),
            "page_out_begin": Out(1), "page_out_accept": In(1),
            "page_out_we": Out(L), "page_out_waddr": Out(range(max(po, 2))),
            "page_out_wdata": Out(8 * L), "page_out_commit": Out(1),
            "page_in_claim": Out(1), "page_in_held": In(1), "page_in_sum": In(16),
            "page_in_raddr": Out(range(max(pi, 2))), "page_in_rdata": In(8 * L),
            "page_in_release": Out(1), "page_in_ready": In(1),
            "app_commit": In(1),
            "state": Out(NodeState), "node_id": Out(16), "soc": Out(1),
            "events": Out(data.StructLayout({name: 1 for name in CLIENT_EVENTS})),
        })

    def elaborate(self, platform):
        m = Module()
        L = self._lanes
        f, tx = self.frame, self.tx
        fld = f.fields
        desc = self._desc
        po, pi = desc.page_out_bytes, desc.page_in_bytes
        rom_bytes = desc.encode()
        ev = self.events

        state = Signal(NodeState)
        node_id = Signal(16, init=NODE_ALL)
        local_ip = Signal(32)
        m.d.comb += [self.state.eq(state), self.node_id.eq(node_id),
                     self.local_ip.eq(local_ip)]

        # ---- the request as it arrives: the header, the first body bytes, the page
        # registered: the port is in 4 bytes before the payload, the verdict much later
        ours = Signal()
        m.d.sync += ours.eq((f.kind == FrameKind.UDP) & (fld.dst_port == FINEMB_PORT))
        hdr = Signal(8 * HEADER)
        body = Signal(8 * _BODY)
        off = f.payload_offset
        lane = [f.payload_data[8 * q:8 * q + 8] for q in range(L)]
        with m.If(f.payload_valid & ours):
            for k in range(HEADER):
                with m.If(off == k - k % L):
                    m.d.sync += hdr.word_select(k, 8).eq(lane[k % L])
            for k in range(_BODY):
                at = HEADER + k
                with m.If(off == at - at % L):
                    m.d.sync += body.word_select(k, 8).eq(lane[at % L])
        h_magic, h_version, h_type = hdr[0:16], hdr[16:24], hdr[24:32]
        h_node, h_cycle = hdr[32:48], hdr[64:96]
        h_length, h_seq = hdr[96:112], hdr[112:128]
        addressed = state != NodeState.INIT

        # the page of an ISEND_REQ for this node goes straight into the output page (the
        # header is complete when its first byte arrives); the buffer refuses it when the
        # application holds the page it would go to
        page_req = Signal()       # this frame is an ISEND_REQ for this node ...
        page_ok = Signal()        # ... whose page the buffer accepted
        begin = (f.payload_valid & ours & (off == HEADER) & addressed &
                 (h_type == MsgType.ISEND_REQ) & (h_node == node_id) & ~page_req)
        with m.If(f.first):
            m.d.sync += [page_req.eq(0), page_ok.eq(0)]
        with m.If(begin):
            m.d.comb += self.page_out_begin.eq(1)
            m.d.sync += [page_req.eq(1), page_ok.eq(self.page_out_accept)]
            with m.If(~self.page_out_accept):
                m.d.comb += ev.overrun.eq(1)
        # (the page starts at an even payload byte: its bytes keep their lanes)
        assert HEADER % L == 0
        writing = f.payload_valid & ours & ((page_req & page_ok) | begin)
        m.d.comb += [self.page_out_we.eq(Cat(*(writing & f.payload_keep[q] &
                                               (off + q >= HEADER) & (off + q < HEADER + po)
                                               for q in range(L)))),
                     self.page_out_waddr.eq(off - HEADER), self.page_out_wdata.eq(f.payload_data)]

        # ---- the verdict
        # the response being prepared (latched when it starts; the FSM below sends it)
        r_type = Signal(8)
        r_node = Signal(16)
        r_flags = Signal(16)
        r_cycle = Signal(32)
        r_seq = Signal(16)
        r_len = Signal(11)        # body bytes
        r_eth = Signal(48)
        r_ip = Signal(32)
        r_port = Signal(16)
        r_body = Signal(8 * 20)   # fixed body bytes (ID_RES 18, ADDR_RES 13, IODESC_RES 4)
        io_off = Signal(16)       # IODESC_RES: first descriptor byte ...
        io_len = Signal(11)       # ... and how many
        resp_busy = Signal()      # a response is being prepared or sent

        verdict = f.done & f.accept & ours

        def bswap(value, nbytes):
            return Cat(*(value.word_select(nbytes - 1 - k, 8) for k in range(nbytes)))

        mac_wire = bswap(Const(self._mac, 48), 6)    # the MAC's bytes in wire order
        b_mac = body[0:48]
        addr_ip = body[48:80]           # ADDR_REQ: mac, ipv4 (bytes in order), netmask, id
        addr_id = body[112:128]
        io_req_off, io_req_len = body[0:16], body[16:32]

        # what the request's header and body say, registered (IODESC's chunk over two
        # steps): they stop changing with the payload's last byte, and the verdict comes
        # with the end of the frame, after at least the FCS's four bytes
        good_header = Signal()
        for_me = Signal()         # addressed to this node, which has an address
        own_mac = Signal()        # ADDR_REQ: for this node's MAC ...
        id_taken = Signal()       # ... or giving this node's id to another
        page_size_ok = Signal()   # ISEND_REQ: the output page's size
        total = len(rom_bytes)
        first = Signal(16)        # IODESC_REQ: the chunk's first descriptor byte ...
        chunk = Signal(range(IODESC_CHUNK + 1))    # ... and its length
        m.d.sync += [
            good_header.eq((h_magic == MAGIC) & (h_version == VERSION) &
                           (fld.payload_len >= HEADER) & (h_length == fld.payload_len - HEADER)),
            for_me.eq(addressed & (h_node == node_id)),
            own_mac.eq(b_mac == mac_wire),
            id_taken.eq(addressed & (addr_id == node_id)),
            page_size_ok.eq(h_length == po),
            first.eq(Mux(io_req_off > total, total, io_req_off)),
        ]
        left = Signal(16)
        m.d.comb += left.eq(total - first)
        count = Mux(io_req_len < left, io_req_len, left)
        m.d.sync += chunk.eq(Mux(count > IODESC_CHUNK, IODESC_CHUNK, count))
        soc_period = body[0:32]         # SoC: cycle period in ns
        reinit_reason = body[0:8]

        started = Signal()        # a response starts this cycle

        r_state = Signal(NodeState)     # the state a response reports

        def reply(type_, body_len, body_value, *, node, new_state, flags=0, broadcast=False):
            """Start a response to the request of this verdict (dropped, and counted,
            while another is pending: the master asks again)."""
            with m.If(resp_busy):
                m.d.comb += ev.response_busy.eq(1)
            with m.Else():
                m.d.comb += started.eq(1)
                m.d.sync += [r_type.eq(type_), r_len.eq(body_len), r_node.eq(node),
                             r_flags.eq(flags), r_cycle.eq(h_cycle), r_seq.eq(h_seq),
                             r_body.eq(body_value), r_state.eq(new_state),
                             self.tx_tag.eq(self.rx_tag)]
                if broadcast:
                    m.d.sync += [r_eth.eq(mac_to_int(BROADCAST_MAC)),
                                 r_ip.eq(ip_to_int(BROADCAST_IP)), r_port.eq(FINEMB_PORT)]
                else:
                    m.d.sync += [r_eth.eq(fld.sender_mac), r_ip.eq(fld.sender_ip),
                                 r_port.eq(fld.src_port)]

        # ---- the cycle watchdog (three cycle periods without SoC -> REINIT)
        period_cycles = Signal(32)
        since_soc = Signal(32)
        restart_watchdog = Signal()     # since_soc starts again from 0
        with m.If(since_soc != 0xFFFFFFFF):
            m.d.sync += since_soc.eq(since_soc + 1)

        with m.If(verdict):
            m.d.comb += ev.finemb_rx.eq(1)
            with m.If(~good_header):
                m.d.comb += ev.bad_header.eq(1)
            with m.Else():
                with m.Switch(h_type):
                    with m.Case(MsgType.SOC):
                        m.d.comb += self.soc.eq(1)
                        m.d.comb += restart_watchdog.eq(1)
                        m.d.sync += [since_soc.eq(0),
                                     period_cycles.eq(soc_period >> self._ns_shift)]
                    with m.Case(MsgType.ID_REQ):
                        with m.If(state == NodeState.INIT):
                            reply(MsgType.ID_RES, 18, Cat(
                                mac_wire, Const(VENDOR_ROSGATE, 16), Const(self._serial, 32),
                                Const(2, 8), Const(0b01, 8), Const(pi, 16), Const(po, 16)),
                                node=NODE_ALL, new_state=NodeState.INIT, broadcast=True)
                    with m.Case(MsgType.ADDR_REQ):
                        with m.If(own_mac):
                            new_state = Mux(state == NodeState.OP, NodeState.OP,
                                            NodeState.PREOP)
                            m.d.sync += [local_ip.eq(bswap(addr_ip, 4)), node_id.eq(addr_id),
                                         state.eq(new_state)]
                            reply(MsgType.ADDR_RES, 13,
                                  Cat(mac_wire, addr_ip, addr_id, Const(0, 8)), node=addr_id,
                                  new_state=new_state)
                        with m.Elif(id_taken):
                            # another node is given this node's id: give it up
                            m.d.comb += ev.id_conflict.eq(1)
                            m.d.sync += [state.eq(NodeState.INIT), node_id.eq(NODE_ALL),
                                         local_ip.eq(0)]
                    with m.Case(MsgType.IODESC_REQ):
                        with m.If(for_me):
                            reply(MsgType.IODESC_RES, 4 + chunk, Cat(first, Const(total, 16)),
                                  node=node_id, new_state=state)
                            with m.If(~resp_busy):
                                m.d.sync += [io_off.eq(first), io_len.eq(chunk)]
                        with m.Else():
                            m.d.comb += ev.other_node.eq(1)
                    with m.Case(MsgType.ISEND_REQ):
                        with m.If(for_me):
                            # the master cycles: (back) to OP, the watchdog re-armed; the
                            # answer still reports a REINIT the node was in, so a master that
                            # only runs cycles learns that its watchdog fired or a REINIT came
                            reported = Mux(state == NodeState.REINIT, NodeState.REINIT,
                                           NodeState.OP)
                            m.d.comb += restart_watchdog.eq(1)
                            m.d.sync += [state.eq(NodeState.OP), since_soc.eq(0)]
                            with m.If(~page_size_ok):
                                m.d.comb += ev.bad_page.eq(1)
                                reply(MsgType.ISEND_RES, pi, 0, node=node_id,
                                      new_state=reported, flags=Flag.ERROR)
                            with m.Else():
                                with m.If(page_ok):
                                    m.d.comb += self.page_out_commit.eq(1)
                                reply(MsgType.ISEND_RES, pi, 0, node=node_id,
                                      new_state=reported)
                        with m.Else():
                            m.d.comb += ev.other_node.eq(1)
                    with m.Case(MsgType.REINIT):
                        with m.If((h_node == NODE_ALL) &
                                  (reinit_reason == ReinitReason.MASTER_RESTART)):
                            m.d.sync += [state.eq(NodeState.INIT), node_id.eq(NODE_ALL),
                                         local_ip.eq(0)]
                        with m.Elif(for_me | ((h_node == NODE_ALL) & addressed)):
                            m.d.sync += state.eq(NodeState.REINIT)
                    with m.Case(MsgType.SOA, MsgType.EOA, MsgType.ASND):
                        pass
                    with m.Default():
                        m.d.comb += ev.bad_header.eq(1)
        # the watchdog
        # registered: the limit when the period changes, the comparison a cycle later (a
        # watchdog of three periods can be a cycle late)
        limit = Signal(34)
        overdue = Signal()
        m.d.sync += [limit.eq(3 * period_cycles),
                     overdue.eq(~restart_watchdog & (period_cycles != 0) & (since_soc > limit))]
        with m.If((state == NodeState.OP) & overdue):
            m.d.comb += ev.missed_cycles.eq(1)
            m.d.sync += state.eq(NodeState.REINIT)

        # ---- the response: header, fixed body, then IO descriptor bytes or the input page
        rom_depth = 1 << max(len(rom_bytes) - 1, 1).bit_length()
        m.submodules.iodesc = rom = Memory(
            shape=8, depth=rom_depth, init=list(rom_bytes) + [0] * (rom_depth - len(rom_bytes)))
        # a descriptor chunk starts anywhere: a read port per lane
        rom_rds = [rom.read_port() for _ in range(L)]
        rom_rd = rom_rds[0]
        req = tx.request
        header_out = Cat(Const(MAGIC, 16), Const(VERSION, 8), r_type, r_node,
                         (r_flags | r_state.shift_left(STATE_SHIFT))[:16], r_cycle,
                         Cat(r_len, Const(0, 5)), r_seq)
        fixed = Cat(header_out, r_body)          # header + fixed body
        # the fixed part, ``L`` bytes a word, through one registered selection: read by the
        # builder (``rd`` is a multiple of ``L``) and, before that, summed a word per cycle
        fixed_words = Array(fixed.word_select(k, 8 * L) for k in range(len(fixed) // (8 * L)))
        is_isend = r_type == MsgType.ISEND_RES
        is_iodesc = r_type == MsgType.IODESC_RES
        fixed_len = Mux(is_isend, HEADER, Mux(is_iodesc, HEADER + 4, HEADER + r_len))
        # the fixed part's one's complement sum: a response's bytes past its fixed part are
        # zero (``reply`` zero-extends the body), so the sum may stop at any word after it
        sum_k = Signal(range(len(fixed_words) + 2))        # words selected for the sum
        summing = Signal()
        fixed_sum = Signal(16)
        chunk_sum = Signal(16)
        payload_sum = Signal(16)
        m.d.comb += payload_sum.eq(ones_complement_add(
            fixed_sum, Mux(is_isend, self.page_in_sum, Mux(is_iodesc, chunk_sum, 0))))

        # the builder reads ``L`` bytes from ``rd`` (a multiple of ``L``): each lane its own
        # source, as the fixed part may end inside a beat
        rd = tx.rd_addr
        m.d.comb += self.page_in_raddr.eq(rd - HEADER)
        fixed_word = Signal(8 * L)
        shift = L.bit_length() - 1
        m.d.sync += fixed_word.eq(fixed_words[Mux(summing, sum_k, rd[shift:6])])
        lanes_out = []
        for q in range(L):
            sel_fixed = Signal(name=f"sel_fixed{q}")
            m.d.sync += sel_fixed.eq(rd + q < fixed_len)
            m.d.comb += rom_rds[q].addr.eq(io_off + rd + q - (HEADER + 4))
            lanes_out.append(Mux(sel_fixed, fixed_word.word_select(q, 8),
                                 Mux(is_isend, self.page_in_rdata.word_select(q, 8),
                                     rom_rds[q].data)))
        m.d.comb += tx.rd_data.eq(Cat(*lanes_out))
        # the selected word comes a cycle later: big-endian, a lone byte even or odd
        summed = Signal()
        sum_odd = Signal()        # (one lane: the byte's half of its word)
        if L == 2:
            sum_word = Cat(fixed_word[8:], fixed_word[:8])
        else:
            sum_word = Mux(sum_odd, Cat(fixed_word, Const(0, 8)), Cat(Const(0, 8), fixed_word))
        m.d.sync += summed.eq(summing)
        with m.If(summed):
            m.d.sync += fixed_sum.eq(ones_complement_add(fixed_sum, sum_word))
            if L == 1:
                m.d.sync += sum_odd.eq(~sum_odd)
        with m.If(summing):
            m.d.sync += sum_k.eq(sum_k + 1)
            with m.If((sum_k + 1) * L >= fixed_len):
                m.d.sync += summing.eq(0)
        sum_ready = ~summing & ~summed
        m.d.comb += [req.kind.eq(FrameKind.UDP), req.eth_dst.eq(r_eth), req.ip_dst.eq(r_ip),
                     req.src_port.eq(FINEMB_PORT), req.dst_port.eq(r_port),
                     req.length.eq(HEADER + r_len), req.payload_sum.eq(payload_sum)]

        wait = Signal(range(self._deadline + 2))
        byte_k = Signal(11)
        byte_odd = Signal()
        with m.FSM() as fsm:
            with m.State("IDLE"):
                with m.If(started):
                    m.d.sync += [wait.eq(self._deadline), chunk_sum.eq(0), byte_k.eq(0),
                                 byte_odd.eq(0), summing.eq(1), sum_k.eq(0), sum_odd.eq(0),
                                 fixed_sum.eq(0)]
                    m.next = "DISPATCH"
            with m.State("DISPATCH"):
                with m.If(is_isend):
                    m.next = "APP"
                with m.Elif(is_iodesc):
                    m.next = "SUM"
                with m.Else():
                    m.next = "SETTLE"
            with m.State("APP"):
                # the application's next input page, or the deadline
                with m.If(self.app_commit):
                    m.next = "SUMMING"
                with m.Elif(wait == 0):
                    m.d.comb += ev.late_app.eq(1)
                    m.next = "SUMMING"
                with m.Else():
                    m.d.sync += wait.eq(wait - 1)
            with m.State("SUMMING"):
                # the page buffer sums a committed page before it becomes the newest
                with m.If(self.page_in_ready):
                    m.d.comb += self.page_in_claim.eq(1)
                    m.next = "SETTLE"
            with m.State("SUM"):
                # the descriptor chunk's sum, one byte per cycle (its first byte is an even
                # payload byte)
                m.d.comb += rom_rd.addr.eq(io_off + byte_k)
                m.d.sync += byte_k.eq(byte_k + 1)
                with m.If(byte_k != 0):
                    word = Mux(byte_odd, Cat(rom_rd.data, Const(0, 8)),
                               Cat(Const(0, 8), rom_rd.data))
                    m.d.sync += [chunk_sum.eq(ones_complement_add(chunk_sum, word)),
                                 byte_odd.eq(~byte_odd)]
                with m.If(byte_k == io_len):
                    m.next = "SETTLE"
            with m.State("SETTLE"):
                with m.If(sum_ready):
                    m.next = "REQUEST"
            with m.State("REQUEST"):
                m.d.comb += tx.valid.eq(1)
                with m.If(tx.ready):
                    m.d.comb += ev.responses.eq(1)
                    m.next = "SENDING"
            with m.State("SENDING"):
                with m.If(tx.done):
                    m.d.comb += self.page_in_release.eq(is_isend)
                    m.next = "IDLE"
        m.d.comb += resp_busy.eq(~fsm.ongoing("IDLE"))
        return m
