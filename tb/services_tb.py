"""The test bench of the ``services`` top (gen.services.ServiceGraph): client ends driven and
drained under random idle and backpressure, raw frames injected on both topics, and every
frame on the reply topic recorded."""

import logging
import os
import random

import cocotb
import numpy as np
from cocotb.triggers import RisingEdge
from cocotbext.axi import AxiStreamBus, AxiStreamFrame, AxiStreamSource

from host.simulator import clock_cycles, start_clock
from tb.harness import ROOT, bench_params
from tb.models.messages import golden_store
from tb.models.services import parse_header
from tb.streams import (HandshakeSink, HandshakeSource, PacketSink, bursty_pauses, random_pauses,
                        reset_aresetn)

__all__ = ["CLOCK_NS", "SORT", "FIBONACCI", "ServicesTB"]

CLOCK_NS = 10
MSG_DIRS = ["examples/hw_services/msg"]
SORT = dict(server="sort", interface="my_reconros_services/srv/Sort", msg_dirs=MSG_DIRS,
            clients=2, block_size=64)
FIBONACCI = dict(server="fibonacci", interface="example_interfaces/action/Fibonacci",
                 msg_dirs=MSG_DIRS, clients=2, step_cycles=30)


class ServicesTB:
    """Ports of the top: per client its body sources and sinks, the raw publishers, the reply
    tap; rosbags for the bodies."""

    def __init__(self, dut):
        self.dut = dut
        self.params = bench_params()
        self.clients = self.params["clients"]
        self.rng = random.Random(cocotb.RANDOM_SEED)
        self.log = logging.getLogger("cocotb.tb")
        self.golden = golden_store("ros2_humble", [ROOT / d for d in self.params["msg_dirs"]])
        self.interface = self.params["interface"]
        clock = dut.aclk
        start_clock(clock, CLOCK_NS)
        self.service = self.params["server"] == "sort"
        body_in = ("request",) if self.service else ("goal",)
        body_out = ("reply",) if self.service else ("feedback", "result")
        self.sources = [{n: self._source(f"c{i}_{n}") for n in body_in}
                        for i in range(self.clients)]
        self.sinks = [{n: PacketSink(dut, f"c{i}_{n}", clock) for n in body_out}
                      for i in range(self.clients)]
        info = "reply_info" if self.service else "response"
        self.infos = [HandshakeSink(dut, f"c{i}_{info}", clock) for i in range(self.clients)]
        self.cancels = ([] if self.service else
                        [HandshakeSource(dut, f"c{i}_cancel", clock) for i in range(self.clients)])
        self.raw_request = self._source("raw_request")
        self.raw_reply = self._source("raw_reply")
        self.tap = PacketSink(dut, "tap_reply", clock)
        self.cycle = 0
        cocotb.start_soon(self._count())

    def _source(self, prefix):
        port = AxiStreamSource(AxiStreamBus.from_prefix(self.dut, prefix), self.dut.aclk,
                               self.dut.aresetn, reset_active_level=False)
        port.log.setLevel(logging.WARNING)
        return port

    async def _count(self):
        while True:
            await RisingEdge(self.dut.aclk)
            self.cycle += 1

    async def reset(self):
        await reset_aresetn(self.dut)

    def set_idle(self, probability):
        for ports in self.sources + [{"r": self.raw_request, "p": self.raw_reply}]:
            for port in ports.values():
                port.set_pause_generator(random_pauses(random.Random(self.rng.random()),
                                                       probability) if probability else None)
                if not probability:
                    port.pause = False
        for source in self.cancels:
            source.set_pause_generator(random_pauses(random.Random(self.rng.random()),
                                                     probability) if probability else None)

    def set_backpressure(self, probability):
        sinks = [s for ports in self.sinks for s in ports.values()] + self.infos + [self.tap]
        for sink in sinks:
            sink.set_pause_generator(bursty_pauses(random.Random(self.rng.random()),
                                                   probability, 6) if probability else None)

    # bodies ----------------------------------------------------------------------------------
    def cdr(self, suffix, **fields):
        name = f"{self.interface}_{suffix}"
        cls = self.golden.types[name]
        return bytes(self.golden.serialize_cdr(cls(**fields), name))

    def sort_request(self, values):
        return self.cdr("Request", unsorted=np.array(values, dtype=np.uint32))

    def sort_reply(self, values):
        return self.cdr("Response", sorted=np.array(values, dtype=np.uint32))

    def goal(self, order):
        return self.cdr("Goal", order=order)

    def sequence(self, suffix, values):
        return self.cdr(suffix, sequence=np.array(values, dtype=np.int32))

    # ports -----------------------------------------------------------------------------------
    async def send(self, client, port, body):
        await self.sources[client][port].send(AxiStreamFrame(body))

    async def inject(self, topic, data, *, short_header=False):
        """A raw frame on the request or reply topic (``short_header``: the first beat keeps
        only 6 bytes)."""
        source = self.raw_request if topic == "request" else self.raw_reply
        await source.send(AxiStreamFrame(data[:6] if short_header else data))

    def counter(self, name):
        return int(getattr(self.dut, name).value)

    def tap_frames(self):
        """Every frame on the reply topic: ``(kind, client, sequence, status, body)``."""
        return [(*parse_header(p.data), bytes(p.data[8:])) for p in self.tap.packets]

    async def wait_for(self, condition, timeout_cycles, what):
        for _ in range(timeout_cycles):
            if condition():
                return
            await RisingEdge(self.dut.aclk)
        raise AssertionError(f"timeout after {timeout_cycles} cycles waiting for {what}")

    async def cycles(self, n):
        await clock_cycles(self.dut.aclk, n)


PARAMS = bench_params() if "ROSGATE_PARAMS" in os.environ else {}
