# amaranth: UnusedElaboratable=no
"""TcpSequenceEngine (hdl/net/tcp/sequence_engine.py) in amaranth.sim against a model of
RFC 9293's sequence-space comparisons written with Python integers modulo 2**32: a new
connection's numbers, the flags of random segments placed around every register (including
across the 2**32 wrap), the writes each intent asks for, SND.NXT after each kind of frame
sent and after a rewind, SND.MAX following SND.NXT only forward, and the control sequence
number of each request chosen."""

import random

from hdl.net.tcp import TcpRequest, TcpSequenceEngine
from hdl.net.tcp.sequence_engine import SEQUENCE_INTENT

from .streamsim import simulate

MOD = 2**32


def signed(value):
    value %= MOD
    return value - MOD if value >= MOD // 2 else value


class SequenceModel:
    """The registers and the comparisons, from RFC 9293 §3.4 and §3.10.7.4."""

    def __init__(self):
        self.reg = dict.fromkeys(("snd_una", "snd_nxt", "snd_max", "rcv_nxt", "wl1", "wl2",
                                  "ctl_seq", "wr_seq"), 0)

    def flags(self, seq, ack, length, fin, written, window):
        r = self.reg
        d = (seq - r["rcv_nxt"]) % MOD
        in_window = lambda x: x % MOD < window     # noqa: E731
        return {
            "seq_is_rcv_nxt": d == 0, "seq_is_rcv_nxt_minus_1": d == MOD - 1,
            "seq_in_window": in_window(d),
            "ack_is_snd_una": ack == r["snd_una"],
            "ack_after_snd_una": signed(ack - r["snd_una"]) > 0,
            "ack_is_snd_una_plus_1": (ack - r["snd_una"]) % MOD == 1,
            "ack_after_snd_max": signed(ack - r["snd_max"]) > 0,
            "ack_is_snd_max": ack == r["snd_max"],
            "ack_is_fin_plus_1": (ack - r["wr_seq"]) % MOD == 1,
            "seq_after_wl1": signed(seq - r["wl1"]) > 0, "seq_is_wl1": seq == r["wl1"],
            "ack_not_before_wl2": signed(ack - r["wl2"]) >= 0,
            "ack_after_snd_nxt": signed(ack - r["snd_nxt"]) > 0,
            "last_in_window": in_window(d + length + fin - 1),
            "fin_at_end": (d + length - written) % MOD == 0,
        }

    def apply(self, intent, seq, ack, rcv_add):
        r = self.reg
        if intent["una"]:
            r["snd_una"] = ack
        if intent["nxt"]:
            r["snd_nxt"] = ack
        if intent["wl"]:
            r["wl1"], r["wl2"] = seq, ack
        if intent["rst"]:
            r["ctl_seq"] = ack
        if intent["rcv"]:
            r["rcv_nxt"] = (seq + 1) % MOD if intent["rcv_syn"] else (r["rcv_nxt"] + rcv_add) % MOD
        if intent["retransmit"]:
            r["snd_nxt"] = r["snd_una"]

    def sent(self, kind, seq=0, length=0):
        r = self.reg
        r["snd_nxt"] = {TcpRequest.SYN: r["snd_una"] + 1, TcpRequest.DATA: seq + length,
                        TcpRequest.FIN: r["wr_seq"] + 1}[kind] % MOD
        if signed(r["snd_nxt"] - r["snd_max"]) > 0:
            r["snd_max"] = r["snd_nxt"]


