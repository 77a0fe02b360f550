"""Six-channel servo PWM generator of the ball-on-plate Stewart platform (docs/kernels.md
"Servo PWM"): the inverse kinematics' leg angles in, one pulse per channel and period out."""

from fractions import Fraction

from amaranth.hdl import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int
from ..stream import AXIStreamSignature

__all__ = ["ServoPwm", "servo_pulse_cycles", "SERVO_MIN_US", "SERVO_MAX_US",
           "SERVO_FULL_SCALE_DEG"]

#: a hobby servo's default pulse range: SERVO_MIN_US at 0 degrees, SERVO_MAX_US at
#: SERVO_FULL_SCALE_DEG
SERVO_MIN_US, SERVO_MAX_US, SERVO_FULL_SCALE_DEG = 500, 2500, 180

_LEGS = 6
_ANGLE_STEPS = 2048           # the inverse kinematics' angle index, 0.1 degree per step


def servo_pulse_cycles(clock_hz, min_us, max_us, full_scale_deg):
    """``(min_cycles, k)``: a leg angle index ``i`` (0.1 degree) gives a pulse of
    ``min_cycles + ((i * k + 2**15) >> 16)`` cycles, ``k`` the rounded 16.16 cycles per index
    step."""
    per_us = Fraction(clock_hz, 1_000_000)
    min_cycles = round(min_us * per_us)
    span = (max_us - min_us) * per_us
    k = round(span * (1 << 16) / (full_scale_deg * 10))
    return min_cycles, k


class ServoPwm(wiring.Component):
    """Drives six hobby servos from :class:`InverseKinematics` output words.

    Each word ``(i << 21) | (leg << 18)`` sets leg ``leg`` to the angle ``i`` x 0.1 degree
    (0 to ``full_scale_deg``); its pulse is ``min_us`` at 0 degrees growing linearly to
    ``max_us`` at ``full_scale_deg`` (see :func:`servo_pulse_cycles` for the rounding). Every
    period (``period_us``) all six outputs go high together and each falls after its pulse;
    a width takes effect at the next period start, so no pulse is ever cut or stretched.

    Parameters
    ----------
    clock_hz : int
        The kernel's clock (100 MHz in a ReconOS slot).
    period_us : int
        PWM period (20,000: 50 Hz).
    min_us, max_us : int
        Pulse at 0 degrees and at ``full_scale_deg`` (500 and 2,500 us).
    full_scale_deg : int
        The servo's range (180).

    Members
    -------
    i : In(AXIStreamSignature(32, keep=False))
        Leg angle words (``tlast`` ignored); always ready.
    pwm : Out(6)
        Channel ``k`` drives leg ``k``'s servo; low until a leg has an angle.
    period_start : Out(1)
        A pulse in the cycle every output goes high: the widths of that period are the
        angles received before it.
    err_leg : Out(1)
        A pulse: a word named leg 6 or 7; it is dropped.
    err_range : Out(1)
        A pulse: an angle above ``full_scale_deg``; the pulse is held at ``max_us``.
    """

    def __init__(self, *, clock_hz=100_000_000, period_us=20_000, min_us=SERVO_MIN_US,
                 max_us=SERVO_MAX_US, full_scale_deg=SERVO_FULL_SCALE_DEG):
        check_int("clock_hz", clock_hz, 100_000, 1_000_000_000)
        check_int("period_us", period_us, 1000, 1_000_000)
        check_int("min_us", min_us, 1, period_us)
        check_int("max_us", max_us, min_us + 1, period_us)
        check_int("full_scale_deg", full_scale_deg, 1, _ANGLE_STEPS // 10)
        self._clock_hz, self._period_us = clock_hz, period_us
        self._min_us, self._max_us, self._full_scale = min_us, max_us, full_scale_deg
        if period_us * clock_hz // 1_000_000 >= 1 << 32:
            raise ParameterError("period_us", period_us, "a period below 2**32 cycles")
        super().__init__({"i": In(AXIStreamSignature(32, keep=False)), "pwm": Out(_LEGS),
                          "period_start": Out(1), "err_leg": Out(1), "err_range": Out(1)})

    @property
    def period_cycles(self):
        return self._period_us * self._clock_hz // 1_000_000

    def pulse_cycles(self, index):
        """The pulse of angle index ``index`` in cycles (the hardware's arithmetic)."""
        min_cycles, k = servo_pulse_cycles(self._clock_hz, self._min_us, self._max_us,
                                           self._full_scale)
        index = min(index, self._full_scale * 10)
        return min_cycles + ((index * k + (1 << 15)) >> 16)

    def elaborate(self, platform):
        m = Module()
        min_cycles, k = servo_pulse_cycles(self._clock_hz, self._min_us, self._max_us,
                                           self._full_scale)
        top = self._full_scale * 10
        period = self.period_cycles
        width = range(period + 1)
        pending = [Signal(width, name=f"pending{n}") for n in range(_LEGS)]
        active = [Signal(width, name=f"active{n}") for n in range(_LEGS)]
        armed = Signal(_LEGS)          # legs that have had an angle
        lit = Signal(_LEGS)
        timer = Signal(range(period))

        word = self.i.tdata
        index = word[21:32]
        leg = word[18:21]
        clipped = Signal(range(_ANGLE_STEPS))
        m.d.comb += [self.i.tready.eq(1), clipped.eq(index)]
        with m.If(index > top):
            m.d.comb += clipped.eq(top)
        pulse = Signal(width)
        m.d.comb += pulse.eq(min_cycles + ((clipped * k + (1 << 15)) >> 16))
        m.d.sync += [self.err_leg.eq(0), self.err_range.eq(0)]
        with m.If(self.i.tvalid):
            with m.If(leg >= _LEGS):
                m.d.sync += self.err_leg.eq(1)
            with m.Else():
                m.d.sync += self.err_range.eq(index > top)
                with m.Switch(leg):
                    for n in range(_LEGS):
                        with m.Case(n):
                            m.d.sync += [pending[n].eq(pulse), armed[n].eq(1)]

        start = timer == 0
        m.d.comb += self.period_start.eq(start)
        m.d.sync += timer.eq(timer + 1)
        with m.If(timer == period - 1):
            m.d.sync += timer.eq(0)
        for n in range(_LEGS):
            with m.If(start):
                m.d.sync += [active[n].eq(pending[n]), lit[n].eq(armed[n] & (pending[n] != 0))]
            with m.Elif(timer == active[n]):
                m.d.sync += lit[n].eq(0)
        m.d.comb += self.pwm.eq(lit)
        return m
