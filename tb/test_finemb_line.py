"""Bench of a line of FinEmbP nodes (docs/finemb.md) with the cycle-accurate master of
tb/finemb_tb.py on the master link and a lossy cable on every link (tb/finemb_line_top.py):
initialisation of the whole line, cycles sequential and pipelined checked against the AVR221
model of every node, a node joining while the others stay in OP without missing a cycle,
frames lost at 1 % and 10 % on every link (nodes go late and recover; every missing answer is
explained by a spoiled frame), and a master that restarts mid-operation."""

import os
import random

import cocotb
import pytest

from hdl.finemb.protocol import NODE_ALL, MsgType, NodeState, ReinitReason
from host.simulator import clock_cycles
from tb.harness import SIMULATORS, run_bench
from tb.models.finemb import body_of

from .finemb_line_top import build_finemb_line_bench_top, loss_threshold
from .finemb_tb import PID_IO, LineMaster

NODES = int(os.environ.get("ROSGATE_FINEMB_NODES", "2"))
#: a period with room for the iso phase of every node and one asynchronous exchange
SLOW_PERIOD = 1000 + 600 * NODES
#: how long a cycle waits for answers (some may be lost) before the next one starts
DEADLINE = 800 + 400 * NODES


def states(dut, n=NODES):
    return [NodeState(int(getattr(dut, f"state{k}").value)) for k in range(n)]


async def started(dut, serials=None):
    master = LineMaster(dut, NODES)
    await master.reset()
    found = await master.init(serials)
    assert sorted(found) == list(range(1, NODES + 1)), found
    return master


@cocotb.test()
async def whole_line_cycles_sequential_and_pipelined(dut):
    """Every node found (by serial), addressed and its IO descriptor read; 15 cycles polled
    one node after the other and 15 pipelined, every answer the AVR221 model's output for its
    node, none late, every node in OP."""
    master = await started(dut)
    assert states(dut) == [NodeState.PREOP] * NODES
    rng = random.Random(cocotb.RANDOM_SEED)
    for polling in ("sequential", "pipelined"):
        for _ in range(15):
            _, _, got = await master.cycle(rng, polling=polling,
                                           deadline=master.now() + DEADLINE)
            assert len(got) == NODES, (polling, master.cycle_no, sorted(got))
    assert states(dut) == [NodeState.OP] * NODES
    assert all(v == 0 for v in master.late.values()), master.late


