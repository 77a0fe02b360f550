"""Discrete PID controller with AVR221 semantics (docs/kernels.md), one update per clock."""

from amaranth.hdl import Cat, Module, Mux, Signal, signed
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from ..stream import AXIStreamSignature

__all__ = ["PidController", "PID_INPUT", "PID_SCALING", "PID_MAX_INT", "PID_MAX_LONG"]

#: gains are real gains times this
PID_SCALING = 128
PID_MAX_INT = 32767
PID_MAX_LONG = (1 << 31) - 1
PID_MAX_I_TERM = PID_MAX_LONG // 2

#: an input beat: set point and measurement, int16 each
PID_INPUT = data.StructLayout({"set_point": signed(16), "measurement": signed(16)})


class PidController(wiring.Component):
    """AVR221 discrete PID as a pipeline: one (set point, measurement) pair in and one
    control output out per clock.

    Per update (docs/kernels.md; all the quirks kept): ``e = sp - pv`` wrapped to int16;
    P term ``P e``, or +-32767 when ``|e| > maxError``; I term ``I sum`` with ``sum += e``, or
    +-(2**30 - 1) with ``sum`` clamped to +-``maxSumError`` when it would leave that range; D
    term ``D (last_pv - pv)`` wrapped to int16 (derivative on the measurement); output
    ``(P + I + D) / 128`` truncated toward zero and clamped to +-32767. ``maxError =
    32767 / (P + 1)`` and ``maxSumError = (2**31 - 1) / 2 / (I + 1)`` are computed by a
    divider when the gains are loaded.

    The integrator and the last measurement are one register each, updated in the cycle a
    pair is accepted; the products and the scaling follow in three more stages (latency 4
    cycles). A stall at ``o`` stops the pipeline.

    Members
    -------
    i : In(AXIStreamSignature(32, keep=False))
        ``tdata`` is a :data:`PID_INPUT` (set point, measurement). ``tlast`` is
        passed through to the output of the same update.
    o : Out(AXIStreamSignature(16, keep=False))
        Control output, int16.
    p_gain, i_gain, d_gain : In(15)
        Gains times 128 (0..32767), taken by ``load``.
    load : In(1)
        Pulse: take the gains, compute the limits (about 32 cycles; ``i`` is not ready
        meanwhile), clear the integrator and the last measurement (AVR221 ``pid_Init``).
    reset_integrator : In(1)
        Pulse: clear the integrator (``pid_Reset_Integrator``).
    ready : Out(1)
        The limits of the loaded gains are valid.
    """

    def __init__(self):
        super().__init__({
            "i": In(AXIStreamSignature(32, keep=False)),
            "o": Out(AXIStreamSignature(16, keep=False)),
            "p_gain": In(15),
            "i_gain": In(15),
            "d_gain": In(15),
            "load": In(1),
            "reset_integrator": In(1),
            "ready": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        p_gain, i_gain, d_gain = Signal(15), Signal(15), Signal(15)
        max_error = Signal(16)
        max_sum = Signal(31)
        last_pv = Signal(signed(16))
        total = Signal(signed(32))

        # restoring dividers for the two limits (31-bit dividends, 31 steps, MSB first); after
        # reset the gains are 0 and the limits those of gains 0. A remainder stays below its
        # divisor (at most 2**15), so it needs 16 bits, its doubling 17
        num_e, num_s = Signal(31), Signal(31)
        den_e, den_s = Signal(16), Signal(16)
        rem_e, rem_s = Signal(16), Signal(16)
        q_e = Signal(31, init=PID_MAX_INT)
        q_s = Signal(31, init=PID_MAX_I_TERM)
        bit = Signal(range(31))
        dividing = Signal()
        m.d.comb += self.ready.eq(~dividing)
        with m.If(self.load):
            m.d.sync += [p_gain.eq(self.p_gain), i_gain.eq(self.i_gain), d_gain.eq(self.d_gain),
                         num_e.eq(PID_MAX_INT), den_e.eq(self.p_gain + 1),
                         num_s.eq(PID_MAX_I_TERM), den_s.eq(self.i_gain + 1),
                         rem_e.eq(0), rem_s.eq(0), bit.eq(30), dividing.eq(1),
                         total.eq(0), last_pv.eq(0)]
        with m.Elif(dividing):
            re = Cat(num_e[30], rem_e)
            rs = Cat(num_s[30], rem_s)
            ge, gs = re >= den_e, rs >= den_s
            m.d.sync += [rem_e.eq(Mux(ge, re - den_e, re)), rem_s.eq(Mux(gs, rs - den_s, rs)),
                         num_e.eq(num_e << 1), num_s.eq(num_s << 1),
                         q_e.eq(Cat(ge, q_e[:30])), q_s.eq(Cat(gs, q_s[:30])),
                         bit.eq(bit - 1)]
            with m.If(bit == 0):
                m.d.sync += dividing.eq(0)
        m.d.comb += [max_error.eq(q_e), max_sum.eq(q_s)]

        # stage 1: error, saturation decisions, the integrator and last measurement
        o_valid = Signal()
        adv = Signal()
        m.d.comb += [adv.eq(~o_valid | self.o.tready),
                     self.i.tready.eq(adv & ~dividing & ~self.load)]
        take = self.i.tvalid & self.i.tready
        beat = data.View(PID_INPUT, self.i.tdata)
        sp, pv = beat.set_point, beat.measurement
        e = Signal(signed(16))
        m.d.comb += e.eq(sp - pv)
        base = Mux(self.reset_integrator, 0, total)
        t = Signal(signed(33))
        m.d.comb += t.eq(base + e)
        v1, last1 = Signal(), Signal()
        e1, dv1 = Signal(signed(16)), Signal(signed(16))
        psat1, isat1 = Signal(signed(2)), Signal(signed(2))
        with m.If(adv):
            m.d.sync += [v1.eq(take), last1.eq(self.i.tlast), e1.eq(e), dv1.eq(last_pv - pv),
                         psat1.eq(Mux(e > max_error, 1, Mux(e < -max_error, -1, 0)))]
        with m.If(take):
            m.d.sync += last_pv.eq(pv)
            with m.If(t > max_sum):
                m.d.sync += [total.eq(max_sum), isat1.eq(1)]
            with m.Elif(t < -max_sum):
                m.d.sync += [total.eq(-max_sum), isat1.eq(-1)]
            with m.Else():
                m.d.sync += [total.eq(t), isat1.eq(0)]
        with m.Elif(self.reset_integrator):
            m.d.sync += total.eq(0)
        sum1 = total                 # the integrator after this update, for the I term

        # stage 2: the three terms
        v2, last2 = Signal(), Signal()
        p2, i2 = Signal(signed(32)), Signal(signed(32))
        d2 = Signal(signed(16))
        with m.If(adv):
            m.d.sync += [v2.eq(v1), last2.eq(last1),
                         p2.eq(Mux(psat1 == 1, PID_MAX_INT,
                                   Mux(psat1 == -1, -PID_MAX_INT, p_gain * e1))),
                         i2.eq(Mux(isat1 == 1, PID_MAX_I_TERM,
                                   Mux(isat1 == -1, -PID_MAX_I_TERM, i_gain * sum1))),
                         d2.eq(d_gain * dv1)]

        # stage 3: sum, / 128 toward zero
        v3, last3 = Signal(), Signal()
        q3 = Signal(signed(32))
        s = Signal(signed(34))
        m.d.comb += s.eq(p2 + i2 + d2)
        with m.If(adv):
            m.d.sync += [v3.eq(v2), last3.eq(last2),
                         q3.eq((s + Mux(s < 0, PID_SCALING - 1, 0)) >> 7)]

        # stage 4: clamp, output register
        with m.If(adv):
            m.d.sync += [o_valid.eq(v3), self.o.tlast.eq(last3),
                         self.o.tdata.eq(Mux(q3 > PID_MAX_INT, PID_MAX_INT,
                                             Mux(q3 < -PID_MAX_INT, -PID_MAX_INT, q3)))]
        m.d.comb += self.o.tvalid.eq(o_valid)
        return m
