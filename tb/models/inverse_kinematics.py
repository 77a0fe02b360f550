"""Inverse kinematics of the ReconROS ball-on-plate Stewart platform, written from
docs/reconos.md with HLS ``ap_fixed`` semantics (every assignment floors to the type's LSB
and wraps to its width; products and sums exact until assigned), computed with exact
rationals, and with defect 15 fixed (the x10 of the angle is not wrapped to 16 bits)."""

import math
from fractions import Fraction

__all__ = ["JOINT_X", "JOINT_Y", "ROT_SIN", "ROT_COS", "SIGN_X", "SIGN_Z", "LUT_SIN", "LUT_COS",
           "ap_fixed", "decode_input", "encode_input", "solve", "solve_float", "client_word"]

JOINT_X = (51, -51, -64, -13, 13, 64)
JOINT_Y = (44, 44, 22, -66, -66, 22)
ROT_SIN_REAL = (0, 0, -0.8660254, -0.8660254, 0.8660254, 0.8660254)
ROT_COS_REAL = (1, 1, -0.5, -0.5, -0.5, -0.5)
SIGN_X = (-1, 1, -1, 1, -1, 1)
SIGN_Z = (1, -1, 1, -1, 1, -1)
Z_OFFSET, TRANS_X, TRANS_Y = 105, 33, -69
LEG_SQUARED, ARM = 13225, 20
LUT_SIZE = 2048
MIN_INIT = 524287


def ap_fixed(value, width, integer):
    """``value`` assigned to ``ap_fixed<width, integer>`` (AP_TRN, AP_WRAP) as a Fraction."""
    frac = width - integer
    raw = math.floor(Fraction(value) * (1 << frac))
    raw = (raw + (1 << (width - 1))) % (1 << width) - (1 << (width - 1))
    return Fraction(raw, 1 << frac)


#: rotation per leg, ap_fixed<10,2>
ROT_SIN = tuple(ap_fixed(Fraction(repr(v)), 10, 2) for v in ROT_SIN_REAL)
ROT_COS = tuple(ap_fixed(Fraction(repr(float(v))), 10, 2) for v in ROT_COS_REAL)
#: sin/cos(i * 0.1 degrees) as 8-decimal literals, ap_fixed<22,2>
LUT_SIN = tuple(ap_fixed(Fraction(f"{math.sin(math.radians(i / 10)):.8f}"), 22, 2)
                for i in range(LUT_SIZE))
LUT_COS = tuple(ap_fixed(Fraction(f"{math.cos(math.radians(i / 10)):.8f}"), 22, 2)
                for i in range(LUT_SIZE))


def decode_input(word):
    """``(alpha_raw, beta_raw, leg)``: the 14-bit two's complement Q6.8 angle fields (bits
    30..17 and 16..3) and the leg (bits 2..0)."""
    def field(v):
        v &= 0x3FFF
        return v - 0x4000 if v & 0x2000 else v
    return field(word >> 17), field(word >> 3), word & 7


def encode_input(alpha_raw, beta_raw, leg):
    return ((alpha_raw & 0x3FFF) << 17) | ((beta_raw & 0x3FFF) << 3) | leg


def client_word(i):
    """The ReconROS test client's i-th request: ``((i*101)<<3) | ((i*152)<<17) | (i mod 7)``
    (32-bit)."""
    return (((i * 101) << 3) | ((i * 152) << 17) | (i % 7)) & 0xFFFFFFFF


def _sin_cos(raw):
    """sin and cos of a Q6.8 degree angle by the LUT: ``x10`` (not wrapped: defect 15 fixed),
    negative angles negated with the sine's sign flipped, index ``>> 8``."""
    v = raw * 10
    sign = 1
    if v < 0:
        v, sign = -v, -1
    index = v >> 8
    return sign * LUT_SIN[index], LUT_COS[index]


def solve(word):
    """The output word ``(i_min << 21) | (leg << 18)`` for an input word (docs/kernels.md)."""
    alpha, beta, leg = decode_input(word)
    leg_word = leg
    if leg >= 6:
        raise ValueError(f"leg {leg} of input word {word:#010x} is not 0..5")
    sa, ca = _sin_cos(alpha)
    sb, cb = _sin_cos(beta)
    px, py = JOINT_X[leg], JOINT_Y[leg]
    rs, rc = ROT_SIN[leg], ROT_COS[leg]
    pos = (22, 10)
    pbx = ap_fixed(cb * px, *pos)
    pby = ap_fixed(sa * sb * px + ca * py, *pos)
    pbz = ap_fixed(-ca * sb * px + sa * py + Z_OFFSET, *pos)
    psx = ap_fixed(SIGN_X[leg] * (rc * pbx - rs * pby) + TRANS_X, *pos)
    psy = ap_fixed(rs * pbx + rc * pby + TRANS_Y, *pos)
    psz = ap_fixed(SIGN_Z[leg] * pbz, *pos)
    best, best_i = Fraction(MIN_INIT), 0
    for i in range(LUT_SIZE):
        length = ap_fixed((psx - ARM * LUT_SIN[i]) ** 2 + psy ** 2 + (psz - ARM * LUT_COS[i]) ** 2,
                          32, 20)
        d = abs(length - LEG_SQUARED)
        if d < best:
            best, best_i = d, i
    return (best_i << 21) | (leg_word << 18)


def solve_float(word):
    """The C (software) version: float math with continuous sin/cos; returns i_min."""
    alpha, beta, leg = decode_input(word)
    a, b = math.radians(alpha / 256), math.radians(beta / 256)
    sa, ca, sb, cb = math.sin(a), math.cos(a), math.sin(b), math.cos(b)
    px, py = JOINT_X[leg], JOINT_Y[leg]
    rs, rc = ROT_SIN_REAL[leg], ROT_COS_REAL[leg]
    pbx = cb * px
    pby = sa * sb * px + ca * py
    pbz = -ca * sb * px + sa * py + Z_OFFSET
    psx = SIGN_X[leg] * (rc * pbx - rs * pby) + TRANS_X
    psy = rs * pbx + rc * pby + TRANS_Y
    psz = SIGN_Z[leg] * pbz
    best, best_i = float(MIN_INIT), 0
    for i in range(LUT_SIZE):
        s, c = math.sin(math.radians(i / 10)), math.cos(math.radians(i / 10))
        d = abs((psx - ARM * s) ** 2 + psy ** 2 + (psz - ARM * c) ** 2 - LEG_SQUARED)
        if d < best:
            best, best_i = d, i
    return best_i
