"""Stream plans: what a hardware (de)serializer moves, in order, for one message type and one
framing.

A plan splits a message into the *fixed part* (every primitive and fixed-size array, plus the
element count of every variable-length field) and the *variable-length fields* (strings and
sequences of primitives). The fixed part is an Amaranth :class:`~amaranth.lib.data.StructLayout`
that mirrors the message (nested messages are nested structs, ``T[N]`` is an array, a
variable-length field holds its element count as ``unsigned(32)``); each variable-length field
travels on its own byte stream.

The plan is a list of :class:`Step`:

``run``
    a static number of bytes made of :class:`Part` (constants, zero padding, fixed-part fields,
    counts, the ROS 1 length prefix, ...);
``pad``
    zero bytes up to a runtime alignment (CDR after a variable-length field);
``payload``
    the bytes of one variable-length field (its count times the element size).

Framings (``FRAMINGS``):

``cdr``
    ROS 2 XCDR1 little endian (docs/messages.md): 4-byte encapsulation header, alignment counted
    after it, strings with a NUL counted in their length, no padding before the elements of an
    empty sequence.
``ros1``
    one TCPROS message (docs/messages.md): ``uint32`` body length, then the body, unaligned.
``reconros``
    ReconROS hardware topics (docs/topics.md), 64-bit beats, with the defects D2-D5 fixed: beat
    0 and
    1 carry publisher id + 1000, then every primitive in ReconROS' flattening order (nested
    fields after top-level ones) as one beat each (signed values sign-extended, floats bit-cast,
    bool/byte/char carried), then the arrays by element width (8, 16, 32, 64 bits), each as
    size, capacity and its bytes in ceil(bytes / 8) beats, then a trailer beat repeating the
    previous one.
"""

from dataclasses import dataclass, field

from amaranth.hdl import signed, unsigned
from amaranth.lib import data

from hdl.params import ParameterError, check_choice

from .model import PRIMITIVES, Named, Primitive, Sequence

__all__ = ["FRAMINGS", "Leaf", "Variable", "Part", "Step", "StreamPlan", "stream_plan",
           "CDR_HEADER", "RECONROS_ID_OFFSET"]

FRAMINGS = ("cdr", "ros1", "reconros")

#: CDR_LE encapsulation; a reader checks the representation id (first two bytes) only.
CDR_HEADER = b"\x00\x01\x00\x00"
CDR_HEADER_MASK = b"\xff\xff\x00\x00"
#: ReconROS beat 0 = publisher thread id + 1000 (docs/topics.md)
RECONROS_ID_OFFSET = 1000

_SIGNED = {"int8", "int16", "int32", "int64"}


@dataclass(frozen=True)
class Leaf:
    """A member of the fixed part: its dotted path, bit offset in the struct, width in bits,
    the ROS element type (``count`` for a count, ``publisher`` for the ReconROS id) and how many
    elements it holds (``T[N]``)."""
    path: str
    offset: int
    width: int
    type: str
    length: int = 1

    @property
    def signed(self):
        return self.type in _SIGNED

    @property
    def element_bytes(self):
        return self.width // 8 // self.length


@dataclass(frozen=True)
class Variable:
    """A variable-length field: a string or a sequence of primitives."""
    index: int
    path: str
    element: str          #: ROS element type; ``char`` for strings
    element_bytes: int
    string: bool
    bound: int            #: declared bound (0: unbounded)
    count: Leaf           #: where the fixed part holds its element count
    nul: bool = False     #: the count on the wire includes a terminating NUL (CDR strings)

    @property
    def port_name(self):
        """Name of its stream port: ``header.frame_id`` -> ``header_frame_id``."""
        return self.path.replace(".", "_").replace("[", "").replace("]", "")


