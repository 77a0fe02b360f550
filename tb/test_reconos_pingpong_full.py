"""The paper's ping-pong experiments at full size (``make test-full``): the echo and copy
nodes answer 1 MiB, 6 MiB and 10 MiB Images byte-exactly (P-RR Tables 3 and 4)."""

import cocotb
import pytest

from .harness import cocotb_bench
from .reconos_pingpong_tb import PingPongTB, run_round_trips
from .reconos_tb import system_configs

MIB = 1 << 20


class BigPingPongTB(PingPongTB):
    def __init__(self, dut):
        # 10 MiB in, 10 MiB copied out, plus the smaller rounds: 128 MiB of process memory
        super().__init__(dut, ram_size=1 << 27)


@cocotb.test()
async def echo_and_copy_1_6_10_mib(dut):
    tb = BigPingPongTB(dut)
    rt = await tb.setup()
    sizes = [1 * MIB, 6 * MIB, 10 * MIB]
    echo = await run_round_trips(tb, "/ping", tb.pong, sizes, 41)
    copy = await run_round_trips(tb, "/ping_copy", tb.pong_copy, sizes, 42, payload_only=True)
    dut._log.warning("round-trip cycles: echo %s, copy %s", echo, copy)
    assert not rt.errors, rt.errors


test_reconos_pingpong_full = cocotb_bench(
    "reconos", {k: pytest.param(v, marks=pytest.mark.full) for k, v in system_configs().items()},
    simulators=("verilator",))
