"""Stream plans: what a hardware (de)serializer moves, in order, for one message type and one
framing.

A plan splits a message into the *fixed part* (every primitive and fixed-size array, plus the
element count of every variable-length field) and the *variable-length fields* (strings,
sequences of primitives, and sequences of messages or strings). The fixed part is an Amaranth
:class:`~amaranth.lib.data.StructLayout` that mirrors the message (nested messages are nested
structs, ``T[N]`` is an array, a variable-length field holds its element count as
``unsigned(32)``); each variable-length field travels on its own byte stream
(:attr:`StreamPlan.streams`).

A sequence of messages or of strings streams its elements *packed*, one after the other: every
primitive little endian and unaligned in declaration order, fixed arrays without a count,
strings and sequences as a ``uint32`` element count (no NUL) followed by their elements. This is
the ROS 1 encoding of each element, the same in every framing. The strings and sequences inside
the elements are *inner* variables (:attr:`Variable.into`): they have a count register but no
stream of their own.

The plan is a list of :class:`Step`:

``run``
    a static number of bytes made of :class:`Part` (constants, zero padding, fixed-part fields,
    counts, the ROS 1 length prefix, ...);
``pad``
    zero bytes up to a runtime alignment (CDR after a variable-length field);
``payload``
    the bytes of one string or sequence of primitives (its count times the element size);
``loop`` / ``next``
    the elements of a sequence of messages or strings: the steps between them (the *body*) run
    once per element; ``loop`` jumps past its ``next`` (``target``) when the count is zero,
    ``next`` back to the step after its ``loop`` (``target``) until the count is done;
``count``
    the count of an inner variable: four bytes on the wire, four in the packed element.

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

from dataclasses import dataclass, field, replace

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
    """A variable-length field: a string, a sequence of primitives, or a sequence of messages or
    strings (``elements``)."""
    index: int
    path: str
    element: str          #: ROS element type; ``char`` for strings, ``string`` or a message type
    element_bytes: int    #: bytes per element (``elements``: packed, 0 if the size varies)
    string: bool
    bound: int            #: declared bound (0: unbounded)
    count: Leaf           #: where the fixed part holds its element count (``None`` if inner)
    nul: bool = False     #: the count on the wire includes a terminating NUL (CDR strings)
    elements: bool = False  #: a sequence of messages or strings, streamed packed
    into: int = None      #: inner: the variable whose stream carries it (``None``: its own)

    @property
    def port_name(self):
        """Name of its stream port: ``header.frame_id`` -> ``header_frame_id``."""
        return self.path.replace(".", "_").replace("[", "").replace("]", "")


@dataclass(frozen=True)
class Part:
    """A static-length piece of a ``run`` step.

    kind: ``const`` (``value``; a reader checks the bytes selected by ``mask``), ``element``
    (bytes of a primitive inside an element: copied between the wire and the packed stream
    of variable ``var``), ``zero``
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
        if self.kind == "element":
            return f"element {self.path} {self.nbytes} B"
        return f"{self.kind} {self.nbytes} B" + (f" {self.path}" if self.path else "")


@dataclass(frozen=True)
class Step:
    """``run`` (``parts``), ``pad`` (to ``align``; only when variable ``var``'s count is not
    zero if ``var`` is set; ``check``: the reader requires zeros), ``payload`` (``var``),
    ``count`` (of inner variable ``var``), ``loop`` and ``next`` (of variable ``var``; ``target``
    is the index of the other one)."""
    kind: str
    parts: tuple = ()
    align: int = 0
    var: int = None
    check: bool = True
    target: int = None

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

    @property
    def streams(self):
        """The variables with a stream port of their own (all but the inner ones)."""
        return [v for v in self.variables if v.into is None]

    def stream_of(self, var):
        """The variable whose stream carries variable ``var``'s bytes."""
        v = self.variables[var]
        return v if v.into is None else self.variables[v.into]

    def step_streams(self):
        """Per step, the index of the stream whose elements it is inside (``None`` outside
        loops; ``loop`` and ``next`` steps are outside their own loop)."""
        out, loops = [], []
        for s in self.steps:
            if s.kind == "next":
                loops.pop()
            out.append(self.stream_of(loops[0]).index if loops else None)
            if s.kind == "loop":
                loops.append(s.var)
        return out

    def static_bytes(self):
        """Bytes of all ``run`` steps outside loops."""
        return sum(s.nbytes for s, stream in zip(self.steps, self.step_streams())
                   if s.kind == "run" and stream is None)

    def describe(self):
        lines = [f"{self.typename} framing {self.framing}: {len(self.steps)} steps, "
                 f"fixed part {self.layout.size} bits, {len(self.variables)} variable-length "
                 f"field(s) on {len(self.streams)} stream(s)"]
        for v in self.streams:
            kind = "string" if v.string else f"sequence<{v.element}>" + (
                " packed" if v.elements else "")
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
            elif s.kind == "payload":
                v = self.variables[s.var]
                lines.append(f"  {i:3d} payload {v.path}: count x {v.element_bytes} B")
            elif s.kind == "count":
                lines.append(f"  {i:3d} count of {self.variables[s.var].path} 4 B")
            elif s.kind == "loop":
                lines.append(f"  {i:3d} loop over the elements of {self.variables[s.var].path}"
                             f" (empty: to {s.target + 1})")
            else:
                lines.append(f"  {i:3d} next element of {self.variables[s.var].path}"
                             f" (back to {s.target + 1})")
        return "\n".join(lines)


