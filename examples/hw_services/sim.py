"""Software side of the services-and-actions demo for ``rosgate sim``: through each client
thread's mailboxes, the two sort clients call the hardware sort service at the same time and
the two Fibonacci clients send goals to the hardware action server at the same time. Then
software calls the service /sort, which the SortGateway thread serves by calling the hardware
service as one more client (``--arg software_calls=N``, default 3, and one call larger than the
server takes, answered empty).

``--arg calls=N`` (default 3 per sort client), ``--arg size=N`` (default 256 values),
``--arg seed=N``. For measurements, ``--arg sort_sizes=1,256,2048`` makes SortClientA alone
call once per size and ``--arg fib_orders=0,10`` makes FibClientA alone send those goals.
Every reply must be its request sorted; every result F(0..order) (or, for a cancelled goal,
the values sent before the cancel); invalid orders and goals that find the server busy are
refused (a busy client sends its goal again).
"""

import random

import cocotb
from cocotb.triggers import Combine, Timer

from hdl.dds.action import CancelStatus, GoalStatus
from hdl.dds.fibonacci_server import MAX_ORDER
from hdl.reconos.service_threads import CallStatus
from host.sim_args import SimArg

OK, REFUSED = CallStatus.OK, CallStatus.REFUSED
SUCCEEDED, CANCELED = GoalStatus.SUCCEEDED, GoalStatus.CANCELED
ERROR_NONE, ERROR_UNKNOWN_GOAL_ID = CancelStatus.ERROR_NONE, CancelStatus.ERROR_UNKNOWN_GOAL_ID


def fibonacci(n):
    values = [0, 1][:n + 1]
    while len(values) < n + 1:
        values.append(values[-1] + values[-2])
    return values


async def _sort_client(ctx, thread, rng, sizes):
    cmd = ctx.resource(thread, "cmd").state
    done = ctx.resource(thread, "done").state
    for k, size in enumerate(sizes):
        values = [rng.randrange(1 << 32) for _ in range(size)]
        for word in [len(values)] + values:
            await cmd.put_wait(word)
        status, cycles, count = [await done.get() for _ in range(3)]
        reply = [await done.get() for _ in range(count if status == OK else 0)]
        ok = status == OK and reply == sorted(values)
        ctx.results["sort_calls"].append({"client": thread, "call": k, "values": len(values),
                                          "cycles": cycles, "sorted": ok})
        ctx.log(f"{thread}: call {k} of {len(values)} values: {cycles} cycles, "
                f"{'sorted' if ok else 'WRONG'}")


async def _fibonacci_client(ctx, thread, goals):
    cmd = ctx.resource(thread, "cmd").state
    done = ctx.resource(thread, "done").state
    for order, cancel_after, stranger in goals:
        while True:
            await cmd.put_wait((order & 0xFF) | cancel_after << 8 | int(stranger) << 16)
            word, cycles, count = [await done.get() for _ in range(3)]
            values = [await done.get() for _ in range(count if word & 0xFF == OK else 0)]
            values = [v - (1 << 32) if v >> 31 else v for v in values]
            status, result, cancel, feedbacks = (word & 0xFF, word >> 8 & 0xFF,
                                                 word >> 16 & 0xFF, word >> 24)
            record = {"client": thread, "order": order, "cancel_after": cancel_after,
                      "stranger": stranger, "status": status, "result": result,
                      "cancel": cancel, "feedbacks": feedbacks, "cycles": cycles,
                      "values": values}
            if status == OK:
                if cancel_after and result == CANCELED:
                    record["correct"] = (values == fibonacci(feedbacks) and
                                         cancel == ERROR_NONE)
                else:
                    record["correct"] = (result == SUCCEEDED and values == fibonacci(order) and
                                         feedbacks == order)
                if stranger:
                    record["correct"] &= cancel in (ERROR_UNKNOWN_GOAL_ID, ERROR_NONE)
            else:
                record["correct"] = status == REFUSED
            ctx.results["fibonacci_goals"].append(record)
            ctx.log(f"{thread}: goal order {order}: status {status}, result {result}, "
                    f"{feedbacks} feedbacks, {cycles} cycles")
            if status != REFUSED or not 0 <= order <= MAX_ORDER:
                break
            await Timer(2, "us")     # the server was busy: again


