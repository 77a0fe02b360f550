"""System assembly: a parsed project (:mod:`gen.config`) to one Amaranth design (
docs/reconos.md; docs/topics.md).

Discovery as in the fpgaDDS paper: each ReconOS thread is built into its slots, every
hardware topic becomes a :class:`~hdl.dds.Topic` whose topology follows from its publisher
and subscriber counts (docs/topics.md) with the subscribers' FIFOs, and the ReconOS
infrastructure is sized for the slots.

Thread implementations
----------------------
A ``[ReconosThread@X]`` is implemented in Amaranth by the Python file
``<project>/src/rt_<x>/amaranth/thread.py`` (``x`` in lower case, next to ReconROS' ``hls``
and ``vhdl`` folders). It defines ``build(ctx)`` returning a component with the slot ports of
:func:`hdl.reconos.ThreadSignature` plus one stream member per hardware-topic endpoint
(``ctx.endpoints``: ``In(HW_TOPIC_STREAM)`` for a subscription, ``Out`` for a publication,
named ``endpoint.port``). ``ctx`` is a :class:`ThreadContext`: the thread's handles by
resource name, struct offsets for the target ABI, the architecture. A thread without such a
file (an HLS or VHDL thread, or a ROS gateway) leaves its slot empty: the slot's FIFO ports
and its topic ports become ports of the system top, for a core made elsewhere.
"""

import contextlib
import importlib.util
import re
import sys
import threading
import traceback
from dataclasses import dataclass
from pathlib import Path

from amaranth.hdl import Module, Shape
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from hdl.dds import HW_TOPIC_STREAM, Topic
from hdl.params import read_as
from hdl.reconos import ReconosSystem, ThreadSignature
from hdl.stream import StreamFIFO

from .config import ConfigError, Location, project_library

__all__ = ["HW_TOPIC_STREAM", "ThreadContext", "HwCall", "SystemTop", "ThreadCodeError",
           "thread_code", "thread_module_path",
           "build_thread", "build_system", "thread_sources", "message_memory_layout"]



