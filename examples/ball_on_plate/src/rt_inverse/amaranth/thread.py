"""The inverse-kinematics node: each /angle request to its leg's arm angle on /legangle."""

from hdl.kernels import InverseKinematics
from hdl.reconos.threads import WordKernelNode


def build(ctx):
    return WordKernelNode(ctx.arch, InverseKinematics(lanes=16), h_sub=ctx.handle("sub"),
                          h_pub=ctx.handle("pub"), h_msg_in=ctx.handle("angle_msg"),
                          h_msg_out=ctx.handle("leg_msg"), dropped="err_leg")