class SequenceEngineTB:
    def __init__(self, dut, model):
        self.dut = dut
        self.model = model

    async def wait_idle(self, ctx, limit=40):
        for _ in range(limit):
            if not ctx.get(self.dut.busy) and not ctx.get(self.dut.arrival_pending) \
                    and not ctx.get(self.dut.init_pending):
                return
            await ctx.tick()
        raise AssertionError("the engine did not return to IDLE")

    def check_registers(self, ctx, where):
        for name in ("snd_una", "snd_nxt", "snd_max", "rcv_nxt", "ctl_seq"):
            got = ctx.get(getattr(self.dut, name))
            assert got == self.model.reg[name], (where, name, hex(got),
                                                 hex(self.model.reg[name]))

    async def initialise(self, ctx, seg_seq, listen):
        dut = self.dut
        ctx.set(dut.seg_seq, seg_seq)
        ctx.set(dut.listen, listen)
        ctx.set(dut.initialise, 1)
        await ctx.tick()
        ctx.set(dut.initialise, 0)
        # the write pointer follows the engine's load, as the transmit buffer does
        iss = None
        for _ in range(10):
            if ctx.get(dut.wr_seq_load):
                ctx.set(dut.wr_seq, ctx.get(dut.wr_seq_value))
            await ctx.tick()
            if iss is None and ctx.get(dut.snd_una) != 0:
                iss = ctx.get(dut.snd_una)
        await self.wait_idle(ctx)
        r = self.model.reg
        iss = ctx.get(dut.snd_una)
        r.update(snd_una=iss, snd_nxt=iss, snd_max=iss, wr_seq=(iss + 1) % MOD,
                 rcv_nxt=(seg_seq + 1) % MOD if listen else r["rcv_nxt"],
                 wl1=seg_seq if listen else 0, wl2=0)
        assert ctx.get(dut.wr_seq) == r["wr_seq"]

    async def arrive(self, ctx, rng, window):
        dut, r = self.dut, self.model.reg
        anchor = r[rng.choice(["rcv_nxt", "snd_una", "snd_max", "wl1"])]
        seq = (anchor + rng.choice([0, 1, -1, rng.randrange(-70000, 70000)])) % MOD
        ack_anchor = r[rng.choice(["snd_una", "snd_nxt", "snd_max", "wr_seq", "wl2"])]
        ack = (ack_anchor + rng.choice([0, 1, -1, 2, rng.randrange(-3000, 3000)])) % MOD
        length = rng.choice([0, 0, 1, rng.randrange(0, 1461)])
        written = rng.choice([0, length, rng.randrange(0, length + 1)])
        fin = rng.random() < 0.3
        for name, value in (("seg_seq", seq), ("seg_ack", ack), ("seg_len", length),
                            ("seg_fin", fin), ("seg_written", written), ("window", window)):
            ctx.set(getattr(dut, name), value)
        expected = self.model.flags(seq, ack, length, fin, written, window)
        ctx.set(dut.arrive, 1)
        await ctx.tick()
        ctx.set(dut.arrive, 0)
        for _ in range(30):
            if ctx.get(dut.deciding):
                break
            await ctx.tick()
        else:
            raise AssertionError("no DECIDE cycle")
        got = ctx.get(dut.flags)
        for name, value in expected.items():
            assert getattr(got, name) == value, (name, hex(seq), hex(ack), length, fin,
                                                 written, window, dict(self.model.reg))
        intent = {name: rng.random() < 0.4 for name in SEQUENCE_INTENT.members}
        rcv_add = rng.randrange(0, 1462)
        ctx.set(dut.intent, intent)
        ctx.set(dut.rcv_add, rcv_add)
        await ctx.tick()
        ctx.set(dut.intent, {name: 0 for name in SEQUENCE_INTENT.members})
        await self.wait_idle(ctx)
        self.model.apply(intent, seq, ack, rcv_add)
        self.check_registers(ctx, ("arrival", intent))

    async def send(self, ctx, kind, seq=0, length=0):
        dut = self.dut
        ctx.set(dut.sent, 1)
        ctx.set(dut.sent_kind, kind)
        ctx.set(dut.sent_seq, seq)
        ctx.set(dut.sent_len, length)
        await ctx.tick()
        ctx.set(dut.sent, 0)
        await self.wait_idle(ctx)
        self.model.sent(kind, seq, length)
        self.check_registers(ctx, ("sent", kind))

    async def choose(self, ctx, kind, rst_at_nxt):
        dut, r = self.dut, self.model.reg
        ctx.set(dut.request_due, 1)
        ctx.set(dut.request_kind, kind)
        ctx.set(dut.rst_at_nxt, rst_at_nxt)
        assert ctx.get(dut.choose) == 1
        await ctx.tick()
        ctx.set(dut.request_due, 0)
        if kind == TcpRequest.RST and not rst_at_nxt:
            pass                    # keeps the number an arrival wrote
        elif kind in (TcpRequest.RST, TcpRequest.ACK):
            r["ctl_seq"] = r["snd_nxt"]
        elif kind == TcpRequest.SYN:
            r["ctl_seq"] = r["snd_una"]
        elif kind == TcpRequest.FIN:
            r["ctl_seq"] = r["wr_seq"]
        elif kind == TcpRequest.PROBE:
            r["ctl_seq"] = (r["snd_una"] - 1) % MOD
        self.check_registers(ctx, ("choose", kind))


