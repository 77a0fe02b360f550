"""The ROS gateway and the hardware-topic nodes (``hdl.reconos.TopicGatewayThread``) in the
gateway demo's system, through ``rosgate sim``.

* The demo itself (examples/hwtopic_gateway): random images of random encodings, sizes, frame
  ids and stamps published on /inputtopic reach /outputtopic (Threadb -> hardware topic ->
  Threada) and /topic/gateway (through the gateway) unchanged and in order; images published
  on /topic/gateway reach /outputtopic through the gateway; the gateway ignores its own
  publications in software and in hardware (no message more than sent).
* Bad input on the hardware topic: Threadb is left external and this test publishes on the
  hardware topic itself, under random idle, frames written from the spec's framing model
  (tb/models/msgstream.reconros_beats) with bad ones between them (a count above the
  receivers' limit, a message cut short, a message that goes on past its end), each bad one
  followed at once by a small good one, which the deserializer reads to its fields while the
  receivers still complete the bad one: only the good ones appear on /outputtopic and
  /topic/gateway, unchanged and in order; nothing hangs.
"""

import json
import random
import shutil

import pytest

from host.project_sim import run_project_sim

from .harness import ROOT

GATEWAY_DEMO = ROOT / "examples" / "hwtopic_gateway"

INJECTOR = '''
import random

import cocotb
from cocotb.triggers import ClockCycles
from cocotbext.axi import AxiStreamBus, AxiStreamFrame, AxiStreamSource

from gen.config import project_library
from tb.models.msgstream import reconros_beats
from tb.streams import random_pauses

from host.reconos.messages import random_image_message


def frame(beats):
    data = b"".join(d.to_bytes(8, "little") for d, _, _ in beats)
    return AxiStreamFrame(data, tuser=[u for _, u, _ in beats])


async def injector(ctx):
    dut = ctx.cosim.dut
    rng = random.Random(int(ctx.args["seed"]))
    source = AxiStreamSource(AxiStreamBus.from_prefix(dut, "slot1_nicehwtopic"), dut.aclk,
                             dut.aresetn, reset_active_level=False)
    source.set_pause_generator(random_pauses(random.Random(rng.random()), 0.3))
    library = project_library(ctx.project)
    outputs = ctx.broker.subscribe("/outputtopic")
    gateway = ctx.broker.subscribe("/topic/gateway")
    sent, kinds = [], []
    follows_bad = False
    for k in range(int(ctx.args["messages"])):
        kind = rng.choice(["good", "good", "too_many", "cut", "long"])
        if "kinds" in ctx.args:
            kind = ctx.args["kinds"].split(",")[k]
        # the message after a bad one is small, and so is a bad one half of the time: the
        # good one is then read to its fields while the receivers still complete the bad one
        small = follows_bad or (kind != "good" and rng.randrange(2))
        value = random_image_message(rng, 2 if small else 12)
        beats = reconros_beats(library, "sensor_msgs/msg/Image", value, 77)
        if kind == "too_many":
            # the data array's count (the last array: the 8-bit arrays are encoding, data,
            # frame_id) is set above the gateway's max_count
            at = len(beats) - 1
            counts = [i for i, (d, _, _) in enumerate(beats[:-1]) if i > 7]
            beats = [(d, u, l) for d, u, l in beats]
            size_at = next(i for i in counts if beats[i][0] == len(value["data"]) and
                           beats[i + 1][0] == len(value["data"]))
            beats[size_at] = ((1 << 21), 1, 0)
            beats[size_at + 1] = ((1 << 21), 1, 0)
        elif kind == "cut":
            beats = beats[:rng.randrange(3, len(beats) - 1)]
            beats[-1] = (beats[-1][0], 0, 1)
        elif kind == "long":
            beats = beats[:-1] + [(beats[-2][0], 1, 0), (rng.randrange(1 << 64), 1, 0),
                                  (beats[-1][0], 0, 1)]
        kinds.append(kind)
        if kind == "good":
            sent.append(value)
        await source.send(frame(beats))
        follows_bad = kind != "good"
        await ClockCycles(dut.aclk, 0 if follows_bad else rng.randrange(0, 300))
    await source.wait()
    await ctx.cycles(30_000)
    got_out = [outputs.get_nowait() for _ in range(len(outputs))]
    got_gw = [gateway.get_nowait() for _ in range(len(gateway))]
    def stamps(values):
        return [v["header"]["stamp"]["nanosec"] for v in values]
    ctx.results.update(kinds=kinds, sent=len(sent), outputs_equal=got_out == sent,
                       gateway_equal=got_gw == sent, outputs=len(got_out),
                       gateway=len(got_gw), sent_stamps=stamps(sent),
                       output_stamps=stamps(got_out), gateway_stamps=stamps(got_gw))


NODES = [injector]
'''


def external_threadb_project(folder):
    """The demo in ``folder`` without Threadb's source (its hardware-topic port becomes a
    port of the system top) and with the injector as its sim.py."""
    shutil.copytree(GATEWAY_DEMO, folder)
    shutil.rmtree(folder / "src" / "rt_threadb")
    (folder / "sim.py").write_text(INJECTOR)
    return folder / "build.cfg"


@pytest.mark.parametrize("sim", ["icarus", pytest.param("verilator", marks=pytest.mark.full)])
def test_gateway_demo(sim, tmp_path):
    rng = random.Random()
    seed = rng.randrange(1 << 30)
    results = run_project_sim(GATEWAY_DEMO / "build.cfg", sim, out=tmp_path / "out",
                              args={"images": "4", "max_side": "24", "seed": str(seed)},
                              limit_ms=20)
    assert results["all_equal"] and len(results["sent"]) == 8, (seed, results)
    assert results["extra_outputs"] == 0, (seed, results)


@pytest.mark.parametrize("sim", ["icarus", pytest.param("verilator", marks=pytest.mark.full)])
def test_gateway_drops_bad_hardware_messages(sim, tmp_path):
    seed = random.Random().randrange(1 << 30)
    rng = random.Random(seed)
    # each kind of bad message twice, each followed by a good one, in random order
    pairs = [[bad, "good"] for bad in ("too_many", "cut", "long") * 2]
    rng.shuffle(pairs)
    kinds = [kind for pair in pairs for kind in pair] + ["good", "good"]
    project = external_threadb_project(tmp_path / "project")
    results = run_project_sim(project, sim, out=tmp_path / "out",
                              args={"messages": str(len(kinds)), "kinds": ",".join(kinds),
                                    "seed": str(seed)}, limit_ms=3)
    detail = json.dumps({"seed": seed, **results})
    assert results["outputs_equal"] and results["gateway_equal"], detail
    assert results["sent"] == results["outputs"] == results["gateway"], detail
