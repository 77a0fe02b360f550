"""The ball and the Stewart platform for ``rosgate sim`` (docs/ball_on_plate.md).

Each servo period the Servo node reports the six pulse widths it produced. The plant turns
them into arm angles (0.5 to 2.5 ms over 0 to 180 degrees), finds the plate tilt those arms
hold (the platform's inverse kinematics solved backwards), rolls the ball for one period
(``a = 5/7 g sin(tilt)``) and puts the touch panel's next sample (12-bit counts of
0.11667 mm) into the Touch node's mailbox.

``--arg periods=N`` (default 300), ``--arg x=MM --arg y=MM`` where the ball is dropped
(default 90, -60).
"""

import math

from hdl.kernels.ball_control import ROLLING_MM_S2, TOUCH_COUNT_MM
from hdl.kernels.inverse_kinematics import PLATFORM
from hdl.kernels.servo_pwm import SERVO_FULL_SCALE_DEG, SERVO_MAX_US, SERVO_MIN_US
from host.sim_args import SimArg

PERIOD_S = 0.02
COUNT_MM = float(TOUCH_COUNT_MM)
G_ROLL = float(ROLLING_MM_S2)      # mm/s^2 per rad of tilt, a rolling ball


def arm_roots(alpha, beta):
    """Per leg, the arm angles (radians, 0..2 pi) that hold the plate at (alpha, beta)."""
    sa, ca, sb, cb = math.sin(alpha), math.cos(alpha), math.sin(beta), math.cos(beta)
    p, (tx, ty), arm = PLATFORM, PLATFORM.translation, PLATFORM.arm
    out = []
    for leg in range(6):
        px, py = p.joint_x[leg], p.joint_y[leg]
        rs, rc = float(p.rot_sin[leg]), float(p.rot_cos[leg])
        pbx = cb * px
        pby = sa * sb * px + ca * py
        pbz = -ca * sb * px + sa * py + p.z_offset
        psx = p.sign_x[leg] * (rc * pbx - rs * pby) + tx
        psy = rs * pbx + rc * pby + ty
        psz = p.sign_z[leg] * pbz
        k = (psx * psx + psy * psy + psz * psz + arm * arm - p.leg_squared) / (2 * arm)
        s = math.asin(max(-1.0, min(1.0, k / math.hypot(psx, psz))))
        phi = math.atan2(psz, psx)
        out.append([(t % (2 * math.pi)) for t in (s - phi, math.pi - s - phi)])
    return out


def _residuals(alpha, beta, angles):
    """Per leg, the distance of the measured angle to the nearer arm solution."""
    out = []
    for roots, angle in zip(arm_roots(alpha, beta), angles):
        d = [(r - angle + math.pi) % (2 * math.pi) - math.pi for r in roots]
        out.append(min(d, key=abs))
    return out


def plate_tilt(angles, guess=(0.0, 0.0)):
    """The tilt (alpha, beta) whose arm solutions best match ``angles`` (Gauss-Newton)."""
    a, b = guess
    for _ in range(10):
        r = _residuals(a, b, angles)
        h = 1e-6
        ja = [(x - y) / h for x, y in zip(_residuals(a + h, b, angles), r)]
        jb = [(x - y) / h for x, y in zip(_residuals(a, b + h, angles), r)]
        saa, sbb = sum(x * x for x in ja), sum(x * x for x in jb)
        sab = sum(x * y for x, y in zip(ja, jb))
        ga, gb = sum(x * y for x, y in zip(ja, r)), sum(x * y for x, y in zip(jb, r))
        det = saa * sbb - sab * sab
        if det == 0:
            break
        da, db = (sbb * ga - sab * gb) / det, (saa * gb - sab * ga) / det
        a, b = a - da, b - db
        if abs(da) + abs(db) < 1e-12:
            break
    return a, b


def pwm_clock_hz(project):
    """The Servo thread's ``pwm_clock_hz`` (build.cfg Parameters or ``--param``)."""
    servo = next(t for t in project.threads if t.name == "Servo")
    return int(servo.params.get("pwm_clock_hz", 100_000_000))


