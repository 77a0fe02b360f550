"""The sort service node: sorts the request's ``unsorted`` (up to 2048 values) into the
response's ``sorted`` (ReconROS never filled the response: defect 14, fixed).
``Parameters = block_size=N`` sets the largest request (a power of two)."""

from hdl.reconos.threads import SortServiceThread


def build(ctx):
    return SortServiceThread(ctx.arch, h_srvs=ctx.handle("srv"), h_req=ctx.handle("sort_srv_req"),
                             h_res=ctx.handle("sort_srv_res"),
                             block_size=ctx.param("block_size", 2048, int))
