"""Bench of the exported ``services`` top (gen.services.ServiceGraph; docs/services.md): the sort
service and the Fibonacci action, each with a hardware server node and two hardware clients on
two hardware topics.

Golden models: rosbags for every body (requests, replies, goals, feedback, results), Python's
``sorted``, and tb/models/services.py (frame header, kinds, codes, Fibonacci numbers) written
from the docs. Every client port gets random idle (bodies in) and random backpressure (bodies
and headers out); the reply topic's tap sees every frame, checked byte for byte.
"""

import cocotb
from cocotb.triggers import Combine

from tb.harness import cocotb_bench
from tb.models.services import (BAD_REQUEST, CANCEL_STATUS, GOAL_STATUS, KIND, MAX_ORDER,
                                REPLY_OK, fibonacci, frame)

from .services_tb import FIBONACCI, SORT, ServicesTB

SORT_TESTS = ["sort_concurrent_clients", "sort_bad_requests", "sort_unmatched_replies"]
ACTION_TESTS = ["fibonacci_concurrent_goals", "fibonacci_cancel", "fibonacci_bad_input"]

CONFIGS = {"sort": SORT, "fibonacci": FIBONACCI}
# Verilator in make test-full (make test: Icarus; both simulators build the same top)
test_services_sort = cocotb_bench("services", {"sort": SORT}, testcases=SORT_TESTS,
                                  long=[("sort", "verilator")])
# the action's Verilator run is in make test-full (make test: the service on both simulators)
test_services_fibonacci = cocotb_bench("services", {"fibonacci": FIBONACCI},
                                       testcases=ACTION_TESTS,
                                       long=[("fibonacci", "verilator")])

#: a client id no client has (raw frames)
STRANGER = 9


async def start(dut, idle=0.3, backpressure=0.3):
    tb = ServicesTB(dut)
    tb.set_idle(idle)
    tb.set_backpressure(backpressure)
    await tb.reset()
    return tb


# ---- the sort service ----------------------------------------------------------------------

async def run_sort_client(tb, client, requests):
    """Send ``requests`` (lists of values) back to back as client ``client``, return them."""
    for values in requests:
        await tb.send(client, "request", tb.sort_request(values))
    return requests


def check_sort_client(tb, client, requests, unmatched=0):
    infos = [(v & 0xFFFFFFFF, v >> 32) for v in tb.infos[client].values]
    assert infos == [(k, REPLY_OK) for k in range(len(requests))], \
        f"client {client}: reply ids/status {infos}"
    bodies = [bytes(p.data) for p in tb.sinks[client]["reply"].packets]
    assert bodies == [tb.sort_reply(sorted(r)) for r in requests], \
        f"client {client}: a reply is not its request sorted"
    assert tb.counter(f"c{client}_unmatched") == unmatched


@cocotb.test()
async def sort_concurrent_clients(dut):
    """Two clients call at once, up to 4 requests outstanding each: every reply reaches its
    client only, in order, equal to rosbags' CDR of the request sorted; the reply topic carries
    exactly one REPLY frame per request with the request's id."""
    tb = await start(dut)
    rng = tb.rng
    size = tb.params["block_size"]
    work = [[[rng.randrange(1 << 32) for _ in range(rng.choice([0, 1, 2, 7, size]))]
             for _ in range(6)] for _ in range(tb.clients)]
    await Combine(*(cocotb.start_soon(run_sort_client(tb, c, work[c]))
                    for c in range(tb.clients)))
    total = sum(map(len, work))
    await tb.wait_for(lambda: len(tb.tap.packets) == total, 60 * size * total, "all replies")
    await tb.cycles(50)
    for c in range(tb.clients):
        check_sort_client(tb, c, work[c])
    seen = {(c, s): body for _, c, s, _, body in tb.tap_frames()}
    assert len(seen) == total
    for c in range(tb.clients):
        for k, values in enumerate(work[c]):
            assert seen[(c + 1, k)] == tb.sort_reply(sorted(values))
    assert all(f[0] == KIND["REPLY"] and f[3] == REPLY_OK for f in tb.tap_frames())
    assert tb.counter("server_served") == total
    assert tb.counter("server_bad_requests") == 0


