"""The Linux kernel as the peer of the network benches: :class:`host.tap.TapBridge` between
the engine's GMII models and a TAP device in a network namespace the test creates, and waits
bounded in simulated cycles and wall time."""

import concurrent.futures
import os
import random
import time

import cocotb

from host.simulator import clock_cycles
from host.tap import KERNEL_IP, TAP_NAME, TapBridge, namespace_unavailable, network_namespace

from .net_tb import ENGINE_IP, PEER_IP, NetTB

__all__ = ["LinuxTB", "KERNEL_IP", "ENGINE_IP", "TAP_NAME", "WALL_LIMIT_S",
           "namespace_unavailable", "network_namespace"]

#: wall-clock bound of every wait in a Linux-peer bench
WALL_LIMIT_S = 900

assert KERNEL_IP == PEER_IP, "the benches' peer is the kernel on the TAP device"


class LinuxTB(NetTB):
    """:class:`~tb.net_tb.NetTB` with the kernel as the peer through a
    :class:`host.tap.TapBridge` (impairment probability from ``ROSGATE_NET_IMPAIRMENT``), and
    bounded waits."""

    def __init__(self, dut):
        super().__init__(dut)
        self.rng = random.Random(cocotb.RANDOM_SEED)
        p = float(os.environ.get("ROSGATE_NET_IMPAIRMENT", "0"))
        self.pump = TapBridge(self.source, self.sink, dut.aclk,
                              rng=random.Random(self.rng.random()), loss=p, duplicate=p,
                              reorder=p)
        self.started = time.monotonic()

    async def poll(self, what, predicate, limit_cycles, step=256):
        """Wait until ``predicate()``, in steps of ``step`` cycles, bounded in cycles and wall
        time."""
        for k in range(limit_cycles // step):
            if predicate():
                return
            if time.monotonic() - self.started >= WALL_LIMIT_S:
                raise AssertionError(f"wall-clock limit: {what}; {await self.diagnostics()}")
            if k and k % ((1 << 22) // step) == 0:
                self.dut._log.info("%s: %s", what, await self.diagnostics())
            await clock_cycles(self.dut.aclk, step)
        raise AssertionError(f"{what}: not within {limit_cycles} cycles; "
                             f"{await self.diagnostics()}")

    async def diagnostics(self):
        """The pump's and every session's state and counters, for a log line."""
        sessions = []
        for k in range(8):
            state = getattr(self.dut, f"tcp{k}_state", None)
            if state is None:
                break
            counts = await self.session_counters(k)
            sessions.append(f"tcp{k} state {int(state.value)} {counts}")
        return f"pump {self.pump.stats}; " + "; ".join(sessions)

    async def quiet_counters(self):
        """The stack's counters and the pump's count of frames sent to the engine, taken
        when every frame sent has reached its verdict (retried while the kernel sends)."""
        for _ in range(20):
            pumped = self.pump.stats["to_design"]
            await self.source.wait()
            await self.idle(200)
            counters = await self.counters()
            if self.pump.stats["to_design"] == pumped:
                return counters, pumped
        raise AssertionError(f"the kernel never paused; {await self.diagnostics()}")

    async def run_in_thread(self, what, fn, *args, limit_cycles=3_000_000):
        with concurrent.futures.ThreadPoolExecutor(1) as pool:
            future = pool.submit(fn, *args)
            await self.poll(what, future.done, limit_cycles, step=1024)
            return future.result()

    async def transfer(self, sock, session, to_engine, from_engine, limit_cycles):
        """Move ``to_engine`` from the kernel socket into the session and ``from_engine``
        back at the same time; return what each side received."""
        sock.setblocking(False)
        cocotb.start_soon(self._feed(session, from_engine))
        sent = 0
        got = bytearray()

        def step():
            nonlocal sent
            while sent < len(to_engine):
                try:
                    n = sock.send(to_engine[sent:sent + 65536])
                except BlockingIOError:
                    break
                sent += n
            while True:
                try:
                    chunk = sock.recv(65536)
                except BlockingIOError:
                    break
                if not chunk:
                    break
                got.extend(chunk)
            return (sent == len(to_engine) and len(got) >= len(from_engine) and
                    len(session.received) >= len(to_engine))

        await self.poll("transfer", step, limit_cycles)
        return bytes(session.received), bytes(got)

    async def _feed(self, session, data):
        for i in range(0, len(data), 4096):
            await session.write(data[i:i + 4096])