@cocotb.test()
async def hot_join_while_the_others_cycle(dut):
    """The last node is left out at first; while the others run fixed-period cycles, its
    ID exchange goes in one cycle's asynchronous phase, its address and IO descriptor in the
    next; the
    others never miss a cycle, and the newcomer answers from the cycle after it was taken in."""
    master = await started(dut, serials=set(range(1, NODES)))
    rng = random.Random(cocotb.RANDOM_SEED)
    newcomer = NODES
    steps = ["id", "addr", "iodesc"]
    mac = None
    for _ in range(7):
        start, _, got = await master.cycle(rng, polling="pipelined",
                                           deadline=master.now() + SLOW_PERIOD // 2)
        assert set(got) == set(master.nodes), (master.cycle_no, sorted(got))
        if steps:
            step = steps.pop(0)
            window = start + SLOW_PERIOD - 50
            if step == "id":
                master.send(master.request(MsgType.ID_REQ, NODE_ALL,
                                           body_of(MsgType.ID_REQ, 1),
                                           dst_mac="ff:ff:ff:ff:ff:ff", dst_ip="255.255.255.255"))
                answers = await master.answers(window, lambda m: m["type"] == MsgType.ID_RES)
                # (waits out the window: a second node without address would answer too)
                assert len(answers) == 1, "only the node without address answers ID_REQ"
                mac = answers[0][1]["body"][:6]
            elif step == "addr":
                await master.join(newcomer, mac)       # the address, then the descriptor
                steps.pop(0)
            assert master.now() < start + SLOW_PERIOD, "the join overran the cycle"
        await clock_cycles(dut.gmii_clk, max(0, start + SLOW_PERIOD - master.now()))
    assert newcomer in master.nodes and master.answered[newcomer] >= 4
    assert states(dut) == [NodeState.OP] * NODES
    assert all(v == 0 for v in master.late.values()), master.late


async def lossy_cycles(dut, fraction, cycles):
    master = await started(dut)
    rng = random.Random(cocotb.RANDOM_SEED)
    dut.loss_threshold.value = loss_threshold(fraction)
    for _ in range(cycles):
        await master.cycle(rng, polling="pipelined", deadline=master.now() + DEADLINE,
                           check=False)
    lost = int(dut.lost.value)
    missing = sum(master.late.values())
    dut._log.info("loss %.0f %%: %d frames spoiled, %d answers missing of %d", fraction * 100,
                  lost, missing, cycles * NODES)
    # a spoiled frame costs at most one answer (its ISEND_REQ or its ISEND_RES); forwarding
    # of every other frame goes on
    assert missing <= lost, (missing, lost)
    dut.loss_threshold.value = 0
    late_before = dict(master.late)
    for _ in range(5):
        await master.cycle(rng, polling="pipelined", deadline=master.now() + DEADLINE,
                           check=False)
    assert master.late == late_before, "a node did not recover once the links were clean"
    assert states(dut) == [NodeState.OP] * NODES
    return lost, missing


@cocotb.test()
async def one_percent_loss_on_every_link(dut):
    """1 % of frames spoiled on every link for 100 cycles."""
    await lossy_cycles(dut, 0.01, 100)


@cocotb.test()
async def ten_percent_loss_on_every_link(dut):
    """10 % of frames spoiled on every link for 30 cycles: answers go missing (never more
    than frames spoiled), and every node is back in OP and answering afterwards."""
    lost, missing = await lossy_cycles(dut, 0.10, 30)
    assert lost > 0 and missing > 0, (lost, missing)


@cocotb.test()
async def master_restart_mid_operation(dut):
    """A master that restarts: REINIT to all (master restart), every node back to INIT with
    no address, found and initialised again, cycles from cycle number 0 again."""
    master = await started(dut)
    rng = random.Random(cocotb.RANDOM_SEED)
    for _ in range(5):
        _, _, got = await master.cycle(rng, polling="pipelined",
                                       deadline=master.now() + DEADLINE)
        assert len(got) == NODES
    master.send(master.request(MsgType.REINIT, NODE_ALL,
                               body_of(MsgType.REINIT, ReinitReason.MASTER_RESTART)))
    await clock_cycles(dut.gmii_clk, 2000)
    assert states(dut) == [NodeState.INIT] * NODES
    master.nodes.clear()
    master.cycle_no = 0
    found = await master.init()
    assert len(found) == NODES
    for _ in range(5):
        _, _, got = await master.cycle(rng, polling="sequential",
                                       deadline=master.now() + DEADLINE)
        assert len(got) == NODES
        assert {m["cycle"] for m in got.values()} == {master.cycle_no - 1}
    assert states(dut) == [NodeState.OP] * NODES


#: what each simulator runs in ``make test`` (a line is slow in Icarus); ``make test-full``
#: runs every test on both
QUICK = {"icarus": ["whole_line_cycles_sequential_and_pipelined"],
         "verilator": ["hot_join_while_the_others_cycle", "ten_percent_loss_on_every_link",
                       "master_restart_mid_operation"]}


@pytest.mark.parametrize("sim", SIMULATORS)
def test_finemb_line(sim):
    params = {"io": PID_IO, "nodes": NODES}
    run_bench(__name__, "finemb_line", f"n{NODES}", params, sim,
              build=build_finemb_line_bench_top, testcase=QUICK[sim])


@pytest.mark.full
@pytest.mark.parametrize("sim", SIMULATORS)
def test_finemb_line_all(sim):
    run_bench(__name__, "finemb_line", f"n{NODES}", {"io": PID_IO, "nodes": NODES}, sim,
              build=build_finemb_line_bench_top, run_name="all")
