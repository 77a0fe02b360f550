"""The only writer of a TCP session's 32-bit sequence numbers (docs/network.md "TCP
session")."""

from amaranth.hdl import Module, Mux, Signal, signed
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from ...params import check_int
from .codes import TcpRequest

__all__ = ["ARRIVAL_FLAGS", "SEQUENCE_INTENT", "TcpSequenceEngine"]

#: What the engine found comparing an arrived segment with the connection, RFC 9293 terms
#: (``d`` is SEG.SEQ - RCV.NXT).
ARRIVAL_FLAGS = data.StructLayout({name: 1 for name in (
    "seq_is_rcv_nxt", "seq_is_rcv_nxt_minus_1", "seq_in_window", "ack_is_snd_una",
    "ack_after_snd_una", "ack_is_snd_una_plus_1", "ack_after_snd_max", "ack_is_snd_max",
    "ack_is_fin_plus_1", "seq_after_wl1", "seq_is_wl1", "ack_not_before_wl2",
    "ack_after_snd_nxt", "last_in_window", "fin_at_end")})

#: What the connection decided for an arrived segment: which sequence numbers to write.
SEQUENCE_INTENT = data.StructLayout({
    "una": 1,           # SND.UNA = SEG.ACK
    "nxt": 1,           # SND.NXT = SEG.ACK (an ACK beyond SND.NXT after a go-back-N)
    "wl": 1,            # SND.WL1 = SEG.SEQ, SND.WL2 = SEG.ACK (the window was taken)
    "rst": 1,           # the RST to answer with carries SEG.ACK
    "rcv": 1,           # RCV.NXT advances ...
    "rcv_syn": 1,       # ... to SEG.SEQ + 1 (a SYN), else by ``rcv_add``
    "retransmit": 1,    # SND.NXT = SND.UNA (go back N)
})