@cocotb.test()
async def sort_bad_requests(dut):
    """Requests the server cannot read get a BAD_REQUEST reply without body (bad
    encapsulation, a count above the block size, cut inside the values, bytes after the end);
    frames that are not requests (no body, another kind, a short header) are dropped and
    counted; a client's requests between them are served."""
    tb = await start(dut)
    size = tb.params["block_size"]
    good = tb.sort_request([5, 3, 9, 1])
    too_many = tb.sort_request(list(range(size + 1)))
    bad_bodies = [b"\x01\x00\x00\x00" + good[4:],      # big-endian CDR: not supported
                  too_many,
                  good[:-6],                            # cut inside the values
                  good + b"\x00" * 9]                   # goes on past its end
    not_requests = [frame("REQUEST", STRANGER, 50),    # no body
                    frame("GOAL", STRANGER, 51, good)]
    client_work = [[7, 1, 4], list(range(40, 0, -1)), [0xFFFFFFFF, 0]]
    calls = cocotb.start_soon(run_sort_client(tb, 0, client_work))
    for k, body in enumerate(bad_bodies):
        await tb.inject("request", frame("REQUEST", STRANGER, 100 + k, body))
        if k < len(not_requests):
            await tb.inject("request", not_requests[k])
    await tb.inject("request", frame("REQUEST", STRANGER, 60, good), short_header=True)
    await calls
    await tb.wait_for(lambda: len(tb.tap.packets) == len(bad_bodies) + len(client_work),
                      200_000, "replies")
    await tb.cycles(100)
    frames = tb.tap_frames()
    stranger = [f for f in frames if f[1] == STRANGER]
    assert stranger == [(KIND["REPLY"], STRANGER, 100 + k, BAD_REQUEST, b"")
                        for k in range(len(bad_bodies))], stranger
    check_sort_client(tb, 0, client_work)
    assert tb.counter("server_bad_requests") == len(bad_bodies)
    assert tb.counter("server_bad_frames") == len(not_requests) + 1
    assert tb.counter("server_served") == len(client_work)
    assert not tb.infos[1].values and tb.counter("c1_unmatched") == 0


@cocotb.test()
async def sort_unmatched_replies(dut):
    """Replies nobody asked for (a sequence never sent, a second reply to a request, another
    kind, a reply to a client that does not exist) are dropped and counted by the client they
    name; the clients' own calls still get exactly their replies."""
    tb = await start(dut)
    reply = tb.sort_reply([1, 2])
    await tb.inject("reply", frame("REPLY", 1, 0, reply))        # nothing outstanding yet
    await tb.inject("reply", frame("REPLY", 1, 1000, reply))
    await tb.inject("reply", frame("FEEDBACK", 2, 0, reply))
    await tb.inject("reply", frame("REPLY", STRANGER, 0, reply))
    await tb.inject("reply", frame("REPLY", 2, 0, b"", status=BAD_REQUEST))
    await tb.wait_for(lambda: len(tb.tap.packets) == 5, 5000, "the injected frames")
    work = [[[3, 2, 1]], [[9, 8], []]]
    await Combine(*(cocotb.start_soon(run_sort_client(tb, c, work[c])) for c in range(2)))
    await tb.wait_for(lambda: len(tb.tap.packets) == 8, 50_000, "replies")
    # a second reply to client 2's first request, after the real one
    await tb.inject("reply", frame("REPLY", 2, 0, tb.sort_reply([8, 9])))
    await tb.cycles(200)
    check_sort_client(tb, 0, work[0], unmatched=2)
    assert tb.counter("c1_unmatched") == 3
    infos = [(v & 0xFFFFFFFF, v >> 32) for v in tb.infos[1].values]
    assert infos == [(0, REPLY_OK), (1, REPLY_OK)]
    assert [bytes(p.data) for p in tb.sinks[1]["reply"].packets] == \
        [tb.sort_reply([8, 9]), tb.sort_reply([])]


# ---- the Fibonacci action --------------------------------------------------------------------

