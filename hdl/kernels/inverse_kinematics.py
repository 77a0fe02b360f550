"""Inverse kinematics of the ReconROS ball-on-plate Stewart platform (docs/reconos.md),
bit-exact with the HLS fixed-point algorithm, defect 15 fixed."""

import math
from dataclasses import dataclass
from fractions import Fraction

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import check_choice
from ..stream import AXIStreamSignature

__all__ = ["InverseKinematics", "StewartPlatform", "PLATFORM"]



@dataclass(frozen=True)
class StewartPlatform:
    """The ReconROS ball-on-plate Stewart platform (docs/reconos.md, ``rt_inverse``): per leg
    its plate joint (mm), the rotation of its base (sin, cos, as decimal strings: the HLS
    constants), the signs of x and z; then the plate height, the base translation, the arm
    length and the squared leg length (mm)."""
    joint_x: tuple = (51, -51, -64, -13, 13, 64)
    joint_y: tuple = (44, 44, 22, -66, -66, 22)
    rot_sin: tuple = ("0", "0", "-0.8660254", "-0.8660254", "0.8660254", "0.8660254")
    rot_cos: tuple = ("1", "1", "-0.5", "-0.5", "-0.5", "-0.5")
    sign_x: tuple = (-1, 1, -1, 1, -1, 1)
    sign_z: tuple = (1, -1, 1, -1, 1, -1)
    z_offset: int = 105
    translation: tuple = (33, -69)
    arm: int = 20
    leg_squared: int = 13225


#: the platform :class:`InverseKinematics` solves for
PLATFORM = StewartPlatform()

_LUT_SIZE = 2048
_MAX_ANGLE_INDEX = (8192 * 10) >> 8      # |Q6.8 angle| * 10 >> 8 for the 14-bit field


def _floor_scaled(text, frac_bits):
    return math.floor(Fraction(text) * (1 << frac_bits))


def _lut(frac_bits=20):
    """sin/cos(i * 0.1 degree) as 8-decimal literals, floored to ``ap_fixed<22,2>``."""
    sin = [_floor_scaled(f"{math.sin(math.radians(i / 10)):.8f}", frac_bits)
           for i in range(_LUT_SIZE)]
    cos = [_floor_scaled(f"{math.cos(math.radians(i / 10)):.8f}", frac_bits)
           for i in range(_LUT_SIZE)]
    return sin, cos


def _wrap(value, width):
    """Signed ``width``-bit slice of ``value`` (the ``ap_fixed`` wrap)."""
    return value[:width].as_signed()


