# amaranth: UnusedElaboratable=no
"""The stack's TcpResetResponder (hdl/net/responders.py) in amaranth.sim against RFC 9293
§3.10.7.1 written out in Python: a segment nobody takes gets <SEQ=SEG.ACK><CTL=RST> when it
carries ACK, else <SEQ=0><ACK=SEG.SEQ+SEG.LEN><CTL=RST,ACK> (SYN and FIN count in SEG.LEN),
addressed back to its sender; a RST, a claimed or ignored segment, a rejected frame and one
arriving while a RST waits for the builder get nothing."""

import random

from scapy.layers.inet import TCP

from hdl.net.responders import TcpResetResponder
from hdl.net.rx import FrameKind

from .streamsim import simulate

MOD = 2**32


def expected_reset(seg):
    flags = TCP(flags=seg["flags"]).flags
    if "R" in flags or seg["claimed"] or seg["ignore"] or not seg["accept"]:
        return None
    if "A" in flags:
        return {"seq": seg["ack"], "flags": TCP(flags="R").flags.value}
    length = seg["payload_len"] + ("S" in flags) + ("F" in flags)
    return {"seq": 0, "ack": (seg["seq"] + length) % MOD, "flags": TCP(flags="RA").flags.value}


def test_tcp_reset_responder_follows_rfc9293():
    rng = random.Random(61)
    dut = TcpResetResponder()
    mismatches = []
    answered = 0

    async def bench(ctx):
        nonlocal answered
        for n in range(300):
            if ctx.get(dut.busy) and rng.random() < 0.6:
                ctx.set(dut.tx.ready, 1)             # the builder takes the pending RST
                await ctx.tick()
                ctx.set(dut.tx.ready, 0)
                assert ctx.get(dut.tx.valid) == 0
            seg = {"flags": rng.choice(["S", "SA", "A", "PA", "FA", "F", "", "R", "RA", "FSRPAU"]),
                   "seq": rng.randrange(MOD), "ack": rng.randrange(MOD),
                   "payload_len": rng.choice([0, 1, 1460, rng.randrange(1500)]),
                   "claimed": rng.random() < 0.2, "ignore": rng.random() < 0.1,
                   "accept": rng.random() < 0.9, "mac": rng.randrange(2**48),
                   "ip": rng.randrange(MOD), "sport": rng.randrange(65536),
                   "dport": rng.randrange(65536)}
            fields = dut.frame.fields
            ctx.set(fields.flags.as_value(), TCP(flags=seg["flags"]).flags.value)
            for name, value in (("seq", seg["seq"]), ("ack", seg["ack"]),
                                ("payload_len", seg["payload_len"]), ("sender_mac", seg["mac"]),
                                ("sender_ip", seg["ip"]), ("src_port", seg["sport"]),
                                ("dst_port", seg["dport"])):
                ctx.set(getattr(fields, name), value)
            ctx.set(dut.frame.kind, FrameKind.TCP)
            ctx.set(dut.claimed, seg["claimed"])
            ctx.set(dut.ignore, seg["ignore"])
            ctx.set(dut.frame.accept, seg["accept"])
            ctx.set(dut.frame.done, 1)
            busy_before = ctx.get(dut.busy)
            await ctx.tick()
            ctx.set(dut.frame.done, 0)
            want = None if busy_before else expected_reset(seg)
            if want is None:
                assert ctx.get(dut.tx.valid) == busy_before, seg
                continue
            assert ctx.get(dut.tx.valid) == 1
            req = ctx.get(dut.tx.request)
            got = {"seq": req.seq, "flags": req.flags}
            if "ack" in want:               # the ACK field counts only with the ACK flag
                got["ack"] = req.ack
            if got != want or (req.eth_dst, req.ip_dst, req.src_port, req.dst_port, req.length) \
                    != (seg["mac"], seg["ip"], seg["dport"], seg["sport"], 0):
                mismatches.append((seg, got, want))
            answered += 1

    simulate(dut, bench)
    assert not mismatches, mismatches[:3]
    assert answered > 50
