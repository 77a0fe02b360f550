"""The Echo node in Amaranth: take each /image_in message, publish the same message on
/image_out (no copy: the taken message object is published)."""

from hdl.reconos.threads import EchoThread


def build(ctx):
    return EchoThread(ctx.arch, h_sub=ctx.handle("sub"), h_pub=ctx.handle("pub"),
                      h_msg=ctx.handle("image_msg"))
