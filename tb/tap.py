"""The Linux kernel as a network peer (spec net.md §5.2 "Real peer", toolchain.md): a private
network namespace with a TAP device, and a cocotb pump between the simulated GMII and the TAP
file descriptor, with optional seeded loss, duplication and reordering."""

import concurrent.futures
import contextlib
import ctypes
import fcntl
import os
import random
import shutil
import struct
import subprocess
import time
import uuid
import zlib

import cocotb
from cocotb.triggers import ClockCycles

from hdl.net.frames import ETHERTYPE_IPV4, ETHERTYPE_IPV6, IP_PROTO_TCP
from tb.net_tb import ENGINE_IP, PEER_IP, NetTB

__all__ = ["namespace_unavailable", "network_namespace", "TapPump", "LinuxTB", "KERNEL_IP",
           "ENGINE_IP", "TAP_NAME", "WALL_LIMIT_S"]

#: wall-clock bound of every wait in a Linux-peer bench
WALL_LIMIT_S = 900

KERNEL_IP = PEER_IP           # RFC 2544 benchmarking block, only inside the namespace
TAP_NAME = "tap0"
_CLONE_NEWNET = 0x40000000
_TUNSETIFF = 0x400454CA
_IFF_TAP = 0x0002
_IFF_NO_PI = 0x1000


def namespace_unavailable():
    """Why this machine cannot run the TAP benches, or ``None``."""
    if os.geteuid() != 0:
        return "needs root to create a network namespace and a TAP device"
    if not os.path.exists("/dev/net/tun"):
        return "no /dev/net/tun"
    if shutil.which("ip") is None:
        return "no ip command (iproute2)"
    return None


def _ip(*args):
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=10)


@contextlib.contextmanager
def network_namespace():
    """Create namespace ``rg<random>`` with ``lo`` and ``tap0`` (``KERNEL_IP``/24, no default
    route), move this thread into it (child processes such as the simulator inherit it), and
    undo everything on exit."""
    libc = ctypes.CDLL(None, use_errno=True)
    name = f"rg{uuid.uuid4().hex[:8]}"
    _ip("netns", "add", name)
    original = os.open("/proc/self/ns/net", os.O_RDONLY)
    try:
        target = os.open(f"/var/run/netns/{name}", os.O_RDONLY)
        try:
            if libc.setns(target, _CLONE_NEWNET) != 0:
                raise OSError(ctypes.get_errno(), "setns into the test namespace failed")
        finally:
            os.close(target)
        try:
            _ip("link", "set", "lo", "up")
            _ip("tuntap", "add", "dev", TAP_NAME, "mode", "tap")
            _ip("addr", "add", f"{KERNEL_IP}/24", "dev", TAP_NAME)
            _ip("link", "set", TAP_NAME, "up")
            yield name
        finally:
            if libc.setns(original, _CLONE_NEWNET) != 0:
                raise OSError(ctypes.get_errno(), "setns back to the original namespace failed")
    finally:
        os.close(original)
        subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=10)


def _is_tcp(frame):
    """``frame`` (Ethernet, no FCS) is an IPv4 TCP segment."""
    return (len(frame) > 23 and frame[12:14] == ETHERTYPE_IPV4.to_bytes(2, "big") and
            frame[23] == IP_PROTO_TCP)