class ThreadContext:
    """What a project's ``build(ctx)`` gets.

    Attributes
    ----------
    project : gen.config.Project
    thread : gen.config.Thread
    slot : gen.config.Slot
        The slot being built (a thread may fill several).
    arch : str
        ``"r32"`` or ``"r64"``.
    endpoints : list of gen.config.HwEndpoint
        The thread's hardware-topic ports.
    stream : wiring.Signature
        :data:`HW_TOPIC_STREAM`.
    params : dict
        The thread's ``Parameters`` (build.cfg, overridden by ``--param``): name -> string.
    """

    def __init__(self, project, thread, slot, library):
        self.project = project
        self.thread = thread
        self.slot = slot
        self.arch = project.arch
        self.endpoints = thread.endpoints
        self.stream = HW_TOPIC_STREAM
        self.params = _ReadParameters(thread.params)
        self._library = library

    def param(self, name, default, kind=str):
        """The parameter ``name`` read as ``kind`` (``str``, ``int``, ``float``), ``default``
        when not set; a value that does not read as ``kind`` raises :class:`ValueError`
        naming it."""
        if name not in self.params:
            return default
        try:
            return read_as(kind, self.params[name])
        except ValueError as exc:
            raise ValueError(f"{name}={exc}") from None

    def handle(self, name):
        """The thread-local handle of resource ``name`` (``"sub"`` or ``"resourcedip_sub"``)."""
        return self.thread.handle(name)

    def offsets(self, type_name):
        """Byte offsets of the members of ``type_name`` in the rosidl C layout of the target."""
        from gen.msg.layout import CLayout
        layout = CLayout(self._library, "arm64" if self.arch == "r64" else "arm32")
        return {m.name: m.offset for m in layout.struct(type_name).members}

    def memory_layout(self, type_name):
        """Where the stream plan's parts of ``type_name`` are in its rosidl C struct (a
        :class:`hdl.reconos.gateway.MemoryLayout` for the target)."""
        return message_memory_layout(self._library, type_name, self.arch)

    def topic_gateway(self, msgtype, *, to_hw=None, from_hw=None, **options):
        """A :class:`hdl.reconos.TopicGatewayThread` for this thread's hardware topic of
        ``msgtype``: ``to_hw=(sub, msg)`` takes messages from the software subscription
        ``sub`` (into message ``msg``) and publishes them on the hardware topic;
        ``from_hw=(pub, msg)`` publishes what the hardware topic carries on ``pub``. Resource
        names as in the build.cfg."""
        from gen.msg.plan import stream_plan
        from hdl.reconos.gateway import TopicGatewayThread
        typename = self._library[msgtype].name
        ports = {ep.direction: ep.port for ep in self.endpoints
                 if self._library[ep.msgtype].name == typename}
        for wanted, direction in ((to_hw, "pub"), (from_hw, "sub")):
            if wanted is not None and direction not in ports:
                raise ConfigError(self.thread.where, f"thread {self.thread.name}: no hardware "
                                                     f"topic {direction} of {typename}")
        return TopicGatewayThread(
            self.arch, plan=stream_plan(self._library, typename, "reconros"),
            layout=self.memory_layout(typename), publisher_id=self.thread.id,
            to_hw=tuple(map(self.handle, to_hw)) if to_hw else None,
            from_hw=tuple(map(self.handle, from_hw)) if from_hw else None,
            out_port=ports.get("pub", "topic_out"), in_port=ports.get("sub", "topic_in"),
            **options)

    def service_gateway(self, server, client, **options):
        """A :class:`hdl.reconos.ServiceGatewayThread` that serves this thread's software
        service ``server`` (a ``rossrvs``) by calling the service over hardware topics with
        its ``client`` (a ``rossrvc`` ending in ``hw``) of the same type. Resource names as
        in the build.cfg."""
        from gen.msg.plan import stream_plan
        from hdl.reconos.service_gateway import ServiceGatewayThread
        call = self.hw_call(client)
        message = self._server_message(server, "rossrvs", "_req", "_Request", call.interface)
        return ServiceGatewayThread(
            self.arch,
            request_plan=stream_plan(self._library, f"{call.interface}_Request"),
            reply_plan=stream_plan(self._library, f"{call.interface}_Response"),
            request_layout=message_memory_layout(self._library, f"{call.interface}_Request",
                                                 self.arch, "cdr"),
            reply_layout=message_memory_layout(self._library, f"{call.interface}_Response",
                                               self.arch, "cdr"),
            client_id=self.thread.id + 1, h_srvs=self.handle(server),
            h_req=self.handle(f"{message}_req"), h_res=self.handle(f"{message}_res"),
            request_port=call.request_port, reply_port=call.reply_port, **options)

    def action_gateway(self, server, client, **options):
        """A :class:`hdl.reconos.ActionGatewayThread` that serves this thread's software
        action ``server`` (a ``rosactions``) by sending its goals to the action over hardware
        topics with its ``client`` (a ``rosactionc`` ending in ``hw``) of the same type."""
        from gen.msg.layout import CLayout
        from gen.msg.plan import stream_plan
        from hdl.reconos.action_gateway import ActionGatewayThread
        call = self.hw_call(client)
        action = call.interface
        message = self._server_message(server, "rosactions", "_goal_req", "_SendGoal_Request",
                                       action)

        def nested(part, outer, member):
            return message_memory_layout(self._library, f"{action}_{part}", self.arch, "cdr",
                                         within=(f"{action}_{outer}", member))
        response = CLayout(self._library, "arm64" if self.arch == "r64" else "arm32").struct(
            self._library[f"{action}_GetResult_Response"].name)
        return ActionGatewayThread(
            self.arch,
            goal_plan=stream_plan(self._library, f"{action}_Goal"),
            feedback_plan=stream_plan(self._library, f"{action}_Feedback"),
            result_plan=stream_plan(self._library, f"{action}_Result"),
            goal_layout=nested("Goal", "SendGoal_Request", "goal"),
            feedback_layout=nested("Feedback", "FeedbackMessage", "feedback"),
            result_layout=nested("Result", "GetResult_Response", "result"),
            status_offset=next(mb.offset for mb in response.members if mb.name == "status"),
            client_id=self.thread.id + 1, h_as=self.handle(server),
            h_goal=self.handle(f"{message}_goal_req"),
            h_res=self.handle(f"{message}_result_res"), h_fb=self.handle(f"{message}_feedback"),
            request_port=call.request_port, reply_port=call.reply_port, **options)

    def _server_message(self, name, kind, part, type_part, interface):
        """The message resource of this thread's ``kind`` resource ``name`` (``rossrvs`` or
        ``rosactions``), checked to serve ``interface``: its ``<message><part>`` resource
        carries ``<interface><type_part>``."""
        try:
            server = self.thread.resource(name)
        except KeyError:
            server = None
        if server is None or server.type != kind:
            raise ConfigError(self.thread.where, f"thread {self.thread.name}: {name!r} is not a "
                                                 f"{kind} resource of its group")
        message = server.args[1].strip()
        msg = self.thread.resource(message + part)
        if self._library[msg.msgtype].name != self._library[interface + type_part].name:
            raise ConfigError(server.where, f"{name}: serves {msg.msgtype.removesuffix(type_part)}"
                                            f", the hardware one is {interface}")
        return message

    def hw_call(self, name):
        """The service or action resource ``name`` of this thread over hardware topics
        (``rossrvs``/``rossrvc``/``rosactions``/``rosactionc`` ending in ``hw``): a
        :class:`HwCall`."""
        mine = [ep for ep in self.endpoints if ep.key == name]
        if not mine:
            keys = sorted({ep.key for ep in self.endpoints if ep.interface})
            raise ConfigError(self.thread.where, f"thread {self.thread.name}: no service or "
                                                 f"action {name!r} over hardware topics; it "
                                                 f"has {', '.join(keys) or 'none'}")
        ports = {ep.topic.rsplit("_", 1)[1]: ep.port for ep in mine}
        from gen.services import interface_plans
        return HwCall(mine[0].interface, ports["request"], ports["reply"],
                      interface_plans(self._library, mine[0].interface))

    def thread_signature(self):
        """The slot ports plus the topic ports this thread must have."""
        members = dict(ThreadSignature(self.arch).members)
        for ep in self.endpoints:
            members[ep.port] = (In if ep.direction == "sub" else Out)(HW_TOPIC_STREAM)
        return wiring.Signature(members)


