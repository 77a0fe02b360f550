"""Software side of the sort service demo for ``rosgate sim``: two clients call the service
"srv" at the same time (both hardware slots serve it); every response must be its request
sorted. ``--arg requests=N`` (default 3 per client), ``--arg size=N`` (default 2048) and
``--arg clients=N`` (default 2)."""

import random

from cocotb.triggers import Combine
import cocotb
from host.sim_args import SimArg


async def _client(ctx, k, n, size):
    rng = random.Random(k)
    for i in range(n):
        values = [rng.randrange(1 << 32) for _ in range(size)]
        start = ctx.now()
        response = await ctx.broker.call("srv", {"unsorted": values})
        ctx.results["calls"].append({"client": k, "call": i, "size": size,
                                     "cycles": ctx.now() - start,
                                     "sorted": response["sorted"] == sorted(values)})


async def clients(ctx):
    n = int(ctx.args.get("requests", 3))
    size = int(ctx.args.get("size", 2048))
    ctx.results["calls"] = []
    await Combine(*(cocotb.start_soon(_client(ctx, k, n, size))
                    for k in range(int(ctx.args.get("clients", 2)))))
    ctx.results["all_sorted"] = all(c["sorted"] for c in ctx.results["calls"])


def accepts(ctx, name, value):
    """With ``--ros2``: why a call from DDS cannot go to the hardware, or ``None``. The sort
    thread takes 1 to ``block_size`` (2048) values; the bridge answers any other call with
    the empty response, logs it and counts it as rejected."""
    if name != "/srv":
        return None
    block = getattr(ctx.threads.get("SortDemo"), "block_size", 2048)
    n = len(value["unsorted"])
    if not 1 <= n <= block:
        return f"{n} values; the sort thread takes 1 to {block}"
    return None


ARGS = {
    "requests": SimArg("requests per client", 3, kind=int),
    "size": SimArg("numbers per request", 2048, kind=int),
    "clients": SimArg("clients calling at the same time", 2, kind=int),
}

NODES = [clients]
