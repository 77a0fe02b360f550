"""The TCPROS endpoints' RBCP register map (docs/network.md, hdl/ros1/registers.py) on the
``ros1_node`` top, through RBCP frames on GMII, on both simulators: identification, roles,
defaults, read/write registers, the expected-value and header memories, write-1-to-clear,
counters, and a bus error for an address outside every endpoint."""

import random

import cocotb

from hdl.ros1.registers import (
    CHECK_DEFAULT,
    COUNTERS,
    COUNTERS_OFFSET,
    ENDPOINT_ID,
    ENDPOINT_STRIDE,
    EXPECTED,
    HDR_ERR,
    HDR_RX,
    HDR_TX,
    PHASES,
    REG,
)
from host.ros1.rbcp import rbcp_request
from tb.harness import cocotb_bench
from tb.net_tb import NODE_CONFIG, NetTB, rbcp

CONFIGS = {"loopback": NODE_CONFIG}
test_ros1_registers = cocotb_bench("ros1_node", CONFIGS, long=[("loopback", "verilator")])


class RegisterTB(NetTB):
    def __init__(self, dut):
        super().__init__(dut)
        self.ident = 0

    async def read(self, address, length):
        self.ident = (self.ident + 1) & 0xFF
        reply = await rbcp(self, rbcp_request(0xC0, self.ident, address, length))
        assert reply is not None and reply[1] == 0xC8, (hex(address), reply)
        return reply[8:]

    async def write(self, address, data):
        self.ident = (self.ident + 1) & 0xFF
        reply = await rbcp(self, rbcp_request(0x80, self.ident, address, len(data), data))
        assert reply is not None and reply[1] == 0x88, (hex(address), reply)

    async def reg(self, k, name):
        offset, size, _ = REG[name]
        return int.from_bytes(await self.read(k * ENDPOINT_STRIDE + offset, size), "big")

    async def set_reg(self, k, name, value):
        offset, size, _ = REG[name]
        await self.write(k * ENDPOINT_STRIDE + offset, value.to_bytes(size, "big"))


@cocotb.test()
async def run_register_map(dut):
    tb = RegisterTB(dut)
    await tb.reset()
    rng = random.Random(5)
    roles = NODE_CONFIG["endpoints"]
    for k, role in enumerate(roles):
        base = k * ENDPOINT_STRIDE
        assert await tb.read(base + REG["ID"][0], 4) == ENDPOINT_ID + bytes([len(roles)])
        assert await tb.reg(k, "MODE") == (0 if role == "publisher" else 1)
        assert await tb.reg(k, "CHECK") == CHECK_DEFAULT
        assert await tb.reg(k, "MAX_MSG") == 16 * 1024 * 1024
        assert PHASES[await tb.reg(k, "PHASE")] == "idle"
        assert await tb.reg(k, "TCP_STATE") == 0
        for name, value in (("LOCAL_PORT", 0x1234), ("REMOTE_IP", 0xC6120001),
                            ("REMOTE_PORT", 11311), ("HDR_TX_LEN", 300), ("HDR_ERR_LEN", 40),
                            ("CHECK", 0x07), ("MAX_MSG", 123456)):
            if role == "publisher" and name in ("REMOTE_IP", "REMOTE_PORT"):
                continue                    # a publisher shows its peer there (none yet)
            await tb.set_reg(k, name, value)
            assert await tb.reg(k, name) == value, name
        text = b"/camera/image_raw"
        offset, capacity = EXPECTED["topic"]
        await tb.write(base + offset, bytes([len(text)]) + text)
        assert await tb.read(base + offset, 1 + len(text)) == bytes([len(text)]) + text
        for where in (HDR_TX[0], HDR_TX[0] + HDR_TX[1] - 255):
            data = rng.randbytes(255)
            await tb.write(base + where, data)
            assert await tb.read(base + where, 255) == data
        assert await tb.read(base + HDR_RX[0], 4) == bytes(4)
        raw = await tb.read(base + COUNTERS_OFFSET, 4 * len(COUNTERS))
        assert raw == bytes(4 * len(COUNTERS))
        await tb.set_reg(k, "ERROR", 0xFF)           # write-1-to-clear of nothing: stays 0
        assert await tb.reg(k, "ERROR") == 0
    # HDR_ERR is write-only memory here; an address past every endpoint is a bus error
    assert HDR_ERR[1] == 256
    reply = await rbcp(tb, rbcp_request(0xC0, 99, len(roles) * ENDPOINT_STRIDE, 4))
    assert reply is not None and reply[1] == 0xC9, reply
