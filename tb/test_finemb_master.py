"""The Python FinEmbP master (host/finemb/master.py) over the kernel's UDP sockets against a
simulated line of two PID nodes on a TAP device in a namespace the test creates
(host/tapsim.py, the facility ``rosgate tap`` runs): initialisation, cycles checked against
the AVR221 model of each node, a master restart, and nodes that fall out (they forget their
address) initialised again by the master on its own. Bounded: at most 60 cycles, every wait
with a time-out."""

import random

import pytest

from gen.finemb import load_io_description
from hdl.finemb import line_mac
from hdl.finemb.protocol import NodeState
from host.finemb import FinembMaster
from host.finemb.run import line_simulation
from host.tap import KERNEL_IP, TAP_NAME, namespace_unavailable

from .finemb_tb import PID_IO
from .harness import SIM_BUILD
from .models.pid import AvrPid

NODES = 2


@pytest.fixture(scope="module")
def line():
    why = namespace_unavailable()
    if why:
        pytest.skip(f"the TAP facility needs: {why}")
    io = load_io_description(PID_IO)
    with line_simulation(io, NODES, SIM_BUILD / f"tap-finemb-n{NODES}") as sim:
        with FinembMaster(KERNEL_IP, interface=TAP_NAME, timeout_s=5.0) as master:
            yield sim, master, io


def run_checked(master, rng, models, cycles):
    """``cycles`` cycles with random set points and measurements; every answer equal to its
    node's AVR221 model."""
    import time
    for _ in range(cycles):
        outputs = {}
        for k in master.nodes:
            outputs[k] = dict(set_point=rng.randrange(-2000, 2000),
                              measurement=rng.randrange(-2000, 2000), p_gain=200, i_gain=20,
                              d_gain=10)
        # the simulated line answers within tens of milliseconds; a silent node costs the
        # whole second
        got = master.cycle(outputs, time.monotonic() + 1.0)
        for k, inputs in got.items():
            model = models.setdefault(master.nodes[k].mac, AvrPid(200, 20, 10))
            expected = model.update(outputs[k]["set_point"], outputs[k]["measurement"])
            assert inputs["output"] == expected, (master.cycle_no, k, inputs, expected)
        yield got


def test_master_initialises_the_line_and_runs_cycles(line):
    sim, master, io = line
    nodes = master.init(expected=NODES)
    assert sorted(nodes) == [1, 2]
    assert [n.mac_text for _, n in sorted(nodes.items())] == [line_mac(k) for k in range(NODES)]
    assert all(n.descriptor == io and n.serial == k for k, n in nodes.items())
    assert [n.ip for _, n in sorted(nodes.items())] == ["198.18.0.17", "198.18.0.18"]
    models = {}
    rng = random.Random(5)
    for got in run_checked(master, rng, models, 20):
        assert sorted(got) == [1, 2]
    assert all(n.state == NodeState.OP and n.late == 0 for n in master.nodes.values())
    assert master.cycle_rate_hz() > 0
    status = sim.status
    assert status["cycles"] > 0 and all(status["signals"][f"state{k}"] == NodeState.OP
                                        for k in range(NODES))

    # a master restart: nodes forget their addresses, the master finds them again
    master.restart()
    master.init(expected=NODES)
    assert master.cycle_no == 0
    for got in run_checked(master, rng, models, 5):
        assert sorted(got) == [1, 2]

    # nodes that fall out: they forget their address while the master keeps them; after
    # three silent cycles each is initialised again by the master on its own
    master.restart(forget=False)
    silent = 0
    for got in run_checked(master, rng, models, 15):
        silent += len(got) == 0
    assert 3 <= silent <= 6, silent
    assert all(n.reinits >= 1 for n in master.nodes.values())
    for got in run_checked(master, rng, models, 5):
        assert sorted(got) == [1, 2]
    assert all(n.state == NodeState.OP for n in master.nodes.values())
