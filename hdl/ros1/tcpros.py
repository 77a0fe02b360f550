"""TCPROS data connections in hardware (docs/network.md, docs/messages.md): the
connection-header exchange and length-prefixed message streaming on one TCP session."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..net.rbcp import RbcpBusSignature
from ..net.stack import TcpUserSignature
from ..net.tcp import TCP_COUNTERS, TcpError, TcpState
from ..params import check_choice, check_int
from ..msg.bytes import byte_mask
from ..stream import AXIStreamSignature, ByteWindow, keep_count
from .registers import (
    CHECK_DEFAULT, COUNTERS, COUNTERS_OFFSET, CTRL, ENDPOINT_ID, ERRORS, EXPECTED, EXPECTED_AREA,
    HDR_ERR, HDR_RX, HDR_TX, PHASES, REG,
)

__all__ = ["TcprosEndpoint", "message_stream_signature", "ROLES"]

ROLES = ("publisher", "subscriber")

#: connection-header fields compared with EXPECTED values; ``error=`` is only detected
_COMPARED = ("topic", "type", "md5sum")
_KEYS = tuple(f"{key}=".encode() for key in _COMPARED + ("error",))
_PHASE = {name: code for code, name in enumerate(PHASES)}


def _area(area):
    """``m.Case`` pattern of the 16-bit register addresses of ``(base, size)``."""
    base, size = area
    low = size.bit_length() - 1
    return f"{base >> low:0{16 - low}b}" + "-" * low


def message_stream_signature(lanes=1):
    """Messages as AXI-Stream beats of ``lanes`` bytes: ``tlast`` on a message's last beat
    (with 2 lanes ``tkeep`` 0b01 when it holds one byte, the only partial beat), ``tuser`` its
    length in bytes (on every beat; a publisher reads it on the first)."""
    return AXIStreamSignature(8 * lanes, keep=lanes > 1, user_width=32)


class TcprosEndpoint(wiring.Component):
    """A TCPROS publisher or subscriber on one :class:`~hdl.net.tcp.TcpSession`.

    Publisher: listens while CTRL.START is set; reads the subscriber's connection header,
    compares ``topic``, ``type`` and ``md5sum`` with the expected values software wrote
    (``md5sum=*`` accepted with CHECK.STAR), answers with the header in HDR_TX (or HDR_ERR
    and a close on mismatch), then frames each message of ``s_axis`` with its ``uint32_le``
    length. Without a streaming subscriber whole messages are dropped (or held with
    CTRL.BLOCK). A message whose ``tlast`` disagrees with its ``tuser`` length is padded with
    zeros or cut to the length, so the subscriber's framing survives (``length_mismatch``).

    Subscriber: on the rise of CTRL.START connects to REMOTE_IP:REMOTE_PORT, sends HDR_TX,
    validates the publisher's reply (a reply with ``error=`` or a wrong type or md5sum closes
    the connection), then delivers each message body on ``m_axis``; messages longer than
    MAX_MSG are dropped whole.

    The connection headers are read and written a byte per cycle; message bodies move
    ``lanes`` bytes per cycle, the engine's rate (received bytes pass a
    :class:`~hdl.stream.ByteWindow`, so a body starts in lane 0 wherever it fell in the
    session's beats).

    Parameters
    ----------
    role : str
        ``"publisher"`` or ``"subscriber"``.
    lanes : int
        Bytes per beat of the session's streams and of the message stream, 1 or 2 (the
        engine's ``lanes``).

    Members
    -------
    tcp : In(TcpUserSignature(8 * lanes))
        The session's user side.
    regs : In(RbcpBusSignature())
        Register port: strobes for addresses of this endpoint (low 16 bits), acknowledged two
        cycles later.
    s_axis : In(message_stream_signature(lanes))
        Publisher only: messages to send.
    m_axis : Out(message_stream_signature(lanes))
        Subscriber only: received messages.
    phase : Out(range(len(PHASES)))
        :data:`~hdl.ros1.registers.PHASES`.
    """

    def __init__(self, role, *, endpoints=1, lanes=1):
        self._role = check_choice("role", role, ROLES)
        self._endpoints = endpoints
        self._lanes = check_int("lanes", lanes, 1, 2)
        members = {"tcp": In(TcpUserSignature(8 * lanes)), "regs": In(RbcpBusSignature()),
                   "phase": Out(range(len(PHASES)))}
        if role == "publisher":
            members["s_axis"] = In(message_stream_signature(lanes))
        else:
            members["m_axis"] = Out(message_stream_signature(lanes))
        super().__init__(members)

    role = property(lambda self: self._role)

    def elaborate(self, platform):
        m = Module()
        pub = self._role == "publisher"
        L = self._lanes
        tcp = self.tcp
        # transmit: header and length bytes one per beat, bodies as they come
        tx = _ByteBeat(tcp.tx, L)
        # receive: the session's bytes through a window, taken one at a time (headers,
        # lengths) or ``lanes`` at a time (bodies)
        m.submodules.rx_window = window = ByteWindow(L)
        w = window.s_axis
        m.d.comb += [w.tdata.eq(tcp.rx.tdata), w.tvalid.eq(tcp.rx.tvalid),
                     w.tkeep.eq(tcp.rx.tkeep if L > 1 else 1), tcp.rx.tready.eq(w.tready)]
        rx = _ByteTake(m, window)

        # ---- registers
        ctrl = Signal(8)
        local_port = Signal(16, init=0)
        remote_ip = Signal(32)
        remote_port = Signal(16)
        error = Signal(8)
        hdr_tx_len = Signal(16)
        hdr_err_len = Signal(16)
        hdr_rx_len = Signal(16)
        check = Signal(8, init=CHECK_DEFAULT)
        max_msg = Signal(32, init=16 * 1024 * 1024)
        exp_len = [Signal(8, name=f"exp_len_{k}") for k in range(3)]
        phase = Signal(range(len(PHASES)))
        m.d.comb += self.phase.eq(phase)
        # the session's counters are read through its counter port; the endpoint keeps the rest
        counters = {name: Signal(32, name=f"cnt_{name}") for name in COUNTERS
                    if name not in TCP_COUNTERS}

        m.submodules.hdr_tx = hdr_tx_mem = Memory(shape=8, depth=HDR_TX[1], init=[])
        m.submodules.hdr_err = hdr_err_mem = Memory(shape=8, depth=HDR_ERR[1], init=[])
        m.submodules.hdr_rx = hdr_rx_mem = Memory(shape=8, depth=HDR_RX[1], init=[])
        m.submodules.expected = exp_mem = Memory(shape=8, depth=EXPECTED_AREA[1], init=[])
        tx_w = hdr_tx_mem.write_port()
        tx_r = hdr_tx_mem.read_port(transparent_for=())
        tx_rr = hdr_tx_mem.read_port(transparent_for=())
        err_w = hdr_err_mem.write_port()
        err_r = hdr_err_mem.read_port(transparent_for=())
        rx_w = hdr_rx_mem.write_port()
        rx_rr = hdr_rx_mem.read_port(transparent_for=())
        exp_w = exp_mem.write_port()
        exp_r = exp_mem.read_port(transparent_for=())
        exp_rr = exp_mem.read_port(transparent_for=())

        regs = self.regs
        addr = Signal(16)
        is_read = Signal()
        stage = Signal(2)
        m.d.sync += regs.ack.eq(0)
        with m.If(regs.we | regs.re):
            m.d.sync += [addr.eq(regs.addr[:16]), is_read.eq(regs.re), stage.eq(1)]
        with m.Elif(stage == 1):
            m.d.sync += stage.eq(2)
        with m.Elif(stage == 2):
            m.d.sync += [stage.eq(0), regs.ack.eq(1)]
        # memory read ports for register reads take the strobe's address directly
        a16 = regs.addr[:16]
        m.d.comb += [tx_rr.addr.eq(a16), rx_rr.addr.eq(a16), exp_rr.addr.eq(a16)]
        ctrl_pulse = Signal(8)
        m.d.comb += ctrl_pulse.eq(0)

        reg_values = {
            "ID": Const(int.from_bytes(ENDPOINT_ID + bytes([self._endpoints]), "big"), 32),
            "MODE": Const(0 if pub else 1, 8), "CTRL": ctrl, "LOCAL_PORT": local_port,
            "REMOTE_IP": tcp.peer_ip if pub else remote_ip,
            "REMOTE_PORT": tcp.peer_port if pub else remote_port,
            "TCP_STATE": tcp.state.as_value(), "PHASE": phase, "ERROR": error,
            "HDR_TX_LEN": hdr_tx_len, "HDR_ERR_LEN": hdr_err_len, "HDR_RX_LEN": hdr_rx_len,
            "CHECK": check, "MAX_MSG": max_msg,
        }
        writable = {"CTRL": ctrl, "LOCAL_PORT": local_port, "REMOTE_IP": remote_ip,
                    "REMOTE_PORT": remote_port, "HDR_TX_LEN": hdr_tx_len,
                    "HDR_ERR_LEN": hdr_err_len, "CHECK": check, "MAX_MSG": max_msg}
        rd = Signal(8)
        with m.If(stage == 1):
            with m.Switch(addr):
                for name, (offset, size, access) in REG.items():
                    value = reg_values[name]
                    for b in range(size):
                        with m.Case(offset + b):
                            m.d.sync += rd.eq(value.word_select(size - 1 - b, 8))
                for k, name in enumerate(COUNTERS):
                    value = tcp.counter_value if name in TCP_COUNTERS else counters[name]
                    for b in range(4):
                        with m.Case(COUNTERS_OFFSET + 4 * k + b):
                            m.d.sync += rd.eq(value.word_select(3 - b, 8))
                with m.Case(_area(EXPECTED_AREA)):
                    m.d.sync += rd.eq(exp_rr.data)
                with m.Case(_area(HDR_TX)):
                    m.d.sync += rd.eq(tx_rr.data)
                with m.Case(_area(HDR_RX)):
                    m.d.sync += rd.eq(rx_rr.data)
                with m.Default():
                    m.d.sync += rd.eq(0)
        m.d.comb += regs.rd.eq(rd)
        with m.Switch(addr):
            for k, name in enumerate(COUNTERS):
                if name in TCP_COUNTERS:
                    with m.Case(*(COUNTERS_OFFSET + 4 * k + b for b in range(4))):
                        m.d.comb += tcp.counter_index.eq(TCP_COUNTERS.index(name))

        with m.If(regs.we):
            a = regs.addr[:16]
            wd = regs.wd
            with m.Switch(a):
                for name, (offset, size, access) in REG.items():
                    for b in range(size):
                        with m.Case(offset + b):
                            if name in writable:
                                m.d.sync += writable[name].word_select(size - 1 - b, 8).eq(wd)
                            elif name == "ERROR":
                                m.d.sync += error.eq(error & ~wd)
                            if name == "CTRL":
                                m.d.comb += ctrl_pulse.eq(wd)
                with m.Case(_area(EXPECTED_AREA)):
                    m.d.comb += [exp_w.addr.eq(a), exp_w.data.eq(wd), exp_w.en.eq(1)]
                    for k, key in enumerate(_COMPARED):
                        with m.If(a[:8] == EXPECTED[key][0] - EXPECTED_AREA[0]):
                            m.d.sync += exp_len[k].eq(wd)
                with m.Case(_area(HDR_TX)):
                    m.d.comb += [tx_w.addr.eq(a), tx_w.data.eq(wd), tx_w.en.eq(1)]
                with m.Case(_area(HDR_ERR)):
                    m.d.comb += [err_w.addr.eq(a), err_w.data.eq(wd), err_w.en.eq(1)]
        with m.If(regs.we & (regs.addr[:16] == REG["CTRL"][0])):
            m.d.sync += ctrl.eq(regs.wd & (CTRL["START"] | CTRL["BLOCK"]))
        with m.If(regs.we & (regs.addr[:16] == REG["CTRL"][0]) & (regs.wd & CTRL["CLR_CNT"]).any()):
            m.d.comb += tcp.counters_clear.eq(1)
            for counter in counters.values():
                m.d.sync += counter.eq(0)

        def bump(name):
            return counters[name].eq(counters[name] + 1)

        # ---- the TCP session
        start = ctrl[0]
        close_now = Signal()       # one cycle low on open_req: FIN after the queued bytes
        m.d.comb += [tcp.active.eq(0 if pub else 1), tcp.local_port.eq(local_port),
                     tcp.remote_ip.eq(remote_ip), tcp.remote_port.eq(remote_port),
                     tcp.open_req.eq(start & ~close_now),
                     tcp.abort.eq((ctrl_pulse & CTRL["ABORT"]).any()),
                     tcp.close_ack.eq(tcp.close_req)]
        with m.If(regs.we & (regs.addr[:16] == REG["CTRL"][0]) &
                  (regs.wd & CTRL["STOP"]).any()):
            m.d.comb += close_now.eq(1)
        with m.If(tcp.error):
            with m.Switch(tcp.error_code):
                with m.Case(TcpError.REFUSED):
                    m.d.sync += error.eq(error | ERRORS["refused"])
                with m.Case(TcpError.TIMEOUT):
                    m.d.sync += error.eq(error | ERRORS["timeout"])
                with m.Case(TcpError.ARP):
                    m.d.sync += error.eq(error | ERRORS["arp"])
                with m.Case(TcpError.RESET):
                    m.d.sync += error.eq(error | ERRORS["reset"])
        connected = tcp.open_ack & (tcp.state != TcpState.CLOSE_WAIT)

        # ---- header transmit from HDR_TX or HDR_ERR
        send_err = Signal()
        idx = Signal(16)
        hdr_len = Mux(send_err, hdr_err_len, hdr_tx_len)
        hdr_go = tx.tvalid & tx.tready
        nidx = Mux(hdr_go, idx + 1, idx)
        m.d.comb += [tx_r.addr.eq(nidx), err_r.addr.eq(nidx)]

        # ---- header receive: parser state
        total_left = Signal(32)
        field_left = Signal(32)
        lenbytes = Signal(2)
        shift = Signal(32)
        q = Signal(16)                 # position inside the field
        key_match = Signal(4)
        key = Signal(range(5), init=4)  # identified key, 4 = none
        mismatch = Signal(3)
        present = Signal(4)
        good = Signal(3)
        vlen = Signal(16)
        star = Signal()
        rx_pos = Signal(13)
        b_phase = Signal()
        malformed = Signal()
        key_len = [len(k) for k in _KEYS]
        exp_base = [EXPECTED[name][0] - EXPECTED_AREA[0] + 1 for name in _COMPARED]
        pvalue = Signal(16)
        m.d.comb += pvalue.eq(q - Mux(key == 0, key_len[0], Mux(key == 1, key_len[1],
                                                                  Mux(key == 2, key_len[2],
                                                                      key_len[3]))))
        m.d.comb += exp_r.addr.eq(Mux(key == 0, exp_base[0], Mux(key == 1, exp_base[1],
                                                                  exp_base[2])) + pvalue[:8])

        # ---- message streaming state
        msg_len = Signal(32)
        msg_cnt = Signal(32)

        if pub:
            s = self.s_axis
        else:
            mo = self.m_axis

        with m.FSM() as fsm:
            with m.State("IDLE"):
                # a publisher listening or a subscriber connecting: "connecting"
                m.d.comb += phase.eq(Mux(start, _PHASE["connecting"], _PHASE["idle"]))
                m.d.sync += send_err.eq(0)
                with m.If(connected):
                    m.d.sync += [idx.eq(0), total_left.eq(0), lenbytes.eq(0), rx_pos.eq(0),
                                 present.eq(0), good.eq(0), key.eq(4), b_phase.eq(0),
                                 malformed.eq(0),
                                 hdr_rx_len.eq(0)]
                    m.next = "HDR_RX_LEN" if pub else "HDR_TX_PRIME"
            with m.State("HDR_TX_PRIME"):
                # the header memory's read port sees address 0 before the first byte
                m.d.comb += phase.eq(_PHASE["hdr_tx"])
                m.next = "HDR_TX"
            with m.State("HDR_TX"):
                m.d.comb += [phase.eq(_PHASE["hdr_tx"]), tx.tvalid.eq(idx < hdr_len),
                             tx.tdata.eq(Mux(send_err, err_r.data, tx_r.data))]
                with m.If(hdr_go):
                    m.d.sync += idx.eq(idx + 1)
                with m.If(~tcp.open_ack):
                    m.next = "IDLE"
                with m.Elif(idx >= hdr_len):
                    if pub:
                        with m.If(send_err):
                            m.d.comb += close_now.eq(1)
                            m.next = "CLOSING"
                        with m.Else():
                            m.next = "STREAM"
                    else:
                        m.next = "HDR_RX_LEN"
            with m.State("HDR_RX_LEN"):
                m.d.comb += [phase.eq(_PHASE["hdr_rx"]), rx.tready.eq(1)]
                with m.If(rx.tvalid):
                    m.d.sync += [total_left.eq(Cat(total_left[8:], rx.tdata)),
                                 lenbytes.eq(lenbytes + 1)]
                    with m.If(lenbytes == 3):
                        m.d.sync += [lenbytes.eq(0), field_left.eq(0)]
                        m.next = "FIELD_LEN"
                with m.If(~tcp.open_ack):
                    m.next = "IDLE"
            with m.State("FIELD_LEN"):
                m.d.comb += phase.eq(_PHASE["hdr_rx"])
                with m.If(total_left == 0):
                    m.next = "VALIDATE"
                with m.Else():
                    m.d.comb += rx.tready.eq(1)
                    with m.If(rx.tvalid):
                        self._store(m, rx_w, rx_pos, hdr_rx_len, rx.tdata)
                        m.d.sync += [shift.eq(Cat(shift[8:], rx.tdata)),
                                     lenbytes.eq(lenbytes + 1), total_left.eq(total_left - 1)]
                        with m.If(lenbytes == 3):
                            with m.If(Cat(shift[8:], rx.tdata) > total_left - 1):
                                m.d.sync += malformed.eq(1)
                                m.next = "VALIDATE"
                            with m.Else():
                                m.d.sync += [field_left.eq(Cat(shift[8:], rx.tdata)), q.eq(0),
                                             key_match.eq(0b1111), key.eq(4), mismatch.eq(0),
                                             vlen.eq(0), star.eq(0), b_phase.eq(0)]
                                m.next = "FIELD"
                with m.If(~tcp.open_ack):
                    m.next = "IDLE"
            with m.State("FIELD"):
                m.d.comb += phase.eq(_PHASE["hdr_rx"])
                with m.If(field_left == 0):
                    with m.Switch(key):
                        for k in range(3):
                            with m.Case(k):
                                ok = ~mismatch[k] & (vlen == exp_len[k])
                                if k == 2:
                                    ok = ok | (star & (vlen == 1) & check[3])
                                m.d.sync += [present.eq(present | (1 << k)),
                                             good.eq(good | Mux(ok, 1 << k, 0))]
                        with m.Case(3):
                            m.d.sync += present.eq(present | 0b1000)
                    m.d.sync += lenbytes.eq(0)
                    m.next = "FIELD_LEN"
                with m.Elif(~b_phase):
                    # address cycle: the expected byte for this position is read
                    with m.If(rx.tvalid):
                        m.d.sync += b_phase.eq(1)
                with m.Else():
                    m.d.comb += rx.tready.eq(1)
                    byte = rx.tdata
                    with m.If(rx.tvalid):
                        self._store(m, rx_w, rx_pos, hdr_rx_len, byte)
                        m.d.sync += [b_phase.eq(0), q.eq(q + 1), field_left.eq(field_left - 1),
                                     total_left.eq(total_left - 1)]
                        with m.If(key == 4):
                            new_match = Signal(4)
                            for k, text in enumerate(_KEYS):
                                ch = Const(0, 8)
                                for pos, c in enumerate(text):
                                    ch = Mux(q == pos, c, ch)
                                m.d.comb += new_match[k].eq(key_match[k] & (q < len(text)) &
                                                            (byte == ch))
                            m.d.sync += key_match.eq(new_match)
                            for k, text in enumerate(_KEYS):
                                with m.If(new_match[k] & (q == len(text) - 1)):
                                    m.d.sync += key.eq(k)
                        with m.Elif(key < 3):
                            for k in range(3):
                                with m.If((key == k) & ((byte != exp_r.data) |
                                                        (vlen >= exp_len[k]))):
                                    m.d.sync += mismatch[k].eq(1)
                            m.d.sync += [vlen.eq(vlen + 1), star.eq((vlen == 0) & (byte == 0x2A))]
                with m.If(~tcp.open_ack):
                    m.next = "IDLE"
            with m.State("VALIDATE"):
                m.d.comb += phase.eq(_PHASE["validating"])
                # a publisher needs the subscriber's topic; a subscriber the publisher's type
                topic_ok = ~check[0] | good[0] | (Const(0) if pub else ~present[0])
                type_ok = ~check[1] | good[1] | (~present[1] if pub else Const(0))
                md5_ok = ~check[2] | good[2]
                err_ok = ~check[4] | ~present[3]
                ok = topic_ok & type_ok & md5_ok & err_ok & ~malformed
                with m.If(ok):
                    if pub:
                        m.d.sync += [idx.eq(0), send_err.eq(0)]
                        m.next = "HDR_TX_PRIME"
                    else:
                        m.next = "STREAM"
                with m.Else():
                    m.d.sync += [bump("header_rejects"),
                                 error.eq(error | Mux(present[3], ERRORS["peer_error"],
                                                      ERRORS["header_rejected"]))]
                    if pub:
                        m.d.sync += [idx.eq(0), send_err.eq(1)]
                        m.next = "HDR_TX_PRIME"
                    else:
                        m.d.sync += ctrl[0].eq(0)       # no reconnection until software says
                        m.next = "CLOSING"
            with m.State("STREAM"):
                m.d.comb += phase.eq(_PHASE["streaming"])
                with m.If(~connected):
                    m.next = "CLOSING"
            with m.State("CLOSING"):
                m.d.comb += phase.eq(_PHASE["closing"])
                with m.If(~tcp.open_ack):
                    m.next = "IDLE"
        streaming = fsm.ongoing("STREAM")

        if pub:
            self._publisher_stream(m, s, tx, streaming, ctrl, msg_len, msg_cnt, bump, error)
        else:
            self._subscriber_stream(m, rx, window, mo, streaming, max_msg, msg_len, msg_cnt,
                                    bump)
        tx.finish(m)
        rx.finish(m)
        return m

    @staticmethod
    def _store(m, port, pos, length, byte):
        """Keep a received header byte for software (HDR_RX), flag truncation."""
        with m.If(pos < HDR_RX[1]):
            m.d.comb += [port.addr.eq(pos), port.data.eq(byte), port.en.eq(1)]
            m.d.sync += [pos.eq(pos + 1), length.eq(pos + 1)]
        with m.Else():
            m.d.sync += length[15].eq(1)

    @staticmethod
    def _publisher_stream(m, s, tx, streaming, ctrl, msg_len, msg_cnt, bump, error):
        block = ctrl[5]
        lenb = Signal(2)
        # bytes of the message still to send, kept beside ``msg_cnt`` so that the decisions
        # below compare a register with a beat's byte count, not a sum with the length; and
        # the same number saturated at 3 (a beat carries at most 2), so that a beat's byte
        # count, and with it the session's segment arithmetic, waits for two bits, not for
        # a comparison of 30
        remaining = Signal(32)
        few = Signal(2)

        def set_remaining(value):
            value = value[:32]
            m.d.sync += [remaining.eq(value), few.eq(Mux(value[2:] == 0, value[:2], 3))]
        with m.FSM(name="publish"):
            with m.State("WAIT"):
                with m.If(s.tvalid):
                    with m.If(streaming):
                        m.d.sync += [msg_len.eq(s.tuser), msg_cnt.eq(0), lenb.eq(0)]
                        set_remaining(s.tuser)
                        m.next = "LENGTH"
                    with m.Elif(~block):
                        m.next = "DROP"
            with m.State("LENGTH"):
                m.d.comb += [tx.tvalid.eq(1), tx.tdata.eq(msg_len.word_select(lenb, 8))]
                with m.If(~streaming):
                    m.next = "DROP"
                with m.Elif(tx.tready):
                    m.d.sync += lenb.eq(lenb + 1)
                    with m.If(lenb == 3):
                        with m.If(msg_len == 0):
                            m.d.sync += [bump("messages_tx"),
                                         error.eq(error | ERRORS["length_mismatch"])]
                            m.next = "DISCARD"
                        with m.Else():
                            m.next = "BODY"
            with m.State("BODY"):
                # the beat's bytes up to the message's length; a beat that runs past it is cut
                n = keep_count(s.tkeep) if tx.lanes > 1 else Const(1, 1)
                # ``n`` is at most 2: the room left only matters below 2
                room = Mux(few[1], 3, few)
                over = n > room
                sent = Mux(over, room, n)
                tx.body(m, s.tdata, sent, s.tvalid)
                m.d.comb += s.tready.eq(tx.tready)
                with m.If(~streaming):
                    m.next = "DROP"
                with m.Elif(s.tvalid & tx.tready):
                    m.d.sync += msg_cnt.eq(msg_cnt + sent)
                    set_remaining(remaining - sent)
                    with m.If(few == sent):
                        m.d.sync += bump("messages_tx")
                        with m.If(s.tlast & ~over):
                            m.next = "WAIT"
                        with m.Else():
                            m.d.sync += error.eq(error | ERRORS["length_mismatch"])
                            with m.If(s.tlast):
                                m.next = "WAIT"
                            with m.Else():
                                m.next = "DISCARD"
                    with m.Elif(s.tlast):
                        m.d.sync += error.eq(error | ERRORS["length_mismatch"])
                        m.next = "PAD"
            with m.State("PAD"):
                m.d.comb += [tx.tvalid.eq(1), tx.tdata.eq(0)]
                with m.If(~streaming):
                    m.next = "WAIT"
                with m.Elif(tx.tready):
                    m.d.sync += msg_cnt.eq(msg_cnt + 1)
                    set_remaining(remaining - 1)
                    with m.If(few == 1):
                        m.d.sync += bump("messages_tx")
                        m.next = "WAIT"
            with m.State("DISCARD"):
                m.d.comb += s.tready.eq(1)
                with m.If(s.tvalid & s.tlast):
                    m.next = "WAIT"
            with m.State("DROP"):
                m.d.comb += s.tready.eq(1)
                with m.If(s.tvalid & s.tlast):
                    m.d.sync += bump("messages_dropped")
                    m.next = "WAIT"

    @staticmethod
    def _subscriber_stream(m, rx, window, mo, streaming, max_msg, msg_len, msg_cnt, bump):
        lenb = Signal(2)
        lanes = len(mo.tdata) // 8
        # ``msg_len - msg_cnt`` as a register, and saturated at ``lanes + 1``: a beat's byte
        # count and ``tlast`` then come from a few bits, not from a subtraction and a sum
        # compared with the length (a path through the relay into the session that missed
        # the board clock)
        left = Signal(32)
        few = Signal(range(lanes + 2))

        def set_left(value):
            value = value[:32]
            m.d.sync += [left.eq(value),
                         few.eq(Mux(value < lanes + 1, value[:len(few)], lanes + 1))]
        with m.FSM(name="subscribe"):
            with m.State("LENGTH"):
                with m.If(streaming):
                    m.d.comb += rx.tready.eq(1)
                    with m.If(rx.tvalid):
                        m.d.sync += [msg_len.eq(Cat(msg_len[8:], rx.tdata)), lenb.eq(lenb + 1),
                                     msg_cnt.eq(0)]
                        with m.If(lenb == 3):
                            full = Cat(msg_len[8:], rx.tdata)
                            set_left(full)
                            with m.If(full == 0):
                                m.d.sync += bump("messages_dropped")
                            with m.Elif(full > max_msg):
                                m.d.sync += bump("messages_dropped")
                                m.next = "SKIP"
                            with m.Else():
                                m.next = "BODY"
            with m.State("BODY"):
                # up to ``lanes`` bytes of the message a beat, from the window; a beat once
                # offered keeps its bytes until taken, though more may arrive behind them
                have = Mux(window.avail < lanes, window.avail, lanes)
                n = Signal(range(lanes + 1))
                offered = Signal(range(lanes + 1))
                m.d.comb += n.eq(Mux(offered != 0, offered, Mux(few < have, few, have)))
                last = few == n
                keep = Cat(*(n > k for k in range(lanes)))
                m.d.comb += [mo.tvalid.eq(window.avail != 0),
                             mo.tdata.eq(byte_mask(window.window, lanes, n)),
                             mo.tuser.eq(msg_len), mo.tlast.eq(last)]
                if lanes > 1:
                    m.d.comb += mo.tkeep.eq(keep)
                m.d.sync += offered.eq(Mux(mo.tvalid & ~mo.tready, n, 0))
                with m.If(~streaming):
                    m.next = "LENGTH"
                with m.Elif(mo.tvalid & mo.tready):
                    rx.take_bytes(m, n)
                    m.d.sync += msg_cnt.eq(msg_cnt + n)
                    set_left(left - n)
                    with m.If(last):
                        m.d.sync += bump("messages_rx")
                        m.next = "LENGTH"
            with m.State("SKIP"):
                have = Mux(window.avail < lanes, window.avail, lanes)
                n = Mux(few < have, few, have)
                with m.If(~streaming):
                    m.next = "LENGTH"
                with m.Elif(window.avail != 0):
                    rx.take_bytes(m, n)
                    m.d.sync += msg_cnt.eq(msg_cnt + n)
                    set_left(left - n)
                    with m.If(few == n):
                        m.next = "LENGTH"


class _ByteBeat:
    """A session's transmit stream driven a byte at a time (``tvalid``, ``tdata``, ``tready``
    as on a byte stream), or with a body beat of up to ``lanes`` bytes (:meth:`body`)."""

    def __init__(self, stream, lanes):
        self.stream = stream
        self.lanes = lanes
        self.tvalid = Signal(name="tx_byte_valid")
        self.tdata = Signal(8, name="tx_byte")
        self.tready = stream.tready
        self._body = Signal(name="tx_body")
        self._data = Signal(8 * lanes, name="tx_body_data")
        self._count = Signal(range(lanes + 1), name="tx_body_count")
        self._valid = Signal(name="tx_body_valid")

    def body(self, m, data, count, valid):
        """This cycle's beat: ``count`` bytes of ``data`` (lane 0 first) while ``valid``."""
        m.d.comb += [self._body.eq(1), self._data.eq(data), self._count.eq(count),
                     self._valid.eq(valid)]

    def finish(self, m):
        t = self.stream
        m.d.comb += [t.tvalid.eq(Mux(self._body, self._valid, self.tvalid)),
                     t.tdata.eq(Mux(self._body, self._data, self.tdata))]
        if self.lanes > 1:
            m.d.comb += t.tkeep.eq(Mux(self._body,
                                       Cat(*(self._count > k for k in range(self.lanes))), 1))


class _ByteTake:
    """A :class:`~hdl.stream.ByteWindow` read as a byte stream (``tvalid``, ``tdata``,
    ``tready``: one byte taken per handshake), or ``n`` bytes at once (:meth:`take_bytes`)."""

    def __init__(self, m, window):
        self.window = window
        self.tvalid = Signal(name="rx_byte_valid")
        self.tdata = Signal(8, name="rx_byte")
        self.tready = Signal(name="rx_byte_ready")
        self._many = Signal(name="rx_take_many")
        self._amount = Signal(len(window.amount), name="rx_take_amount")
        m.d.comb += [self.tvalid.eq(window.avail != 0), self.tdata.eq(window.window[:8])]

    def take_bytes(self, m, n):
        m.d.comb += [self._many.eq(1), self._amount.eq(n)]

    def finish(self, m):
        w = self.window
        m.d.comb += [w.take.eq(self._many | (self.tready & self.tvalid)),
                     w.amount.eq(Mux(self._many, self._amount, 1))]
