"""A hardware client of the sort service, driven through its mailboxes (sim.py); its id on
the service is its slot's id + 1."""

from hdl.reconos.service_threads import SortClientThread


def build(ctx):
    call = ctx.hw_call("cli")
    return SortClientThread(ctx.arch, ctx.slot.id + 1, **call.plans, h_cmd=ctx.handle("cmd"),
                            h_done=ctx.handle("done"), request_port=call.request_port,
                            reply_port=call.reply_port)