class GoalClient:
    """One action client end: sends goals one at a time, records what comes back per goal."""

    def __init__(self, tb, client):
        self.tb, self.client = tb, client
        self.goals = []       # (sequence, order, accepted, status, feedbacks, result)

    def responses(self):
        out = []
        for v in self.tb.infos[self.client].values:
            out.append((v >> 48 & 0xFF, v >> 32 & 0xFFFF, v & 0xFFFFFFFF, v >> 56))
        return out

    async def response(self, count):
        await self.tb.wait_for(lambda: len(self.tb.infos[self.client].values) > count,
                               200_000, f"client {self.client}: response {count}")
        return self.responses()[count]

    async def run(self, orders, *, retry_busy=True):
        """Send each goal; a valid goal rejected because the server was busy is sent again."""
        tb, seen, sequence = self.tb, 0, 0
        for order in orders:
            while True:
                await tb.send(self.client, "goal", tb.goal(order))
                kind, client, seq, status = await self.response(seen)
                seen += 1
                assert (kind, client, seq) == (KIND["GOAL_RESPONSE"], self.client + 1,
                                               sequence), (kind, client, seq, sequence)
                sequence += 1
                if status:
                    kind, client, seq, status = await self.response(seen)
                    seen += 1
                    assert (kind, seq) == (KIND["RESULT"], sequence - 1)
                    self.goals.append((seq, order, True, status))
                    break
                self.goals.append((seq, order, False, None))
                if not (retry_busy and 0 <= order <= MAX_ORDER):
                    break
                await tb.cycles(tb.rng.randrange(20, 200))

    async def check(self):
        """Each accepted goal got ``order`` feedbacks F(0..k) and the result F(0..order)."""
        tb = self.tb
        accepted = sum(1 for goal in self.goals if goal[2])
        await tb.wait_for(lambda: len(tb.sinks[self.client]["result"].packets) >= accepted,
                          20_000, f"client {self.client}: result bodies")
        feedback = [bytes(p.data) for p in tb.sinks[self.client]["feedback"].packets]
        results = [bytes(p.data) for p in tb.sinks[self.client]["result"].packets]
        expected_feedback, expected_results = [], []
        for _, order, accepted, status in self.goals:
            if not accepted:
                continue
            assert status == GOAL_STATUS["SUCCEEDED"]
            expected_feedback += [tb.sequence("Feedback", fibonacci(k))
                                  for k in range(1, order + 1)]
            expected_results.append(tb.sequence("Result", fibonacci(order)))
        assert feedback == expected_feedback, f"client {self.client}: feedback"
        assert results == expected_results, f"client {self.client}: results"
        for _, order, accepted, _ in self.goals:
            if not 0 <= order <= MAX_ORDER:
                assert not accepted, f"order {order} accepted"


@cocotb.test()
async def fibonacci_concurrent_goals(dut):
    """Two clients send goals at once: one goal runs at a time, a goal arriving meanwhile is
    rejected (and sent again by the client), invalid orders are rejected; every accepted goal
    gets exactly its feedback and its result, at its own client only."""
    tb = await start(dut)
    clients = [GoalClient(tb, c) for c in range(tb.clients)]
    orders = [[3, 0, 47, 6, 1], [5, -1, 2, 46]]
    await Combine(*(cocotb.start_soon(c.run(o)) for c, o in zip(clients, orders)))
    await tb.cycles(50)
    for c in clients:
        await c.check()
    # a valid goal is only rejected when busy; an invalid one may be rejected either way
    busy = sum(1 for c in clients for _, order, accepted, _ in c.goals
               if not accepted and 0 <= order <= MAX_ORDER)
    invalid = sum(1 for c in clients for _, order, _, _ in c.goals if not 0 <= order <= MAX_ORDER)
    assert busy <= tb.counter("server_busy_rejects") <= busy + invalid
    for c in range(tb.clients):
        assert tb.counter(f"c{c}_unmatched") == 0
    # the tap saw each client's frames and nothing else
    for kind, client, _, _, _ in tb.tap_frames():
        assert client in (1, 2) and kind in (KIND["GOAL_RESPONSE"], KIND["FEEDBACK"],
                                             KIND["RESULT"])


