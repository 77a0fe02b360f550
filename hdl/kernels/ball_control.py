"""Kalman filter and PD controller of the ReconROS ball-on-plate demo (``rt_control``,
docs/kernels.md "Ball-on-plate controller"), ``ap_fixed<24,12,AP_RND_CONV,AP_SAT_SYM>``
arithmetic, defects 18 and 19 fixed."""

from fractions import Fraction

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_choice
from ..stream import AXIStreamSignature

__all__ = ["BallControl", "BALL_CONTROL_FRAC", "TOUCH_COUNT_MM", "ROLLING_MM_S2",
           "ball_control_program"]

#: the touch panel's resolution: millimetres per count (a decimal string, as ReconROS' constant)
TOUCH_COUNT_MM = "0.11667"

#: fraction bits of the fixed-point type
BALL_CONTROL_FRAC = 12
_WIDTH = 24
_MAX = (1 << (_WIDTH - 1)) - 1
_COMMAND_MAX = (1 << 13) - 1
#: acceleration of a ball rolling on the plate per radian of tilt: 5/7 g, in mm/s^2
ROLLING_MM_S2 = Fraction(5, 7) * 9810


def _to_fixed(value):
    """``value`` rounded half to even to the type's grid and saturated symmetrically (raw)."""
    scaled = Fraction(value) * (1 << BALL_CONTROL_FRAC)
    floor = scaled.numerator // scaled.denominator
    rest = scaled - floor
    raw = floor + (rest > Fraction(1, 2) or (rest == Fraction(1, 2) and floor % 2 == 1))
    return max(-_MAX, min(_MAX, raw))


def _constants(period, scale_bits):
    period = Fraction(period)
    values = {"ta": period, "b_gain": ROLLING_MM_S2 * period, "q": 4, "sigma_inv": Fraction("0.1"),
              "kp": Fraction("-0.002"), "kd": Fraction("-0.002"), "inv_dt": 1 / period,
              "count_mm": Fraction(TOUCH_COUNT_MM), "clamp": Fraction("0.19199"),
              "rad_to_deg": Fraction("57.324840764"), "one": 1}
    raw = {name: _to_fixed(v) for name, v in values.items()}
    raw["scale"] = 1 << scale_bits           # deg * scale, rounded at 12 bits: Q(scale) deg
    return raw


def ball_control_program():
    """The update as ``(kind, destination, terms)`` steps: ``mac`` sets the destination to
    the rounded, saturated sum of ``terms`` (``(sign, a, b)`` products of registers or
    constants); ``clamp`` sets it to ``terms[0]``'s operand clamped to +-``clamp``;
    ``command`` is a ``mac`` saturated to 14 bits."""
    steps = []

    def mac(dst, *terms, kind="mac"):
        steps.append((kind, dst, [(t[0], t[1], t[2]) if len(t) == 3 else (t[0], t[1], "one")
                                  for t in terms]))

    for a in "xy":
        mac(f"y{a}", (1, f"raw{a}", "count_mm"))
        mac(f"p{a}", (1, f"p{a}"), (1, "ta", f"v{a}"))
        mac(f"v{a}", (1, f"v{a}"), (-1, "b_gain", f"w{a}"))
        mac("a", (1, f"P{a}00"), (1, "ta", f"P{a}10"))
        mac("b", (1, f"P{a}01"), (1, "ta", f"P{a}11"))
        mac("q00", (1, "a"), (1, "ta", "b"), (1, "q"))
        mac("q10", (1, f"P{a}10"), (1, "ta", f"P{a}11"))
        mac("q11", (1, f"P{a}11"), (1, "q"))
        mac("k0", (1, "q00", "sigma_inv"))
        mac("k1", (1, "q10", "sigma_inv"))
        mac("r", (1, f"y{a}"), (-1, f"p{a}"))
        mac(f"p{a}", (1, f"p{a}"), (1, "k0", "r"))
        mac(f"v{a}", (1, f"v{a}"), (1, "k1", "r"))
        mac(f"P{a}00", (1, "q00"), (-1, "k0", "q00"))
        mac(f"P{a}01", (1, "b"), (-1, "k0", "b"))          # Q01 = b
        mac(f"P{a}10", (1, "q10"), (-1, "k1", "q00"))
        mac(f"P{a}11", (1, "q11"), (-1, "k1", "b"))
        mac("r", (1, f"p{a}"), (-1, f"last{a}"))
        mac("d", (1, "r", "inv_dt"))
        mac(f"ctrl{a}", (1, "kp", f"p{a}"), (1, "kd", "d"))
        mac(f"last{a}", (1, f"p{a}"))
    mac("alpha", (-1, "ctrly"), kind="clamp")
    mac("beta", (1, "ctrlx"), kind="clamp")
    mac("wx", (-1, "beta"))
    mac("wy", (1, "alpha"))
    for tilt in ("alpha", "beta"):
        mac("deg", (1, tilt, "rad_to_deg"))
        mac(f"cmd_{tilt}", (1, "deg", "scale"), kind="command")
    return steps


