"""The touch panel node: every sample the panel's converter puts in the mailbox
(x in bits 11..0, y in 27..16, 12-bit counts) is published on /touch."""

from hdl.reconos.threads import MailboxPublisher


def build(ctx):
    return MailboxPublisher(ctx.arch, h_mbox=ctx.handle("touch_mbox"), h_pub=ctx.handle("pub"),
                            h_msg=ctx.handle("touch_msg"))
