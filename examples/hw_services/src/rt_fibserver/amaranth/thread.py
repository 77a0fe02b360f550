"""The Fibonacci action's server: a FibonacciServer node on the action's two hardware
topics."""

from hdl.dds.fibonacci_server import FibonacciServer
from hdl.reconos.service_threads import TopicNodeThread


def build(ctx):
    call = ctx.hw_call("server")
    node = FibonacciServer(**call.plans, step_cycles=ctx.param("step_cycles", 1000, int))
    return TopicNodeThread(ctx.arch, node, {call.request_port: "request_in",
                                            call.reply_port: "reply_out"})
