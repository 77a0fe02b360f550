"""rosidl C struct layout (docs/reconos.md): what hardware threads address over MEMIF.

A message is a C struct of its fields in order, each at its natural alignment; nested
messages are embedded structs; ``string`` is ``rosidl_runtime_c__String {char *data; size_t
size; size_t capacity}`` (``wstring``: ``uint16_t *data``), ``T[]``/``T[<=N]`` are
``{T *data; size_t size; size_t capacity}``, ``T[N]`` is an inline C array; a struct's alignment
is its largest member's and its size is rounded up to it; an empty message gets rosidl's
``uint8_t structure_needs_at_least_one_member``.
"""

from dataclasses import dataclass

from .model import PRIMITIVES, Array, Named, Primitive, Sequence

__all__ = ["ARCHES", "CLayout", "Member", "StructLayout", "c_identifier", "c_type_name"]

#: arch -> (pointer and size_t bytes, alignment of 8-byte scalars); arm32 = ARM EABI (ILP32)
ARCHES = {"arm32": (4, 8), "arm64": (8, 8), "x86_64": (8, 8)}

_C_PRIMITIVE = {
    "bool": "bool", "byte": "uint8_t", "char": "uint8_t", "int8": "int8_t", "uint8": "uint8_t",
    "int16": "int16_t", "uint16": "uint16_t", "int32": "int32_t", "uint32": "uint32_t",
    "int64": "int64_t", "uint64": "uint64_t", "float32": "float", "float64": "double",
}


def c_identifier(typename):
    """``sensor_msgs/msg/Image`` -> ``sensor_msgs__msg__Image`` (rosidl's C name)."""
    return typename.replace("/", "__")


def c_type_name(type_):
    """The C type rosidl uses for a field type (sequences and strings by their struct name)."""
    if isinstance(type_, Primitive):
        if type_.name == "string":
            return "rosidl_runtime_c__String"
        if type_.name == "wstring":
            return "rosidl_runtime_c__U16String"
        return _C_PRIMITIVE[type_.name]
    if isinstance(type_, Named):
        return c_identifier(type_.typename)
    if isinstance(type_, Sequence):
        element = type_.element
        if isinstance(element, Primitive):
            if element.is_string:
                return c_type_name(element) + "__Sequence"
            return f"rosidl_runtime_c__{element.name}__Sequence"
        return c_identifier(element.typename) + "__Sequence"
    raise TypeError(f"no C type name for {type_}")


@dataclass(frozen=True)
class Member:
    """One member of a C struct: field name, offset, size, alignment, C type, ROS type."""
    name: str
    offset: int
    size: int
    align: int
    ctype: str
    type: object
    count: int = 0  # > 0 for a fixed array


@dataclass(frozen=True)
class StructLayout:
    name: str
    size: int
    align: int
    members: tuple


class CLayout:
    """Layouts of the types of a :class:`~gen.msg.MessageLibrary` for one architecture."""

    def __init__(self, library, arch):
        if arch not in ARCHES:
            raise ValueError(f"arch must be one of {', '.join(ARCHES)}, not {arch!r}")
        self.library = library
        self.arch = arch
        self.pointer, self.align8 = ARCHES[arch]
        self._cache = {}

    def _scalar(self, size):
        return size, (self.align8 if size == 8 else size)

    def size_align(self, type_):
        """``(size, alignment)`` of a field type."""
        if isinstance(type_, Primitive):
            if type_.is_string:
                return 3 * self.pointer, self.pointer
            return self._scalar(PRIMITIVES[type_.name])
        if isinstance(type_, Named):
            layout = self.struct(type_.typename)
            return layout.size, layout.align
        if isinstance(type_, Sequence):
            return 3 * self.pointer, self.pointer
        if isinstance(type_, Array):
            size, align = self.size_align(type_.element)
            return size * type_.length, align
        raise TypeError(f"unknown field type {type_!r}")

    def struct(self, name):
        """The :class:`StructLayout` of message type ``name``."""
        definition = self.library[name]
        if definition.name in self._cache:
            return self._cache[definition.name]
        offset, align, members = 0, 1, []
        fields = definition.fields or []
        if not fields:
            members.append(Member("structure_needs_at_least_one_member", 0, 1, 1, "uint8_t",
                                  Primitive("uint8")))
            offset = 1
        for field in fields:
            size, falign = self.size_align(field.type)
            offset = -(-offset // falign) * falign
            count = field.type.length if isinstance(field.type, Array) else 0
            ctype = c_type_name(field.type.element if count else field.type)
            members.append(Member(field.name, offset, size, falign, ctype, field.type, count))
            offset += size
            align = max(align, falign)
        layout = StructLayout(definition.name, -(-offset // align) * align, align,
                              tuple(members))
        self._cache[definition.name] = layout
        return layout

    def flat(self, name, prefix="", base=0):
        """Leaves ``(path, offset, size, ctype)`` in memory order: nested structs expanded,
        strings and sequences as ``.data`` (pointer), ``.size``, ``.capacity``, fixed arrays of
        primitives as one leaf, fixed arrays of messages element by element (``path[i]``)."""
        leaves = []
        for member in self.struct(name).members:
            path = f"{prefix}{member.name}"
            offset = base + member.offset
            type_ = member.type
            if isinstance(type_, Array) and isinstance(type_.element, Named):
                esize = member.size // type_.length
                for i in range(type_.length):
                    leaves += self.flat(type_.element.typename, f"{path}[{i}].", offset + i * esize)
            elif isinstance(type_, Array) and isinstance(type_.element, Primitive) \
                    and type_.element.is_string:
                esize = member.size // type_.length
                for i in range(type_.length):
                    leaves += self._triple(f"{path}[{i}]", offset + i * esize, "char *")
            elif isinstance(type_, Named):
                leaves += self.flat(type_.typename, path + ".", offset)
            elif isinstance(type_, Sequence) or (isinstance(type_, Primitive) and type_.is_string):
                leaves += self._triple(path, offset, member.ctype)
            else:
                leaves.append((path, offset, member.size, member.ctype))
        return leaves

    def _triple(self, path, offset, ctype):
        p = self.pointer
        return [(f"{path}.data", offset, p, "pointer"), (f"{path}.size", offset + p, p, "size_t"),
                (f"{path}.capacity", offset + 2 * p, p, "size_t")]