class _Node:
    """Message tree: ``prim`` (leaf), ``var`` (string or sequence of primitives), ``loop`` (a
    sequence of messages or strings: one child, the element), ``struct`` (a nested message:
    children), ``array`` (``T[N]`` of messages or strings: one child per element), ``empty``.
    ``in_loop``: inside a loop's elements (a ``prim``'s leaf is not in the fixed part)."""

    def __init__(self, kind, path, leaf=None, var=None, children=(), prim_bytes=0, nbytes=0,
                 in_loop=False):
        self.kind, self.path, self.leaf, self.var = kind, path, leaf, var
        self.in_loop = in_loop
        self.children = list(children)
        self.prim_bytes = prim_bytes
        self.nbytes = nbytes


def _packed_bytes(node):
    """Packed size of an element (``None`` if it holds strings or sequences)."""
    if node.kind == "prim":
        return node.nbytes
    if node.kind == "empty":
        return 0
    if node.kind in ("struct", "array"):
        sizes = [_packed_bytes(c) for c in node.children]
        return None if None in sizes else sum(sizes)
    return None


class _Builder:
    def __init__(self, library, typename, framing):
        self.library = library
        self.typename = library[typename].name
        self.framing = framing
        self.leaves = []
        self.variables = []
        self._into = None     # inside the elements of this variable's stream

    def _primitive_shape(self, name):
        size = PRIMITIVES[name]
        return signed(size * 8) if name in _SIGNED else unsigned(size * 8)

    def _leaf(self, leaf):
        """``leaf``, a member of the fixed part unless inside a loop's elements."""
        if self._into is None:
            self.leaves.append(leaf)
        return leaf

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
            leaf = self._leaf(Leaf(path, offset, shape.width, type_.name))
            return shape, _Node("prim", path, leaf=leaf, prim_bytes=PRIMITIVES[type_.name],
                                nbytes=PRIMITIVES[type_.name], in_loop=self._into is not None)
        if isinstance(type_, Primitive) or isinstance(type_, Sequence):
            return unsigned(32), self._variable(type_, path, offset)
        if isinstance(type_, Named):
            layout, children = self.struct(type_.typename, path + ".", offset)
            return layout, _Node("struct", path, children=children)
        # Array
        element = type_.element
        if isinstance(element, Primitive) and not element.is_string:
            shape = self._primitive_shape(element.name)
            leaf = self._leaf(Leaf(path, offset, shape.width * type_.length, element.name,
                                   type_.length))
            return (data.ArrayLayout(shape, type_.length),
                    _Node("prim", path, leaf=leaf, prim_bytes=PRIMITIVES[element.name],
                          nbytes=PRIMITIVES[element.name] * type_.length,
                          in_loop=self._into is not None))
        shapes, children, size = [], [], 0
        for i in range(type_.length):
            shape, node = self.member(element, f"{path}[{i}]", offset + size)
            shapes.append(shape)
            children.append(node)
            size += data.Layout.cast(shape).size if isinstance(shape, data.Layout) \
                else shape.width
        return data.ArrayLayout(shapes[0], type_.length), _Node("array", path,
                                                                children=children)

    def _refuse_wstring(self, type_, path):
        if isinstance(type_, Primitive) and type_.name == "wstring":
            raise ParameterError("typename", self.typename,
                                 f"a type without wstring fields ({path} is a wstring: its "
                                 "wire format differs between ROS 2 middlewares)")

    def _variable(self, type_, path, offset):
        self._refuse_wstring(type_, path)
        element_type = None
        if isinstance(type_, Primitive):
            element, nbytes, string, bound = "char", 1, True, type_.bound
        elif isinstance(type_.element, Primitive) and not type_.element.is_string:
            element, nbytes, string, bound = (type_.element.name, PRIMITIVES[type_.element.name],
                                              False, type_.bound)
        else:
            self._refuse_wstring(type_.element, path + "[]")
            if self.framing == "reconros":
                raise ParameterError(
                    "typename", self.typename,
                    "a type for the reconros framing without sequences of messages or strings "
                    f"(ReconROS' hardware framing has no encoding for {path}, {type_})")
            element_type = type_.element
            element = element_type.typename if isinstance(element_type, Named) else "string"
            nbytes, string, bound = None, False, type_.bound
        leaf = self._leaf(Leaf(path, offset, 32, "count"))
        var = Variable(len(self.variables), path, element, nbytes, string, bound, leaf,
                       nul=string and self.framing == "cdr", elements=element_type is not None,
                       into=self._into)
        self.variables.append(var)
        if element_type is None:
            return _Node("var", path, var=var)
        outer = self._into
        self._into = var.index if outer is None else outer
        _, body = self.member(element_type, path + "[]", 0)
        self._into = outer
        size = _packed_bytes(body)
        if size is not None:
            var = self.variables[var.index] = replace(var, element_bytes=size)
        return _Node("loop", path, var=var, children=[body])


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


