# amaranth: UnusedElaboratable=no
"""TcpCongestionControl (hdl/net/tcp/congestion.py) in amaranth.sim against RFC 5681
counted in segments (a model written from the RFC and docs/network.md): slow start below
ssthresh, one segment per window above it, fast retransmit on the third duplicate ACK with
ssthresh = max(flight / 2, 2) and the window inflated by 3, one more per further duplicate,
a timeout back to one segment, the window capped by the descriptor ring."""

import random

import pytest

from hdl.net.tcp import INITIAL_WINDOW, TcpCongestionControl

from .streamsim import simulate


class CongestionModel:
    def __init__(self, descriptors):
        self.most = descriptors - 1
        self.reset()

    def reset(self):
        self.cwnd, self.ssthresh, self.acked, self.dupacks = INITIAL_WINDOW, self.most, 0, 0

    def new_ack(self):
        self.dupacks = 0
        if self.cwnd < self.ssthresh:
            self.cwnd = min(self.cwnd + 1, self.most)
        elif self.acked + 1 >= self.cwnd:
            self.acked, self.cwnd = 0, min(self.cwnd + 1, self.most)
        else:
            self.acked += 1

    def dup_ack(self, in_flight):
        """Returns whether this duplicate asks for a fast retransmit (the third one)."""
        third = self.dupacks == 2
        if third:
            self.ssthresh = max(in_flight // 2, 2)
            self.cwnd = min(self.ssthresh + 3, self.most)
        elif self.dupacks == 3:
            self.cwnd = min(self.cwnd + 1, self.most)
        self.dupacks = min(self.dupacks + 1, 3)
        return third

    def timeout(self, in_flight):
        self.ssthresh = max(in_flight // 2, 2)
        self.cwnd, self.acked, self.dupacks = 1, 0, 0


@pytest.mark.parametrize("descriptors", [4, 64])
def test_tcp_congestion_control_matches_rfc5681(descriptors):
    rng = random.Random(descriptors)
    dut = TcpCongestionControl(descriptors=descriptors)
    model = CongestionModel(descriptors)

    async def bench(ctx):
        for step in range(3000):
            in_flight = rng.randrange(descriptors)
            ctx.set(dut.in_flight, in_flight)
            event = rng.choices(["new_ack", "dup_ack", "timeout", "reset", None],
                                [50, 30, 3, 1, 16])[0]
            if event:
                ctx.set(getattr(dut, event), 1)
            retransmit = ctx.get(dut.fast_retransmit)
            await ctx.tick()
            if event:
                ctx.set(getattr(dut, event), 0)
            if event == "new_ack":
                model.new_ack()
            elif event == "dup_ack":
                assert retransmit == model.dup_ack(in_flight), step
            elif event == "timeout":
                model.timeout(in_flight)
            elif event == "reset":
                model.reset()
            else:
                assert retransmit == 0
            assert ctx.get(dut.cwnd) == model.cwnd, (step, event, model.__dict__)

    simulate(dut, bench)