class TcpSequenceEngine(wiring.Component):
    """Sequence numbers SND.UNA, SND.NXT, SND.MAX, RCV.NXT, SND.WL1, SND.WL2 and the
    control sequence number, written through one 32-bit adder and compared on one 32-bit
    subtractor.

    Comparing a segment with six 32-bit numbers at once would need six wide subtractors
    on the path from the parser; one subtractor and a short program do it instead. An arrived
    segment's fields (latched by the connection at the verdict) are compared one per cycle
    (9 cycles; the subtractor's operands depend only on the program's step, so nothing an
    idle cycle decides reaches the comparisons), the engine then spends one cycle in DECIDE,
    where the connection reads ``flags`` and gives its ``intent``, and writes the new
    sequence numbers over the next 4 (the next segment's payload comes at least 33 cycles
    later at two bytes per cycle: a gap shrunk to 4 bytes, the preamble and 54 header
    bytes). A new connection's numbers take 5 cycles from ``initialise``; SND.MAX follows
    SND.NXT forward in 2 cycles after a frame is sent.

    Outside programs, in an idle cycle, the adder serves one of: the SND.NXT of a frame just
    sent or SND.NXT = SND.UNA for a retransmission timeout; the sequence number of the
    request being chosen (``choose``), its ``ctl_seq``, is a copy of SND.NXT, SND.UNA,
    SND.UNA - 1 or the write pointer, so the choice (which frames are due, whether the next
    segment fits the windows) never waits for the adder. A program withdraws the pending
    request (the scheduler chooses it again), so what the program compared stays true.

    Parameters
    ----------
    iss_seed : int
        Initial value of the initial-sequence-number clock, which counts cycles.

    Members
    -------
    sent, sent_kind : In(1), In(TcpRequest)
        The frame builder took a request this cycle.
    sent_seq, sent_len : In(32), In(11)
        The data segment sent (a DATA request).
    rewind : In(1)
        Retransmission timeout: SND.NXT = SND.UNA (in an idle cycle, never with ``sent``).
    request_due, request_kind, request_pending : In(1), In(TcpRequest), In(1)
        The scheduler's next request and whether one is pending.
    rst_at_nxt : In(1)
        A RST carries SND.NXT (else the ``ctl_seq`` an arrival wrote).
    choose : Out(1)
        The scheduler may take its next request now; ``ctl_seq`` is written with it.
    arrive : In(1)
        A segment of the connection has been latched: compare it.
    initialise, listen : In(1), In(1)
        A new connection: SND.UNA = SND.NXT = SND.MAX = ISS, the write pointer ISS + 1,
        RCV.NXT = SEG.SEQ + 1 and SND.WL1 = SEG.SEQ for a server (``listen``, from its SYN).
    seg_seq, seg_ack, seg_len, seg_fin, seg_written : In
        The latched segment: SEG.SEQ, SEG.ACK, payload length, FIN, and payload bytes the
        receive ring wrote.
    window : In(16)
        RCV.WND.
    flags : Out(ARRIVAL_FLAGS)
        The comparisons of the last arrival (valid in DECIDE).
    deciding : Out(1)
        The engine is in DECIDE: ``intent`` and ``rcv_add`` are taken this cycle.
    intent : In(SEQUENCE_INTENT)
    rcv_add : In(12)
        Bytes (and FIN) RCV.NXT advances by.
    snd_una, snd_nxt, snd_max, rcv_nxt, ctl_seq : Out(32)
    wr_seq : In(32)
        The transmit buffer's write pointer (the FIN's sequence number) ...
    wr_seq_load, wr_seq_value : Out(1), Out(32)
        ... which the engine sets for a new connection.
    busy : Out(1)
        A program runs.
    arrival_pending, init_pending : Out(1), Out(1)
        A program waits to start.
    """

    def __init__(self, *, iss_seed=0x1000):
        self._iss_seed = check_int("iss_seed", iss_seed, 0, 2**32 - 1)
        super().__init__({
            "sent": In(1), "sent_kind": In(TcpRequest), "sent_seq": In(32), "sent_len": In(11),
            "rewind": In(1),
            "request_due": In(1), "request_kind": In(TcpRequest), "request_pending": In(1),
            "rst_at_nxt": In(1), "choose": Out(1),
            "arrive": In(1), "initialise": In(1), "listen": In(1),
            "seg_seq": In(32), "seg_ack": In(32), "seg_len": In(11), "seg_fin": In(1),
            "seg_written": In(11), "window": In(16),
            "flags": Out(ARRIVAL_FLAGS), "deciding": Out(1),
            "intent": In(SEQUENCE_INTENT), "rcv_add": In(12),
            "snd_una": Out(32), "snd_nxt": Out(32), "snd_max": Out(32), "rcv_nxt": Out(32),
            "ctl_seq": Out(32),
            "wr_seq": In(32), "wr_seq_load": Out(1), "wr_seq_value": Out(32),
            "busy": Out(1), "arrival_pending": Out(1), "init_pending": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        R = TcpRequest
        iss_clock = Signal(32, init=self._iss_seed)
        m.d.sync += iss_clock.eq(iss_clock + 1)
        wl1 = Signal(32)
        wl2 = Signal(32)
        registers = {"snd_una": self.snd_una, "snd_nxt": self.snd_nxt, "snd_max": self.snd_max,
                     "rcv_nxt": self.rcv_nxt, "wl1": wl1, "wl2": wl2, "ctl_seq": self.ctl_seq}
        write = {name: Signal(name=f"write_{name}") for name in registers}
        write["wr_seq"] = self.wr_seq_load

        # one adder: result = a + b (+ carry), or a - b (- 1)
        alu_a = Signal(32)
        alu_b = Signal(32)
        alu_sub = Signal()
        alu_minus_1 = Signal()
        alu = Signal(32)
        m.d.comb += [alu.eq(alu_a + Mux(alu_sub, ~alu_b, alu_b) + (alu_sub & ~alu_minus_1)),
                     self.wr_seq_value.eq(alu)]
        flags = self.flags
        d = Signal(32)              # SEG.SEQ - RCV.NXT
        snd_max_behind = Signal()
        seqlen = Signal(12)
        m.d.comb += seqlen.eq(self.seg_len + self.seg_fin)

        # operands: one of a few wide registers, or a small signed value
        small_a = Signal(signed(13))
        small_b = Signal(signed(13))
        a_sources = {"small": small_a, "sent_seq": self.sent_seq, "iss_clock": iss_clock,
                     "seg_seq": self.seg_seq, "seg_ack": self.seg_ack,
                     "snd_nxt": self.snd_nxt, "d": d}
        b_sources = {"small": small_b, "snd_una": self.snd_una, "snd_nxt": self.snd_nxt,
                     "snd_max": self.snd_max, "rcv_nxt": self.rcv_nxt, "wr_seq": self.wr_seq,
                     "wl1": wl1, "wl2": wl2}
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

        # the arrival's comparisons have a subtractor of their own, whose operands depend
        # only on the program's state: the adder's operands follow whatever an idle cycle
        # serves (a frame sent, the request chosen), and that path must not reach the flags
        cmp_a = Signal(32)
        cmp_b = Signal(32)
        cmp_minus_1 = Signal()
        cmp_small = Signal(signed(13))
        cmp = Signal(32)
        m.d.comb += cmp.eq(cmp_a - cmp_b - cmp_minus_1)
        cmp_zero = cmp == 0
        cmp_positive = ~cmp[31] & ~cmp_zero
        cmp_in_window = (cmp[16:] == 0) & (cmp[:16] < self.window)
        cmp_sources = {"seg_seq": self.seg_seq, "seg_ack": self.seg_ack, "d": d,
                       "rcv_nxt": self.rcv_nxt, "snd_una": self.snd_una,
                       "snd_max": self.snd_max, "wr_seq": self.wr_seq, "wl1": wl1, "wl2": wl2,
                       "snd_nxt": self.snd_nxt}

        def compare(a, b, *, minus_1=False, results=()):
            """``a - b`` (``- 1``) on the comparator this cycle; store ``results`` from it."""
            if not isinstance(b, str):
                m.d.comb += cmp_small.eq(b)
            m.d.comb += [cmp_a.eq(cmp_sources[a]),
                         cmp_b.eq(cmp_sources[b] if isinstance(b, str) else cmp_small),
                         cmp_minus_1.eq(minus_1)]
            m.d.sync += list(results)

        snd_una_minus_1 = Signal(32)
        m.d.comb += snd_una_minus_1.eq(self.snd_una - 1)

        intent = Signal(SEQUENCE_INTENT)
        rcv_add = Signal(12)
        with m.If(self.deciding):
            m.d.sync += [intent.eq(self.intent), rcv_add.eq(self.rcv_add)]
        sent_op = self.sent & ((self.sent_kind == R.SYN) | (self.sent_kind == R.DATA) |
                               (self.sent_kind == R.FIN))
        with m.If(self.arrive):
            m.d.sync += self.arrival_pending.eq(1)
        with m.If(self.initialise):
            m.d.sync += self.init_pending.eq(1)

        with m.FSM(name="sequence_engine") as engine:
            with m.State("IDLE"):
                with m.If(sent_op):
                    with m.Switch(self.sent_kind):
                        with m.Case(R.SYN):
                            op(1, "snd_una", writes=("snd_nxt",))
                        with m.Case(R.DATA):
                            op("sent_seq", self.sent_len, writes=("snd_nxt",))
                        with m.Case(R.FIN):
                            op(1, "wr_seq", writes=("snd_nxt",))
                with m.Elif(self.rewind):
                    op(0, "snd_una", writes=("snd_nxt",))
                with m.Elif(~self.request_pending & self.request_due & ~self.arrival_pending &
                            ~self.init_pending):
                    m.d.comb += self.choose.eq(1)
                    with m.Switch(self.request_kind):
                        # copies of registers, not the adder: the request's choice (the
                        # connection's due frames, the transmit windows) stays off its path
                        with m.Case(R.RST):
                            with m.If(self.rst_at_nxt):
                                m.d.sync += self.ctl_seq.eq(self.snd_nxt)
                        with m.Case(R.SYN):
                            m.d.sync += self.ctl_seq.eq(self.snd_una)
                        with m.Case(R.FIN):
                            m.d.sync += self.ctl_seq.eq(self.wr_seq)
                        with m.Case(R.PROBE):
                            m.d.sync += self.ctl_seq.eq(snd_una_minus_1)
                        with m.Case(R.ACK):
                            m.d.sync += self.ctl_seq.eq(self.snd_nxt)
                with m.If(sent_op):
                    m.next = "MAX_COMPARE"
                with m.Elif(self.arrival_pending):
                    m.d.sync += self.arrival_pending.eq(0)
                    m.next = "COMPARE_RCV_NXT"
                with m.Elif(self.init_pending):
                    m.d.sync += self.init_pending.eq(0)
                    m.next = "INIT_ISS"
            # SND.MAX follows SND.NXT forward
            with m.State("MAX_COMPARE"):
                compare("snd_nxt", "snd_max", results=[snd_max_behind.eq(cmp_positive)])
                m.next = "MAX_WRITE"
            with m.State("MAX_WRITE"):
                op(0, "snd_nxt", writes=[("snd_max", snd_max_behind)])
                m.next = "IDLE"
            # a new connection's sequence numbers
            with m.State("INIT_ISS"):
                op("iss_clock", 0, writes=("snd_una", "snd_nxt", "snd_max"))
                m.next = "INIT_WR_SEQ"
            with m.State("INIT_WR_SEQ"):
                op(1, "snd_una", writes=("wr_seq",))
                m.next = "INIT_RCV_NXT"
            with m.State("INIT_RCV_NXT"):
                op("seg_seq", 1, writes=[("rcv_nxt", self.listen)])
                m.next = "INIT_WL1"
            with m.State("INIT_WL1"):
                with m.If(self.listen):
                    op("seg_seq", 0, writes=("wl1",))
                with m.Else():
                    op(0, 0, writes=("wl1",))
                m.next = "INIT_WL2"
            with m.State("INIT_WL2"):
                op(0, 0, writes=("wl2",))
                m.next = "IDLE"
            # a segment of the connection: its comparisons, one per cycle, on the comparator
            compares = [
                ("COMPARE_RCV_NXT", "seg_seq", "rcv_nxt", False, [
                    d.eq(cmp), flags.seq_is_rcv_nxt.eq(cmp_zero),
                    flags.seq_is_rcv_nxt_minus_1.eq(cmp == 0xFFFFFFFF),
                    flags.seq_in_window.eq(cmp_in_window)]),
                ("COMPARE_SND_UNA", "seg_ack", "snd_una", False, [
                    flags.ack_is_snd_una.eq(cmp_zero),
                    flags.ack_after_snd_una.eq(cmp_positive),
                    flags.ack_is_snd_una_plus_1.eq(cmp == 1)]),
                ("COMPARE_SND_MAX", "seg_ack", "snd_max", False, [
                    flags.ack_after_snd_max.eq(cmp_positive),
                    flags.ack_is_snd_max.eq(cmp_zero)]),
                ("COMPARE_FIN", "seg_ack", "wr_seq", True, [
                    flags.ack_is_fin_plus_1.eq(cmp_zero)]),
                ("COMPARE_WL1", "seg_seq", "wl1", False, [
                    flags.seq_after_wl1.eq(cmp_positive), flags.seq_is_wl1.eq(cmp_zero)]),
                ("COMPARE_WL2", "seg_ack", "wl2", False, [
                    flags.ack_not_before_wl2.eq(~cmp[31])]),
                ("COMPARE_SND_NXT", "seg_ack", "snd_nxt", False, [
                    flags.ack_after_snd_nxt.eq(cmp_positive)]),
                # d + (SEG.LEN - 1) and d + (payload - written), as differences
                ("LAST_IN_WINDOW", "d", 1 - seqlen, False, [
                    flags.last_in_window.eq(cmp_in_window)]),
                ("FIN_AT_END", "d", self.seg_written - self.seg_len, False, [
                    flags.fin_at_end.eq(cmp_zero)]),
            ]
            for k, (name, a, b, minus_1, results) in enumerate(compares):
                with m.State(name):
                    compare(a, b, minus_1=minus_1, results=results)
                    m.next = compares[k + 1][0] if k + 1 < len(compares) else "DECIDE"
            # ... the connection's decision ...
            with m.State("DECIDE"):
                m.d.comb += self.deciding.eq(1)
                m.next = "WRITE_ACK"
            # ... and the new sequence numbers
            with m.State("WRITE_ACK"):
                op("seg_ack", 0, writes=[("snd_una", intent.una), ("snd_nxt", intent.nxt),
                                         ("wl2", intent.wl), ("ctl_seq", intent.rst)])
                m.next = "WRITE_SEQ"
            with m.State("WRITE_SEQ"):
                op("seg_seq", 0, writes=[("wl1", intent.wl)])
                m.next = "WRITE_RCV_NXT"
            with m.State("WRITE_RCV_NXT"):
                with m.If(intent.rcv_syn):
                    op("seg_seq", 1, writes=[("rcv_nxt", intent.rcv)])
                with m.Else():
                    op(rcv_add, "rcv_nxt", writes=[("rcv_nxt", intent.rcv)])
                m.next = "WRITE_RETRANSMIT"
            with m.State("WRITE_RETRANSMIT"):
                op(0, "snd_una", writes=[("snd_nxt", intent.retransmit)])
                m.next = "IDLE"
        m.d.comb += self.busy.eq(~engine.ongoing("IDLE"))
        for name, reg in registers.items():
            with m.If(write[name]):
                m.d.sync += reg.eq(alu)
        return m
