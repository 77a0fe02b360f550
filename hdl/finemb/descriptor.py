"""A FinEmbP node's IO descriptor: its application's ports, where each lives in the process
data pages, and the descriptor bytes the master reads (docs/finemb.md)."""

import struct
from dataclasses import dataclass

from ..params import ParameterError
from .protocol import PORT_TYPE_BYTES, Direction, PortType

__all__ = ["IoPort", "IoDescriptor", "MAX_PAGE_BYTES"]

#: the largest process data page a node holds (one direction)
MAX_PAGE_BYTES = 1024
#: how each port type is stored in a page (little-endian struct codes)
_STRUCT_CODES = {PortType.BOOL: "?", PortType.U8: "B", PortType.I8: "b", PortType.U16: "H",
                 PortType.I16: "h", PortType.U32: "I", PortType.I32: "i", PortType.F32: "f",
                 PortType.F64: "d"}


@dataclass(frozen=True)
class IoPort:
    """One port of a node's application.

    Attributes
    ----------
    port_id : int
    name : str
    direction : Direction
        ``OUT``: master -> node (in the output page); ``IN``: node -> master.
    type : PortType
    size : int
        Bytes (the type's size; a ``BLOB`` gives its own).
    offset : int
        Byte offset in its page (aligned to the type's size).
    """

    port_id: int
    name: str
    direction: Direction
    type: PortType
    size: int
    offset: int