def arm_angle(cycles, clock_hz):
    """The arm angle (radians) a servo takes for a pulse of ``cycles`` PWM clocks."""
    us = cycles * 1e6 / clock_hz
    return math.radians((us - SERVO_MIN_US) * SERVO_FULL_SCALE_DEG
                        / (SERVO_MAX_US - SERVO_MIN_US))


class Ball:
    def __init__(self, x, y):
        self.x, self.y, self.vx, self.vy = x, y, 0.0, 0.0

    def roll(self, alpha, beta, dt, substeps=20):
        ax, ay = G_ROLL * math.sin(beta), -G_ROLL * math.sin(alpha)
        h = dt / substeps
        for _ in range(substeps):
            self.vx += ax * h
            self.vy += ay * h
            self.x += self.vx * h
            self.y += self.vy * h

    def touch_word(self):
        def counts(pos):
            return max(-2048, min(2047, round(pos / COUNT_MM))) & 0xFFF
        return counts(self.x) | (counts(self.y) << 16)


def setup(ctx):
    ctx.legs = ctx.broker.subscribe("/legangle")
    ctx.touch_cycle = None
    ctx.pwm_clock_hz = pwm_clock_hz(ctx.project)
    ctx.results.update(period_s=PERIOD_S, pwm_clock_hz=ctx.pwm_clock_hz, periods=[],
                       latencies=[], touches=[])


async def plant(ctx):
    touch = ctx.resource("Touch", "touch_mbox").state
    servo = ctx.resource("Servo", "servo_mbox").state
    ball = Ball(float(ctx.args.get("x", 90)), float(ctx.args.get("y", -60)))
    tilt = (0.0, 0.0)
    ctx.touch_cycle = ctx.now()
    ctx.results["touches"].append(ball.touch_word())
    await touch.put_wait(ball.touch_word())
    periods = int(ctx.args.get("periods", 300))
    for n in range(periods):
        ctx.progress(n, periods, "control periods")
        report = [await servo.get() for _ in range(6)]
        widths = [w & 0xFFFFFF for w in sorted(report, key=lambda w: w >> 24)]
        if all(widths):
            tilt = plate_tilt([arm_angle(w, ctx.pwm_clock_hz) for w in widths], tilt)
        ball.roll(tilt[0], tilt[1], PERIOD_S)
        ctx.results["periods"].append({"t": round((n + 1) * PERIOD_S, 3), "x": ball.x,
                                       "y": ball.y, "alpha": tilt[0], "beta": tilt[1],
                                       "widths": widths})
        ctx.touch_cycle = ctx.now()
        ctx.results["touches"].append(ball.touch_word())
        await touch.put_wait(ball.touch_word())
    last = ctx.results["periods"][-1]
    ctx.results["final_radius_mm"] = math.hypot(last["x"], last["y"])
    ctx.log(f"plant: ball at ({last['x']:.2f}, {last['y']:.2f}) mm after "
            f"{last['t']:.2f} s")


async def chain_timing(ctx):
    """Cycles from a touch sample to the sixth leg angle it leads to."""
    for _ in range(int(ctx.args.get("periods", 300))):
        for _ in range(6):
            await ctx.legs.get()
        ctx.results["latencies"].append(ctx.now() - ctx.touch_cycle)


ARGS = {
    "x": SimArg("the ball's start position x on the plate, mm", 90, kind=float),
    "y": SimArg("the ball's start position y on the plate, mm", -60, kind=float),
    "periods": SimArg("control periods to simulate", 300, kind=int),
}

NODES = [plant, chain_timing]


def summary(results, clock_mhz):
    lat = results["latencies"]
    mean = sum(lat) / max(1, len(lat))
    return [f"ball {results['final_radius_mm']:.2f} mm from the centre after "
            f"{results['periods'][-1]['t']:.2f} s ({len(results['periods'])} periods)",
            f"touch sample to the sixth leg angle: {mean:.0f} cycles on average "
            f"({mean / clock_mhz:.1f} us at {clock_mhz:g} MHz; sampling period "
            f"{results['period_s'] * 1000:g} ms)"]
