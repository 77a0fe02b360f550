"""RBCP client: SiTCP's register protocol over UDP (docs/network.md)."""

import socket
import threading

from hdl.net.frames import (
    DEFAULT_RBCP_PORT,
    RBCP_BUS_ERROR,
    RBCP_HEADER,
    RBCP_READ,
    RBCP_REPLY,
    RBCP_VERSION,
    RBCP_WRITE,
)

__all__ = ["RbcpClient", "RbcpBusError", "RbcpTimeout", "rbcp_request", "rbcp_reply_ok"]

MAX_CHUNK = 255


def rbcp_request(cmd, ident, address, length, data=b""):
    """An RBCP request datagram (docs/network.md): Ver/Type, CMD/Flag, ID, Length, the
    32-bit address MSB first, then the write data."""
    return bytes([RBCP_VERSION, cmd, ident, length]) + address.to_bytes(4, "big") + bytes(data)


def rbcp_reply_ok(reply, cmd, ident):
    """Whether ``reply`` answers request ``ident`` of ``cmd`` (with or without bus error)."""
    return (len(reply) >= RBCP_HEADER and reply[0] == RBCP_VERSION and reply[2] == ident and
            reply[1] & ~RBCP_BUS_ERROR == cmd | RBCP_REPLY)


class RbcpBusError(IOError):
    """The device answered with the bus-error flag."""


class RbcpTimeout(IOError):
    """No valid reply after every retry."""


class RbcpClient:
    """Reads and writes byte ranges of a device's register space; longer ranges are split
    into requests of up to 255 bytes. Each request carries a new ID; a reply with another ID,
    version or command is ignored, and the request is sent again after ``timeout`` seconds,
    ``retries`` times.
    """

    def __init__(self, ip, port=DEFAULT_RBCP_PORT, *, timeout=1.0, retries=3, sock=True):
        self.address = (ip, port)
        self.timeout = timeout
        self.retries = retries
        self._id = 0
        self._lock = threading.Lock()
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM) if sock else None

    def close(self):
        if self._sock is not None:
            self._sock.close()

    def _transaction(self, cmd, address, length, data=b""):
        if not 1 <= length <= MAX_CHUNK:
            raise ValueError(f"RBCP length must be 1..255, not {length}")
        if not 0 <= address <= 0xFFFFFFFF - length + 1:
            raise ValueError(f"RBCP address range 0x{address:x}+{length} does not fit 32 bits")
        with self._lock:
            ident = self._id
            self._id = (self._id + 1) & 0xFF
            reply = self._exchange(rbcp_request(cmd, ident, address, length, data), cmd, ident)
        if reply is None:
            raise RbcpTimeout(f"no RBCP reply from {self.address[0]}:{self.address[1]} for "
                              f"0x{address:08x} after {self.retries + 1} tries")
        if reply[1] & RBCP_BUS_ERROR:
            raise RbcpBusError(f"bus error at 0x{address:08x} (+{length} bytes)")
        return reply[RBCP_HEADER:RBCP_HEADER + length]

    def _exchange(self, request, cmd, ident):
        """Send ``request`` until a matching reply arrives; the reply, or ``None``. Other
        transports (a simulation's link) override this."""
        self._sock.settimeout(self.timeout)
        for _ in range(self.retries + 1):
            self._sock.sendto(request, self.address)
            try:
                while True:
                    reply, _ = self._sock.recvfrom(2048)
                    if rbcp_reply_ok(reply, cmd, ident):
                        return reply
            except socket.timeout:
                continue
        return None

    def read(self, address, length):
        out = bytearray()
        while length:
            n = min(length, MAX_CHUNK)
            out += self._transaction(RBCP_READ, address, n)
            address += n
            length -= n
        return bytes(out)

    def write(self, address, data):
        data = bytes(data)
        for i in range(0, len(data), MAX_CHUNK):
            chunk = data[i:i + MAX_CHUNK]
            self._transaction(RBCP_WRITE, address + i, len(chunk), chunk)

    def read_int(self, address, size):
        return int.from_bytes(self.read(address, size), "big")

    def write_int(self, address, size, value):
        self.write(address, int(value).to_bytes(size, "big"))
