"""cocotb side of ``make bench`` for message (de)serializers: one large message each way at
full rate (no idle, no backpressure), checked against the golden bytes, cycles recorded."""

import json
import os

import cocotb
from cocotb.triggers import RisingEdge, with_timeout

from gen.msg.model import Named, Sequence
from tb.models.messages import random_primitive, random_value
from tb.models.msgstream import set_at
from tb.msg_codec_tb import MsgCodecTB


class EdgeWatch:
    """First and last cycle (the bench's shared cycle count) of transfers on one port."""

    def __init__(self, tb, prefix, *, first_on_valid=False):
        self.tb = tb
        self.valid = getattr(tb.dut, f"{prefix}_tvalid" if not first_on_valid else
                             f"{prefix}_valid")
        self.ready = getattr(tb.dut, f"{prefix}_tready" if not first_on_valid else
                             f"{prefix}_ready")
        self.first_on_valid = first_on_valid
        self.first = self.last = None
        cocotb.start_soon(self._run())

    async def _run(self):
        while True:
            await RisingEdge(self.tb.dut.aclk)
            valid = self.valid.value == 1
            if valid and (self.first_on_valid or self.ready.value == 1):
                if self.first is None:
                    self.first = self.tb.cycle
                self.last = self.tb.cycle


def element_value(tb, typename, values=None):
    """A random element; ``values``: every sequence of messages in it gets that many."""
    value = random_value(tb.library, typename, tb.rng, max_len=6)
    for f in tb.library[typename].fields:
        if values is not None and isinstance(f.type, Sequence) and \
                isinstance(f.type.element, Named):
            value[f.name] = [random_value(tb.library, f.type.element.typename, tb.rng)
                             for _ in range(values)]
    return value


@cocotb.test()
async def measure(dut):
    tb = MsgCodecTB(dut, seed=1)
    await tb.reset()
    case = json.loads(os.environ["ROSGATE_BENCH_CASE"])
    value = tb.random_message()
    for path, item in case["set"].items():
        if isinstance(item, dict):      # {"bytes": n} or {"elements": n[, "values": k]}
            v = next(v for v in tb.plan.variables if v.path == path)
            if "bytes" in item:
                item = bytes(i * 7 % 251 for i in range(item["bytes"]))
            elif v.elements:
                item = [element_value(tb, v.element, item.get("values"))
                        for _ in range(item["elements"])]
            else:
                item = [random_primitive(v.element, tb.rng) for _ in range(item["elements"])]
        set_at(value, path, item)
    start = EdgeWatch(tb, "ser_fields", first_on_valid=True)
    out = EdgeWatch(tb, "ser_m_axis")
    await tb.serialize(value)
    frame = await with_timeout(tb.ser_out.recv(compact=False), 100, "ms")
    tb.check_serialized(frame, value, 0)
    wire = tb.wire_bytes(value)
    inp = EdgeWatch(tb, "des_s_axis")
    await tb.run_deserializer([value], timeout_cycles=10_000_000)
    last_payload = max(p.packets[-1].cycles[-1] for p in tb.des_payloads)
    biggest = max(tb.des_payloads, key=lambda p: len(p.packets[-1].data)).packets[-1]
    record = {
        "wire_bytes": len(wire),
        "serialize_cycles": out.last - start.first + 1,
        "deserialize_cycles": last_payload - inp.first + 1,
        "payload_bytes": len(biggest.data),
        "payload_cycles": biggest.cycles[-1] - biggest.cycles[0] + 1,
    }
    with open(os.environ["ROSGATE_BENCH_OUT"], "w") as f:
        json.dump(record, f)