class TapPump:
    """Moves frames between ``tap0`` and the engine's GMII models, inside a cocotb test.

    Kernel frames are polled every ``poll_cycles`` cycles (at most 8 per poll) and sent with
    preamble, padding and FCS; engine frames have their FCS checked and removed. With
    ``loss``, ``duplicate`` and ``reorder`` probabilities, each direction drops a TCP segment,
    sends it twice, or holds it back behind the next one, from a seeded generator. Other
    frames (ARP, ICMP, RBCP) pass untouched: their clients (ping, sitcpy's RBCP) have no
    retransmission, and what the impairment tests is TCP.
    """

    def __init__(self, tb, rng, *, loss=0.0, duplicate=0.0, reorder=0.0, poll_cycles=128):
        self.tb = tb
        self.rng = rng
        self.loss, self.duplicate, self.reorder = loss, duplicate, reorder
        self.poll_cycles = poll_cycles
        self.fd = self._open()
        self.stats = {"to_engine": 0, "from_engine": 0, "dropped": 0, "duplicated": 0,
                      "reordered": 0, "ipv6": 0}
        self._held = {"in": None, "out": None}
        self.ipv6_frames = []               # the last 64 IPv6 frames from the kernel
        cocotb.start_soon(self._kernel_to_engine())
        cocotb.start_soon(self._engine_to_kernel())

    _fd = None

    @classmethod
    def _open(cls):
        """The TAP file descriptor, opened once per simulator process (a TAP device takes one
        attachment; every cocotb test of the run reuses it)."""
        if cls._fd is None:
            fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
            fcntl.ioctl(fd, _TUNSETIFF, struct.pack("16sH", TAP_NAME.encode(),
                                                     _IFF_TAP | _IFF_NO_PI))
            cls._fd = fd
        return cls._fd

    def _impair(self, direction, frame):
        """Frames to pass on now for ``frame`` under the configured impairments."""
        rng = self.rng
        if not _is_tcp(frame):
            return [frame]
        if rng.random() < self.loss:
            self.stats["dropped"] += 1
            return []
        out = [frame]
        if rng.random() < self.duplicate:
            self.stats["duplicated"] += 1
            out.append(frame)
        held = self._held[direction]
        if held is not None:
            self._held[direction] = None
            return out + [held]
        if rng.random() < self.reorder:
            self.stats["reordered"] += 1
            self._held[direction] = frame
            return out[1:]
        return out

    async def _kernel_to_engine(self):
        from cocotbext.eth import GmiiFrame
        while True:
            for _ in range(8):
                try:
                    frame = os.read(self.fd, 2048)
                except BlockingIOError:
                    break
                if frame[12:14] == ETHERTYPE_IPV6.to_bytes(2, "big"):
                    self.stats["ipv6"] += 1
                    self.ipv6_frames = (self.ipv6_frames + [frame])[-64:]
                for f in self._impair("in", frame):
                    self.stats["to_engine"] += 1
                    self.tb.source.send_nowait(GmiiFrame.from_payload(f))
            await ClockCycles(self.tb.dut.aclk, self.poll_cycles)

    async def _engine_to_kernel(self):
        while True:
            gf = await self.tb.sink.recv()
            payload = bytes(gf.get_payload(strip_fcs=False))
            body, fcs = payload[:-4], payload[-4:]
            assert zlib.crc32(body).to_bytes(4, "little") == fcs, "engine frame with bad FCS"
            assert not any(gf.error or []), "engine frame with TX_ER"
            for f in self._impair("out", body):
                self.stats["from_engine"] += 1
                try:
                    os.write(self.fd, f)
                except BlockingIOError:
                    self.stats["dropped"] += 1


class LinuxTB(NetTB):
    """:class:`~tb.net_tb.NetTB` with the kernel as the peer through a :class:`TapPump`
    (impairment probability from ``ROSGATE_NET_IMPAIRMENT``), and bounded waits."""

    def __init__(self, dut):
        super().__init__(dut)
        self.rng = random.Random(cocotb.RANDOM_SEED)
        p = float(os.environ.get("ROSGATE_NET_IMPAIRMENT", "0"))
        self.pump = TapPump(self, random.Random(self.rng.random()), loss=p, duplicate=p,
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
            await ClockCycles(self.dut.aclk, step)
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
            pumped = self.pump.stats["to_engine"]
            await self.source.wait()
            await self.idle(200)
            counters = await self.counters()
            if self.pump.stats["to_engine"] == pumped:
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


