# amaranth: UnusedElaboratable=no
"""Golden models and parameters of the kernels: the models against the spec's own numbers
(docs/kernels.md PID vectors, docs/reconos.md fixed-point constants,
docs/kernels.md tables),
OpenCV's border modes, and parameter errors that name the bad value."""

import numpy as np
import pytest

from hdl.kernels import EqualizeHist, GaussianBlur, InverseKinematics, Sobel
from hdl.kernels.colour import hsv_tables
from hdl.kernels.window import border_index
from hdl.params import ParameterError
from tb.models import inverse_kinematics as ik
from tb.models.pid import AvrPid


def test_pid_model_spec_vectors():
    pid = AvrPid(256, 64, 32)
    assert (pid.max_error, pid.max_sum) == (127, 16_519_104)
    out = [pid.update(1000, pv) for pv in (0, 100, 250, 400, 600, 800, 950, 1000, 1020, 1000)]
    assert out == [755, 1180, 1543, 1843, 2030, 2130, 2012, 1937, 1895, 1945]
    assert pid.sum == 3880
    wrap = AvrPid(128, 1, 0)
    assert [wrap.update(30000, -30000) for _ in range(3)] == [-299, -342, -385]


def test_ik_model_constants_follow_the_spec():
    assert ik.ROT_SIN[2] == -0.8671875 and ik.ROT_SIN[4] == 0.86328125
    assert ik.ROT_COS[2] == -0.5
    assert ik.decode_input(ik.encode_input(-5, 7, 3)) == (-5, 7, 3)
    assert ik.client_word(1) == (101 << 3) | (152 << 17) | 1


def test_ik_defect_15_is_fixed():
    """20 degrees (raw 5120): x10 = 51200 wraps in 16 bits (ReconROS) to -14336 (index 56
    of the negated angle); rosgate keeps 51200 (index 200)."""
    raw = 20 * 256
    assert ik._sin_cos(raw) == (ik.LUT_SIN[200], ik.LUT_COS[200])
    assert ik._sin_cos(-raw) == (-ik.LUT_SIN[200], ik.LUT_COS[200])
    wrapped = (raw * 10 + 0x8000) % 0x10000 - 0x8000
    assert wrapped == -14336 and (-wrapped) >> 8 == 56


@pytest.mark.parametrize("i", [0, 1, 5, 17, 100, 999])
def test_ik_fixed_point_model_near_the_float_version(i):
    """The ap_fixed model and the C float version pick arm angles a few tenths of a degree
    apart (the LUT truncates the tilt to 0.1 degree)."""
    word = ik.client_word(i)
    assert word & 7 < 6
    assert abs((ik.solve(word) >> 21) - ik.solve_float(word)) <= 8


def test_hsv_tables_match_the_spec():
    sdiv, hdiv = hsv_tables(180)
    assert sdiv[0] == hdiv[0] == 0
    assert sdiv[1] == 1_044_480 and hdiv[1] == 122_880
    assert max(sdiv).bit_length() == 20 and max(hdiv).bit_length() == 17


@pytest.mark.parametrize("border,mode", [("reflect101", "reflect"), ("replicate", "edge"),
                                         ("constant", "constant")])
def test_border_index_matches_numpy_pad(border, mode):
    line = np.arange(1, 8)
    padded = np.pad(line, 3, mode=mode)
    for x in range(-3, 10):
        src = border_index(x, len(line), border)
        assert padded[x + 3] == (0 if src is None else line[src])


def test_bad_parameters_name_the_value():
    with pytest.raises(ParameterError, match="mode must be one of .* not 'canny'"):
        Sobel("canny")
    with pytest.raises(ParameterError, match="ksize must be one of 3, 5, not 7"):
        GaussianBlur(7)
    with pytest.raises(ParameterError, match="border must be one of .* not 'constant'"):
        GaussianBlur(3, border="constant")
    with pytest.raises(ParameterError, match="pixels_per_beat must be one of .* not 3"):
        Sobel(pixels_per_beat=3)
    with pytest.raises(ParameterError, match="max_width must be a multiple of pixels_per_beat"):
        Sobel(pixels_per_beat=4, max_width=642)
    with pytest.raises(ParameterError, match="channels must be one of 4, not 3"):
        Sobel("reconros", channels=3)
    with pytest.raises(ParameterError, match=r"max_width \* max_height must be at most"):
        EqualizeHist(max_width=4096, max_height=4096)
    with pytest.raises(ParameterError, match="lanes must be one of 8, 16, 32, not 12"):
        InverseKinematics(lanes=12)


def test_ball_control_covariance_is_a_p_a_transpose_plus_q():
    """Defect 18 fixed: the model's predicted covariance equals A P A^T + q I (A = [1 Ta;
    0 1]) to within the rounding of its four assignments, for random covariances."""
    import random
    from fractions import Fraction

    from tb.models.ball_control import BallControlModel, fixed
    rng = random.Random(18)
    m = BallControlModel()
    ta = Fraction(m.c["ta"], 4096)
    for _ in range(200):
        raw = [rng.randrange(-40000, 40000) for _ in range(4)]
        raw[2] = raw[1]
        P = [Fraction(v, 4096) for v in raw]
        exact = [P[0] + ta * (P[1] + P[2]) + ta * ta * P[3] + 4, P[1] + ta * P[3],
                 P[2] + ta * P[3], P[3] + 4]
        s = m._set
        a = s(raw[0], (m.c["ta"], raw[2]))
        b = s(raw[1], (m.c["ta"], raw[3]))
        got = [s(a, (m.c["ta"], b), m.c["q"]), b, s(raw[2], (m.c["ta"], raw[3])),
               s(raw[3], m.c["q"])]
        assert all(abs(g - fixed(e)) <= 2 for g, e in zip(got, exact)), (raw, got)


def test_ball_control_tilts_are_q6_8_degrees_for_inverse_kinematics():
    """Defect 19 fixed: a clamped tilt (0.19199 rad = 11.0 degrees) leaves as Q6.8 and the
    inverse-kinematics decoding reads 11 degrees; ReconROS' shift by 6 reads a quarter."""
    from tb.models.ball_control import BallControlModel
    for scale_bits, degrees in ((8, 11.0), (6, 2.75)):
        m = BallControlModel(scale_bits=scale_bits)
        alpha, beta = m.update(2000, 2000)           # far off centre: both tilts clamp
        assert (alpha, beta) == (round(11.0 * (1 << scale_bits)),
                                 -round(11.0 * (1 << scale_bits))), (alpha, beta)
        assert abs(alpha / 256 - degrees) < 0.01


def test_ball_control_settles_a_dropped_ball():
    """The model balances balls dropped up to 150 mm off centre within 3 mm in 300 samples."""
    from tb.models.ball_control import BallControlModel, RollingBall, tilt_radians
    for x, y in ((150.0, 0.0), (-100.0, 100.0), (20.0, -140.0)):
        m, ball = BallControlModel(), RollingBall(x, y)
        for _ in range(300):
            alpha, beta = m.update(*ball.touch())
            ball.step(tilt_radians(alpha & 0x3FFF), tilt_radians(beta & 0x3FFF), 0.03)
        assert (ball.x ** 2 + ball.y ** 2) ** 0.5 < 3.0, (x, y, ball.x, ball.y)


@pytest.mark.parametrize("kwargs,name", [({"scale_bits": 7}, "scale_bits"),
                                         ({"period": "0"}, "period"),
                                         ({"period": "fast"}, "period")])
def test_ball_control_parameters_are_checked(kwargs, name):
    from hdl.kernels import BallControl
    with pytest.raises(ParameterError, match=name):
        BallControl(**kwargs)
