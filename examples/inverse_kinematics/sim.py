"""The test client of ReconROS' inverse-kinematics demo for ``rosgate sim``
(RRX:Inverse/client_app): publishes ``((i * 101) << 3) | ((i * 152) << 17) | (i % 7)`` on
/angle for i = 0, 1, ... and records each answer on /legangle with its round-trip cycles.
Words for leg 6 (every seventh) name no leg: the node drops them and answers nothing.
``--arg requests=N`` (default 50)."""

from host.sim_args import SimArg


def setup(ctx):
    ctx.answers = ctx.broker.subscribe("/legangle")
    ctx.results["requests"] = []


def client_word(i):
    return (((i * 101) << 3) | ((i * 152) << 17) | (i % 7)) & 0xFFFFFFFF


async def client(ctx):
    for i in range(int(ctx.args.get("requests", 50))):
        word = client_word(i)
        start = ctx.now()
        ctx.broker.publish("/angle", {"data": word})
        if i % 7 == 6:           # no leg 6: no answer; the next request must still be served
            ctx.results["requests"].append({"i": i, "word": word, "answer": None})
            continue
        answer = await ctx.answers.get()
        ctx.results["requests"].append({"i": i, "word": word, "answer": answer["data"],
                                        "cycles": ctx.now() - start})
    answered = [r for r in ctx.results["requests"] if r["answer"] is not None]
    ctx.results["answered"] = len(answered)
    ctx.results["mean_cycles"] = sum(r["cycles"] for r in answered) / max(1, len(answered))
    ctx.log(f"client: {len(answered)} answers, {ctx.results['mean_cycles']:.0f} cycles each "
            "on average")


ARGS = {
    "requests": SimArg("platform poses to solve", 50, kind=int),
}

NODES = [client]


def summary(results, clock_mhz):
    return [f"{results['answered']} legs solved, {results['mean_cycles']:.0f} cycles "
            f"({results['mean_cycles'] / clock_mhz:.2f} us) from publish to answer"]
