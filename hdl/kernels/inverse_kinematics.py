"""Inverse kinematics of the ReconROS ball-on-plate Stewart platform (docs/reconos.md),
bit-exact with the HLS fixed-point algorithm, defect 15 fixed."""

import math
from dataclasses import dataclass
from fractions import Fraction

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..logic import shifted_sum, split_product, split_square
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


#: cycles from the tilt's table values in registers to the search's first table address,
#: which is when the plate joint's position (``psx``, ``psz``) reaches the search: three
#: rounds of products (two cycles each: partial products, their sum), a sum after the
#: second and third, less the table read. The height's square comes four cycles later and
#: is used four stages into the search.
SETUP_CYCLES = 7
#: a table entry's way through a lane, a register each: its read, the arm's two
#: coordinates, the partial products of their squares, the squares, their sum, that plus the
#: height's square (the leg's squared length), the distance to the leg's length, its
#: magnitude; the comparison with the lane's best ends it
SEARCH_STAGES = 8


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
    ...); one solution takes :meth:`cycles_per_solution` cycles (16 lanes: 159). Every
    product is split into partial products of at most 18x18 bits (an ECP5 or 7-series
    multiplier each) registered before their sum, and every sum, comparison and table read
    has a register stage of its own: the fixed-point chain in front of the search is a
    pipeline the solution waits out (:data:`SETUP_CYCLES`), the search is a pipeline of
    :data:`SEARCH_STAGES` stages per lane, and the lanes' minima are reduced one tree level a
    cycle.

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
        """Cycles from one accepted input word to the next: the angle read, the setup, the
        search's addresses and pipeline, the reduction and the output."""
        levels = (self._lanes - 1).bit_length()
        return 1 + 1 + SETUP_CYCLES + _LUT_SIZE // self._lanes + SEARCH_STAGES + levels + 1

    def elaborate(self, platform):
        m = Module()
        lanes = self._lanes
        steps = _LUT_SIZE // lanes
        levels = (lanes - 1).bit_length()
        sin, cos = _lut()

        # angle table for alpha and beta (|index| <= 320)
        n_angle = _MAX_ANGLE_INDEX + 1
        m.submodules.angle_lut = angle_lut = Memory(
            shape=44, depth=n_angle,
            init=[(s & 0x3FFFFF) | (c & 0x3FFFFF) << 22 for s, c in zip(sin[:n_angle],
                                                                       cos[:n_angle])])
        rd_a, rd_b = angle_lut.read_port(), angle_lut.read_port()

        o_valid = Signal()
        leg = Signal(3)
        neg_a, neg_b = Signal(), Signal()
        m.d.comb += [self.o.tvalid.eq(o_valid), self.o.tlast.eq(1)]
        with m.If(self.o.tvalid & self.o.tready):
            m.d.sync += o_valid.eq(0)

        def angle_index(raw):
            v = Signal(signed(18))
            m.d.comb += v.eq(shifted_sum([(10, raw)]))
            mag = Mux(v < 0, -v, v)
            return v < 0, (mag >> 8)[:9]

        raw_a, raw_b = self.i.tdata[17:31].as_signed(), self.i.tdata[3:17].as_signed()
        na, ia = angle_index(raw_a)
        nb, ib = angle_index(raw_b)
        m.d.comb += [rd_a.addr.eq(ia), rd_b.addr.eq(ib)]
        m.d.sync += self.err_leg.eq(self.i.tvalid & self.i.tready & (self.i.tdata[:3] >= 6))

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

        # the setup: a pipeline from the tilt's table values, which stay put while it runs
        sa, ca, sb, cb = (Signal(signed(22), name=n) for n in ("sa", "ca", "sb", "cb"))
        ab = split_product(m, sa, sb, "sa_sb")
        cab = split_product(m, ca, sb, "ca_sb")
        cbpx = split_product(m, cb, px, "cb_px")
        capy = split_product(m, ca, py, "ca_py")
        sapy = split_product(m, sa, py, "sa_py")
        abpx = split_product(m, ab, px, "sa_sb_px")
        cabpx = split_product(m, cab, px, "ca_sb_px")
        pbx, pby, pbz = (Signal(signed(22), name=n) for n in ("pbx", "pby", "pbz"))
        m.d.sync += [
            pbx.eq(_wrap(cbpx >> 8, 22)),
            pby.eq(_wrap((abpx + (capy << 20)) >> 28, 22)),
            pbz.eq(_wrap((-cabpx + (sapy << 20) +
                          Const(PLATFORM.z_offset << 40, signed(49))) >> 28, 22))]
        rcx, rsy = split_product(m, rc, pbx, "rc_pbx"), split_product(m, rs, pby, "rs_pby")
        rsx, rcy = split_product(m, rs, pbx, "rs_pbx"), split_product(m, rc, pby, "rc_pby")
        psx, psy, psz = (Signal(signed(22), name=n) for n in ("psx", "psy", "psz"))
        # +-(rcx - rsy) + tx: both signs side by side, so that two additions are in series
        m.d.sync += [
            psx.eq(_wrap(Mux(sx, rsy - rcx + (tx << 20), rcx - rsy + (tx << 20)) >> 8, 22)),
            psy.eq(_wrap((rsx + rcy + (ty << 20)) >> 8, 22)),
            psz.eq(_wrap(Mux(sz, -pbz, pbz), 22))]
        psy2 = Signal(64)
        m.d.comb += psy2.eq(split_product(m, psy, psy, "psy_psy") << 16)

        # the search: lane j reads entries j, j + lanes, ... at address t; each stage of
        # its pipeline carries a valid bit and the address it came from
        t = Signal(range(steps + 1))
        searching = Signal()
        best = [Signal(33, name=f"best{j}") for j in range(lanes)]
        best_i = [Signal(11, name=f"best_i{j}") for j in range(lanes)]
        valid = [Signal(name=f"search_valid{k}") for k in range(SEARCH_STAGES)]
        where = [Signal(range(steps), name=f"search_t{k}") for k in range(SEARCH_STAGES)]
        m.d.sync += [valid[0].eq(searching & (t < steps)), where[0].eq(t)]
        m.d.sync += [v.eq(u) for u, v in zip(valid, valid[1:])]
        m.d.sync += [v.eq(u) for u, v in zip(where, where[1:])]
        length_offset = PLATFORM.leg_squared << 12
        for j in range(lanes):
            bank = Memory(shape=44, depth=steps,
                          init=[(sin[i] & 0x3FFFFF) | (cos[i] & 0x3FFFFF) << 22
                                for i in range(j, _LUT_SIZE, lanes)])
            m.submodules[f"arm_lut{j}"] = bank
            port = bank.read_port()
            m.d.comb += port.addr.eq(t)
            s = port.data[:22].as_signed()
            c = port.data[22:].as_signed()
            a = Signal(signed(34), name=f"a{j}")
            cc = Signal(signed(34), name=f"c{j}")
            m.d.sync += [a.eq((psx << 8) - shifted_sum([(PLATFORM.arm, s)])),
                         cc.eq((psz << 8) - shifted_sum([(PLATFORM.arm, c)]))]
            aa, ccc = split_square(m, a, f"a{j}_sq"), split_square(m, cc, f"c{j}_sq")
            both = Signal(69, name=f"squares{j}")
            m.d.sync += both.eq(aa + ccc)
            length = Signal(signed(32), name=f"len{j}")
            m.d.sync += length.eq(_wrap((both + psy2) >> 28, 32))
            diff = Signal(signed(34), name=f"diff{j}")
            m.d.sync += diff.eq(length - length_offset)
            d = Signal(33, name=f"d{j}")
            m.d.sync += d.eq(Mux(diff < 0, -diff, diff))
            with m.If(valid[-1] & (d < best[j])):
                m.d.sync += [best[j].eq(d), best_i[j].eq(where[-1] * lanes + j)]

        # the reduction: the smallest distance, the lowest index on ties; a level a cycle
        level = list(zip(best, best_i))
        depth = 0
        while len(level) > 1:
            nxt = []
            for n in range(0, len(level), 2):
                (da, ia_), (db, ib_) = level[n], level[n + 1]
                dd = Signal(33, name=f"red{depth}_{n}_d")
                ii = Signal(11, name=f"red{depth}_{n}_i")
                take_b = (db < da) | ((db == da) & (ib_ < ia_))
                m.d.sync += [dd.eq(Mux(take_b, db, da)), ii.eq(Mux(take_b, ib_, ia_))]
                nxt.append((dd, ii))
            level, depth = nxt, depth + 1
        win_i = level[0][1]

        wait = Signal(range(max(SETUP_CYCLES, SEARCH_STAGES + levels) + 1))
        with m.FSM(name="ik"):
            with m.State("IDLE"):
                m.d.comb += self.i.tready.eq(1)
                with m.If(self.i.tvalid & (self.i.tdata[:3] < 6)):
                    m.d.sync += [leg.eq(self.i.tdata[:3]), neg_a.eq(na), neg_b.eq(nb)]
                    m.next = "ANGLES"
            with m.State("ANGLES"):
                # table data of alpha and beta are on the read ports
                m.d.sync += [sa.eq(Mux(neg_a, -rd_a.data[:22].as_signed(),
                                       rd_a.data[:22].as_signed())),
                             ca.eq(rd_a.data[22:].as_signed()),
                             sb.eq(Mux(neg_b, -rd_b.data[:22].as_signed(),
                                       rd_b.data[:22].as_signed())),
                             cb.eq(rd_b.data[22:].as_signed()),
                             wait.eq(SETUP_CYCLES - 1)]
                m.next = "SETUP"
            with m.State("SETUP"):
                m.d.sync += wait.eq(wait - 1)
                with m.If(wait == 0):
                    m.d.sync += [t.eq(0), searching.eq(1)]
                    m.d.sync += [b.eq(524287 << 12) for b in best]
                    m.d.sync += [b.eq(0) for b in best_i]
                    m.next = "SEARCH"
            with m.State("SEARCH"):
                m.d.sync += t.eq(t + 1)
                with m.If(t == steps - 1):
                    m.d.sync += [searching.eq(0), wait.eq(SEARCH_STAGES + levels - 1)]
                    m.next = "DRAIN"
            with m.State("DRAIN"):
                m.d.sync += wait.eq(wait - 1)
                with m.If(wait == 0):
                    m.next = "OUTPUT"
            with m.State("OUTPUT"):
                with m.If(~o_valid | self.o.tready):
                    m.d.sync += [o_valid.eq(1), self.o.tdata.eq(Cat(Const(0, 18), leg, win_i))]
                    m.next = "IDLE"
        return m
