"""The type model of ROS 2 interface definitions (messages, and services/actions expanded)."""

from dataclasses import dataclass, field

__all__ = ["PRIMITIVES", "Primitive", "Named", "Array", "Sequence", "Field", "Constant",
           "MessageDef", "MessageDefinitionError"]

#: ROS 2 primitive -> size in bytes (strings: the element size)
PRIMITIVES = {
    "bool": 1, "byte": 1, "char": 1, "int8": 1, "uint8": 1, "int16": 2, "uint16": 2,
    "int32": 4, "uint32": 4, "int64": 8, "uint64": 8, "float32": 4, "float64": 8,
    "string": 1, "wstring": 2,
}


@dataclass(frozen=True)
class Primitive:
    """A primitive type; ``bound`` is the maximum length of a bounded string (0: unbounded)."""
    name: str
    bound: int = 0

    @property
    def is_string(self):
        return self.name in ("string", "wstring")

    def __str__(self):
        return f"{self.name}<={self.bound}" if self.bound else self.name


@dataclass(frozen=True)
class Named:
    """A nested message type, by its full name ``pkg/msg/Type``."""
    typename: str

    def __str__(self):
        return self.typename


@dataclass(frozen=True)
class Array:
    """``T[N]``: exactly ``length`` elements."""
    element: object
    length: int

    def __str__(self):
        return f"{self.element}[{self.length}]"


@dataclass(frozen=True)
class Sequence:
    """``T[]`` or ``T[<=N]`` (``bound`` 0: unbounded)."""
    element: object
    bound: int = 0

    def __str__(self):
        return f"{self.element}[<={self.bound}]" if self.bound else f"{self.element}[]"


@dataclass(frozen=True)
class Field:
    name: str
    type: object
    default: object = None
    line: int = 0


@dataclass(frozen=True)
class Constant:
    name: str
    type: Primitive
    value: object


@dataclass
class MessageDef:
    """One message type: full name, fields in order, constants, and where it was defined."""
    name: str
    fields: list
    constants: list = field(default_factory=list)
    source: str = "<builtin>"
    line: int = 0

    @property
    def package(self):
        return self.name.split("/")[0]


class MessageDefinitionError(ValueError):
    """A bad interface definition: names the file, the line and the offending token."""

    def __init__(self, source, line, token, message):
        self.source, self.line, self.token = source, line, token
        where = f"{source}:{line}" if line else str(source)
        super().__init__(f"{where}: {message}" + (f" ({token!r})" if token is not None else ""))
