"""The FinEmbP master against a simulated line of PID nodes on a TAP device: what
``rosgate tap finemb`` and the FinEmbP benchmark run."""

import time

from hdl.finemb import FinembLine

from ..tap import KERNEL_IP, TAP_NAME
from ..tapsim import TapSimulation
from .master import FinembMaster

__all__ = ["PlantModel", "line_simulation", "run_line_with_master"]


class PlantModel:
    """A first-order plant per node for the PID benchmark: the measurement moves an eighth of
    the way to the controller's output each cycle; the set point steps between +-``step``
    every ``hold`` cycles."""

    def __init__(self, step=1000, hold=200, gains=(256, 64, 32)):
        self.step, self.hold = step, hold
        self.gains = dict(zip(("p_gain", "i_gain", "d_gain"), gains))
        self.measurement = {}

    def outputs(self, cycle, node_ids):
        set_point = self.step if (cycle // self.hold) % 2 == 0 else -self.step
        return {k: dict(set_point=set_point, measurement=self.measurement.get(k, 0),
                        **self.gains) for k in node_ids}

    def update(self, inputs):
        for k, values in inputs.items():
            pv = self.measurement.get(k, 0)
            self.measurement[k] = max(-32768, min(32767, pv + (values["output"] - pv) // 8))


def line_simulation(descriptor, nodes, build_dir, *, kernel_ip=KERNEL_IP, progress=None):
    """A :class:`~host.tapsim.TapSimulation` of a line of ``nodes`` PID nodes (node 0's
    port 0 on the TAP device)."""
    line = FinembLine(descriptor, nodes)
    watch = [f"state{k}" for k in range(nodes)]
    return TapSimulation(line, "finemb_line", build_dir, port="port0", kernel_ip=kernel_ip,
                         watch=watch, progress=progress)


def run_line_with_master(descriptor, nodes, *, cycles, build_dir, period_s=0.0,
                         answer_timeout_s=5.0, outputs=None, on_cycle=None, progress=None):
    """Simulate a line, initialise it with a :class:`FinembMaster` through the kernel and run
    ``cycles`` cycles (``period_s`` apart at the least); ``outputs(cycle, node_ids)`` gives
    each node's output page (default: a :class:`PlantModel`), ``on_cycle(master, inputs)``
    is called after each. Returns the statistics, ``simulation`` being the simulator's last
    status (:attr:`~host.tapsim.TapSimulation.status`)."""
    plant = PlantModel()
    outputs = outputs or plant.outputs
    with line_simulation(descriptor, nodes, build_dir, progress=progress) as simulation, \
            FinembMaster(KERNEL_IP, interface=TAP_NAME, timeout_s=answer_timeout_s) as master:
        master.init(expected=nodes)
        for _ in range(cycles):
            start = time.monotonic()
            inputs = master.cycle(outputs(master.cycle_no, sorted(master.nodes)),
                                  start + answer_timeout_s)
            plant.update(inputs)
            if on_cycle is not None:
                on_cycle(master, inputs)
            time.sleep(max(0.0, start + period_s - time.monotonic()))
        return {"cycles": master.cycles_run, "cycle_rate_hz": master.cycle_rate_hz(),
                "late": sum(n.late for n in master.nodes.values()),
                "states": {k: n.state.name for k, n in master.nodes.items()},
                "answered": {k: n.answered for k, n in master.nodes.items()},
                "simulation": simulation.status}
