"""All message types a project can use: ROS 2 standard interfaces (rosbags type store) plus the
project's own ``.msg``/``.srv``/``.action`` files."""

from pathlib import Path

from .model import (
    Array,
    Constant,
    Field,
    MessageDef,
    MessageDefinitionError,
    Named,
    Primitive,
    Sequence,
)
from .parser import parse_file

__all__ = ["MessageLibrary", "normalize_name"]


def normalize_name(name):
    """``pkg/Type`` -> ``pkg/msg/Type``; full names are kept."""
    parts = name.strip().split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return "/".join(parts)


def _from_rosbags(node):
    from rosbags.typesys.base import Nodetype
    kind, arg = node
    if kind == Nodetype.BASE:
        return Primitive(arg[0], arg[1])
    if kind == Nodetype.NAME:
        return Named(arg)
    if kind == Nodetype.ARRAY:
        return Array(_from_rosbags(arg[0]), arg[1])
    return Sequence(_from_rosbags(arg[0]), arg[1])


class MessageLibrary:
    """Message definitions by full name (``pkg/msg/Type``, ``pkg/srv/Name_Request``, ...).

    Parameters
    ----------
    folders : iterable of paths
        Project folders to scan recursively for ``.msg``, ``.srv`` and ``.action`` files.
    store : str
        rosbags type store of the standard interfaces (``"ros2_humble"`` by default).
    """

    def __init__(self, folders=(), store="ros2_humble"):
        from rosbags.typesys import Stores, get_typestore
        self.store_name = store
        self.typestore = get_typestore(Stores(store))
        self.types = {}
        for name, (consts, fields) in self.typestore.fielddefs.items():
            if [f[0] for f in fields] == ["structure_needs_at_least_one_member"]:
                fields = []  # rosbags' placeholder for an empty message (rosidl adds it back)
            self.types[name] = MessageDef(
                name, [Field(fname, _from_rosbags(node)) for fname, node in fields],
                [Constant(cname, Primitive(ctype), value) for cname, ctype, value in consts],
                f"<rosbags {store}>")
        self.project_types = []
        for folder in folders:
            for path in sorted(Path(folder).rglob("*")):
                if path.suffix in (".msg", ".srv", ".action") and path.is_file():
                    for definition in parse_file(path):
                        self.add(definition)
        self.check()

    def add(self, definition):
        if definition.name in self.types and not self.types[definition.name].source.startswith(
                "<rosbags"):
            raise MessageDefinitionError(definition.source, definition.line, definition.name,
                                         "type defined twice (also in "
                                         f"{self.types[definition.name].source})")
        self.types[definition.name] = definition
        self.project_types.append(definition.name)

    def __contains__(self, name):
        return normalize_name(name) in self.types

    def __getitem__(self, name):
        full = normalize_name(name)
        try:
            return self.types[full]
        except KeyError:
            raise KeyError(f"unknown message type {name!r}") from None

    def check(self):
        """Every nested type exists and no type contains itself."""
        for definition in self.types.values():
            for field in definition.fields:
                named = _named_of(field.type)
                if named is not None and named.typename not in self.types:
                    raise MessageDefinitionError(definition.source, field.line,
                                                 named.typename, "unknown type")
        state = {}

        def visit(name, chain):
            if state.get(name) == "done":
                return
            if state.get(name) == "active":
                definition = self.types[chain[0]]
                raise MessageDefinitionError(definition.source, definition.line, name,
                                             "type contains itself: " + " -> ".join(chain))
            state[name] = "active"
            for field in self.types[name].fields:
                named = _named_of(field.type)
                if named is not None:
                    visit(named.typename, chain + [named.typename])
            state[name] = "done"

        for name in self.types:
            visit(name, [name])

    def dependencies(self, name):
        """``name`` and every type it contains, dependencies first."""
        order, seen = [], set()

        def visit(n):
            if n in seen:
                return
            seen.add(n)
            for field in self.types[n].fields:
                named = _named_of(field.type)
                if named is not None:
                    visit(named.typename)
            order.append(n)

        visit(normalize_name(name))
        return order


def _named_of(type_):
    while isinstance(type_, (Array, Sequence)):
        type_ = type_.element
    return type_ if isinstance(type_, Named) else None
