"""A hardware client of the Fibonacci action, driven through its mailboxes (sim.py); its id
on the action is its slot's id + 1."""

from hdl.reconos.service_threads import FibonacciClientThread


def build(ctx):
    call = ctx.hw_call("client")
    return FibonacciClientThread(ctx.arch, ctx.slot.id + 1, **call.plans,
                                 h_cmd=ctx.handle("cmd"), h_done=ctx.handle("done"),
                                 request_port=call.request_port, reply_port=call.reply_port)
