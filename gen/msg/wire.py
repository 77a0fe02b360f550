"""Wire encodings of ROS messages (docs/messages.md): ROS 2 CDR (XCDR1, little endian) and
ROS 1 (TCPROS body). Values are dicts (nested dicts for nested messages) or objects with the
field names as attributes (rosbags messages work).

CDR: 4-byte encapsulation header ``00 01 00 00``; alignment counted from the byte after it;
each primitive aligned to its size (at most 8); ``string`` = uint32 length including the NUL,
the bytes, NUL; sequences = uint32 count then the elements; fixed arrays have no count; an empty
message is one zero byte (rosidl's placeholder member). ROS 1: the same order with no alignment,
strings without NUL, and nothing for an empty message.
"""

import struct

from .model import Array, Named, Primitive

__all__ = ["STRUCT_FORMAT", "WireError", "encode_cdr", "decode_cdr", "encode_ros1", "decode_ros1",
           "CDR_LE_HEADER", "BYTE_ELEMENTS", "default_value"]

CDR_LE_HEADER = b"\x00\x01\x00\x00"

#: element types whose arrays and sequences are ``bytes`` in values (decoded and encoded)
BYTE_ELEMENTS = ("uint8", "byte", "char")

#: ROS primitive -> Python ``struct`` format character (little endian when prefixed ``<``)
STRUCT_FORMAT = {"bool": "?", "byte": "B", "char": "B", "int8": "b", "uint8": "B", "int16": "h",
           "uint16": "H", "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q",
           "float32": "f", "float64": "d"}


class WireError(ValueError):
    """A value that cannot be encoded, or bytes that cannot be decoded; names the field."""


def _get(value, name):
    if isinstance(value, dict):
        return value[name]
    return getattr(value, name)


class _Codec:
    def __init__(self, library, *, aligned, string_nul, empty_byte):
        self.library = library
        self.aligned = aligned
        self.string_nul = string_nul
        self.empty_byte = empty_byte

    # encoding ---------------------------------------------------------------------------
    def _pad(self, out, n):
        if self.aligned:
            out.extend(b"\x00" * (-len(out) % min(n, 8)))

    def encode(self, typename, value):
        out = bytearray()
        self._struct(out, typename, value, "")
        return bytes(out)

    def _struct(self, out, typename, value, path):
        definition = self.library[typename]
        if not definition.fields:
            if self.empty_byte:
                out.append(0)
            return
        for field in definition.fields:
            try:
                item = _get(value, field.name)
            except (KeyError, AttributeError):
                raise WireError(f"{typename}: value has no field {path}{field.name!r}") from None
            self._value(out, field.type, item, f"{path}{field.name}")

    def _value(self, out, type_, item, path):
        if isinstance(type_, Primitive):
            if type_.is_string:
                self._string(out, type_, item, path)
            else:
                size = struct.calcsize(STRUCT_FORMAT[type_.name])
                self._pad(out, size)
                try:
                    out.extend(struct.pack("<" + STRUCT_FORMAT[type_.name], item))
                except struct.error as exc:
                    raise WireError(f"{path}: {item!r} does not fit {type_.name} ({exc})") \
                        from None
        elif isinstance(type_, Named):
            self._struct(out, type_.typename, item, path + ".")
        else:
            items = list(item) if not isinstance(item, (bytes, bytearray)) else item
            if isinstance(type_, Array):
                if len(items) != type_.length:
                    raise WireError(f"{path}: {type_} needs {type_.length} elements, got "
                                    f"{len(items)}")
            else:
                if type_.bound and len(items) > type_.bound:
                    raise WireError(f"{path}: {len(items)} elements exceed the bound of {type_}")
                self._pad(out, 4)
                out.extend(struct.pack("<I", len(items)))
            element = type_.element
            if isinstance(element, Primitive) and element.name in BYTE_ELEMENTS \
                    and len(items):
                out.extend(items if isinstance(items, (bytes, bytearray))
                           else bytes(bytearray(int(x) for x in items)))
            else:
                for i, x in enumerate(items):
                    self._value(out, element, x, f"{path}[{i}]")

    def _string(self, out, type_, item, path):
        if type_.name == "wstring":
            raise WireError(f"{path}: wstring is not supported by rosgate's encoders")
        data = item.encode("utf-8") if isinstance(item, str) else bytes(item)
        if type_.bound and len(data) > type_.bound:
            raise WireError(f"{path}: {len(data)} bytes exceed {type_}")
        self._pad(out, 4)
        out.extend(struct.pack("<I", len(data) + self.string_nul))
        out.extend(data)
        if self.string_nul:
            out.append(0)

    # decoding ---------------------------------------------------------------------------
    def decode(self, typename, data, padding=0):
        self._data = memoryview(bytes(data))
        self._pos = 0
        value = self._read_struct(typename, "")
        left = len(self._data) - self._pos
        if left and (left > padding or any(self._data[self._pos:])):
            raise WireError(f"{typename}: {left} bytes left over")
        return value

    def _take(self, n, path):
        if self._pos + n > len(self._data):
            raise WireError(f"{path}: message ends early (need {n} bytes at {self._pos}, "
                            f"{len(self._data)} in all)")
        chunk = self._data[self._pos:self._pos + n]
        self._pos += n
        return chunk

    def _skip_pad(self, n, path):
        if self.aligned:
            pad = -self._pos % min(n, 8)
            if any(self._take(pad, path)):
                raise WireError(f"{path}: alignment padding is not zero")

    def _read_struct(self, typename, path):
        definition = self.library[typename]
        if not definition.fields:
            if self.empty_byte:
                self._take(1, path or typename)
            return {}
        return {f.name: self._read(f.type, f"{path}{f.name}") for f in definition.fields}

    def _count(self, path):
        self._skip_pad(4, path)
        return struct.unpack("<I", self._take(4, path))[0]

    def _read(self, type_, path):
        if isinstance(type_, Primitive):
            if type_.is_string:
                if type_.name == "wstring":
                    raise WireError(f"{path}: wstring is not supported by rosgate's decoders")
                n = self._count(path)
                raw = bytes(self._take(n, path))
                if self.string_nul:
                    if not raw or raw[-1] != 0:
                        raise WireError(f"{path}: string without its NUL terminator")
                    raw = raw[:-1]
                try:
                    return raw.decode("utf-8")
                except UnicodeDecodeError as exc:
                    raise WireError(f"{path}: string is not UTF-8 ({exc.reason} at byte "
                                    f"{exc.start})") from None
            fmt = STRUCT_FORMAT[type_.name]
            size = struct.calcsize(fmt)
            self._skip_pad(size, path)
            return struct.unpack("<" + fmt, self._take(size, path))[0]
        if isinstance(type_, Named):
            return self._read_struct(type_.typename, path + ".")
        if isinstance(type_, Array):
            count = type_.length
        else:
            count = self._count(path)
            if type_.bound and count > type_.bound:
                raise WireError(f"{path}: count {count} exceeds the bound of {type_}")
        element = type_.element
        if isinstance(element, Primitive) and element.name in BYTE_ELEMENTS:
            return bytes(self._take(count, path))
        return [self._read(element, f"{path}[{i}]") for i in range(count)]