def _count(runs, var):
    """The count of ``var``: a part of the fixed part, or a ``count`` step inside a loop."""
    if var.into is None:
        runs.part(Part("count", 4, var=var.index, path=var.path))
    else:
        runs.step(Step("count", var=var.index))


def _primitive(node):
    """The part of a primitive: a fixed-part field, or element bytes inside a loop."""
    if node.in_loop:
        return Part("element", node.nbytes, leaf=node.leaf, path=node.path)
    return Part("field", node.nbytes, leaf=node.leaf)


def _cdr_alignment(element):
    """The CDR alignment of a fixed-size ``element`` whose first primitive has the largest
    alignment in it and whose size is a multiple of that: the first element is aligned to it
    and every following one starts aligned. ``None`` for any other element."""
    prims, empty = [], [False]

    def collect(node):
        if node.kind in ("struct", "array"):
            for child in node.children:
                collect(child)
        elif node.kind == "prim":
            prims.append(node)
        elif node.kind == "empty":
            empty[0] = True
        else:
            raise LookupError
    try:
        collect(element)
    except LookupError:
        return None
    a = max([min(p.prim_bytes, 8) for p in prims] + [1])
    offset = 0
    for p in prims:
        offset += -offset % min(p.prim_bytes, 8) + p.nbytes
    if empty[0] or not prims or min(prims[0].prim_bytes, 8) != a or offset % a:
        return None
    return a


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

    def unknown():
        state["align"], state["offset"] = 1, 0

    def walk(node):
        if node.kind in ("struct", "array"):
            for child in node.children:
                walk(child)
        elif node.kind == "empty":
            runs.part(Part("reserved", 1, path=node.path or "empty message"))
            advance(1)
        elif node.kind == "prim":
            align(min(node.prim_bytes, 8))
            runs.part(_primitive(node))
            advance(node.nbytes)
        elif node.kind == "loop":
            align(4)
            _count(runs, node.var)
            advance(4)
            element = node.children[0]
            a = _cdr_alignment(element)
            if a is None:
                runs.step(Step("loop", var=node.var.index))
                unknown()        # each element starts where the previous one ended
                walk(element)
                runs.step(Step("next", var=node.var.index))
                unknown()
                return
            # fixed-size elements that end aligned as they start: one padding before the
            # first (none for an empty sequence), none between them
            if a > state["align"] or -state["offset"] % a:
                runs.step(Step("pad", align=a, var=node.var.index))
            runs.step(Step("loop", var=node.var.index))
            state["align"], state["offset"] = a, 0
            walk(element)
            assert state["offset"] == 0, node.path
            runs.step(Step("next", var=node.var.index))
            state["align"], state["offset"] = min(a, 4), 0
        else:
            v = node.var
            align(4)
            _count(runs, v)
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
            runs.part(_primitive(node))
        elif node.kind == "loop":
            _count(runs, node.var)
            runs.step(Step("loop", var=node.var.index))
            walk(node.children[0])
            runs.step(Step("next", var=node.var.index))
        elif node.kind == "var":
            _count(runs, node.var)
            runs.step(Step("payload", var=node.var.index))

    for node in nodes:
        walk(node)
    runs.flush()
    return runs.steps


def _link_loops(steps):
    """Set ``target`` of every ``loop`` and ``next`` step to the index of the other."""
    steps, open_loops = list(steps), []
    for i, s in enumerate(steps):
        if s.kind == "loop":
            open_loops.append(i)
        elif s.kind == "next":
            start = open_loops.pop()
            steps[start] = replace(steps[start], target=i)
            steps[i] = replace(s, target=start)
    return steps


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
    :data:`FRAMINGS` or a type with a field hardware cannot stream (wstring; in the reconros
    framing, a sequence of messages or strings).
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
    steps = _link_loops({"cdr": lambda: _cdr(nodes), "ros1": lambda: _ros1(nodes),
                         "reconros": lambda: _reconros(nodes, publisher)}[framing]())
    return StreamPlan(builder.typename, framing, layout, builder.leaves, builder.variables,
                      steps)