@cocotb.test()
async def fibonacci_cancel(dut):
    """A cancel of the running goal is answered ERROR_NONE and ends the goal with status
    CANCELED and the values computed so far (the last feedback); a cancel of a goal that is not
    running (another client's number, a number never used) is answered
    ERROR_UNKNOWN_GOAL_ID and counted."""
    tb = await start(dut, idle=0.2, backpressure=0.2)
    client = GoalClient(tb, 0)
    await tb.send(0, "goal", tb.goal(40))
    kind, _, seq, status = await client.response(0)
    assert (kind, seq, status) == (KIND["GOAL_RESPONSE"], 0, 1)
    await tb.wait_for(lambda: len(tb.sinks[0]["feedback"].packets) >= 3, 100_000, "feedback")
    await tb.cancels[1].send(0)          # client 2 names goal 0: not its goal
    kind, client_id, seq, status = (await GoalClient(tb, 1).response(0))
    assert (kind, client_id, seq, status) == (KIND["CANCEL_RESPONSE"], 2, 0,
                                              CANCEL_STATUS["ERROR_UNKNOWN_GOAL_ID"])
    await tb.cancels[0].send(0)
    kinds = []
    while len(kinds) < 2:
        kinds.append(await client.response(len(kinds) + 1))
    by_kind = {k: (seq, status) for k, _, seq, status in kinds}
    assert by_kind[KIND["CANCEL_RESPONSE"]] == (0, CANCEL_STATUS["ERROR_NONE"])
    assert by_kind[KIND["RESULT"]] == (0, GOAL_STATUS["CANCELED"])
    await tb.wait_for(lambda: len(tb.sinks[0]["result"].packets) == 1, 10_000, "the result")
    feedback = [bytes(p.data) for p in tb.sinks[0]["feedback"].packets]
    assert feedback == [tb.sequence("Feedback", fibonacci(k)) for k in range(1, len(feedback) + 1)]
    assert len(feedback) < 40
    assert bytes(tb.sinks[0]["result"].packets[0].data) == \
        tb.sequence("Result", fibonacci(len(feedback)))
    await tb.cancels[0].send(77)         # never used
    kind, _, seq, status = await client.response(3)
    assert (kind, seq, status) == (KIND["CANCEL_RESPONSE"], 77,
                                   CANCEL_STATUS["ERROR_UNKNOWN_GOAL_ID"])
    assert tb.counter("server_unknown_cancels") == 2
    # the server serves the next goal normally
    await tb.send(0, "goal", tb.goal(4))
    assert (await client.response(4))[0] == KIND["GOAL_RESPONSE"]
    assert (await client.response(5))[:1] == (KIND["RESULT"],)
    # the client reports a RESULT's header before its body, which the sink may still hold back
    await tb.wait_for(lambda: len(tb.sinks[0]["result"].packets) == 2, 10_000, "the 2nd result")
    assert bytes(tb.sinks[0]["result"].packets[1].data) == tb.sequence("Result", fibonacci(4))


@cocotb.test()
async def fibonacci_bad_input(dut):
    """A goal the server cannot read is rejected; a CANCEL with a body, another kind and a short
    header are dropped and counted; frames on the reply topic that answer nothing a client asked
    (a result, feedback or goal response of no goal of it, a cancel response to no cancel) are
    dropped and counted; a client's goal afterwards runs normally."""
    tb = await start(dut)
    good = tb.goal(3)
    await tb.inject("request", frame("GOAL", STRANGER, 1, b"\x01\x00\x00\x00" + good[4:]))
    await tb.inject("request", frame("GOAL", STRANGER, 2, good[:6]))
    await tb.inject("request", frame("CANCEL", STRANGER, 3, good))
    await tb.inject("request", frame("REQUEST", STRANGER, 4, good))
    await tb.inject("request", frame("GOAL", STRANGER, 5, good), short_header=True)
    result = tb.sequence("Result", [0, 1])
    await tb.inject("reply", frame("RESULT", 1, 0, result, status=4))
    await tb.inject("reply", frame("FEEDBACK", 1, 0, result))
    await tb.inject("reply", frame("GOAL_RESPONSE", 1, 0, status=1))
    await tb.inject("reply", frame("CANCEL_RESPONSE", 1, 0))
    await tb.wait_for(lambda: len(tb.tap.packets) >= 6, 50_000, "the rejections")
    await tb.cycles(50)
    frames = tb.tap_frames()
    # goal 2 may be rejected as busy while goal 1 is being read
    rejected = sorted(f for f in frames if f[1] == STRANGER)
    assert rejected == [(KIND["GOAL_RESPONSE"], STRANGER, 1, 0, b""),
                        (KIND["GOAL_RESPONSE"], STRANGER, 2, 0, b"")], rejected
    assert tb.counter("server_bad_frames") == 3
    assert tb.counter("c0_unmatched") == 4
    client = GoalClient(tb, 0)
    await client.run([3])
    await tb.cycles(20)
    await client.check()
    assert tb.counter("c0_unmatched") == 4
