"""rosbags as the golden model of message encodings, and random message values.

The rosbags type store parses the project's .msg/.srv files with rosbags' own parser, so the
golden bytes depend on rosgate's parser nowhere.
"""

import struct
from pathlib import Path

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from gen.msg.model import Array, Named, Primitive, Sequence
from gen.msg.wire import BYTE_ELEMENTS, STRUCT_FORMAT

__all__ = ["golden_store", "random_value", "random_primitive", "to_rosbags", "ByteRam",
           "random_field_value"]

# rosbags reads `byte` as int8 (ROS 1's meaning); rosidl (ROS 2) makes it an unsigned octet.
# The byte on the wire is the same, so only the Python representation is converted.
_NUMPY = {"bool": np.bool_, "byte": np.int8, "char": np.uint8, "int8": np.int8,
          "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16, "int32": np.int32,
          "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64, "float32": np.float32,
          "float64": np.float64}


def golden_store(store, folders=()):
    """A rosbags type store with the project's .msg, .srv and .action types registered."""
    ts = get_typestore(Stores(store))
    types = {}
    for folder in folders:
        for path in sorted(Path(folder).rglob("*")):
            package = path.parent.parent.name
            if path.suffix == ".msg":
                types.update(get_types_from_msg(path.read_text(),
                                                f"{package}/msg/{path.stem}"))
            elif path.suffix == ".srv":
                request, response = path.read_text().split("---\n")
                for part, suffix in ((request, "Request"), (response, "Response")):
                    name = f"{package}/srv/{path.stem}_{suffix}"
                    parsed = get_types_from_msg(part, name)
                    types.update({name: value for value in parsed.values()})
            elif path.suffix == ".action":
                parts = path.read_text().split("---\n")
                for part, suffix in zip(parts, ("Goal", "Result", "Feedback")):
                    name = f"{package}/action/{path.stem}_{suffix}"
                    parsed = get_types_from_msg(part, name)
                    types.update({name: value for value in parsed.values()})
    ts.register(types)
    return ts


def random_primitive(name, rng, bound=0):
    if name == "bool":
        return rng.random() < 0.5
    if name in ("string",):
        n = rng.randint(0, bound or 12)
        return "".join(rng.choice("abcxyz019_ #=") for _ in range(n))
    if name == "float32":
        return struct.unpack("<f", struct.pack("<f", rng.uniform(-1e6, 1e6)))[0]
    if name == "float64":
        return rng.uniform(-1e12, 1e12)
    bits = {"byte": 8, "char": 8, "int8": 8, "uint8": 8, "int16": 16, "uint16": 16,
            "int32": 32, "uint32": 32, "int64": 64, "uint64": 64}[name]
    if name.startswith("int"):
        return rng.randint(-(1 << (bits - 1)), (1 << (bits - 1)) - 1)
    return rng.randint(0, (1 << bits) - 1)


def random_sequence(element, n, rng):
    """``n`` random elements of the primitive type ``element``: ``bytes`` for
    :data:`BYTE_ELEMENTS`, else a list."""
    if element in BYTE_ELEMENTS:
        return rng.randbytes(n)
    return [random_primitive(element, rng) for _ in range(n)]


def random_value(library, typename, rng, max_len=6):
    """A random value (dicts) of ``typename``; uint8/byte/char arrays as ``bytes``."""
    def value(type_):
        if isinstance(type_, Primitive):
            return random_primitive(type_.name, rng, type_.bound)
        if isinstance(type_, Named):
            return random_value(library, type_.typename, rng, max_len)
        if isinstance(type_, Array):
            n = type_.length
        else:
            n = rng.randint(0, type_.bound or max_len)
        element = type_.element
        if isinstance(element, Primitive) and element.name in BYTE_ELEMENTS:
            return rng.randbytes(n)
        return [value(element) for _ in range(n)]

    return {f.name: value(f.type) for f in library[typename].fields}


def to_rosbags(ts, library, typename, value):
    """Build the rosbags message object holding ``value``."""
    definition = library[typename]
    cls = ts.types[definition.name]

    def convert(type_, item):
        if isinstance(type_, Named):
            return to_rosbags(ts, library, type_.typename, item)
        if isinstance(type_, (Array, Sequence)):
            element = type_.element
            if isinstance(element, Primitive) and not element.is_string:
                if isinstance(item, (bytes, bytearray)):
                    return np.frombuffer(bytes(item), dtype=_NUMPY[element.name]).copy()
                return np.array(item, dtype=_NUMPY[element.name])
            return [convert(element, x) for x in item]
        if isinstance(type_, Primitive) and type_.name == "byte":
            return item - 256 if item > 127 else item
        return item

    if not definition.fields:
        return cls()
    return cls(**{f.name: convert(f.type, value[f.name]) for f in definition.fields})


class ByteRam:
    """Bytes in a ``bytearray`` with the ``read``/``write`` of a simulated memory: the
    physical memory of a process memory model outside a simulator."""

    def __init__(self, size):
        self.data = bytearray(size)

    def read(self, addr, n):
        return bytes(self.data[addr:addr + n])

    def write(self, addr, data):
        self.data[addr:addr + len(data)] = data


def random_field_value(library, type_, rng, depth=0):
    """A random value of field type ``type_`` that a rosidl struct holds exactly (floats
    rounded to their width, sequences of 0..3 elements, nesting cut at depth 4)."""
    if isinstance(type_, Named):
        return {f.name: random_field_value(library, f.type, rng, depth + 1)
                for f in library[type_.typename].fields}
    if isinstance(type_, Primitive):
        if type_.is_string:
            n = rng.randrange(0, (type_.bound or 12) + 1)
            return "".join(rng.choice("abcxyz_/0") for _ in range(n))
        if type_.name == "bool":
            return rng.random() < 0.5
        if type_.name.startswith("float"):
            return struct.unpack("<" + STRUCT_FORMAT[type_.name], struct.pack(
                "<" + STRUCT_FORMAT[type_.name], rng.uniform(-1e3, 1e3)))[0]
        size = struct.calcsize(STRUCT_FORMAT[type_.name])
        if type_.name.startswith("int"):
            return rng.randrange(-(1 << (8 * size - 1)), 1 << (8 * size - 1))
        return rng.randrange(1 << (8 * size))
    n = type_.length if isinstance(type_, Array) else \
        rng.randrange(0, min(type_.bound or 3, 3) + 1) if depth < 4 else 0
    items = [random_field_value(library, type_.element, rng, depth + 1) for _ in range(n)]
    if isinstance(type_.element, Primitive) and type_.element.name in BYTE_ELEMENTS:
        return bytes(items)
    return items
