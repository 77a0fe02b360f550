"""The compiled AXI4 memory (``host.compiled``) against cocotbext-axi's ``AxiRam``: the same
random traffic (``axi_traffic_master.sv``: INCR, FIXED and WRAP bursts, narrow beats, random
strobes, W ahead of AW, addresses past the memory, random idle on every valid and random
backpressure on every ready) takes the same cycles, sees every handshake in the same cycle
with the same payload (the master's signature), gets the same SLVERR answers and leaves the
same bytes, seed for seed. Reads and writes go to different pages: the order of a read and a
write of one word at the same edge is left open by AXI (and found to differ). One Verilator build of each runs every seed; the cocotb test below
runs only when the pytest test of this module starts it."""

import hashlib
import json
import random
from pathlib import Path

import cocotb
import pytest
from cocotb.triggers import ClockCycles, RisingEdge, with_timeout

from host.compiled import CompiledAxiRam, attach_memory, memory_harness
from host.simulator import QUICK_CXX_OPT, run_top, start_clock, top_params

from .harness import ROOT, SIM_BUILD, amount

MASTER = ROOT / "tb" / "axi_traffic_master.sv"
#: bytes of memory; the master's bursts past it (at 1 MiB and above) get SLVERR
SIZE = 1 << 20
#: the bytes the traffic touches: eight 4 KiB pages from 0
WINDOW = 8 * 4096


class TrafficTB:
    """One memory model behind the traffic master."""

    def __init__(self, dut, size):
        self.dut = dut
        start_clock(dut.aclk, 10)
        self.ram = attach_memory(dut, size)

    async def run_seed(self, seed, bursts):
        """Fill the window from ``seed``, run ``bursts`` write and read bursts; return what
        the two models must agree on."""
        self.ram.write(0, random.Random(seed).randbytes(WINDOW))
        self.dut.seed.value = seed
        self.dut.bursts.value = bursts
        self.dut.aresetn.value = 0
        await ClockCycles(self.dut.aclk, 3)
        self.dut.aresetn.value = 1
        await with_timeout(RisingEdge(self.dut.done), 200 * bursts * 16 * 10, "ns")
        await ClockCycles(self.dut.aclk, 1)
        return {"cycles": int(self.dut.cycles.value),
                "signature": f"{int(self.dut.signature.value):016x}",
                "errors": int(self.dut.errors.value),
                "memory": hashlib.sha256(self.ram.read(0, WINDOW)).hexdigest()}


@cocotb.test()
async def run_traffic(dut):
    """Every seed of the parameters through the memory this build has."""
    p = top_params()
    tb = TrafficTB(dut, p["size"])
    results = {"compiled": isinstance(tb.ram, CompiledAxiRam), "seeds": {}}
    for seed in p["seeds"]:
        results["seeds"][str(seed)] = await tb.run_seed(seed, p["bursts"])
    Path(p["out"]).write_text(json.dumps(results))


def _run(kind, seeds, bursts, tmp_path):
    out = tmp_path / f"{kind}.json"
    run_top(__name__, MASTER.stem, None, "verilator", SIM_BUILD / f"compiled_axi_ram-{kind}",
            params={"seeds": seeds, "bursts": bursts, "size": SIZE, "out": str(out)},
            extra_env={"PYTHONPATH": str(ROOT)}, lint=False, cxx_opt=QUICK_CXX_OPT,
            exported=MASTER, harness=memory_harness() if kind == "compiled" else None)
    return json.loads(out.read_text())


def test_compiled_memory_takes_axiram_cycles(tmp_path):
    """Seed for seed, the compiled memory and AxiRam agree on every handshake's cycle and
    payload, the SLVERR answers and the memory left behind."""
    seeds = [random.randrange(1 << 32) for _ in range(amount(6, 40))]
    bursts = amount(150, 600)
    python, compiled = (_run(kind, seeds, bursts, tmp_path) for kind in ("axiram", "compiled"))
    assert not python["compiled"] and compiled["compiled"]
    for seed in map(str, seeds):
        assert compiled["seeds"][seed] == python["seeds"][seed], f"seed {seed}"
        assert python["seeds"][seed]["errors"] > 0, f"seed {seed}: no burst past the memory"


def test_compiled_memory_refuses_bad_sizes():
    """A size that is not a positive multiple of 4 KiB is refused by value, before the
    simulator is asked for memory."""
    for size in (0, -4096, 1000, 4096.0):
        with pytest.raises(ValueError, match=repr(size)):
            CompiledAxiRam(size)
