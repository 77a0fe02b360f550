"""The rt_inverse node in Amaranth: take each /angle word, solve the leg's arm angle with the
InverseKinematics kernel, publish it on /legangle. ``Parameters = lanes=N`` (8, 16, 32) sets
the kernel's search lanes."""

from hdl.kernels import InverseKinematics
from hdl.reconos.threads import WordKernelNode


def build(ctx):
    lanes = ctx.param("lanes", 16, int)
    return WordKernelNode(ctx.arch, InverseKinematics(lanes=lanes), h_sub=ctx.handle("sub"),
                          h_pub=ctx.handle("pub"), h_msg_in=ctx.handle("angle_msg"),
                          h_msg_out=ctx.handle("leg_msg"), dropped="err_leg")