async def sort_clients(ctx):
    rng = random.Random(int(ctx.args.get("seed", 1)))
    calls = int(ctx.args.get("calls", 3))
    size = int(ctx.args.get("size", 256))
    ctx.results["sort_calls"] = []
    if "sort_sizes" in ctx.args:
        plans = {"SortClientA": [int(n) for n in ctx.args["sort_sizes"].split(",") if n]}
    else:
        plans = {t: [rng.choice([size, size // 2, 1, 0]) for _ in range(calls)]
                 for t in ("SortClientA", "SortClientB")}
    await Combine(*(cocotb.start_soon(_sort_client(ctx, t, random.Random(rng.random()), sizes))
                    for t, sizes in plans.items()))
    ctx.results["all_sorted"] = all(c["sorted"] for c in ctx.results["sort_calls"])
    if "sort_sizes" not in ctx.args:
        await _software_calls(ctx, rng, int(ctx.args.get("software_calls", 3)), size)


async def _software_calls(ctx, rng, calls, size):
    """Calls of the software service /sort, which the SortGateway thread serves by calling
    the hardware service as one more client: each reply is the request sorted; a request
    larger than the server's block comes back empty (the server's BAD_REQUEST)."""
    if not calls:
        return
    ctx.results["software_calls"] = []
    server = next(t for t in ctx.project.threads if t.name == "SortServer")
    block = int(server.params.get("block_size", 2048))
    sizes = [rng.choice([size, 1, 0]) for _ in range(calls)]
    if calls:
        sizes.insert(calls // 2, 4096)
    for k, n in enumerate(sizes):
        values = [rng.randrange(1 << 32) for _ in range(n)]
        start = ctx.now()
        reply = await ctx.broker.call("/sort", {"unsorted": values})
        expected = sorted(values) if n <= block else []
        ok = list(reply["sorted"]) == expected
        ctx.results["software_calls"].append({"call": k, "values": n, "sorted": ok,
                                              "cycles": ctx.now() - start})
        ctx.log(f"/sort from software through the gateway: {n} values, {ctx.now() - start} "
                f"cycles, {'as expected' if ok else 'WRONG'}")
    ctx.results["all_sorted"] &= all(c["sorted"] for c in ctx.results["software_calls"])


async def fibonacci_clients(ctx):
    ctx.results["fibonacci_goals"] = []
    plans = {"FibClientA": [(10, 0, False), (47, 0, False), (30, 3, False), (5, 0, True)],
             "FibClientB": [(20, 0, False), (-1, 0, False), (0, 0, False)]}
    if "fib_orders" in ctx.args:
        plans = {"FibClientA": [(int(n), 0, False) for n in ctx.args["fib_orders"].split(",")
                                if n]}
    await Combine(*(cocotb.start_soon(_fibonacci_client(ctx, t, g)) for t, g in plans.items()))
    ctx.results["all_goals_correct"] = all(g["correct"] for g in ctx.results["fibonacci_goals"])
    if "fib_orders" not in ctx.args and int(ctx.args.get("software_calls", 3)):
        await _software_goals(ctx)


async def _software_goals(ctx):
    """Goals of the software action /fibonacci, which the FibGateway thread serves by sending
    them to the hardware server as one more client: a valid goal ends SUCCEEDED with F(0..n)
    after n feedbacks, an invalid order is rejected, a goal canceled after its first feedback
    ends CANCELED with the values sent before."""
    ctx.results["software_goals"] = []
    for order, cancel in ((12, False), (MAX_ORDER + 1, False), (MAX_ORDER, True)):
        start = ctx.now()
        goal = ctx.broker.send_goal("/fibonacci", {"order": order})
        accepted = await goal.accepted.get()
        record = {"order": order, "cancel": cancel, "accepted": accepted, "feedbacks": 0}
        if accepted:
            goal.request_result()
            while (result := goal.result.get_nowait()) is None:
                feedback = goal.feedback.get_nowait()
                if feedback is None:
                    await ctx.cycles(50)
                    continue
                record["feedbacks"] += 1
                if cancel and record["feedbacks"] == 1:
                    goal.cancel()
            while goal.feedback.get_nowait() is not None:
                record["feedbacks"] += 1
            values = list(result["result"]["sequence"])
            record.update(status=int(result["status"]), values=values)
            if cancel:
                record["correct"] = (record["status"] == CANCELED and
                                     values == fibonacci(len(values) - 1) and
                                     len(values) - 1 < order)
            else:
                record["correct"] = (record["status"] == SUCCEEDED and
                                     values == fibonacci(order) and
                                     record["feedbacks"] == order)
        else:
            record["correct"] = not 0 <= order <= MAX_ORDER
        record["cycles"] = ctx.now() - start
        ctx.results["software_goals"].append(record)
        ctx.log(f"/fibonacci from software through the gateway: order {order}"
                f"{', canceled after its first feedback' if cancel else ''}: "
                f"{'accepted' if accepted else 'rejected'}, status {record.get('status')}, "
                f"{record['feedbacks']} feedbacks, {record['cycles']} cycles")
    ctx.results["all_goals_correct"] &= all(g["correct"] for g in ctx.results["software_goals"])


ARGS = {
    "seed": SimArg("seed of the random requests", 1, kind=int),
    "calls": SimArg("calls per client", 3, kind=int),
    "size": SimArg("numbers per sort request", 256, kind=int),
    "software_calls": SimArg("calls of /sort from software through the sort gateway (and "
                             "one of 4096 values it must answer empty)", 3, kind=int),
    "sort_sizes": SimArg("instead: the sort requests' sizes, one call each", kind=int,
                         many=True),
    "fib_orders": SimArg("instead: the Fibonacci goals' orders, one goal each", kind=int,
                         many=True),
}

NODES = [sort_clients, fibonacci_clients]


def summary(results, clock_mhz):
    lines = [f"{'sort client':<12} {'call':>4} {'values':>6} {'cycles':>8} {'us':>8}  sorted"]
    for c in results["sort_calls"]:
        lines.append(f"{c['client']:<12} {c['call']:>4} {c['values']:>6} {c['cycles']:>8} "
                     f"{c['cycles'] / clock_mhz:>8.1f}  {'yes' if c['sorted'] else 'NO'}")
    for c in results.get("software_calls", []):
        lines.append(f"{'/sort (sw)':<12} {c['call']:>4} {c['values']:>6} {c['cycles']:>8} "
                     f"{c['cycles'] / clock_mhz:>8.1f}  {'yes' if c['sorted'] else 'NO'}")
    lines.append(f"{'fib client':<12} {'order':>5} {'status':>6} {'result':>6} {'cancel':>6} "
                 f"{'feedbacks':>9} {'cycles':>8}  correct")
    for g in results["fibonacci_goals"]:
        lines.append(f"{g['client']:<12} {g['order']:>5} {g['status']:>6} {g['result']:>6} "
                     f"{g['cancel']:>6} {g['feedbacks']:>9} {g['cycles']:>8}  "
                     f"{'yes' if g['correct'] else 'NO'}")
    return lines
