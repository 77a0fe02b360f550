"""The control node: Kalman filter and PD controller (BallControl) from /touch to six
inverse-kinematics requests on /angle. ``Parameters = period=S`` is the sampling period."""

from hdl.kernels import BallControl
from hdl.reconos.threads import WordKernelNode


def build(ctx):
    return WordKernelNode(ctx.arch, BallControl(period=ctx.params.get("period", "0.02")),
                          h_sub=ctx.handle("sub"), h_pub=ctx.handle("pub"),
                          h_msg_in=ctx.handle("touch_msg"), h_msg_out=ctx.handle("angle_msg"))
