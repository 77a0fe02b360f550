"""What the hardware (de)serializer ports carry for a message value, from its stream plan.

The fixed part is the plan's struct layout filled from the value (little-endian bit packing,
floats as IEEE-754 bits, bool/byte/char as octets); each variable-length field is its raw
bytes (strings without NUL, elements little endian). The golden wire bytes come from rosbags
(CDR, ROS 1) or :func:`reconros_beats` (docs/topics.md, with rosgate's fixes), never from the RTL.
"""

import re
import struct

from gen.msg.model import PRIMITIVES, Array, Named, Primitive
from gen.msg.plan import RECONROS_ID_OFFSET
from gen.msg.wire import STRUCT_FORMAT

__all__ = ["fixed_part", "variable_bytes", "leaf_values", "expected_fields", "reconros_beats",
           "value_at", "set_at", "reconros_fields", "plan_encode"]


def _keys(path):
    """``"pair[1].b"`` -> ``["pair", 1, "b"]``."""
    return [name or int(index) for name, index in re.findall(r"([^.\[\]]+)|\[(\d+)\]", path)]


def value_at(value, path):
    """``value_at(v, "pair[1].b")`` -> ``v["pair"][1]["b"]``."""
    for key in _keys(path):
        value = value[key]
    return value


def set_at(value, path, item):
    """Set the member of ``value`` at ``path`` (as :func:`value_at` reads it) to ``item``."""
    *head, last = _keys(path)
    target = value
    for key in head:
        target = target[key]
    target[last] = item


def _element_bytes(element, items):
    if isinstance(items, (bytes, bytearray)):
        return bytes(items)
    return b"".join(struct.pack("<" + STRUCT_FORMAT[element], x) for x in items)


def _raw(value):
    return value.encode() if isinstance(value, str) else bytes(value)


def variable_bytes(plan, value, packed=None):
    """The bytes of every stream, in ``plan.streams`` order. A sequence of messages or strings
    is its elements packed: ``packed(element type, element)`` gives one element's bytes (the
    bench uses rosbags' ROS 1 serializer; a string is its uint32 length and bytes)."""
    out = []
    for v in plan.streams:
        item = value_at(value, v.path)
        if v.elements:
            out.append(b"".join(packed(v.element, x) for x in item))
        else:
            out.append(_raw(item) if v.string else _element_bytes(v.element, item))
    return out


def fixed_part(plan, value, publisher=0):
    """The fixed part as an integer (bit 0 = struct bit 0)."""
    bits = 0
    for leaf in plan.leaves:
        if leaf.type == "publisher":
            raw = publisher.to_bytes(4, "little")
        elif leaf.type == "count":
            item = value_at(value, leaf.path)
            v = next(x for x in plan.variables if x.path == leaf.path)
            n = len(_raw(item)) if v.string else len(item)
            raw = n.to_bytes(4, "little")
        else:
            item = value_at(value, leaf.path)
            items = item if leaf.length > 1 else [item]
            raw = _element_bytes(leaf.type, items)
        bits |= int.from_bytes(raw, "little") << leaf.offset
    return bits


