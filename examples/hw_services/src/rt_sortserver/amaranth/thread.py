"""The sort service's server: a SortServer node on the service's two hardware topics."""

from hdl.dds.sort_server import SortServer
from hdl.reconos.service_threads import TopicNodeThread


def build(ctx):
    call = ctx.hw_call("srv")
    node = SortServer(**call.plans, block_size=ctx.param("block_size", 2048, int))
    return TopicNodeThread(ctx.arch, node, {call.request_port: "request_in",
                                            call.reply_port: "reply_out"})