class BallControl(wiring.Component):
    """The ball-on-plate control node: per touch sample a Kalman filter per axis and a PD
    controller (docs/kernels.md), out six words for :class:`InverseKinematics`.

    The update is a program of multiply-accumulate terms on one 24x24 multiplier, three
    cycles a term (operands, product, sum) and one to round and store each result, one
    sample at a time.

    Parameters
    ----------
    period : str or Fraction
        Sampling period in seconds, ``Ta`` and ``Δ`` of the filter (ReconROS: 0.03).
    scale_bits : int
        The tilts leave as degrees times ``2**scale_bits``: 8 (Q6.8, what
        :class:`InverseKinematics` reads; defect 19 fixed) or 6 (ReconROS' output).

    Members
    -------
    i : In(AXIStreamSignature(32, keep=False))
        Touch samples: bits 11..0 x, 27..16 y, 12-bit two's complement panel counts
        (``tlast`` ignored). Taken when the previous sample's words are out.
    o : Out(AXIStreamSignature(32, keep=False))
        Per sample, legs 0..5: ``(alpha << 17) | (beta << 3) | leg`` with 14-bit tilts;
        ``tlast`` on leg 5.
    """

    def __init__(self, *, period="0.03", scale_bits=8):
        check_choice("scale_bits", scale_bits, (6, 8))
        try:
            period = Fraction(period)
        except (TypeError, ValueError):
            raise ParameterError("period", period, "a number of seconds") from None
        if not Fraction(1, 1000) <= period <= 1:
            raise ParameterError("period", period, "a period from 0.001 to 1 s")
        self._period, self._scale_bits = period, scale_bits
        super().__init__({"i": In(AXIStreamSignature(32, keep=False)),
                          "o": Out(AXIStreamSignature(32, keep=False))})

    @property
    def cycles_per_sample(self):
        """Cycles from taking a sample to offering its first word."""
        program = ball_control_program()
        return 3 * sum(len(terms) for _, _, terms in program) + len(program) + 1

    def elaborate(self, platform):
        m = Module()
        frac = BALL_CONTROL_FRAC
        constants = _constants(self._period, self._scale_bits)
        program = ball_control_program()
        names = sorted({dst for _, dst, _ in program} | {"rawx", "rawy"})
        assert not set(names) & set(constants), "a register named like a constant"
        regs = {name: Signal(signed(_WIDTH), name=f"r_{name}",
                             init=(1 << frac) if name in ("Px00", "Px11", "Py00", "Py11")
                             else 0)
                for name in names if not name.startswith("cmd_")}
        commands = {t: Signal(signed(14), name=f"cmd_{t}") for t in ("alpha", "beta")}

        def operand(name):
            if name in constants:
                return Const(constants[name], signed(_WIDTH))
            return regs[name]

        # flattened terms: (kind, dst, sign, a, b, first, last)
        terms = []
        for kind, dst, step_terms in program:
            for k, (sign, a, b) in enumerate(step_terms):
                terms.append((kind, dst, sign, a, b, k == 0, k == len(step_terms) - 1))

        pc = Signal(range(len(terms) + 1))
        phase = Signal(range(4))
        busy = Signal()
        emitting = Signal()
        leg = Signal(range(6))
        op_a = Signal(signed(_WIDTH + 1))
        op_b = Signal(signed(_WIDTH))
        product = Signal(signed(2 * _WIDTH + 1))
        acc = Signal(signed(2 * _WIDTH + 4))

        m.d.comb += self.i.tready.eq(~busy & ~emitting)
        with m.If(self.i.tvalid & self.i.tready):
            m.d.sync += [regs["rawx"].eq(Cat(Const(0, frac), self.i.tdata[0:12]).as_signed()),
                         regs["rawy"].eq(Cat(Const(0, frac), self.i.tdata[16:28]).as_signed()),
                         busy.eq(1), pc.eq(0), phase.eq(0)]

        # phase 0: operands (the sign on the first); 1: product; 2: sum; 3 (after a step's
        # last term): round half to even, saturate, store
        first_now = Signal()
        last_now = Signal()
        with m.Switch(pc):
            for n, (kind, dst, sign, a, b, first, last) in enumerate(terms):
                with m.Case(n):
                    m.d.comb += [first_now.eq(first), last_now.eq(last)]
                    with m.If(busy & (phase == 0)):
                        value = operand(a)
                        m.d.sync += [op_a.eq(-value if sign < 0 else value),
                                     op_b.eq(operand(b))]
        with m.If(busy & (phase == 1)):
            m.d.sync += [product.eq(op_a * op_b), phase.eq(2)]
        with m.If(busy & (phase == 0)):
            m.d.sync += phase.eq(1)

        quotient = acc[frac:].as_signed()
        rest = acc[:frac]
        half = 1 << (frac - 1)
        up = (rest > half) | ((rest == half) & quotient[0])
        rounded = Signal(signed(len(acc) - frac + 1))
        m.d.comb += rounded.eq(quotient + up)

        def saturate(value, limit):
            return Mux(value > limit, limit, Mux(value < -limit, -limit, value))

        def next_term():
            with m.If(pc == len(terms) - 1):
                m.d.sync += [busy.eq(0), emitting.eq(1), leg.eq(0)]
            with m.Else():
                m.d.sync += [pc.eq(pc + 1), phase.eq(0)]

        with m.If(busy & (phase == 2)):
            m.d.sync += acc.eq(Mux(first_now, 0, acc) + product)
            with m.If(last_now):
                m.d.sync += phase.eq(3)
            with m.Else():
                next_term()
        with m.If(busy & (phase == 3)):
            with m.Switch(pc):
                for n, (kind, dst, sign, a, b, first, last) in enumerate(terms):
                    if not last:
                        continue
                    with m.Case(n):
                        if kind == "command":
                            m.d.sync += commands[dst[4:]].eq(saturate(rounded, _COMMAND_MAX))
                        elif kind == "clamp":
                            m.d.sync += regs[dst].eq(saturate(rounded, constants["clamp"]))
                        else:
                            m.d.sync += regs[dst].eq(saturate(rounded, _MAX))
            next_term()

        o = self.o
        m.d.comb += [o.tvalid.eq(emitting), o.tlast.eq(leg == 5),
                     o.tdata.eq(Cat(leg, commands["beta"], commands["alpha"]))]
        with m.If(o.tvalid & o.tready):
            m.d.sync += leg.eq(leg + 1)
            with m.If(leg == 5):
                m.d.sync += emitting.eq(0)
        return m
