"""Ball-on-plate Kalman filter and PD controller, written from docs/kernels.md ("Ball-on-plate
controller"): ``ap_fixed<24,12,AP_RND_CONV,AP_SAT_SYM>`` arithmetic, every assignment the
exact value of its expression rounded half to even to 12 fraction bits and saturated
symmetrically; plus the rolling-ball plant the example closes the loop through."""

import math
from fractions import Fraction

__all__ = ["FRAC", "fixed", "BallControlModel", "leg_words", "RollingBall", "tilt_radians",
           "word_tilts", "servo_pulse"]

FRAC = 12
_MAX = (1 << 23) - 1


def _round_half_even(value):
    """``value`` (a Fraction) to the nearest integer, ties to even."""
    floor = value.numerator // value.denominator
    rest = value - floor
    if rest > Fraction(1, 2) or (rest == Fraction(1, 2) and floor % 2):
        return floor + 1
    return floor


def fixed(value):
    """``value`` (a number or Fraction, real units) as the raw 24-bit integer of the type."""
    raw = _round_half_even(Fraction(value) * (1 << FRAC))
    return max(-_MAX, min(_MAX, raw))


def _real(raw):
    return Fraction(raw, 1 << FRAC)


class BallControlModel:
    """One :meth:`update` per touch sample; raw type integers everywhere (``value / 4096``)."""

    G_ROLL = Fraction(5, 7) * Fraction("9810")        # mm/s^2 per rad, a rolling ball

    def __init__(self, period="0.03", scale_bits=8):
        period = Fraction(period)
        self.c = {name: fixed(v) for name, v in {
            "ta": period, "b": self.G_ROLL * period, "q": 4, "sigma_inv": Fraction("0.1"),
            "kp": Fraction("-0.002"), "kd": Fraction("-0.002"), "inv_dt": 1 / period,
            "count_mm": Fraction("0.11667"), "clamp": Fraction("0.19199"),
            "rad_to_deg": Fraction("57.324840764")}.items()}
        self.scale_bits = scale_bits
        one = fixed(1)
        self.axes = [{"p": 0, "v": 0, "w": 0, "last": 0,
                      "P": [one, 0, 0, one]} for _ in range(2)]

    def _set(self, *terms):
        """The type's value of the sum of products ``terms`` ((a, b) raw pairs or raw ints)."""
        exact = sum(_real(t[0]) * _real(t[1]) if isinstance(t, tuple) else _real(t)
                    for t in terms)
        return fixed(exact)

    def update(self, raw_x, raw_y):
        """Filter and control one sample; returns the tilts (alpha, beta) as 14-bit Q(scale)
        degrees."""
        c, s = self.c, self._set
        ctrl = []
        for axis, raw in zip(self.axes, (raw_x, raw_y)):
            y = fixed(Fraction(raw) * _real(c["count_mm"]))
            p, v, P = axis["p"], axis["v"], axis["P"]
            p = s(p, (c["ta"], v))
            v = s(v, (-c["b"], axis["w"]))
            a = s(P[0], (c["ta"], P[2]))
            b = s(P[1], (c["ta"], P[3]))
            q00 = s(a, (c["ta"], b), c["q"])
            q01 = b
            q10 = s(P[2], (c["ta"], P[3]))
            q11 = s(P[3], c["q"])
            k0 = s((q00, c["sigma_inv"]))
            k1 = s((q10, c["sigma_inv"]))
            r = s(y, -p)
            p = s(p, (k0, r))
            v = s(v, (k1, r))
            axis["P"] = [s(q00, (-k0, q00)), s(q01, (-k0, q01)), s(q10, (-k1, q00)),
                         s(q11, (-k1, q01))]
            d = s((s(p, -axis["last"]), c["inv_dt"]))
            ctrl.append(s((c["kp"], p), (c["kd"], d)))
            axis.update(p=p, v=v, last=p)
        clamp = c["clamp"]
        alpha = max(-clamp, min(clamp, -ctrl[1]))
        beta = max(-clamp, min(clamp, ctrl[0]))
        self.axes[0]["w"], self.axes[1]["w"] = -beta, alpha
        return tuple(self._command(t) for t in (alpha, beta))

    def _command(self, tilt):
        deg = self._set((tilt, self.c["rad_to_deg"]))
        value = _round_half_even(_real(deg) * (1 << self.scale_bits))
        return max(-8191, min(8191, value))


def leg_words(alpha, beta):
    """The six ``InverseKinematics`` input words of one pair of tilts."""
    return [((alpha & 0x3FFF) << 17) | ((beta & 0x3FFF) << 3) | leg for leg in range(6)]


class RollingBall:
    """A ball rolling on a tilted plate (docs/kernels.md): ``a_x = +g' sin(beta)``,
    ``a_y = -g' sin(alpha)`` with ``g' = 5/7 g``, integrated in ``substeps`` Euler steps per
    sample; the touch panel reads the position in counts of 0.11667 mm, 12-bit two's
    complement, saturated."""

    G_ROLL = 5 / 7 * 9810.0
    COUNT_MM = 0.11667

    def __init__(self, x, y, vx=0.0, vy=0.0):
        self.x, self.y, self.vx, self.vy = x, y, vx, vy

    def touch(self):
        def counts(pos):
            return max(-2048, min(2047, round(pos / self.COUNT_MM)))
        return counts(self.x), counts(self.y)

    def step(self, alpha, beta, dt, substeps=20):
        """Advance ``dt`` seconds with the plate tilted by ``alpha``, ``beta`` (radians)."""
        h = dt / substeps
        ax, ay = self.G_ROLL * math.sin(beta), -self.G_ROLL * math.sin(alpha)
        for _ in range(substeps):
            self.vx += ax * h
            self.vy += ay * h
            self.x += self.vx * h
            self.y += self.vy * h


def tilt_radians(command, scale_bits=8):
    """A 14-bit tilt of the controller's words in radians."""
    value = command - (1 << 14) if command & (1 << 13) else command
    return math.radians(value / (1 << scale_bits))


def word_tilts(word):
    """(alpha, beta) 14-bit fields of an ``InverseKinematics`` input word."""
    return (word >> 17) & 0x3FFF, (word >> 3) & 0x3FFF


def servo_pulse(index, clock_hz=100_000_000, min_us=500, max_us=2500, full_scale_deg=180):
    """The pulse in cycles for leg angle index ``index`` (0.1 degree), docs/kernels.md "Servo
    PWM": ``min + round16(i * k)`` with ``k`` the rounded 16.16 cycles per step, the index
    clipped to the servo's range."""
    per_us = Fraction(clock_hz, 1_000_000)
    k = round(Fraction(max_us - min_us) * per_us * 65536 / (full_scale_deg * 10))
    index = min(index, full_scale_deg * 10)
    return round(min_us * per_us) + ((index * k + 32768) >> 16)