class InverseKinematics(wiring.Component):
    """Arm angle of one leg of the ReconROS Stewart platform for a plate tilt (the
    ``rt_inverse`` node: ``/angle`` UInt32 in, ``legangle`` UInt32 out).

    Input word: bits 30..17 alpha, 16..3 beta (14-bit two's complement, Q6.8 degrees), 2..0
    the leg (0..5). Output word: ``(i_min << 21) | (leg << 18)`` where ``i_min`` (the arm
    angle in 0.1 degree) minimises ``|L - 13225|`` over the 2048-entry sin/cos table, first
    minimum winning, with every intermediate floored and wrapped exactly as the HLS types
    of the spec do (positions ``ap_fixed<22,10>``, lengths ``ap_fixed<32,20>``).

    Defect 15 fixed: the angle is multiplied by 10 in 18 bits, so tilts of 12.8 degrees and
    more are not wrapped (ReconROS computes it in 16 bits).

    The table is searched by ``lanes`` parallel lanes (lane j takes entries j, j + lanes,
    ...); one solution takes ``2048 / lanes + 7`` cycles (16 lanes: 135).

    Parameters
    ----------
    lanes : int
        8, 16 or 32.

    Members
    -------
    i : In(AXIStreamSignature(32, keep=False))
        Input words (``tlast`` ignored).
    o : Out(AXIStreamSignature(32, keep=False))
        One output word per valid input, ``tlast`` set.
    err_leg : Out(1)
        One-cycle pulse (registered): an input named leg 6 or 7; it is dropped (no output).
    """

    def __init__(self, *, lanes=16):
        self._lanes = check_choice("lanes", lanes, (8, 16, 32))
        super().__init__({
            "i": In(AXIStreamSignature(32, keep=False)),
            "o": Out(AXIStreamSignature(32, keep=False)),
            "err_leg": Out(1),
        })

    lanes = property(lambda self: self._lanes)

    def cycles_per_solution(self):
        return _LUT_SIZE // self._lanes + 7

    def elaborate(self, platform):
        m = Module()
        lanes = self._lanes
        steps = _LUT_SIZE // lanes
        sin, cos = _lut()

        # angle table for alpha and beta (|index| <= 320)
        n_angle = _MAX_ANGLE_INDEX + 1
        m.submodules.angle_lut = angle_lut = Memory(
            shape=44, depth=n_angle,
            init=[(s & 0x3FFFFF) | (c & 0x3FFFFF) << 22 for s, c in zip(sin[:n_angle],
                                                                       cos[:n_angle])])
        rd_a, rd_b = angle_lut.read_port(), angle_lut.read_port()

        busy = Signal()
        o_valid = Signal()
        phase = Signal(range(8))
        leg = Signal(3)
        neg_a, neg_b = Signal(), Signal()
        m.d.comb += [self.o.tvalid.eq(o_valid), self.o.tlast.eq(1)]
        with m.If(self.o.tvalid & self.o.tready):
            m.d.sync += o_valid.eq(0)

        def angle_index(raw):
            v = Signal(signed(18))
            m.d.comb += v.eq(raw * 10)
            mag = Mux(v < 0, -v, v)
            return v < 0, (mag >> 8)[:9]

        raw_a, raw_b = self.i.tdata[17:31].as_signed(), self.i.tdata[3:17].as_signed()
        na, ia = angle_index(raw_a)
        nb, ib = angle_index(raw_b)
        m.d.comb += [rd_a.addr.eq(ia), rd_b.addr.eq(ib), self.i.tready.eq(~busy)]
        m.d.sync += self.err_leg.eq(self.i.tvalid & ~busy & (self.i.tdata[:3] >= 6))
        with m.If(self.i.tvalid & ~busy & (self.i.tdata[:3] < 6)):
            m.d.sync += [busy.eq(1), phase.eq(0), leg.eq(self.i.tdata[:3]),
                         neg_a.eq(na), neg_b.eq(nb)]

        def lut_value(port, neg):
            s = port.data[:22].as_signed()
            c = port.data[22:].as_signed()
            return Mux(neg, -s, s), c

        # per-leg constants
        def per_leg(values, shape):
            sig = Signal(shape)
            with m.Switch(leg):
                for n, v in enumerate(values):
                    with m.Case(n):
                        m.d.comb += sig.eq(v)
            return sig

        tx, ty = PLATFORM.translation
        px = per_leg(PLATFORM.joint_x, signed(8))
        py = per_leg(PLATFORM.joint_y, signed(8))
        rs = per_leg([_floor_scaled(v, 8) for v in PLATFORM.rot_sin], signed(10))
        rc = per_leg([_floor_scaled(v, 8) for v in PLATFORM.rot_cos], signed(10))
        sx = per_leg([v < 0 for v in PLATFORM.sign_x], 1)
        sz = per_leg([v < 0 for v in PLATFORM.sign_z], 1)

        pbx, pby, pbz = (Signal(signed(22), name=n) for n in ("pbx", "pby", "pbz"))
        psx, psy, psz = (Signal(signed(22), name=n) for n in ("psx", "psy", "psz"))
        psy2 = Signal(64)
        t = Signal(range(steps + 2))
        best = [Signal(33, name=f"best{j}") for j in range(lanes)]
        best_i = [Signal(11, name=f"best_i{j}") for j in range(lanes)]
        banks = []
        for j in range(lanes):
            bank = Memory(shape=44, depth=steps,
                          init=[(sin[i] & 0x3FFFFF) | (cos[i] & 0x3FFFFF) << 22
                                for i in range(j, _LUT_SIZE, lanes)])
            m.submodules[f"arm_lut{j}"] = bank
            port = bank.read_port()
            m.d.comb += port.addr.eq(t)
            banks.append(port)

        with m.If(busy):
            with m.Switch(phase):
                with m.Case(0):
                    # table data of alpha and beta are on the read ports
                    sa, ca = lut_value(rd_a, neg_a)
                    sb, cb = lut_value(rd_b, neg_b)
                    m.d.sync += [
                        pbx.eq(_wrap((cb * px) >> 8, 22)),
                        pby.eq(_wrap((sa * sb * px + ((ca * py) << 20)) >> 28, 22)),
                        pbz.eq(_wrap((-(ca * sb * px) + ((sa * py) << 20) +
                                      Const(PLATFORM.z_offset << 40, signed(49))) >> 28, 22)),
                        phase.eq(1)]
                with m.Case(1):
                    x = rc * pbx - rs * pby
                    m.d.sync += [
                        psx.eq(_wrap((Mux(sx, -x, x) + (tx << 20)) >> 8, 22)),
                        psy.eq(_wrap((rs * pbx + rc * pby + (ty << 20)) >> 8, 22)),
                        psz.eq(_wrap(Mux(sz, -pbz, pbz), 22)),
                        t.eq(0), phase.eq(2)]
                    m.d.sync += [b.eq(524287 << 12) for b in best]
                    m.d.sync += [b.eq(0) for b in best_i]
                with m.Case(2):
                    # search: address t now, data of t - 1 on the ports
                    m.d.sync += [psy2.eq((psy * psy) << 16), t.eq(t + 1)]
                    with m.If(t == steps):
                        m.d.sync += phase.eq(3)
                    with m.If(t != 0):
                        for j, port in enumerate(banks):
                            s = port.data[:22].as_signed()
                            c = port.data[22:].as_signed()
                            a = Signal(signed(34), name=f"a{j}")
                            cc = Signal(signed(34), name=f"c{j}")
                            m.d.comb += [a.eq((psx << 8) - PLATFORM.arm * s),
                                         cc.eq((psz << 8) - PLATFORM.arm * c)]
                            length = Signal(signed(32), name=f"len{j}")
                            m.d.comb += length.eq(_wrap((a * a + cc * cc + psy2) >> 28, 32))
                            diff = Signal(signed(34), name=f"diff{j}")
                            m.d.comb += diff.eq(length - (PLATFORM.leg_squared << 12))
                            d = Signal(33, name=f"d{j}")
                            m.d.comb += d.eq(Mux(diff < 0, -diff, diff))
                            with m.If(d < best[j]):
                                m.d.sync += [best[j].eq(d), best_i[j].eq((t - 1) * lanes + j)]
                with m.Case(3):
                    # reduce: the smallest distance, the lowest index on ties
                    level = list(zip(best, best_i))
                    depth = 0
                    while len(level) > 1:
                        nxt = []
                        for n in range(0, len(level), 2):
                            (da, ia), (db, ib) = level[n], level[n + 1]
                            d = Signal(33, name=f"red{depth}_{n}_d")
                            i = Signal(11, name=f"red{depth}_{n}_i")
                            take_b = (db < da) | ((db == da) & (ib < ia))
                            m.d.comb += [d.eq(Mux(take_b, db, da)), i.eq(Mux(take_b, ib, ia))]
                            nxt.append((d, i))
                        level, depth = nxt, depth + 1
                    win_i = level[0][1]
                    with m.If(~o_valid | self.o.tready):
                        m.d.sync += [o_valid.eq(1), busy.eq(0),
                                     self.o.tdata.eq(Cat(Const(0, 18), leg, win_i))]
        return m
