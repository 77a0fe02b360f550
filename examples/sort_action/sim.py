"""The sort action's client for ``rosgate sim``: sends goals of random values to the hardware
action server "sort", collects its feedback and checks each result. ``--arg goals=N``
(default 2) and ``--arg size=N`` (default 200; more than the server's block size is
rejected)."""

import random
from host.sim_args import SimArg


async def client(ctx):
    rng = random.Random(int(ctx.args.get("seed", 1)))
    size = int(ctx.args.get("size", 200))
    ctx.results["goals"] = []
    for k in range(int(ctx.args.get("goals", 2))):
        values = [rng.randrange(1, 100_000) for _ in range(size)]
        start = ctx.now()
        goal = ctx.broker.send_goal("sort", {"unsorted": values}, bytes([k + 1] * 16))
        accepted = await goal.accepted.get()
        record = {"goal": k, "size": size, "accepted": accepted}
        if accepted:
            goal.request_result()
            result = await goal.result.get()
            feedback = []
            while (item := goal.feedback.get_nowait()) is not None:
                feedback.append(round(item["feedback"]["percent"], 2))
            record.update(cycles=ctx.now() - start, feedback=feedback,
                          sorted=list(result["result"]["sorted"]) == sorted(values))
        ctx.log(f"client: goal {k} of {size} values: {record}")
        ctx.results["goals"].append(record)


ARGS = {
    "seed": SimArg("seed of the random numbers", 1, kind=int),
    "size": SimArg("numbers per goal", 200, kind=int),
    "goals": SimArg("goals sent one after another", 2, kind=int),
}

NODES = [client]


def summary(results, clock_mhz):
    lines = [f"{'goal':>4} {'values':>6} {'accepted':>8} {'cycles':>8} {'us':>8}  feedback (%)"
             f"  sorted"]
    for g in results["goals"]:
        if g["accepted"]:
            lines.append(f"{g['goal']:>4} {g['size']:>6} {'yes':>8} {g['cycles']:>8} "
                         f"{g['cycles'] / clock_mhz:>8.1f}  {g['feedback']}  "
                         f"{'yes' if g['sorted'] else 'NO'}")
        else:
            lines.append(f"{g['goal']:>4} {g['size']:>6} {'no':>8}")
    return lines
