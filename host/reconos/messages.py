"""ROS messages as rosidl C structs in the process memory (the layout of
:class:`gen.msg.layout.CLayout` for the system's architecture)."""

import struct

from gen.msg.model import Array, Named, Primitive
from gen.msg.wire import BYTE_ELEMENTS
from gen.msg.wire import STRUCT_FORMAT as _FMT

__all__ = ["MessageMemory", "image_message"]


class MessageMemory:
    """ROS messages as rosidl C structs in :class:`ProcessMemory` (docs/reconos.md).

    Values are dicts of field name to value: primitives as ints/floats, strings as ``str``,
    nested messages as dicts, ``uint8``/``byte``/``char`` sequences and arrays as ``bytes``,
    other sequences and arrays of primitives as lists.

    As rosidl's generated functions do, storing a value into a struct (``__assign``, a take)
    first frees the strings and sequences the struct held (``__fini``), and resizing a
    sequence (``ROS_MESSAGE_SET_SIZE``) frees its old buffer once the elements are copied. A
    pointer that is not the start of a heap block (the hardware wrote it) is left alone and
    counted in :attr:`foreign`.
    """

    def __init__(self, memory, library):
        from gen.msg.layout import CLayout
        self.mem = memory
        self.library = library
        self.layout = CLayout(library, "arm64" if memory.arch.name == "r64" else "arm32")
        self.p = self.layout.pointer
        #: pointers found in a struct being finalised that no heap block starts at
        self.foreign = 0

    def sizeof(self, type_name):
        return self.layout.struct(type_name).size

    def create(self, type_name):
        """``pkg__msg__Type__create()``: a zeroed struct; return its VA."""
        return self.mem.malloc(self.sizeof(type_name))

    def _ptr(self, va, value=None):
        if value is None:
            return int.from_bytes(self.mem.read(va, self.p), "little")
        self.mem.write(va, value.to_bytes(self.p, "little"))

    def member(self, type_name, path):
        """Byte offset of a field path (``"data"``, ``"header.stamp.sec"``)."""
        offset = 0
        for part in path.split("."):
            s = self.layout.struct(type_name)
            mem = next(m for m in s.members if m.name == part)
            offset += mem.offset
            type_name = getattr(mem.type, "typename", None)
        return offset

    def set_sequence(self, va, elem_size, count):
        """``ROS_MESSAGE_SET_SIZE``: reallocate the sequence at ``va`` for ``count`` elements
        (keeping the old contents), size = capacity = count; return the data pointer."""
        old, size, cap = self._ptr(va), self._ptr(va + self.p), self._ptr(va + 2 * self.p)
        if count != cap:
            data = self.mem.malloc(count * elem_size) if count else 0
            if old and data:
                self.mem.write(data, self.mem.read(old, min(size, count) * elem_size))
            self._release(old)
            self._ptr(va, data)
        self._ptr(va + self.p, count)
        self._ptr(va + 2 * self.p, count)
        return self._ptr(va)

    def _primitive_size(self, name):
        return struct.calcsize("<" + _FMT[name])

    def _release(self, ptr):
        if not ptr:
            return
        if self.mem.owns(ptr):
            self.mem.free(ptr)
        else:
            self.foreign += 1

    def fini(self, va, type_name):
        """``pkg__msg__Type__fini``: free every string and sequence the struct at ``va``
        holds (nested ones first) and zero their pointers; the struct itself stays."""
        self._fini_value(va, Named(type_name))

    def _fini_value(self, at, t):
        if isinstance(t, Named):
            for m in self.layout.struct(t.typename).members:
                self._fini_value(at + m.offset, m.type)
        elif isinstance(t, Primitive) and t.is_string:
            self._drop_sequence(at)
        elif isinstance(t, Primitive) or \
                isinstance(t, Array) and isinstance(t.element, Primitive) and \
                not t.element.is_string:
            return
        elif isinstance(t.element, Primitive) and not t.element.is_string:
            self._drop_sequence(at)
        else:
            size, _ = self.layout.size_align(t.element)
            base, n = (at, t.length) if isinstance(t, Array) else \
                (self._ptr(at), self._ptr(at + self.p))
            if base and (isinstance(t, Array) or self.mem.owns(base)):
                for i in range(n):
                    self._fini_value(base + i * size, t.element)
            if not isinstance(t, Array):
                self._drop_sequence(at)

    def _drop_sequence(self, at):
        """Free the buffer of the string or sequence ``{data, size, capacity}`` at ``at``
        and zero it."""
        self._release(self._ptr(at))
        for k in range(3):
            self._ptr(at + k * self.p, 0)

    def write(self, va, type_name, value):
        """Store ``value`` in the struct at ``va``: what the struct held is freed
        (:meth:`fini`), strings and sequences get new buffers (``malloc``), as rosidl's
        ``__assign`` functions do."""
        self.fini(va, type_name)
        self._store(va, type_name, value)

    def _store(self, va, type_name, value):
        for m in self.layout.struct(type_name).members:
            if m.name == "structure_needs_at_least_one_member":
                continue
            self._write_value(va + m.offset, m.type, value[m.name])

    def _write_value(self, at, t, v):
        if isinstance(t, Named):
            self._store(at, t.typename, v)
        elif isinstance(t, Primitive) and t.is_string:
            if t.name == "wstring":
                raise TypeError("the co-simulation model does not store wstring")
            raw = v.encode() + b"\0"
            buf = self.mem.malloc(len(raw))
            self.mem.write(buf, raw)
            self._ptr(at, buf)
            self._ptr(at + self.p, len(raw) - 1)
            self._ptr(at + 2 * self.p, len(raw))
        elif isinstance(t, Primitive):
            self.mem.write(at, struct.pack("<" + _FMT[t.name], v))
        elif isinstance(t.element, Primitive) and not t.element.is_string:
            raw = self._pack_elements(t.element, v)
            if isinstance(t, Array):
                self.mem.write(at, raw)
            else:
                n = len(v)
                buf = self.mem.malloc(max(len(raw), 1)) if n else 0
                if n:
                    self.mem.write(buf, raw)
                self._ptr(at, buf)
                self._ptr(at + self.p, n)
                self._ptr(at + 2 * self.p, n)
        else:
            # strings or messages: each element is a String or a struct of the element size
            size, _ = self.layout.size_align(t.element)
            base = at
            if not isinstance(t, Array):
                base = self.mem.malloc(size * len(v)) if len(v) else 0
                self._ptr(at, base)
                self._ptr(at + self.p, len(v))
                self._ptr(at + 2 * self.p, len(v))
            for i, item in enumerate(v):
                self._write_value(base + i * size, t.element, item)

    def _pack_elements(self, element, v):
        if isinstance(v, (bytes, bytearray)):
            return bytes(v)
        return struct.pack(f"<{len(v)}{_FMT[element.name]}", *v)

    def read(self, va, type_name):
        """The value of the struct at ``va`` (the inverse of :meth:`write`)."""
        out = {}
        for m in self.layout.struct(type_name).members:
            if m.name == "structure_needs_at_least_one_member":
                continue
            out[m.name] = self._read_value(va + m.offset, m.type)
        return out

    def _read_value(self, at, t):
        if isinstance(t, Named):
            return self.read(at, t.typename)
        if isinstance(t, Primitive) and t.is_string:
            ptr, n = self._ptr(at), self._ptr(at + self.p)
            return self.mem.read(ptr, n).decode() if n else ""
        if isinstance(t, Primitive):
            raw = self.mem.read(at, self._primitive_size(t.name))
            return struct.unpack("<" + _FMT[t.name], raw)[0]
        if isinstance(t, Array):
            ptr, n = at, t.length
        else:
            ptr, n = self._ptr(at), self._ptr(at + self.p)
        if isinstance(t.element, Primitive) and not t.element.is_string:
            esz = self._primitive_size(t.element.name)
            raw = self.mem.read(ptr, n * esz) if n else b""
            if t.element.name in BYTE_ELEMENTS:
                return raw
            return list(struct.unpack(f"<{n}{_FMT[t.element.name]}", raw))
        size, _ = self.layout.size_align(t.element)
        return [self._read_value(ptr + i * size, t.element) for i in range(n)]


