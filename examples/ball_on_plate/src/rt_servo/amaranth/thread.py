"""The servo node: six PWM channels from the /legangle arm angles; each period's measured
pulse widths go to the servo mailbox (what the plant model reads). ``Parameters =
pwm_clock_hz=N``: the rate the PWM counts at (the example's time scale)."""

from hdl.kernels import ServoPwm
from hdl.reconos.threads import ServoNode


def build(ctx):
    pwm = ServoPwm(clock_hz=ctx.param("pwm_clock_hz", 100_000_000, int))
    return ServoNode(ctx.arch, pwm, h_sub=ctx.handle("sub"), h_msg=ctx.handle("leg_msg"),
                     h_mbox=ctx.handle("servo_mbox"))