@dataclass(frozen=True)
class Part:
    """A static-length piece of a ``run`` step.

    kind: ``const`` (``value``; a reader checks the bytes selected by ``mask``), ``zero``
    (padding that must be zero), ``nul`` (a string's terminator, must be zero), ``reserved``
    (written as zero, not checked), ``field`` (``leaf``'s bytes), ``extend`` (``leaf``
    sign/zero-extended to ``nbytes``), ``count`` (element count of variable ``var``, plus one
    for a CDR string), ``capacity`` (ReconROS: the same count), ``length`` (ROS 1 body length),
    ``publisher`` (ReconROS id + 1000; ``leaf`` is the fixed part's ``publisher``),
    ``trailer`` (ReconROS: repeats the previous beat).
    """
    kind: str
    nbytes: int
    leaf: Leaf = None
    var: int = None
    value: bytes = b""
    mask: bytes = b""
    path: str = ""

    def describe(self):
        if self.kind == "const":
            return f"const {self.value.hex(' ')}"
        if self.kind in ("field", "extend"):
            what = f"{self.leaf.type}[{self.leaf.length}]" if self.leaf.length > 1 \
                else self.leaf.type
            return f"{self.kind} {self.leaf.path} {what} {self.nbytes} B"
        if self.kind in ("count", "capacity"):
            return f"{self.kind} of {self.path} {self.nbytes} B"
        return f"{self.kind} {self.nbytes} B" + (f" {self.path}" if self.path else "")


@dataclass(frozen=True)
class Step:
    """``run`` (``parts``), ``pad`` (to ``align``; only when variable ``var``'s count is not
    zero if ``var`` is set; ``check``: the reader requires zeros) or ``payload`` (``var``)."""
    kind: str
    parts: tuple = ()
    align: int = 0
    var: int = None
    check: bool = True

    @property
    def nbytes(self):
        return sum(p.nbytes for p in self.parts)


@dataclass
class StreamPlan:
    """The plan of ``typename`` in ``framing``; see the module documentation."""
    typename: str
    framing: str
    layout: data.StructLayout
    leaves: list
    variables: list
    steps: list = field(default_factory=list)

    @property
    def origin(self):
        """Byte position alignment is counted from (after the CDR header)."""
        return 4 if self.framing == "cdr" else 0

    @property
    def publisher_offset(self):
        """ReconROS: beat 0 carries the publisher id plus this."""
        return RECONROS_ID_OFFSET

    @property
    def data_width(self):
        """Beat width the framing is defined for (``None``: any)."""
        return 64 if self.framing == "reconros" else None

    def static_bytes(self):
        """Bytes of all ``run`` steps."""
        return sum(s.nbytes for s in self.steps if s.kind == "run")

    def describe(self):
        lines = [f"{self.typename} framing {self.framing}: {len(self.steps)} steps, "
                 f"fixed part {self.layout.size} bits, {len(self.variables)} variable-length "
                 f"field(s)"]
        for v in self.variables:
            kind = "string" if v.string else f"sequence<{v.element}>"
            lines.append(f"  stream {v.port_name}: {kind}"
                         + (f" bound {v.bound}" if v.bound else ""))
        for i, s in enumerate(self.steps):
            if s.kind == "run":
                lines.append(f"  {i:3d} run {s.nbytes} B: "
                             + " | ".join(p.describe() for p in s.parts))
            elif s.kind == "pad":
                cond = f" if {self.variables[s.var].path} is not empty" if s.var is not None \
                    else ""
                lines.append(f"  {i:3d} pad to {s.align}{cond}"
                             + ("" if s.check else " (not checked)"))
            else:
                v = self.variables[s.var]
                lines.append(f"  {i:3d} payload {v.path}: count x {v.element_bytes} B")
        return "\n".join(lines)


class _Node:
    """Message tree: ``prim`` (leaf), ``var`` (variable), ``struct`` (a nested message:
    children), ``array`` (``T[N]`` of messages or strings: one child per element), ``empty``."""

    def __init__(self, kind, path, leaf=None, var=None, children=(), prim_bytes=0):
        self.kind, self.path, self.leaf, self.var = kind, path, leaf, var
        self.children = list(children)
        self.prim_bytes = prim_bytes


