"""Small cocotb port drivers the cocotbext-axi models do not cover: beats with ``tkeep`` 0
and ``tuser`` flags (:class:`PacketSink`), and a plain valid/ready payload port
(:class:`HandshakeSource`, :class:`HandshakeSink`)."""


import logging

import cocotb
from cocotb.triggers import ClockCycles, RisingEdge

from host.compiled.streams import pause_runs

__all__ = ["random_pauses", "bursty_pauses", "count_pulses", "reset_aresetn", "StreamPort", "PacketSink", "HandshakeSource", "HandshakeSink",
           "Packet"]


def random_pauses(rng, probability):
    """Pause generator: ``True`` (pause this cycle) with the given probability."""
    return pause_runs(rng, probability)


def bursty_pauses(rng, probability, max_run=24):
    """Pause generator with runs: long stalls and long bursts."""
    return pause_runs(rng, probability, max_run)


async def count_pulses(signal, counters, key):
    """Count the rising edges of a registered one-cycle pulse output into ``counters[key]``
    (cheaper than reading it every cycle; a combinational output may glitch)."""
    while True:
        await RisingEdge(signal)
        counters[key] += 1


async def reset_aresetn(dut, clock=None):
    """Hold the active-low ``aresetn`` of an exported top for 4 cycles, then wait 2."""
    clock = clock or dut.aclk
    dut.aresetn.value = 0
    await ClockCycles(clock, 4)
    dut.aresetn.value = 1
    await ClockCycles(clock, 2)


class StreamPort:
    """A kernel's input and output streams (``<name>_i`` driven by a cocotbext-axi source,
    ``<name>_<out>`` taken by a :class:`PacketSink`), with idle and backpressure."""

    def __init__(self, dut, name, rng, *, out="o", into="i"):
        from cocotbext.axi import AxiStreamBus, AxiStreamSource
        self.source = AxiStreamSource(AxiStreamBus.from_prefix(dut, f"{name}_{into}"),
                                      dut.aclk, dut.aresetn, reset_active_level=False)
        self.source.log.setLevel(logging.WARNING)
        self.sink = PacketSink(dut, f"{name}_{out}", dut.aclk)
        self.rng = rng

    def set_pauses(self, idle, backpressure):
        """Random idle at the source and backpressure at the sink (0: none)."""
        self.source.set_pause_generator(random_pauses(self.rng, idle) if idle else None)
        if not idle:
            self.source.pause = False   # the generator may have stopped on a pause
        self.sink.set_pause_generator(random_pauses(self.rng, backpressure)
                                      if backpressure else None)

    def words(self):
        """Every received beat's ``tdata``, packets concatenated."""
        return [d for packet in self.sink.packets for d, _, _ in packet.beats]


class Packet:
    """A received packet: its bytes (by ``tkeep``), its beats, and the cycle of each beat."""

    def __init__(self):
        self.data = bytearray()
        self.beats = []       # (tdata, tkeep, tuser)
        self.cycles = []

    def __repr__(self):
        return f"Packet({bytes(self.data)!r}, {len(self.beats)} beats)"


class _Pausable:
    """A port driver whose idle or backpressure cycles come from a pause generator."""

    pauses = None

    def set_pause_generator(self, generator=None):
        self.pauses = generator

    def paused(self):
        """Consume one cycle of the generator: whether to pause this cycle."""
        return bool(self.pauses and next(self.pauses))


class PacketSink(_Pausable):
    """Receives packets on an AXI4-Stream port ``<prefix>_t*`` with random backpressure
    (every byte counts where the port has no ``tkeep``). While the top's ``aresetn`` is low
    no beat is taken (AXI4-Stream: a handshake in reset is none) and a packet begun before
    is dropped: a test that resets the top does not receive the tail of the last test's
    packet."""

    def __init__(self, dut, prefix, clock):
        self.clock = clock
        self.aresetn = getattr(dut, "aresetn", None)
        self.tdata = getattr(dut, f"{prefix}_tdata")
        self.tkeep = getattr(dut, f"{prefix}_tkeep", None)
        self.tlast = getattr(dut, f"{prefix}_tlast")
        self.tvalid = getattr(dut, f"{prefix}_tvalid")
        self.tready = getattr(dut, f"{prefix}_tready")
        self.tuser = getattr(dut, f"{prefix}_tuser", None)
        self.prefix = prefix
        self.bytes = len(self.tdata) // 8
        self.packets = []
        self.current = Packet()
        self.cycle = 0
        self.tready.value = 0
        self._task = cocotb.start_soon(self._run())

    def stop(self, ready=1):
        """Stop taking beats; leave ``tready`` at ``ready``."""
        self._task.cancel()
        self.tready.value = ready

    async def _run(self):
        driven = None
        edge = RisingEdge(self.clock)
        while True:
            ready = not self.paused()
            if ready != driven:
                self.tready.value = int(ready)
                driven = ready
            await edge
            self.cycle += 1
            if self.aresetn is not None and self.aresetn.value == 0:
                self.current = Packet()
                continue
            if ready and self.tvalid.value == 1:
                keep = int(self.tkeep.value) if self.tkeep is not None else (1 << self.bytes) - 1
                if not self.tdata.value.is_resolvable:
                    raise AssertionError(f"{self.prefix}_tdata is {self.tdata.value} in a beat")
                data = int(self.tdata.value).to_bytes(self.bytes, "little")
                user = int(self.tuser.value) if self.tuser is not None else 0
                self.current.data += bytes(d for i, d in enumerate(data) if keep >> i & 1)
                self.current.beats.append((int(self.tdata.value), keep, user))
                self.current.cycles.append(self.cycle)
                if self.tlast.value == 1:
                    self.packets.append(self.current)
                    self.current = Packet()


class HandshakeSource(_Pausable):
    """Drives ``<prefix>_payload/_valid`` and waits for ``_ready``, with random idle."""

    def __init__(self, dut, prefix, clock):
        self.clock = clock
        self.payload = getattr(dut, f"{prefix}_payload")
        self.valid = getattr(dut, f"{prefix}_valid")
        self.ready = getattr(dut, f"{prefix}_ready")
        self.valid.value = 0

    async def send(self, value):
        while self.paused():
            self.valid.value = 0
            await RisingEdge(self.clock)
        self.payload.value = value
        self.valid.value = 1
        while True:
            await RisingEdge(self.clock)
            if self.ready.value == 1:
                break
        self.valid.value = 0


class HandshakeSink(_Pausable):
    """Accepts ``<prefix>_payload`` values with random backpressure; records each value."""

    def __init__(self, dut, prefix, clock):
        self.clock = clock
        self.payload = getattr(dut, f"{prefix}_payload")
        self.valid = getattr(dut, f"{prefix}_valid")
        self.ready = getattr(dut, f"{prefix}_ready")
        self.values = []
        self.ready.value = 0
        cocotb.start_soon(self._run())

    async def _run(self):
        while True:
            ready = not self.paused()
            self.ready.value = int(ready)
            await RisingEdge(self.clock)
            if ready and self.valid.value == 1:
                self.values.append(int(self.payload.value))