@dataclass
class HwCall:
    """A thread's service or action over hardware topics (docs/services.md).

    Attributes
    ----------
    interface : str
        ``pkg/srv/Name`` or ``pkg/action/Name``.
    request_port, reply_port : str
        The thread's ports on the ``<name>_request`` and ``<name>_reply`` topics.
    plans : dict
        :func:`gen.services.interface_plans` of the interface.
    """
    interface: str
    request_port: str
    reply_port: str
    plans: dict


def message_memory_layout(library, typename, arch, framing="reconros", within=None):
    """The :class:`hdl.reconos.gateway.MemoryLayout` of ``typename``: byte offset of each
    fixed leaf and each string or sequence of its ``framing`` stream plan in the rosidl C
    struct of ``arch`` (``r32``/``r64``).

    ``within=(outer, member)``: ``typename`` as member ``member`` of the struct ``outer`` (an
    action's goal in its ``_SendGoal_Request``): offsets from the start of ``outer``, whose
    size, rounded up to whole 8-byte words, is the layout's size (heap blocks of the ReconOS
    runtime are word-aligned, so the rounding stays inside the block)."""
    from gen.msg.layout import CLayout
    from gen.msg.plan import stream_plan
    from hdl.reconos.gateway import WORD, MemoryLayout
    layout = CLayout(library, "arm64" if arch == "r64" else "arm32")
    name = library[typename].name
    plan = stream_plan(library, name, framing)
    outer = library[within[0]].name if within else name
    prefix = f"{within[1]}." if within else ""

    def offset(path):
        at, struct = 0, layout.struct(outer)
        for part in (prefix + path).split("."):
            member = next((mb for mb in struct.members if mb.name == part), None)
            if member is None:
                raise ValueError(f"{name}: no member {path!r} in its C layout")
            at += member.offset
            if hasattr(member.type, "typename"):
                struct = layout.struct(member.type.typename)
        return at
    leaves = {leaf.path: offset(leaf.path) for leaf in plan.leaves
              if leaf.type not in ("count", "publisher")}
    size = layout.struct(outer).size
    return MemoryLayout(-(-size // WORD) * WORD if within else size, leaves,
                        {v.path: offset(v.path) for v in plan.variables})


class _ReadParameters(dict):
    """A thread's parameters that remember which names ``build(ctx)`` looked at, so a
    parameter no thread reads (a typo) is refused rather than ignored."""

    def __init__(self, params):
        super().__init__(params)
        self.read = set()

    def __getitem__(self, name):
        self.read.add(name)
        return super().__getitem__(name)

    def get(self, name, default=None):
        self.read.add(name)
        return super().get(name, default)

    def __contains__(self, name):
        self.read.add(name)
        return super().__contains__(name)

    def __iter__(self):
        self.read.update(super().keys())
        return super().__iter__()

    def keys(self):
        self.read.update(super().keys())
        return super().keys()

    def items(self):
        self.read.update(super().keys())
        return super().items()

    def pop(self, name, *default):
        self.read.add(name)
        return super().pop(name, *default)


def _wildcard(thread, name):
    """Whether ``name`` was set for every thread (``--param *.NAME=VALUE``): a thread need
    not read it, as long as one does."""
    return thread.param_options.get(name, "").split(" ", 1)[-1].startswith("*.")


def _params_location(thread):
    """The build.cfg line of ``thread``'s ``Parameters`` (its section's header without one)."""
    return thread.params_at or thread.where


def _describe_params(thread):
    """``{name: value}`` of ``thread``, saying which came from the command line."""
    parts = [f"{name}={value!r}" + (f" (from {thread.param_options[name]})"
                                    if name in thread.param_options else "")
             for name, value in thread.params.items()]
    return "{" + ", ".join(parts) + "}"


class ThreadCodeError(ConfigError):
    """An error in a project's own thread code (``src/rt_*/amaranth/*.py``): a syntax error, an
    exception in ``build()`` or in its components' ``elaborate()``, a combinational cycle.
    ``str()`` is ``file:line: Type: message`` of the place in the user's file."""

    def __init__(self, file, line, message):
        self.location = Location(str(file), line, "-")
        self.message = message
        ValueError.__init__(self, f"{file}:{line}: {message}")


@contextlib.contextmanager
def thread_code(project, keep=()):
    """Turn an exception raised in (or, for a combinational cycle, pointing into) the
    project's thread sources into a :class:`ThreadCodeError` at the user's file and line;
    other exceptions, and those of the types ``keep``, pass unchanged."""
    try:
        yield
    except ConfigError:
        raise
    except Exception as exc:
        if isinstance(exc, keep) and not isinstance(exc, SyntaxError):
            raise
        where = _in_project_sources(exc, project.dir / "src")
        if where is None:
            raise
        raise ThreadCodeError(*where, f"{type(exc).__name__}: {str(exc).strip()}") from None


def _in_project_sources(exc, src):
    """(file, line) in ``src`` that ``exc`` came from, else ``None``."""
    src = src.resolve()

    def inside(file):
        try:
            return Path(file).resolve().is_relative_to(src)
        except (OSError, ValueError):
            return False
    if isinstance(exc, SyntaxError) and exc.filename and inside(exc.filename):
        return exc.filename, exc.lineno
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if inside(f.filename)]
    if frames:
        return frames[-1].filename, frames[-1].lineno
    for mo in re.finditer(r"(/[^\s:()]+\.py):(\d+)", str(exc)):
        if inside(mo.group(1)):
            return mo.group(1), int(mo.group(2))
    return None


