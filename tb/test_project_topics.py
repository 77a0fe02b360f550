"""The hardware topic of ReconROS' gateway demo as rosgate assembles it (docs/topics.md):
``nicehwtopic`` with publishers Threadb (slot 1) and Gateway1 (slot 2, ``_out``) and
subscribers Threada (slot 0, 64-beat FIFO) and Gateway1 (``_in``): N:M. The bench uses the
demo's build.cfg without its thread sources and with the gateway as a thread of the same
endpoints, so that no slot has an Amaranth thread and the topic ports are ports of the system
top; it drives them with random idle and back-pressure and checks that both subscribers get
every message of both publishers whole, each publisher's messages in order, nothing lost,
duplicated or corrupted. (The demo with its threads runs in tb/test_project_sim.py.)"""

import random

import cocotb
import pytest
from cocotb.triggers import ClockCycles, Combine, with_timeout
from cocotbext.axi import AxiStreamBus, AxiStreamFrame, AxiStreamSink, AxiStreamSource

from host.simulator import start_clock
from .harness import bench_params, run_bench
from .projects import external_threads_project
from .streams import random_pauses, reset_aresetn

PUBS = {"Threadb": "slot1_nicehwtopic", "Gateway1": "slot2_nicehwtopic_out"}
SUBS = {"Threada": "slot0_nicehwtopic", "Gateway1": "slot2_nicehwtopic_in"}


class TopicPortsTB:
    def __init__(self, dut, seed):
        self.dut = dut
        self.rng = random.Random(seed)
        start_clock(dut.aclk, 10)
        for name in bench_params()["idle_inputs"]:
            getattr(dut, name).value = 0
        self.sources = {k: AxiStreamSource(AxiStreamBus.from_prefix(dut, p), dut.aclk,
                                           dut.aresetn, reset_active_level=False)
                        for k, p in PUBS.items()}
        self.sinks = {k: AxiStreamSink(AxiStreamBus.from_prefix(dut, p), dut.aclk, dut.aresetn,
                                       reset_active_level=False)
                      for k, p in SUBS.items()}

    def set_idle_generator(self, p):
        for s in self.sources.values():
            s.set_pause_generator(random_pauses(random.Random(self.rng.random()), p))

    def set_backpressure_generator(self, p):
        for s in self.sinks.values():
            s.set_pause_generator(random_pauses(random.Random(self.rng.random()), p))

    async def reset(self):
        await reset_aresetn(self.dut)


def message(pub, seq, rng):
    """Beats of message ``seq`` of ``pub`` (ReconROS style: beat 0 = publisher id + 1000),
    1..40 beats, the rest random."""
    n = rng.randrange(1, 41)
    beats = [1000 + pub, seq] + [rng.randrange(1 << 64) for _ in range(n)]
    return b"".join(b.to_bytes(8, "little") for b in beats)


async def run_traffic(tb, count, idle, backpressure):
    tb.set_idle_generator(idle)
    tb.set_backpressure_generator(backpressure)
    sent = {}
    for pub, (name, src) in enumerate(tb.sources.items()):
        sent[name] = [message(pub, i, tb.rng) for i in range(count)]

    async def publish(name):
        for data in sent[name]:
            await tb.sources[name].send(AxiStreamFrame(data, tuser=1))

    async def receive(sub):
        got = []
        for _ in range(2 * count):
            frame = await tb.sinks[sub].recv()
            got.append(bytes(frame.tdata))
        return got

    pubs = [cocotb.start_soon(publish(n)) for n in sent]
    subs = {s: cocotb.start_soon(receive(s)) for s in tb.sinks}
    await with_timeout(Combine(*pubs, *subs.values()), 2000 * count, "ns")
    for sub, task in subs.items():
        got = task.result()
        for pub, (name, msgs) in enumerate(sent.items()):
            mine = [m for m in got if int.from_bytes(m[:8], "little") == 1000 + pub]
            assert mine == msgs, f"{sub} got {name}'s messages wrong (lost, reordered, cut)"
        assert len(got) == 2 * count, f"{sub}: {len(got)} messages"
    await ClockCycles(tb.dut.aclk, 50)
    for sub, sink in tb.sinks.items():
        assert sink.empty(), f"{sub} received an extra message"


@cocotb.test()
async def topic_under_idle_and_backpressure(dut):
    tb = TopicPortsTB(dut, seed=bench_params()["seed"])
    await tb.reset()
    for idle, bp in ((0.0, 0.0), (0.3, 0.0), (0.0, 0.5), (0.4, 0.4)):
        await run_traffic(tb, 12, idle, bp)


@pytest.mark.parametrize("sim", ["icarus", pytest.param("verilator", marks=pytest.mark.full)])
def test_project_topic(sim, tmp_path):
    from gen.config import load_project
    from gen.system import build_system
    from host.project_sim import top_ports
    system = build_system(load_project(external_threads_project(tmp_path)))
    idle = [n for n, flow in top_ports(system).items()
            if flow == "in" and n.startswith("slot") and "nicehwtopic" not in n]
    run_bench(__name__, "rosgate_system", "hwtopic_gateway", {"idle_inputs": idle, "seed": 5},
              sim, build=lambda **_: system)