class _Builder:
    def __init__(self, library, typename, framing):
        self.library = library
        self.typename = library[typename].name
        self.framing = framing
        self.leaves = []
        self.variables = []

    def _primitive_shape(self, name):
        size = PRIMITIVES[name]
        return signed(size * 8) if name in _SIGNED else unsigned(size * 8)

    def struct(self, typename, prefix, offset):
        definition = self.library[typename]
        members, nodes, size = {}, [], 0
        if not definition.fields:
            return data.StructLayout({}), [_Node("empty", prefix.rstrip("."))]
        for f in definition.fields:
            shape, node = self.member(f.type, prefix + f.name, offset + size)
            members[f.name] = shape
            nodes.append(node)
            size += data.Layout.cast(shape).size if isinstance(shape, data.Layout) \
                else shape.width
        return data.StructLayout(members), nodes

    def member(self, type_, path, offset):
        if isinstance(type_, Primitive) and not type_.is_string:
            shape = self._primitive_shape(type_.name)
            leaf = Leaf(path, offset, shape.width, type_.name)
            self.leaves.append(leaf)
            return shape, _Node("prim", path, leaf=leaf, prim_bytes=PRIMITIVES[type_.name])
        if isinstance(type_, Primitive) or isinstance(type_, Sequence):
            return unsigned(32), self._variable(type_, path, offset)
        if isinstance(type_, Named):
            layout, children = self.struct(type_.typename, path + ".", offset)
            return layout, _Node("struct", path, children=children)
        # Array
        element = type_.element
        if isinstance(element, Primitive) and not element.is_string:
            shape = self._primitive_shape(element.name)
            leaf = Leaf(path, offset, shape.width * type_.length, element.name, type_.length)
            self.leaves.append(leaf)
            return (data.ArrayLayout(shape, type_.length),
                    _Node("prim", path, leaf=leaf, prim_bytes=PRIMITIVES[element.name]))
        shapes, children, size = [], [], 0
        for i in range(type_.length):
            shape, node = self.member(element, f"{path}[{i}]", offset + size)
            shapes.append(shape)
            children.append(node)
            size += data.Layout.cast(shape).size if isinstance(shape, data.Layout) \
                else shape.width
        return data.ArrayLayout(shapes[0], type_.length), _Node("array", path,
                                                                children=children)

    def _variable(self, type_, path, offset):
        if isinstance(type_, Primitive):
            if type_.name == "wstring":
                raise ParameterError("typename", self.typename,
                                     f"a type without wstring fields ({path} is a wstring)")
            element, nbytes, string, bound = "char", 1, True, type_.bound
        else:
            element_type = type_.element
            if not isinstance(element_type, Primitive) or element_type.is_string:
                raise ParameterError(
                    "typename", self.typename,
                    "a type whose variable-length fields are strings or sequences of "
                    f"primitives ({path} is {type_})")
            element, nbytes, string, bound = (element_type.name, PRIMITIVES[element_type.name],
                                              False, type_.bound)
        leaf = Leaf(path, offset, 32, "count")
        self.leaves.append(leaf)
        var = Variable(len(self.variables), path, element, nbytes, string, bound, leaf,
                       nul=string and self.framing == "cdr")
        self.variables.append(var)
        return _Node("var", path, var=var)


class _Runs:
    """Collects parts into ``run`` steps; other steps close the current run."""

    def __init__(self):
        self.steps, self.parts = [], []

    def part(self, part):
        if part.nbytes:
            self.parts.append(part)

    def step(self, step):
        self.flush()
        self.steps.append(step)

    def flush(self):
        if self.parts:
            self.steps.append(Step("run", tuple(self.parts)))
            self.parts = []