def leaf_values(plan, bits):
    """Split a fixed-part integer into ``{path: raw bytes}``."""
    return {leaf.path: ((bits >> leaf.offset) & ((1 << leaf.width) - 1)).to_bytes(
        leaf.width // 8, "little") for leaf in plan.leaves}


def expected_fields(plan, value, publisher=0):
    """``{path: raw bytes}`` the deserializer must show for ``value``."""
    return leaf_values(plan, fixed_part(plan, value, publisher))


def reconros_fields(library, typename):
    """``[(path, type)]`` in ReconROS' flattening order (docs/topics.md; ReconROS
    ``msg_parsing._deep_replace``): per round, nested messages are replaced by their fields
    appended at the end, then fixed arrays of messages by their elements' fields."""
    items = [(f.name, f.type) for f in library[typename].fields]

    def nested(t):
        return isinstance(t, Named)

    def message_array(t):
        return isinstance(t, Array) and isinstance(t.element, Named)

    while any(nested(t) or message_array(t) for _, t in items):
        out = [(k, t) for k, t in items if not nested(t)]
        for k, t in items:
            if nested(t):
                out += [(f"{k}.{f.name}", f.type) for f in library[t.typename].fields]
        items = out
        out = [(k, t) for k, t in items if not message_array(t)]
        for k, t in items:
            if message_array(t):
                for i in range(t.length):
                    out += [(f"{k}[{i}].{f.name}", f.type)
                            for f in library[t.element.typename].fields]
        items = out
    return items


def reconros_beats(library, typename, value, publisher):
    """ReconROS framing (docs/topics.md, with D2-D5 fixed) of ``value``:
    a list of ``(tdata, tuser, tlast)`` 64-bit beats, written from the spec."""
    beats = [publisher + RECONROS_ID_OFFSET] * 2
    arrays = {1: [], 2: [], 4: [], 8: []}
    for path, type_ in reconros_fields(library, typename):
        item = value_at(value, path)
        if isinstance(type_, Primitive) and not type_.is_string:
            raw = _element_bytes(type_.name, [item])
            number = int.from_bytes(raw, "little")
            if type_.name.startswith("int") and number >> (8 * len(raw) - 1):
                number |= ((1 << 64) - 1) ^ ((1 << 8 * len(raw)) - 1)  # sign-extend
            beats.append(number)
        elif isinstance(type_, Primitive):
            arrays[1].append((len(_raw(item)), _raw(item)))
        else:
            name = type_.element.name
            arrays[PRIMITIVES[name]].append((len(item), _element_bytes(name, item)))
    for size in (1, 2, 4, 8):
        for count, raw in arrays[size]:
            beats += [count, count]
            raw += b"\x00" * (-len(raw) % 8)
            beats += [int.from_bytes(raw[i:i + 8], "little") for i in range(0, len(raw), 8)]
    beats.append(beats[-1])
    n = len(beats)
    return [(data, int(0 < i < n - 1), int(i == n - 1)) for i, data in enumerate(beats)]


def plan_encode(plan, value, publisher=0):
    """Execute ``plan`` in Python: the bytes a serializer following it emits for ``value``.

    Lets the plans themselves be checked against rosbags, apart from the hardware. Loops run
    once per element; a path with ``[]`` names the element of the loop over that prefix."""
    bits = fixed_part(plan, value, publisher)
    at = {}                                        # loop variable path -> element index

    def item(path):
        *outer, last = path.split("[]")
        prefix, current = "", value
        for piece in outer:
            prefix += piece
            current = value_at(current, piece.lstrip(".")) if piece.lstrip(".") else current
            current = current[at[prefix]]
            prefix += "[]"
        return value_at(current, last.lstrip(".")) if last.lstrip(".") else current

    def raw(v):
        x = item(v.path)
        return _raw(x) if v.string else _element_bytes(v.element, x)

    top_counts = {v.index: len(_raw(x) if v.string else x)
                  for v in plan.streams for x in [value_at(value, v.path)]}
    counts = {}
    left = {}
    out = bytearray()
    i = 0
    while i < len(plan.steps):
        step = plan.steps[i]
        v = plan.variables[step.var] if step.var is not None else None
        if step.kind in ("payload", "count", "loop", "pad") and v is not None \
                and v.path not in counts:
            x = item(v.path)
            counts[v.path] = len(_raw(x) if v.string else x)
        if step.kind == "payload":
            out += raw(v)
            del counts[v.path]
        elif step.kind == "count":
            out += (counts[v.path] + v.nul).to_bytes(4, "little")
        elif step.kind == "loop":
            left[v.path] = counts.pop(v.path)
            at[v.path] = 0
            if not left[v.path]:
                i = step.target
        elif step.kind == "next":
            left[v.path] -= 1
            at[v.path] += 1
            if left[v.path]:
                i = step.target
        elif step.kind == "pad":
            if step.var is None or counts[v.path]:
                out += bytes(-(len(out) - plan.origin) % step.align)
        else:
            for part in step.parts:
                if part.kind == "element":
                    x = item(part.path)
                    out += _element_bytes(part.leaf.type, x if part.leaf.length > 1 else [x])
                else:
                    out += _part_bytes(plan, part, bits, top_counts, 0, publisher, out)
        i += 1
    if plan.framing == "ros1":
        out[:4] = (len(out) - 4).to_bytes(4, "little")
    return bytes(out)


def _part_bytes(plan, part, bits, counts, body, publisher, out):
    n = part.nbytes
    if part.kind == "const":
        return part.value
    if part.kind in ("zero", "nul", "reserved"):
        return bytes(n)
    if part.kind in ("field", "extend"):
        leaf = part.leaf
        raw = (bits >> leaf.offset) & ((1 << leaf.width) - 1)
        if part.kind == "extend" and leaf.signed and raw >> (leaf.width - 1):
            raw -= 1 << leaf.width
        return (raw % (1 << 8 * n)).to_bytes(n, "little")
    if part.kind == "count":
        return (counts[part.var] + plan.variables[part.var].nul).to_bytes(n, "little")
    if part.kind == "capacity":
        return counts[part.var].to_bytes(n, "little")
    if part.kind == "length":
        return body.to_bytes(n, "little")
    if part.kind == "publisher":
        return (publisher + RECONROS_ID_OFFSET).to_bytes(n, "little")
    if part.kind == "trailer":
        return bytes(out[-8:])
    raise ValueError(part.kind)