def default_value(library, typename):
    """The value a message of ``typename`` has when nothing is set: numbers 0, ``False``,
    empty strings and sequences, fixed arrays of default elements (bytes for byte arrays)."""
    def of(type_):
        if isinstance(type_, Primitive):
            if type_.is_string:
                return ""
            return False if type_.name == "bool" else \
                0.0 if type_.name.startswith("float") else 0
        if isinstance(type_, Named):
            return default_value(library, type_.typename)
        byte_elements = isinstance(type_.element, Primitive) and \
            type_.element.name in BYTE_ELEMENTS
        if isinstance(type_, Array):
            return bytes(type_.length) if byte_elements else \
                [of(type_.element) for _ in range(type_.length)]
        return b"" if byte_elements else []
    return {f.name: of(f.type) for f in library[typename].fields}


def encode_cdr(library, typename, value):
    """XCDR1 little-endian bytes of ``value``, encapsulation header included."""
    codec = _Codec(library, aligned=True, string_nul=True, empty_byte=True)
    return CDR_LE_HEADER + codec.encode(library[typename].name, value)


def decode_cdr(library, typename, data, *, padded=False):
    """Inverse of :func:`encode_cdr`: a dict (bytes for uint8/byte/char arrays).

    ``padded``: accept up to 3 zero bytes after the value, as DDS samples are padded to a
    multiple of 4 (XTypes 7.4.3.5.3; the options' low 2 bits, when set, give the count)."""
    data = bytes(data)
    if len(data) < 4 or data[:2] != CDR_LE_HEADER[:2]:
        raise WireError(f"{typename}: not a little-endian CDR encapsulation "
                        f"(header {data[:4].hex()})")
    codec = _Codec(library, aligned=True, string_nul=True, empty_byte=True)
    return codec.decode(library[typename].name, data[4:], padding=3 if padded else 0)


def encode_ros1(library, typename, value):
    """ROS 1 message body (no length prefix); ``library`` should use the ROS 1 store."""
    codec = _Codec(library, aligned=False, string_nul=False, empty_byte=False)
    return codec.encode(library[typename].name, value)


def decode_ros1(library, typename, data):
    codec = _Codec(library, aligned=False, string_nul=False, empty_byte=False)
    return codec.decode(library[typename].name, data)