def _cdr(nodes):
    runs = _Runs()
    runs.part(Part("const", 4, value=CDR_HEADER, mask=CDR_HEADER_MASK, path="encapsulation"))
    state = {"align": 8, "offset": 0}  # position mod align is known statically

    def advance(n):
        state["offset"] = (state["offset"] + n) % state["align"]

    def align(a):
        if a <= state["align"]:
            n = -state["offset"] % a
            runs.part(Part("zero", n))
            advance(n)
        else:
            runs.step(Step("pad", align=a))
            state["align"], state["offset"] = a, 0

    def walk(node):
        if node.kind in ("struct", "array"):
            for child in node.children:
                walk(child)
        elif node.kind == "empty":
            runs.part(Part("reserved", 1, path=node.path or "empty message"))
            advance(1)
        elif node.kind == "prim":
            align(min(node.prim_bytes, 8))
            runs.part(Part("field", node.leaf.width // 8, leaf=node.leaf))
            advance(node.leaf.width // 8)
        else:
            v = node.var
            align(4)
            runs.part(Part("count", 4, var=v.index, path=v.path))
            advance(4)
            if v.element_bytes == 8:
                runs.step(Step("pad", align=8, var=v.index))
            runs.step(Step("payload", var=v.index))
            if v.string:
                runs.part(Part("nul", 1, path=v.path))
                state["align"], state["offset"] = 1, 0
            else:
                state["align"], state["offset"] = min(4, v.element_bytes), 0

    for node in nodes:
        walk(node)
    runs.flush()
    return runs.steps


def _ros1(nodes):
    runs = _Runs()
    runs.part(Part("length", 4, path="message length"))

    def walk(node):
        if node.kind in ("struct", "array"):
            for child in node.children:
                walk(child)
        elif node.kind == "prim":
            runs.part(Part("field", node.leaf.width // 8, leaf=node.leaf))
        elif node.kind == "var":
            runs.part(Part("count", 4, var=node.var.index, path=node.var.path))
            runs.step(Step("payload", var=node.var.index))

    for node in nodes:
        walk(node)
    runs.flush()
    return runs.steps


def reconros_order(nodes):
    """ReconROS' flattening (docs/topics.md, ``msg_parsing._deep_replace``), one nesting level per
    round: every nested message is removed and its fields appended at the end, in order; then
    every fixed array of messages is removed and its elements' fields appended at the end."""
    items = list(nodes)
    while any(n.kind in ("struct", "array") for n in items):
        structs = [n for n in items if n.kind == "struct"]
        items = [n for n in items if n.kind != "struct"] + [c for n in structs
                                                            for c in n.children]
        arrays = [n for n in items if n.kind == "array"]
        items = [n for n in items if n.kind != "array"] + [
            c for n in arrays for element in n.children
            for c in (element.children if element.kind == "struct" else [element])]
    return [n for n in items if n.kind != "empty"]


def _reconros(nodes, publisher):
    runs = _Runs()
    runs.part(Part("publisher", 8, leaf=publisher, path="beat 0"))
    runs.part(Part("publisher", 8, leaf=publisher, path="beat 1"))
    items = reconros_order(nodes)
    arrays = []
    for node in items:
        if node.kind == "prim" and node.leaf.length == 1:
            runs.part(Part("extend", 8, leaf=node.leaf))
        else:
            arrays.append(node)
    width = {n: (1 if n.kind == "var" and n.var.string else
                 n.var.element_bytes if n.kind == "var" else n.leaf.element_bytes)
             for n in arrays}
    for size in (1, 2, 4, 8):
        for node in (n for n in arrays if width[n] == size):
            if node.kind == "var":
                v = node.var
                runs.part(Part("count", 8, var=v.index, path=v.path))
                runs.part(Part("capacity", 8, var=v.index, path=v.path))
                runs.step(Step("payload", var=v.index))
                runs.step(Step("pad", align=8, check=False))
            else:
                leaf = node.leaf
                n = leaf.length.to_bytes(8, "little")
                runs.part(Part("const", 8, value=n, mask=b"\xff" * 8, path=f"{leaf.path} size"))
                runs.part(Part("const", 8, value=n, mask=b"\x00" * 8,
                               path=f"{leaf.path} capacity"))
                runs.part(Part("field", leaf.width // 8, leaf=leaf))
                runs.part(Part("reserved", -(leaf.width // 8) % 8, path=f"{leaf.path} pad"))
    runs.part(Part("trailer", 8, path="repeat of the previous beat"))
    runs.flush()
    return runs.steps


def stream_plan(library, typename, framing="cdr"):
    """Return the :class:`StreamPlan` of ``typename`` (a name in ``library``) in ``framing``.

    Use a ROS 1 library (``store="ros1_noetic"``) for ``ros1``: its ``std_msgs/Header`` has
    ``seq``. Raises :class:`~hdl.params.ParameterError` for a framing not in
    :data:`FRAMINGS` or a type with a field hardware cannot stream (wstring, a sequence of
    strings or of messages).
    """
    check_choice("framing", framing, FRAMINGS)
    builder = _Builder(library, typename, framing)
    publisher = None
    if framing == "reconros":
        publisher = Leaf("publisher", 0, 32, "publisher")
        builder.leaves.append(publisher)
        inner, nodes = builder.struct(builder.typename, "", 32)
        layout = data.StructLayout({"publisher": unsigned(32),
                                    **{name: m.shape for name, m in inner}})
    else:
        layout, nodes = builder.struct(builder.typename, "", 0)
    steps = {"cdr": lambda: _cdr(nodes), "ros1": lambda: _ros1(nodes),
             "reconros": lambda: _reconros(nodes, publisher)}[framing]()
    return StreamPlan(builder.typename, framing, layout, builder.leaves, builder.variables,
                      steps)
