"""ROS 1 type identity: the md5sum TCPROS headers carry (genmsg ``compute_md5_text``,
docs/messages.md).

md5 text of a message: one line per constant ``TYPE NAME=VALUE``, then one line per field:
``TYPE NAME`` for built-in types (primitives, ``time``, ``duration``, with their array suffix),
``MD5 NAME`` for a nested message (the nested type's md5, array suffix dropped); lines joined
by newlines, no trailing newline. A service's md5 is the md5 of the request's md5 text
followed directly by the response's.
"""

import hashlib

from .model import Array, Named, Primitive, Sequence

__all__ = ["md5_text", "md5sum", "service_md5sum", "message_definition", "ros1_name",
           "encode_connection_header", "decode_connection_header", "frame_message",
           "ConnectionHeaderError"]

_BUILTIN_NAMED = {"builtin_interfaces/msg/Time": "time",
                  "builtin_interfaces/msg/Duration": "duration"}


def ros1_name(typename):
    """``pkg/msg/Type`` -> ``pkg/Type`` (the spelling of TCPROS ``type`` and definitions)."""
    parts = typename.split("/")
    return f"{parts[0]}/{parts[-1]}" if len(parts) == 3 and parts[1] == "msg" else typename


def _ros1_type(type_, short=False):
    if isinstance(type_, Primitive):
        return f"{type_.name}<={type_.bound}" if type_.bound else type_.name
    if isinstance(type_, Named):
        name = _BUILTIN_NAMED.get(type_.typename, type_.typename)
        return ros1_name(name) if short else name
    suffix = f"[{type_.length}]" if isinstance(type_, Array) else \
        (f"[<={type_.bound}]" if type_.bound else "[]")
    return _ros1_type(type_.element, short) + suffix


def _constant_text(const):
    value = const.value
    if isinstance(value, bool):
        value = int(value)
    return f"{const.type.name} {const.name}={value}"


def md5_text(library, typename):
    """The text whose md5 is the ROS 1 md5sum of ``typename``."""
    definition = library[typename]
    lines = [_constant_text(c) for c in definition.constants]
    for field in definition.fields:
        base = field.type
        while isinstance(base, (Array, Sequence)):
            base = base.element
        if isinstance(base, Named) and base.typename not in _BUILTIN_NAMED:
            lines.append(f"{md5sum(library, base.typename)} {field.name}")
        else:
            lines.append(f"{_ros1_type(field.type)} {field.name}")
    return "\n".join(lines)


def md5sum(library, typename):
    """ROS 1 md5sum of message type ``typename`` (use a library on the ROS 1 store)."""
    return hashlib.md5(md5_text(library, typename).encode()).hexdigest()


def service_md5sum(library, request, response):
    """ROS 1 md5sum of a service from its request and response types."""
    text = md5_text(library, request) + md5_text(library, response)
    return hashlib.md5(text.encode()).hexdigest()


_SEPARATOR = "=" * 80


def _definition_text(library, typename):
    definition = library[typename]
    lines = [_constant_text(c) for c in definition.constants]
    lines += [f"{_ros1_type(f.type, short=True)} {f.name}" for f in definition.fields]
    return "".join(line + "\n" for line in lines)


def message_definition(library, typename):
    """The ``message_definition`` a TCPROS connection header carries (gendeps style): the
    type's constants and fields, then each nested type once, in order of first use, after a
    line of 80 ``=`` and ``MSG: pkg/Type``."""
    order, seen = [], set()

    def visit(name):
        for field in library[name].fields:
            base = field.type
            while isinstance(base, (Array, Sequence)):
                base = base.element
            if isinstance(base, Named) and base.typename not in _BUILTIN_NAMED \
                    and base.typename not in seen:
                seen.add(base.typename)
                order.append(base.typename)
                visit(base.typename)

    visit(library[typename].name)
    text = _definition_text(library, typename)
    for name in order:
        text += f"{_SEPARATOR}\nMSG: {ros1_name(name)}\n{_definition_text(library, name)}"
    return text


class ConnectionHeaderError(ValueError):
    """A TCPROS connection header that cannot be decoded; the message names the offset."""


def encode_connection_header(fields):
    """TCPROS connection header (docs/messages.md): ``uint32_le`` total length, then per field
    ``uint32_le`` length + ``key=value``. ``fields`` is a mapping or a sequence of pairs, kept
    in order."""
    items = fields.items() if hasattr(fields, "items") else fields
    body = b""
    for key, value in items:
        key = str(key)
        if not key or "=" in key:
            raise ValueError(f"connection header key {key!r} is empty or contains '='")
        raw = key.encode() + b"=" + (value if isinstance(value, bytes) else str(value).encode())
        body += len(raw).to_bytes(4, "little") + raw
    return len(body).to_bytes(4, "little") + body


def decode_connection_header(data, *, prefixed=False):
    """Inverse of :func:`encode_connection_header`: ``{key: value}``, each field split at its
    first ``=``. ``data`` is the header body, or with ``prefixed`` the whole header with its
    total length (which must match)."""
    data = bytes(data)
    if prefixed:
        if len(data) < 4 or int.from_bytes(data[:4], "little") != len(data) - 4:
            raise ConnectionHeaderError("total length at offset 0 does not match the data")
        data = data[4:]
    fields = {}
    pos = 0
    while pos < len(data):
        if pos + 4 > len(data):
            raise ConnectionHeaderError(f"field length cut off at offset {pos}")
        n = int.from_bytes(data[pos:pos + 4], "little")
        raw = data[pos + 4:pos + 4 + n]
        if len(raw) != n:
            raise ConnectionHeaderError(f"field of {n} bytes at offset {pos} runs past the end")
        if b"=" not in raw:
            raise ConnectionHeaderError(f"field at offset {pos} has no '=': {raw[:40]!r}")
        key, value = raw.split(b"=", 1)
        fields[key.decode()] = value.decode(errors="replace")
        pos += 4 + n
    return fields


def frame_message(body):
    """A TCPROS message on the wire: ``uint32_le`` length + the serialized body."""
    return len(body).to_bytes(4, "little") + bytes(body)