#: bytes per pixel of the encodings :func:`random_image_message` chooses from
IMAGE_CHANNELS = {"bgr8": 3, "rgb8": 3, "mono8": 1, "mono16": 2}


def random_image_message(rng, max_side, *, min_side=1):
    """A random ``sensor_msgs/Image`` value from ``rng`` (a :class:`random.Random`):
    ``min_side`` to ``max_side`` pixels a side, one of the :data:`IMAGE_CHANNELS` encodings,
    a random stamp, frame id and ``is_bigendian`` flag, random bytes."""
    width = rng.randrange(min_side, max_side + 1)
    height = rng.randrange(min_side, max_side + 1)
    encoding = rng.choice(tuple(IMAGE_CHANNELS))
    step = width * IMAGE_CHANNELS[encoding]
    return {"header": {"stamp": {"sec": rng.randrange(-(1 << 31), 1 << 31),
                                 "nanosec": rng.randrange(1 << 32)},
                       "frame_id": "".join(rng.choice("abcdefghij_/") for _ in
                                           range(rng.randrange(0, 20)))},
            "height": height, "width": width, "encoding": encoding,
            "is_bigendian": rng.randrange(2), "step": step,
            "data": rng.randbytes(step * height)}


def image_message(pixels, seq=0, *, encoding="bgr8", step=None, data=None, frame_id="camera"):
    """The ``sensor_msgs/Image`` value of the ``height x width x 3`` array ``pixels``, stamped
    ``seq`` seconds; ``encoding``, ``step`` and ``data`` override what the pixels give (for
    images a node must refuse)."""
    height, width = pixels.shape[:2]
    return {"header": {"stamp": {"sec": seq, "nanosec": 0}, "frame_id": frame_id},
            "height": height, "width": width, "encoding": encoding, "is_bigendian": 0,
            "step": 3 * width if step is None else step,
            "data": pixels.tobytes() if data is None else data}