def thread_module_path(project, thread):
    """``<project>/src/rt_<name in lower case>/amaranth/thread.py``; a thread whose folder is
    spelt otherwise, or whose ``HwSource`` says ``amaranth`` without that file, is refused
    rather than left to become an external core."""
    path = project.dir / "src" / thread.core_name / "amaranth" / "thread.py"
    if path.is_file():
        return path
    src = project.dir / "src"
    near = [d for d in (src.iterdir() if src.is_dir() else ())
            if d.name.lower() == thread.core_name and (d / "amaranth" / "thread.py").is_file()]
    if near:
        raise ConfigError(thread.where, f"thread {thread.name}: its Amaranth source is in "
                                        f"src/{near[0].name}/amaranth/thread.py, but thread "
                                        f"folders are lower-case: rename the folder to "
                                        f"src/{thread.core_name}")
    if (thread.hwsource or "").lower() == "amaranth":
        raise ConfigError(thread.where, f"thread {thread.name}: HwSource = amaranth, but "
                                        f"there is no src/{thread.core_name}/amaranth/thread.py")
    return path


#: one thread module loaded at a time: a module is in ``sys.modules`` while it executes, and a
#: second system built meanwhile (the benches build several side by side in threads) would
#: otherwise take it before its ``build`` exists
_LOAD_LOCK = threading.Lock()