def test_tcp_sequence_engine_matches_the_model():
    rng = random.Random(31)
    dut = TcpSequenceEngine(iss_seed=MOD - 700)      # ISS near the wrap
    model = SequenceModel()
    tb = SequenceEngineTB(dut, model)

    async def bench(ctx):
        for connection in range(6):
            await tb.initialise(ctx, rng.randrange(MOD) if connection % 2 else MOD - 3,
                                listen=connection % 3 != 2)
            if connection % 3 == 2:
                model.reg["rcv_nxt"] = ctx.get(dut.rcv_nxt)
                model.reg["wl1"] = 0
            tb.check_registers(ctx, "initialise")
            for _ in range(60):
                action = rng.random()
                if action < 0.5:
                    await tb.arrive(ctx, rng, rng.choice([0, 1, 1460, 65535,
                                                          rng.randrange(65536)]))
                elif action < 0.75:
                    kind = rng.choice([TcpRequest.SYN, TcpRequest.DATA, TcpRequest.FIN])
                    seq = (model.reg["snd_una"] + rng.randrange(0, 5000)) % MOD
                    await tb.send(ctx, kind, seq, rng.randrange(1, 1461))
                elif action < 0.85:
                    ctx.set(dut.rewind, 1)
                    await ctx.tick()
                    ctx.set(dut.rewind, 0)
                    model.reg["snd_nxt"] = model.reg["snd_una"]
                    tb.check_registers(ctx, "rewind")
                else:
                    kind = rng.choice([TcpRequest.RST, TcpRequest.SYN, TcpRequest.FIN,
                                       TcpRequest.PROBE, TcpRequest.ACK])
                    await tb.choose(ctx, kind, rng.random() < 0.5)

    simulate(dut, bench)


def test_tcp_sequence_engine_choose_waits_for_programs():
    """No request is chosen while a program runs or waits, nor while one is pending."""
    dut = TcpSequenceEngine()

    async def bench(ctx):
        ctx.set(dut.request_due, 1)
        ctx.set(dut.request_kind, TcpRequest.ACK)
        assert ctx.get(dut.choose) == 1
        ctx.set(dut.request_pending, 1)
        assert ctx.get(dut.choose) == 0
        ctx.set(dut.request_pending, 0)
        ctx.set(dut.arrive, 1)
        await ctx.tick()
        ctx.set(dut.arrive, 0)
        assert ctx.get(dut.arrival_pending) == 1 and ctx.get(dut.choose) == 0
        busy_cycles = 0
        for _ in range(30):
            await ctx.tick()
            if ctx.get(dut.busy):
                busy_cycles += 1
                assert ctx.get(dut.choose) == 0
        assert busy_cycles == 14       # 9 comparisons, DECIDE, 4 writes
        assert ctx.get(dut.choose) == 1

    simulate(dut, bench)