class IoDescriptor:
    """The ports of a node's application, packed into an output and an input page.

    Ports are laid out in the order given, each page on its own: a port starts at the next
    offset aligned to its type's size (a blob to 1). A page is never empty in rosgate (a node
    with no port in a direction still sends its header).

    Parameters
    ----------
    name : str
        The application's name (UTF-8, at most 255 bytes).
    ports : list of (name, direction, type) or (name, direction, type, size)
        ``direction`` ``"out"``/``"in"`` (or :class:`Direction`), ``type`` a
        :class:`PortType` name (``"i16"``) or member; ``size`` only for a blob.
    """

    def __init__(self, name, ports):
        if not isinstance(name, str) or not 0 < len(name.encode()) < 256:
            raise ParameterError("name", name, "an application name of 1..255 UTF-8 bytes")
        self.name = name
        offsets = {Direction.OUT: 0, Direction.IN: 0}
        self.ports = []
        seen = set()
        for k, spec in enumerate(ports):
            if not 3 <= len(spec) <= 4:
                raise ParameterError(f"ports[{k}]", spec, "(name, direction, type[, size])")
            pname, direction, ptype = spec[:3]
            if not isinstance(pname, str) or not 0 < len(pname.encode()) < 256 or pname in seen:
                raise ParameterError(f"ports[{k}] name", pname,
                                     "a unique port name of 1..255 UTF-8 bytes")
            seen.add(pname)
            direction = _enum(Direction, direction, f"ports[{k}] ({pname}) direction",
                              {"out": Direction.OUT, "in": Direction.IN})
            ptype = _enum(PortType, ptype, f"ports[{k}] ({pname}) type",
                          {t.name.lower(): t for t in PortType})
            if ptype == PortType.BLOB:
                size = spec[3] if len(spec) == 4 else None
                if not isinstance(size, int) or not 1 <= size <= MAX_PAGE_BYTES:
                    raise ParameterError(f"ports[{k}] ({pname}) size", size,
                                         f"a blob size of 1..{MAX_PAGE_BYTES} bytes")
                align = 1
            else:
                if len(spec) == 4 and spec[3] != PORT_TYPE_BYTES[ptype]:
                    raise ParameterError(f"ports[{k}] ({pname}) size", spec[3],
                                         f"{PORT_TYPE_BYTES[ptype]} (the size of "
                                         f"{ptype.name.lower()}) or no size")
                size = align = PORT_TYPE_BYTES[ptype]
            offset = -(-offsets[direction] // align) * align
            offsets[direction] = offset + size
            self.ports.append(IoPort(k, pname, direction, ptype, size, offset))
        self.page_out_bytes = max(offsets[Direction.OUT], 1)
        self.page_in_bytes = max(offsets[Direction.IN], 1)
        for direction, used in offsets.items():
            if used > MAX_PAGE_BYTES:
                raise ParameterError("ports", f"{used} bytes of {direction.name.lower()} page",
                                     f"at most {MAX_PAGE_BYTES} bytes per page")

    def port(self, name):
        """The port called ``name``."""
        for p in self.ports:
            if p.name == name:
                return p
        raise KeyError(f"no port {name!r} in application {self.name!r} (ports: "
                       f"{', '.join(p.name for p in self.ports)})")

    def page_bytes(self, direction):
        """Bytes of the page of ``direction``."""
        return self.page_out_bytes if Direction(direction) == Direction.OUT else \
            self.page_in_bytes

    def pack(self, direction, values):
        """The page of ``direction`` holding ``values`` (port name -> value; ports not named
        are 0): each port little-endian at its offset, a blob as its bytes."""
        direction = Direction(direction)
        page = bytearray(self.page_bytes(direction))
        for port in self.ports:
            if port.direction != direction or port.name not in values:
                continue
            value = values[port.name]
            if port.type == PortType.BLOB:
                data = bytes(value)[:port.size].ljust(port.size, b"\0")
            else:
                data = struct.pack("<" + _STRUCT_CODES[port.type], value)
            page[port.offset:port.offset + port.size] = data
        unknown = set(values) - {p.name for p in self.ports if p.direction == direction}
        if unknown:
            raise KeyError(f"no {direction.name.lower()} port {sorted(unknown)[0]!r} in "
                           f"application {self.name!r}")
        return bytes(page)

    def unpack(self, direction, page):
        """Port name -> value of a page of ``direction``."""
        direction = Direction(direction)
        if len(page) != self.page_bytes(direction):
            raise ValueError(f"a {direction.name.lower()} page of {len(page)} bytes; "
                             f"{self.name!r} has {self.page_bytes(direction)}")
        out = {}
        for port in self.ports:
            if port.direction == direction:
                raw = bytes(page[port.offset:port.offset + port.size])
                out[port.name] = raw if port.type == PortType.BLOB else \
                    struct.unpack("<" + _STRUCT_CODES[port.type], raw)[0]
        return out

    def encode(self):
        """The descriptor bytes a node sends in IODESC_RES: ``u16 n_ports, u16
        page_out_bytes, u16 page_in_bytes, u16 name_len``, the name, then per port ``u16
        port_id, u8 direction, u8 type, u16 offset, u16 size, u8 name_len`` and its name."""
        name = self.name.encode()
        out = struct.pack("<HHHH", len(self.ports), self.page_out_bytes, self.page_in_bytes,
                          len(name)) + name
        for p in self.ports:
            pname = p.name.encode()
            out += struct.pack("<HBBHHB", p.port_id, p.direction, p.type, p.offset, p.size,
                               len(pname)) + pname
        return out

    @classmethod
    def decode(cls, data):
        """The descriptor of ``data`` (as :meth:`encode` writes it); ``ValueError`` naming
        what is wrong."""
        try:
            n, page_out, page_in, name_len = struct.unpack_from("<HHHH", data)
            pos = 8

            def text(n):
                nonlocal pos
                if pos + n > len(data):
                    raise ValueError(f"a name of {n} bytes at byte {pos} runs past the end "
                                     f"({len(data)} bytes)")
                pos += n
                return data[pos - n:pos].decode()

            name = text(name_len)
            specs, layout = [], []
            for _ in range(n):
                port_id, direction, ptype, offset, size, plen = struct.unpack_from(
                    "<HBBHHB", data, pos)
                pos += 9
                pname = text(plen)
                spec = (pname, Direction(direction), PortType(ptype))
                specs.append(spec + ((size,) if ptype == PortType.BLOB else ()))
                layout.append((port_id, offset, size))
        except (struct.error, UnicodeDecodeError, ValueError) as exc:
            raise ValueError(f"not an IO descriptor: {exc}") from None
        if pos != len(data):
            raise ValueError(f"IO descriptor of {pos} bytes followed by {len(data) - pos} more")
        desc = cls(name, specs)
        got = [(p.port_id, p.offset, p.size) for p in desc.ports]
        if got != layout or (desc.page_out_bytes, desc.page_in_bytes) != (page_out, page_in):
            raise ValueError("IO descriptor layout disagrees with its ports' packing")
        return desc

    def __eq__(self, other):
        return isinstance(other, IoDescriptor) and (self.name, self.ports) == \
            (other.name, other.ports)

    def __repr__(self):
        return (f"IoDescriptor({self.name!r}, {len(self.ports)} ports, out "
                f"{self.page_out_bytes} B, in {self.page_in_bytes} B)")


def _enum(kind, value, what, names):
    if isinstance(value, kind):
        return value
    if isinstance(value, str) and value.lower() in names:
        return names[value.lower()]
    raise ParameterError(what, value, "one of " + ", ".join(names))