def _load(path, thread):
    name = f"rosgate_project_{thread.core_name}_{abs(hash(str(path)))}"
    with _LOAD_LOCK:
        module = sys.modules.get(name)
        if module is None:
            spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            try:
                spec.loader.exec_module(module)
            except Exception:
                del sys.modules[name]
                raise
    if not callable(getattr(module, "build", None)):
        raise ThreadCodeError(path, 1, f"defines no build(ctx) function (thread {thread.name} "
                                       f"is built by calling it)")
    return module


def build_thread(project, thread, slot, library=None):
    """The component of ``thread`` for ``slot`` or ``None`` when the project has no Amaranth
    implementation of it (see the module documentation)."""
    path = thread_module_path(project, thread)
    ctx = ThreadContext(project, thread, slot, library or project_library(project))
    if thread.gateway is not None and not path.is_file():
        if thread.gateway["kind"] == "service":
            return ctx.service_gateway("srvs", "srvc")
        if thread.gateway["kind"] == "action":
            return ctx.action_gateway("server", "client")
        return ctx.topic_gateway(thread.gateway["msgtype"], to_hw=("sub", "msg_in"),
                                 from_hw=("pub", "msg_out"))
    if not path.is_file():
        return None
    try:
        with thread_code(project, keep=ValueError):
            component = _load(path, thread).build(ctx)
    except ConfigError:
        raise
    except ValueError as exc:
        # a parameter the thread refuses (hdl.params.ParameterError is a ValueError)
        raise ConfigError(_params_location(thread),
                          f"{path}: build() of thread {thread.name} refused its parameters "
                          f"{_describe_params(thread)}: {exc}") from None
    thread.params_read |= ctx.params.read
    unread = [name for name in thread.params if name not in ctx.params.read
              and not _wildcard(thread, name)]
    if unread:
        name = unread[0]
        source = thread.param_options.get(name, f"{name}={thread.params[name]}")
        raise ConfigError(_params_location(thread),
                          f"{source}: thread {thread.name} has no parameter {name!r} (its "
                          f"build() reads: {', '.join(sorted(ctx.params.read)) or 'none'})")
    expected = ctx.thread_signature().members
    got = getattr(component, "signature", None)
    members = got.members if got is not None else {}
    for name, member in expected.items():
        if name not in members or members[name] != member:
            found = "it has none" if name not in members else \
                f"it has {_describe_member(members[name])}"
            raise ThreadCodeError(path, _build_line(path), f"build() of thread {thread.name} "
                                  f"returned a {type(component).__name__} without the port "
                                  f"{name!r} the thread needs: {_describe_member(member)}; "
                                  f"{found}")
    return component


def _describe_member(member):
    """A port in words: ``In(32 bits)`` or ``Out(FifoReadSignature: data, empty, re)``."""
    flow = "In" if member.flow == In else "Out"
    if member.is_port:
        return f"{flow}({Shape.cast(member.shape).width} bits)"
    signature = member.signature
    return f"{flow}({type(signature).__name__}: {', '.join(signature.members)})"


def _build_line(path):
    """The line of ``def build`` in ``path`` (1 if not found)."""
    for number, text in enumerate(Path(path).read_text().splitlines(), 1):
        if text.startswith("def build"):
            return number
    return 1


