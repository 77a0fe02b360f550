"""The Linux kernel as the network peer of a simulated design: a private network namespace
with a TAP device, and a bridge between the TAP file descriptor and the simulated GMII, with
optional seeded loss, duplication and reordering of TCP segments.

Whatever runs in the namespace (``ip netns exec <name> ...``: ping, tcpdump, sockets, an RBCP
client) talks to the simulated hardware through the kernel's own TCP/IP stack. Creating the
namespace needs root (``CAP_NET_ADMIN``) and ``/dev/net/tun``.
"""

import contextlib
import ctypes
import fcntl
import os
import shutil
import struct
import subprocess
import uuid
import zlib

import cocotb

from hdl.net.frames import ETHERTYPE_IPV4, ETHERTYPE_IPV6, IP_PROTO_TCP
from host.simulator import clock_cycles

__all__ = ["namespace_unavailable", "network_namespace", "TapBridge", "KERNEL_IP", "TAP_NAME"]

#: the kernel's address on the TAP device by default (RFC 2544 benchmarking block; it exists
#: only inside the namespace)
KERNEL_IP = "198.18.0.1"
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
def network_namespace(kernel_ip=KERNEL_IP, prefix=24, tap=TAP_NAME):
    """Create namespace ``rg<random>`` with ``lo`` and the TAP device ``tap`` (``kernel_ip``
    /``prefix``, no default route), move this thread into it (child processes such as the
    simulator inherit it), yield its name, and undo everything on exit."""
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
            _ip("tuntap", "add", "dev", tap, "mode", "tap")
            _ip("addr", "add", f"{kernel_ip}/{prefix}", "dev", tap)
            _ip("link", "set", tap, "up")
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


class TapBridge:
    """Moves frames between a TAP device and a simulated GMII port, inside a cocotb test.

    Kernel frames are polled every ``poll_cycles`` cycles (at most 8 per poll) and sent to
    ``source`` (a cocotbext-eth ``GmiiSource``) with preamble, padding and FCS; frames from
    ``sink`` (a ``GmiiSink``) have their FCS checked and removed before they go to the kernel.
    With ``loss``, ``duplicate`` and ``reorder`` probabilities, each direction drops a TCP
    segment, sends it twice, or holds it back behind the next one, from the seeded ``rng``.
    Other frames (ARP, ICMP, UDP) pass untouched: their clients have no retransmission, and
    what the impairment tests is TCP.

    Parameters
    ----------
    source, sink :
        The GMII models of the design's receive and transmit sides.
    clock : cocotb handle
        The clock the polling counts.
    tap : str
        The TAP device (created by :func:`network_namespace`).
    rng : random.Random or None
        Needed with impairments.
    strict : bool
        Raise on a frame from the design with a bad FCS or ``TX_ER`` (tests); otherwise
        count it in ``stats`` and drop it.
    capture : scapy PcapWriter or None
        Receives every frame that crosses the bridge, both ways.
    """

    def __init__(self, source, sink, clock, *, tap=TAP_NAME, rng=None, loss=0.0, duplicate=0.0,
                 reorder=0.0, poll_cycles=128, strict=True, capture=None):
        if (loss or duplicate or reorder) and rng is None:
            raise ValueError("TapBridge: impairments need a seeded rng")
        self.source, self.sink, self.clock = source, sink, clock
        self.rng = rng
        self.loss, self.duplicate, self.reorder = loss, duplicate, reorder
        self.poll_cycles = poll_cycles
        self.strict = strict
        self.capture = capture
        self.fd = self.open_tap(tap)
        self.stats = {"to_design": 0, "from_design": 0, "dropped": 0, "duplicated": 0,
                      "reordered": 0, "ipv6": 0, "bad_fcs": 0}
        self._held = {"in": None, "out": None}
        self.ipv6_frames = []               # the last 64 IPv6 frames from the kernel
        cocotb.start_soon(self._kernel_to_design())
        cocotb.start_soon(self._design_to_kernel())

    _fds = {}

    @classmethod
    def open_tap(cls, tap):
        """The TAP file descriptor, opened once per simulator process (a TAP device takes one
        attachment; every cocotb test of the run reuses it)."""
        if tap not in cls._fds:
            fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
            fcntl.ioctl(fd, _TUNSETIFF, struct.pack("16sH", tap.encode(),
                                                     _IFF_TAP | _IFF_NO_PI))
            cls._fds[tap] = fd
        return cls._fds[tap]

    def _impair(self, direction, frame):
        """Frames to pass on now for ``frame`` under the configured impairments."""
        rng = self.rng
        if rng is None or not _is_tcp(frame):
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

    def _record(self, frame):
        if self.capture is not None:
            from scapy.layers.l2 import Ether
            self.capture.write(Ether(frame))

    async def _kernel_to_design(self):
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
                    self.stats["to_design"] += 1
                    self._record(f)
                    self.source.send_nowait(GmiiFrame.from_payload(f))
            await clock_cycles(self.clock, self.poll_cycles)

    async def _design_to_kernel(self):
        while True:
            gf = await self.sink.recv()
            payload = bytes(gf.get_payload(strip_fcs=False))
            body, fcs = payload[:-4], payload[-4:]
            if zlib.crc32(body).to_bytes(4, "little") != fcs or any(gf.error or []):
                self.stats["bad_fcs"] += 1
                if self.strict:
                    raise AssertionError("a frame from the design with a bad FCS or TX_ER")
                continue
            for f in self._impair("out", body):
                self.stats["from_design"] += 1
                self._record(f)
                try:
                    os.write(self.fd, f)
                except BlockingIOError:
                    self.stats["dropped"] += 1
