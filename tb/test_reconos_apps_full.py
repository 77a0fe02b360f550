"""Long runs of the ReconROS demo nodes (``make test-full``): the Sobel service pair on the
paper's 640x480 ``bgr8`` frame (docs/reconos.md), a real photograph, bit-exact."""

import cocotb
import pytest

from .harness import cocotb_bench
from .reconos_apps_tb import run_sobel_pair
from .reconos_tb import apps_configs


@cocotb.test()
async def sobel_service_pair_640x480(dut):
    cycles = await run_sobel_pair(dut, "coffee_640x480.png")
    dut._log.warning("640x480 bgr8 round trip (DIP copy in, Sobel service, copy back, "
                     "publish): %d cycles = %.2f ms at 100 MHz", cycles, cycles / 1e5)


test_reconos_apps_full = cocotb_bench(
    "reconos", {k: pytest.param(v, marks=pytest.mark.full) for k, v in apps_configs().items()},
    simulators=("verilator",))