class SystemTop(wiring.Component):
    """A whole ReconROS project: the ReconOS infrastructure with its threads and the
    hardware topics between them.

    Members
    -------
    s_axi_osif, s_axi_intc, s_axi_proc, m_axi_mem, irq_osif, irq_pgf :
        As :class:`hdl.reconos.ReconosSystem`.
    slot<i>, slot<i>_rst :
        Slot ``i`` has no Amaranth thread: its FIFO ports and reset for an external core.
    slot<i>_clk : In(1)
        Clock of slot ``i`` when it is not the system clock.
    slot<i>_<port> : stream
        A topic port of the external thread in slot ``i`` (``Out`` for its subscription,
        ``In`` for its publication).
    """

    def __init__(self, project, *, library=None):
        self.project = project
        library = library or project_library(project)
        slots = sorted(project.slots, key=lambda s: s.id)
        self.threads = []
        self.async_slots = []
        for slot in slots:
            thread = slot.thread
            self.threads.append(build_thread(project, thread, slot, library) if thread else None)
            if slot.clock is not project.system_clock:
                self.async_slots.append(slot.id)
        built = [s.thread for s in slots if self.threads[s.id] is not None]
        read = set().union(*(t.params_read for t in built))
        for thread in built:
            for name in thread.params:
                if _wildcard(thread, name) and name not in read:
                    raise ConfigError(_params_location(thread),
                                      f"{thread.param_options[name]}: no thread has a parameter "
                                      f"{name!r} (their build() functions read: "
                                      f"{', '.join(sorted(read)) or 'none'})")
        for slot in slots:
            if slot.id in self.async_slots and self.threads[slot.id] is None:
                raise ConfigError(slot.where, f"slot {slot.name} runs on clock "
                                              f"{slot.clock.name} but has no Amaranth thread; "
                                              "external slots must be on the system clock")
        self.reconos = ReconosSystem(project.arch, self.threads, async_slots=self.async_slots)
        members = dict(self.reconos.signature.members)
        self._external_ports = {}
        for slot in slots:
            if self.threads[slot.id] is not None or slot.thread is None:
                continue
            for ep in slot.thread.endpoints:
                name = f"slot{slot.id}_{ep.port}"
                members[name] = (Out if ep.direction == "sub" else In)(HW_TOPIC_STREAM)
                self._external_ports[(slot.id, ep.port)] = name
        super().__init__(members)

    def _endpoint_ports(self, endpoint):
        """The stream interfaces of ``endpoint`` in each of its thread's slots."""
        out = []
        for slot in endpoint.thread.slots:
            component = self.threads[slot.id]
            if component is None:
                out.append(wiring.flipped(getattr(self, self._external_ports[(slot.id,
                                                                          endpoint.port)])))
            else:
                out.append(getattr(component, endpoint.port))
        return out

    def elaborate(self, platform):
        m = Module()
        m.submodules.reconos = rs = self.reconos
        for name, member in rs.signature.members.items():
            outer, inner = getattr(self, name), getattr(rs, name)
            if member.is_signature:
                wiring.connect(m, wiring.flipped(outer), inner)
            elif member.flow == In:
                m.d.comb += inner.eq(outer)
            else:
                m.d.comb += outer.eq(inner)
        for topic in self.project.topics.values():
            pubs = [p for ep in topic.pubs for p in self._endpoint_ports(ep)]
            subs = []
            for ep in topic.subs:
                subs += [(p, ep.depth) for p in self._endpoint_ports(ep)]
            fabric = Topic(len(pubs), len(subs), 64, user_width=1, monitor=False)
            m.submodules[f"topic_{topic.name}"] = fabric
            for i, port in enumerate(pubs):
                wiring.connect(m, port, fabric.s_axis[i])
            for j, (port, depth) in enumerate(subs):
                if depth:
                    fifo = StreamFIFO(HW_TOPIC_STREAM, depth)
                    m.submodules[f"topic_{topic.name}_fifo{j}"] = fifo
                    wiring.connect(m, fabric.m_axis[j], fifo.s_axis)
                    wiring.connect(m, fifo.m_axis, port)
                else:
                    wiring.connect(m, fabric.m_axis[j], port)
        return m


def build_system(project, *, library=None):
    """The :class:`SystemTop` of ``project``."""
    with thread_code(project):
        return SystemTop(project, library=library)


def thread_sources(project):
    """Thread name -> ``"amaranth"`` (path) or why its slot is external."""
    out = {}
    for thread in project.threads:
        path = thread_module_path(project, thread)
        if path.is_file():
            out[thread.name] = f"amaranth ({path.relative_to(project.dir)})"
        elif thread.gateway is not None:
            out[thread.name] = ("ROS gateway: rosgate's "
                                + {"topic": "TopicGatewayThread",
                                   "service": "ServiceGatewayThread",
                                   "action": "ActionGatewayThread"}[thread.gateway["kind"]])
        else:
            out[thread.name] = (f"{thread.hwsource or 'no HwSource'}: external core (no "
                                f"{path.relative_to(project.dir)})")
    return out

