"""ReconROS ``build.cfg`` project files, read unchanged (docs/reconos.md, docs/topics.md).

:func:`load_project` parses a project file the way ReconROS' ``project.py`` does
(``RawConfigParser`` with case-sensitive keys, sections matched by prefix, arguments split on
``[, ]+``) and checks it: every error is a :class:`ConfigError` naming the file, line,
section and key, what was expected and what was found.

What rosgate derives from the file:

* slots ``Name(k)`` with id ``Id + k`` for each ``[HwSlot@Name(a:b)]``;
* resources in global parse order, ``rossrvmsg`` expanded into ``_res``, ``_req`` and
  ``rosactionmsg`` into ``_goal_req``, ``_result_res``, ``_feedback`` in place, range groups
  ``[ResourceGroup@G(a:b)]`` into ``G_a``..``G_b`` with ``%`` replaced by the index;
* each thread's resource list (its handles) = the resources of its groups in global parse
  order, hardware-topic endpoints excluded (docs/build-cfg.md); thread ids: ``ReconosThread``
  sections in
  file order, then ``ROSGateway`` sections;
* hardware topics: every ``rossub``/``rospub`` marked ``hw`` grouped by topic name, with the
  topology of docs/topics.md; a gateway subscribes and publishes its ``HWTopic``.

The partial-reconfiguration ``Reconf`` thread is not generated: rosgate builds static systems
(``PartialReconfiguration = true`` is refused with a clear error).
"""

import re
from dataclasses import dataclass, field
from pathlib import Path

from gen.msg.parser import (
    ACTION_FEEDBACK_MESSAGE,
    ACTION_GET_RESULT_RESPONSE,
    ACTION_SEND_GOAL_REQUEST,
    SERVICE_REQUEST,
    SERVICE_RESPONSE,
)
from hdl.reconos.protocol import ResourceType

__all__ = ["ConfigError", "Location", "Project", "Clock", "Slot", "Resource", "Thread",
           "HwEndpoint", "HwTopic", "load_project", "parse_project", "split_args", "unquote",
           "apply_parameters"]

_SPLIT = re.compile(r"[, ]+")
_RANGE = re.compile(r"^(?P<name>[^()]*)\((?P<start>[0-9]+):(?P<end>[0-9]+)\)$")

#: build.cfg resource type -> resources it expands into (name suffix, type, message suffix)
EXPANSIONS = {
    "rossrvmsg": (("_res", "rossrvmsgres", SERVICE_RESPONSE),
                  ("_req", "rossrvmsgreq", SERVICE_REQUEST)),
    "rosactionmsg": (("_goal_req", "rosactionmsggoalreq", ACTION_SEND_GOAL_REQUEST),
                     ("_result_res", "rosactionmsgresultres", ACTION_GET_RESULT_RESPONSE),
                     ("_feedback", "rosactionmsgfeedback", ACTION_FEEDBACK_MESSAGE)),
}
#: build.cfg resource types (besides the expansions) -> (min args, max args, argument names)
RESOURCE_ARGS = {
    "mbox": (1, 1, "size"),
    "sem": (1, 2, "sem_init arguments (pshared, value)"),
    "mutex": (0, 0, ""),
    "cond": (0, 0, ""),
    "mem": (1, 1, "size in bytes"),
    "rosnode": (1, 1, '"node name"'),
    "rostmr": (2, 2, "node, period"),
    "rosmsg": (3, 4, "package, msg, Type [, sequence length]"),
    "rossub": (4, 6, 'node, message, "topic", wait_us | node, pkg/Type, "topic", hw [, depth]'),
    "rospub": (3, 4, 'node, message, "topic" | node, pkg/Type, "topic", hw'),
    "rossrvmsg": (3, 3, "package, srv, Type"),
    "rossrvs": (2, 4, 'node, service message[, "service", wait_us] | node, service message, '
                      '"service", hw [, depth]'),
    "rossrvc": (2, 4, 'node, service message[, "service", wait_us] | node, service message, '
                      '"service", hw [, depth]'),
    "rosactionmsg": (3, 3, "package, action, Type"),
    "rosactions": (4, 4, 'node, action message, "action", wait_us | ..., "action", hw '
                         '[, depth]'),
    "rosactionc": (4, 4, 'node, action message, "action", wait_us | ..., "action", hw '
                         '[, depth]'),
}
#: services and actions that may run over hardware topics -> (what it is, its message resource)
HW_CALLS = {"rossrvs": ("service", "rossrvmsg"), "rossrvc": ("service", "rossrvmsg"),
            "rosactions": ("action", "rosactionmsg"), "rosactionc": ("action", "rosactionmsg")}
#: resource type -> (argument index, resource type it must name in the same group)
REFERENCES = {
    "rostmr": ((0, ("rosnode",)),),
    "rossub": ((0, ("rosnode",)), (1, ("rosmsg",))),
    "rospub": ((0, ("rosnode",)), (1, ("rosmsg",))),
    "rossrvs": ((0, ("rosnode",)), (1, ("rossrvmsg",))),
    "rossrvc": ((0, ("rosnode",)), (1, ("rossrvmsg",))),
    "rosactions": ((0, ("rosnode",)), (1, ("rosactionmsg",))),
    "rosactionc": ((0, ("rosnode",)), (1, ("rosactionmsg",))),
}

SECTION_KEYS = {
    "General": {
        "required": ("Name", "TargetBoard", "TargetPart", "ReferenceDesign", "TargetOS",
                     "TargetXil", "SystemClock"),
        "optional": ("TargetHls", "CFlags", "LdFlags", "PartialReconfiguration",
                     "ROS2Distribution", "CPUArchitecture", "Hls_CFlags", "HLSMultithreading",
                     "TargetBoardAddress", "TargetBoardUser", "TargetBoardPassword")},
    "Clock": {"required": ("ClockSource", "ClockFreq"), "optional": ()},
    "HwSlot": {"required": ("Id", "Clock"), "optional": ("Reconfigurable", "Ports")},
    "ReconosThread": {"required": ("Slot",),
                      "optional": ("HwSource", "SwSource", "ResourceGroup", "UseMem",
                                   "VideoOut", "Ports", "Parameters")},
    # a topic (ReconROS), or a service or action (rosgate): one of GATEWAY_KINDS' key sets
    "ROSGateway": {"required": ("Slot",),
                   "optional": ("HWTopic", "SWTopic", "MsgType", "HWService", "SWService",
                                "SrvType", "HWAction", "SWAction", "ActionType")},
}
#: what a [ROSGateway@N] connects: its kind -> (hardware name, software name, type) keys
GATEWAY_KINDS = {"topic": ("HWTopic", "SWTopic", "MsgType"),
                 "service": ("HWService", "SWService", "SrvType"),
                 "action": ("HWAction", "SWAction", "ActionType")}
BOARDS = {"zcu104": "r64", "zedboard": "r32", "pynqz1": "r32", "miniitx": "r32"}
TARGET_OS = {"linux64": "r64", "linux": "r32", "linux_x86": None}


@dataclass(frozen=True)
class Location:
    """Where something was written: file, line, section and key (``key`` may be ``None``)."""
    file: str
    line: int
    section: str
    key: str = None

    def __str__(self):
        where = f"{self.file}:{self.line}: [{self.section}]"
        return f"{where} {self.key}" if self.key else where


class ConfigError(ValueError):
    """A project file is not valid; ``location`` says where, the message what was expected."""

    def __init__(self, location, message):
        self.location = location
        self.message = message
        super().__init__(f"{location}: {message}")


def split_args(value):
    """ReconROS' argument split: ``re.split(r"[, ]+", value)`` (quotes are kept)."""
    return [a for a in _SPLIT.split(value.strip()) if a != ""]


def unquote(token):
    return token[1:-1] if len(token) >= 2 and token[0] == token[-1] == '"' else token


# --- the file ------------------------------------------------------------------------------

@dataclass
class _Section:
    name: str
    line: int
    values: dict = field(default_factory=dict)   # key -> value
    lines: dict = field(default_factory=dict)    # key -> line

    def where(self, file, key=None):
        return Location(file, self.lines.get(key, self.line) if key else self.line,
                        self.name, key)


def _read_sections(text, file):
    """``RawConfigParser`` semantics with line numbers: ``#``/``;`` comment lines, ``key = v``
    or ``key: v``, indented continuation lines, duplicate sections and keys refused."""
    sections = []
    by_name = {}
    current = None
    last_key = None
    for number, raw in enumerate(text.splitlines(), 1):
        stripped = raw.strip()
        if not stripped or stripped[0] in "#;":
            last_key = None if not stripped else last_key
            continue
        if raw[0].isspace() and current is not None and last_key is not None:
            current.values[last_key] += "\n" + stripped
            continue
        if stripped.startswith("["):
            if not stripped.endswith("]"):
                raise ConfigError(Location(file, number, stripped),
                                  "a section header ends with ']'")
            name = stripped[1:-1].strip()
            if name in by_name:
                raise ConfigError(Location(file, number, name),
                                  f"section defined twice (first on line {by_name[name].line})")
            current = by_name[name] = _Section(name, number)
            sections.append(current)
            last_key = None
            continue
        if current is None:
            raise ConfigError(Location(file, number, "(none)"),
                              f"expected a [section] header before {stripped!r}")
        mo = re.match(r"^(?P<key>[^=:]+?)\s*[=:]\s*(?P<value>.*)$", stripped)
        if mo is None:
            raise ConfigError(current.where(file), f"line {number}: expected 'KEY = VALUE', "
                                                   f"found {stripped!r}")
        key = mo.group("key")
        if key in current.values:
            raise ConfigError(Location(file, number, current.name, key),
                              f"key defined twice in this section (first on line "
                              f"{current.lines[key]})")
        current.values[key] = mo.group("value")
        current.lines[key] = number
        last_key = key
    return sections


# --- the model -----------------------------------------------------------------------------

@dataclass
class Clock:
    name: str
    id: int
    source: str
    freq: int
    where: Location

    @property
    def period_ns(self):
        return 1e9 / self.freq


@dataclass
class Slot:
    """Slot ``name`` = ``Group(k)``; ``id`` is its hardware slot number (OSIF index)."""
    name: str
    id: int
    clock: Clock
    where: Location
    thread: "Thread" = None


@dataclass
class Resource:
    """One ReconROS resource after expansion. ``args`` as written (quotes kept)."""
    name: str
    type: str
    args: list
    group: str
    id: int
    where: Location
    msgtype: str = None     # full message type for rosmsg / srv / action messages
    key: str = None         # the build.cfg key it came from
    declared: str = None    # the build.cfg type (rossrvmsg for its _res and _req)

    @property
    def c_name(self):
        """Name of the C object and HLS handle macro (lower case ``<group>_<name>``)."""
        return f"{self.group}_{self.name}".lower()

    @property
    def type_code(self):
        return int(ResourceType[self.type.upper()])


@dataclass
class HwEndpoint:
    """A thread's publisher or subscriber on a hardware topic. ``port`` is the thread's
    AXI-Stream member name (``<topic>``, or ``<topic>_in``/``_out`` for a thread that both
    publishes and subscribes, as ReconROS' gateways do); ``depth`` the subscriber FIFO (0: none)."""
    thread: "Thread"
    direction: str
    topic: str
    msgtype: str
    depth: int
    where: Location
    port: str = None
    #: the build.cfg key of the resource, and for a service or action over hardware topics
    #: its interface (``pkg/srv/Name``, ``pkg/action/Name``)
    key: str = None
    interface: str = None


@dataclass
class HwTopic:
    name: str
    msgtype: str
    pubs: list
    subs: list

    @property
    def topology(self):
        return {(True, True): "ONE_TO_ONE", (True, False): "ONE_TO_N",
                (False, True): "N_TO_ONE", (False, False): "N_TO_M"}[
            (len(self.pubs) == 1, len(self.subs) == 1)]


@dataclass
class Thread:
    name: str
    id: int
    slots: list
    hwsource: str
    swsource: str
    groups: list
    resources: list
    endpoints: list
    use_mem: bool
    where: Location
    gateway: dict = None
    #: ``Parameters`` (a rosgate extension): name -> value, strings, for ``build(ctx)``
    params: dict = field(default_factory=dict)
    #: the command-line setting each parameter set by ``--param`` came from: name -> text
    param_options: dict = field(default_factory=dict)
    #: the section's ``Parameters`` line (``None`` when it has none)
    params_at: Location = None
    #: the parameters its ``build(ctx)`` read (filled when the thread is built)
    params_read: set = field(default_factory=set)

    @property
    def core_name(self):
        return f"rt_{self.name.lower()}"

    @property
    def handles(self):
        """Thread-local handle of each resource, by C name and by bare name (docs/build-cfg.md)."""
        out = {}
        for h, r in enumerate(self.resources):
            out[r.c_name] = h
            out.setdefault(r.name, h)
            out.setdefault(r.name.lower(), h)
        return out

    def handle(self, name):
        try:
            return self.handles[name]
        except KeyError:
            raise KeyError(f"thread {self.name}: no resource {name!r}; its resources: "
                           f"{', '.join(r.name for r in self.resources)}") from None

    def resource(self, name):
        return self.resources[self.handle(name)]


@dataclass
class Project:
    path: Path
    name: str
    general: dict
    board: str
    board_rev: str
    part: str
    reference_design: str
    target_os: str
    arch: str
    system_clock: Clock
    clocks: list
    slots: list
    resources: list
    threads: list
    topics: dict
    msg_dirs: list
    warnings: list = field(default_factory=list)
    #: where ``TargetPart`` was written (for errors about the part)
    part_at: Location = None

    @property
    def dir(self):
        return self.path.parent

    @property
    def clock_mhz(self):
        return self.system_clock.freq / 1e6


# --- parsing -------------------------------------------------------------------------------

def _kind(section_name):
    """The kind of a section (the name before ``@``; ``None`` for an unknown one: a prefix
    match would take ``HwSlott@X`` for a slot)."""
    kind = section_name.split("@", 1)[0].strip()
    return kind if kind in ("General", "Clock", "HwSlot", "ResourceGroup", "ReconosThread",
                            "ROSGateway") else None


def _parameters(sec, file):
    """``Parameters = name=value, name=value`` of a thread section (a rosgate extension)."""
    out = {}
    for token in split_args(sec.values.get("Parameters", "")):
        name, eq, value = token.partition("=")
        if not eq or not name.isidentifier() or not value:
            raise ConfigError(sec.where(file, "Parameters"),
                              f"{token!r} is not name=value (for example mode=reconros)")
        out[name] = unquote(value)
    return out


def apply_parameters(project, settings, option="--param"):
    """Set thread parameters from ``THREAD.NAME=VALUE`` strings (the command line's
    ``--param``; ``*.NAME=VALUE`` sets it for every thread), over the build.cfg's
    ``Parameters``; a bad setting raises :class:`ValueError` naming it."""
    names = {t.name: t for t in project.threads}
    for setting in settings:
        target, eq, value = setting.partition("=")
        thread, dot, name = target.partition(".")
        if not eq or not dot or not name.isidentifier() or not value:
            raise ValueError(f"{option} {setting!r}: expected THREAD.NAME=VALUE, for example "
                             f"Sobel.mode=reconros")
        if thread == "*":
            for t in project.threads:
                t.params[name] = value
                t.param_options[name] = f"{option} {setting}"
            continue
        if thread not in names:
            raise ValueError(f"{option} {setting!r}: no thread {thread!r} in {project.path} "
                             f"(threads: {', '.join(names) or 'none'})")
        names[thread].params[name] = value
        names[thread].param_options[name] = f"{option} {setting}"
    return project


def _check_keys(sec, kind, file):
    spec = SECTION_KEYS[kind]
    known = spec["required"] + spec["optional"]
    for key in sec.values:
        if key in known or (kind == "HwSlot" and re.fullmatch(r"Region_[0-9]+", key)):
            continue
        raise ConfigError(sec.where(file, key), f"unknown key; a [{kind}] section has "
                                                f"{', '.join(known)}")
    for key in spec["required"]:
        if key not in sec.values:
            raise ConfigError(sec.where(file), f"missing required key {key!r}")


def _name_after_at(sec, file, *, ranged=None):
    """``X@Name`` -> ``Name``; ``ranged``: True requires ``Name(a:b)``, None allows it."""
    if "@" not in sec.name or not sec.name.split("@", 1)[1]:
        raise ConfigError(sec.where(file), "expected a name after '@' in the section header")
    name = sec.name.split("@", 1)[1].strip()
    mo = _RANGE.match(name)
    if ranged and mo is None:
        raise ConfigError(sec.where(file), f"expected a slot range 'Name(a:b)', found {name!r}")
    if mo is None:
        if "(" in name or ")" in name:
            raise ConfigError(sec.where(file), f"expected 'Name' or 'Name(a:b)', found {name!r}")
        return name, None
    start, end = int(mo.group("start")), int(mo.group("end"))
    if end < start:
        raise ConfigError(sec.where(file), f"range ({start}:{end}) is empty")
    return mo.group("name"), range(start, end + 1)


def _int(sec, key, file, lo=0):
    value = sec.values[key].strip()
    try:
        number = int(value)
    except ValueError:
        raise ConfigError(sec.where(file, key), f"expected an integer, found {value!r}") from None
    if number < lo:
        raise ConfigError(sec.where(file, key), f"expected an integer >= {lo}, found {number}")
    return number


def _bool(sec, key, file, default):
    if key not in sec.values:
        return default
    value = sec.values[key].strip()
    if value not in ("True", "true", "False", "false"):
        raise ConfigError(sec.where(file, key), f"expected true or false, found {value!r}")
    return value in ("True", "true")


def _message_type(args, kind, where):
    pkg, sub, typ = args[0], args[1], args[2]
    expected = {"rosmsg": "msg", "rossrvmsg": "srv", "rosactionmsg": "action"}[kind]
    if sub != expected:
        raise ConfigError(where, f"expected {expected!r} as the second argument of {kind}, "
                                 f"found {sub!r}")
    if typ == "U_Int32":       # ReconROS' naming quirk (docs/build-cfg.md)
        typ = "UInt32"
    return f"{pkg}/{sub}/{typ}"


def parse_project(text, path="build.cfg", *, msg_dirs=None):
    """Parse project file ``text`` (named ``path`` in messages); see :func:`load_project`."""
    path = Path(path)
    file = str(path)
    sections = _read_sections(text, file)
    kinds = {}
    for sec in sections:
        kind = _kind(sec.name)
        if kind is None:
            raise ConfigError(sec.where(file),
                              "unknown section; expected General, Clock@N, HwSlot@N(a:b), "
                              "ResourceGroup@N, ResourceGroup@N(a:b), ReconosThread@N or "
                              "ROSGateway@N")
        if kind != "ResourceGroup":
            _check_keys(sec, kind, file)
        kinds.setdefault(kind, []).append(sec)
    if "General" not in kinds:
        raise ConfigError(Location(file, 1, "General"), "missing the [General] section")
    gen = kinds["General"][0]
    general = dict(gen.values)

    board_tokens = split_args(general["TargetBoard"])
    board = board_tokens[0]
    if board not in BOARDS:
        raise ConfigError(gen.where(file, "TargetBoard"),
                          f"expected one of {', '.join(BOARDS)} (with a revision), found "
                          f"{board!r}")
    target_os = general["TargetOS"].strip()
    if target_os not in TARGET_OS:
        raise ConfigError(gen.where(file, "TargetOS"),
                          f"expected one of {', '.join(TARGET_OS)}, found {target_os!r}")
    if TARGET_OS[target_os] is None:
        raise ConfigError(gen.where(file, "TargetOS"),
                          "linux_x86 has no FPGA; rosgate builds Zynq (linux) and ZynqMP "
                          "(linux64) systems")
    arch = TARGET_OS[target_os]
    if arch != BOARDS[board]:
        raise ConfigError(gen.where(file, "TargetOS"),
                          f"TargetOS {target_os} is {arch}, but TargetBoard {board} is a "
                          f"{BOARDS[board]} platform")
    if _bool(gen, "PartialReconfiguration", file, False):
        raise ConfigError(gen.where(file, "PartialReconfiguration"),
                          "partial reconfiguration is not supported by rosgate (static systems "
                          "only); expected false")

    # clocks
    clocks = {}
    for i, sec in enumerate(kinds.get("Clock", [])):
        name, _ = _name_after_at(sec, file, ranged=False)
        source = sec.values["ClockSource"].strip()
        if source not in ("static", "dynamic"):
            raise ConfigError(sec.where(file, "ClockSource"),
                              f"expected static or dynamic, found {source!r}")
        clocks[name] = Clock(name, i, source, _int(sec, "ClockFreq", file, 1), sec.where(file))
    sysclk = general["SystemClock"].strip()
    if sysclk not in clocks:
        raise ConfigError(gen.where(file, "SystemClock"),
                          f"no [Clock@{sysclk}] section; clocks: {', '.join(clocks) or 'none'}")

    # resources, in global parse order
    resources = []
    groups = {}
    for sec in kinds.get("ResourceGroup", []):
        gname, indices = _name_after_at(sec, file)
        instances = [(gname, None)] if indices is None else [(f"{gname}_{i}", i)
                                                             for i in indices]
        for group, index in instances:
            if group in groups:
                raise ConfigError(sec.where(file), f"resource group {group!r} defined twice")
            groups[group] = []
            for key, value in sec.values.items():
                where = sec.where(file, key)
                if index is not None:
                    value = value.replace("%", str(index))
                groups[group].extend(_resource(key, value, group, where))
            resources.extend(groups[group])
    for i, r in enumerate(resources):
        r.id = 128 + i
    for group, members in groups.items():
        _check_references(members)

    # slots
    slots = []
    slot_ids = {}
    for sec in kinds.get("HwSlot", []):
        sname, indices = _name_after_at(sec, file, ranged=True)
        first = _int(sec, "Id", file)
        cname = sec.values["Clock"].strip()
        if cname not in clocks:
            raise ConfigError(sec.where(file, "Clock"),
                              f"no [Clock@{cname}] section; clocks: {', '.join(clocks)}")
        _bool(sec, "Reconfigurable", file, False)
        for k in indices:
            slot = Slot(f"{sname}({k})", first + k, clocks[cname], sec.where(file))
            if slot.id in slot_ids:
                raise ConfigError(sec.where(file, "Id"),
                                  f"slot {slot.name} gets id {slot.id}, already the id of "
                                  f"{slot_ids[slot.id].name}")
            slot_ids[slot.id] = slot
            slots.append(slot)
    if not slots:
        raise ConfigError(gen.where(file), "no [HwSlot@Name(a:b)] section: a system needs at "
                                           "least one slot")
    if sorted(slot_ids) != list(range(len(slots))):
        raise ConfigError(kinds["HwSlot"][0].where(file, "Id"),
                          f"slot ids must be 0..{len(slots) - 1} without gaps, found "
                          f"{sorted(slot_ids)}")

    # threads
    threads = []
    for sec in kinds.get("ReconosThread", []):
        name, _ = _name_after_at(sec, file, ranged=False)
        tslots = _match_slots(sec, "Slot", slots, file)
        gnames = []
        if "ResourceGroup" in sec.values:
            for token in split_args(sec.values["ResourceGroup"]):
                mo = _RANGE.match(token)
                gnames += ([f"{mo.group('name')}_{i}" for i in range(int(mo.group('start')),
                                                                     int(mo.group('end')) + 1)]
                           if mo else [token])
            for g in gnames:
                if g not in groups:
                    raise ConfigError(sec.where(file, "ResourceGroup"),
                                      f"no resource group {g!r}; groups: "
                                      f"{', '.join(groups) or 'none'}")
        hw = sec.values.get("HwSource", "").split(",")[0].strip() or None
        sw = sec.values.get("SwSource", "").split(",")[0].strip() or None
        thread = Thread(name, len(threads), tslots, hw, sw, gnames, [], [],
                        _bool(sec, "UseMem", file, True), sec.where(file),
                        params=_parameters(sec, file),
                        params_at=sec.where(file, "Parameters") if "Parameters" in sec.values
                        else None)
        _thread_resources(thread, resources)
        threads.append(thread)
    for sec in kinds.get("ROSGateway", []):
        threads.append(_gateway(sec, file, len(threads), slots, resources, groups))

    for thread in threads:
        for slot in thread.slots:
            if slot.thread is not None:
                raise ConfigError(Location(file, thread.where.line, thread.where.section, "Slot"),
                                  f"slot {slot.name} is already taken by thread "
                                  f"{slot.thread.name} (one thread per slot in a static "
                                  "system)")
            slot.thread = thread

    topics = _hw_topics(threads)
    project = Project(path=path, name=general["Name"].strip(), general=general, board=board,
                      board_rev=board_tokens[1] if len(board_tokens) > 1 else "",
                      part=general["TargetPart"].strip(),
                      reference_design=general["ReferenceDesign"].strip(),
                      target_os=target_os, arch=arch, system_clock=clocks[sysclk],
                      clocks=list(clocks.values()), slots=slots, resources=resources,
                      threads=threads, topics=topics,
                      msg_dirs=list(msg_dirs) if msg_dirs is not None else
                      [path.parent / "msg"], part_at=gen.where(file, "TargetPart"))
    project.warnings = [r.warning for r in resources if getattr(r, "warning", None)]
    for topic in topics.values():
        for ep in topic.pubs + topic.subs:
            for slot in ep.thread.slots:
                if slot.clock is not project.system_clock:
                    raise ConfigError(ep.where, f"hardware topic {topic.name!r} runs on the "
                                                f"system clock {sysclk}, but slot {slot.name} "
                                                f"of thread {ep.thread.name} is on "
                                                f"{slot.clock.name} (docs/topics.md)")
    return project


def _resource(key, value, group, where):
    args = split_args(value)
    if not args:
        raise ConfigError(where, "expected 'TYPE, ARG, ...', found nothing")
    kind, rest = args[0], args[1:]
    if kind not in RESOURCE_ARGS:
        raise ConfigError(where, f"unknown resource type {kind!r}; expected one of "
                                 f"{', '.join(RESOURCE_ARGS)}")
    if kind in HW_CALLS and "hw" in rest:
        return _hw_call_endpoints(key, kind, rest, group, where)
    lo, hi, names = RESOURCE_ARGS[kind]
    hw = kind in ("rossub", "rospub") and "hw" in rest
    if not hw and kind in ("rossub", "rospub"):
        hi = 4 if kind == "rossub" else 3
    if not lo <= len(rest) <= hi:
        raise ConfigError(where, f"{kind} takes {names}; found {len(rest)} argument(s) "
                                 f"{', '.join(rest) or '(none)'}")
    if hw:
        return [_hw_endpoint(key, kind, rest, group, where)]
    if kind in EXPANSIONS:
        msgtype = _message_type(rest, kind, where)
        return [Resource(key + suffix, rtype, rest, group, 0, where, msgtype + msg_suffix,
                         key=key, declared=kind)
                for suffix, rtype, msg_suffix in EXPANSIONS[kind]]
    r = Resource(key, kind, rest, group, 0, where, key=key, declared=kind)
    if kind == "rosmsg":
        r.msgtype = _message_type(rest, kind, where)
        if len(rest) == 4:
            _positive(rest[3], where, "sequence length")
    elif kind in ("mbox", "mem"):
        _positive(rest[0], where, "mbox size" if kind == "mbox" else "memory size")
    elif kind == "rossub":
        _positive(rest[3], where, "wait time in us", lo=0)
    elif kind in ("rossrvs", "rossrvc", "rosactions", "rosactionc"):
        if len(rest) == 4:
            _positive(rest[3], where, "wait time in us", lo=0)
        else:
            r.warning = (f"{where}: {kind} without a service name and wait time (ReconROS' C "
                         f"export would not compile); rosgate names the service {key!r}")
    return [r]


def _positive(token, where, what, lo=1):
    try:
        value = int(token)
    except ValueError:
        raise ConfigError(where, f"expected an integer {what}, found {token!r}") from None
    if value < lo:
        raise ConfigError(where, f"expected {what} >= {lo}, found {value}")
    return value


def _hw_endpoint(key, kind, rest, group, where):
    hw_at = rest.index("hw")
    if hw_at != 3 or (kind == "rospub" and len(rest) != 4) or len(rest) > 5:
        raise ConfigError(where, f"expected '{kind}, node, pkg/Type, \"topic\", hw"
                                 f"{' [, depth]' if kind == 'rossub' else ''}' for a hardware "
                                 f"topic (docs/topics.md); found {', '.join([kind] + rest)}")
    msgtype = rest[1]
    if msgtype.count("/") != 1:
        raise ConfigError(where, f"a hardware topic's message is 'pkg/Type', found {msgtype!r}")
    pkg, typ = msgtype.split("/")
    depth = _positive(rest[4], where, "subscriber FIFO depth", lo=0) if len(rest) == 5 else 0
    if depth and (depth < 2 or depth > 65536 or depth & (depth - 1)):
        raise ConfigError(where, f"expected a subscriber FIFO depth that is a power of two in "
                                 f"2..65536 (beats), found {depth}")
    topic = _hw_topic_name(rest[2], where)
    r = Resource(key, "hwtopic" + ("sub" if kind == "rossub" else "pub"), rest, group, 0, where,
                 f"{pkg}/msg/{typ}", key=key, declared=kind)
    r.topic = topic
    r.depth = depth
    return r


def _hw_topic_name(token, where):
    topic = unquote(token).strip("/").replace("/", "_")
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", topic):
        raise ConfigError(where, f"hardware topic name {token} does not make a port name")
    return topic


def _hw_call_endpoints(key, kind, rest, group, where):
    """A service or action over hardware topics (docs/services.md): its request and reply
    topics, ``<name>_request`` and ``<name>_reply``; the interface comes from the message
    resource (argument 2) once the group is read."""
    if len(rest) not in (4, 5) or rest[3] != "hw":
        raise ConfigError(where, f"expected '{kind}, node, message, \"name\", hw [, depth]' for "
                                 f"a {HW_CALLS[kind][0]} over hardware topics "
                                 f"(docs/services.md); found {', '.join([kind] + rest)}")
    depth = _positive(rest[4], where, "subscriber FIFO depth", lo=0) if len(rest) == 5 else 0
    if depth and (depth < 2 or depth > 65536 or depth & (depth - 1)):
        raise ConfigError(where, f"expected a subscriber FIFO depth that is a power of two in "
                                 f"2..65536 (beats), found {depth}")
    name = _hw_topic_name(rest[2], where)
    serves = kind in ("rossrvs", "rosactions")
    out = []
    for part, direction in (("request", "sub" if serves else "pub"),
                            ("reply", "pub" if serves else "sub")):
        r = Resource(f"{key}_{part}", "hwtopic" + direction, rest, group, 0, where, key=key,
                     declared=kind)
        r.topic = f"{name}_{part}"
        r.depth = depth if direction == "sub" else 0
        r.interface_ref = rest[1]
        out.append(r)
    return out


def _check_references(members):
    """Each node and message argument names a resource of the right type in the group; a
    service or action over hardware topics gets its interface from its message resource."""
    declared = {r.key: r.declared for r in members}
    for r in members:
        if getattr(r, "interface_ref", None) is not None:
            wanted = HW_CALLS[r.declared][1]
            source = next((x for x in members if x.key == r.interface_ref), None)
            if source is None or source.declared != wanted:
                what = f"a {source.declared} resource" if source else "not defined"
                raise ConfigError(r.where, f"argument 2 ({r.interface_ref!r}) must name a "
                                           f"{wanted} resource of group {r.group!r}; it is "
                                           f"{what}")
            r.msgtype = _message_type(source.args, wanted, source.where)
        refs = ((0, ("rosnode",)),) if r.type.startswith("hwtopic") else \
            REFERENCES.get(r.type, ())
        for index, wanted in refs:
            target = r.args[index]
            found = declared.get(target)
            if found not in wanted:
                what = f"a {found} resource" if found else "not defined"
                raise ConfigError(r.where, f"argument {index + 1} ({target!r}) must name a "
                                           f"{' or '.join(wanted)} resource of group "
                                           f"{r.group!r}; it is {what}")


def _match_slots(sec, key, slots, file):
    pattern = sec.values[key].strip()
    regex = (pattern.replace("(", r"\(").replace(")", r"\)").replace(",", "|")
             .replace("*", ".*").replace(" ", ""))
    try:
        found = [s for s in slots if re.match(regex, s.name)]
    except re.error as exc:
        raise ConfigError(sec.where(file, key), f"bad slot pattern {pattern!r}: {exc}") from None
    if not found:
        raise ConfigError(sec.where(file, key),
                          f"slot pattern {pattern!r} matches no slot; slots: "
                          f"{', '.join(s.name for s in slots) or 'none'}")
    return found


def _thread_resources(thread, resources):
    for r in resources:
        if r.group not in thread.groups:
            continue
        if r.type.startswith("hwtopic"):
            call = getattr(r, "interface_ref", None) is not None
            thread.endpoints.append(HwEndpoint(thread, r.type[len("hwtopic"):], r.topic,
                                               r.msgtype, r.depth, r.where, key=r.key,
                                               interface=r.msgtype if call else None))
        else:
            thread.resources.append(r)


def _gateway_kind(sec, file):
    """The kind of a ``[ROSGateway@N]`` (``GATEWAY_KINDS``) from the keys it has."""
    present = [kind for kind, keys in GATEWAY_KINDS.items()
               if any(k in sec.values for k in keys)]
    sets = "; ".join(", ".join(keys) for keys in GATEWAY_KINDS.values())
    if len(present) != 1:
        raise ConfigError(sec.where(file), f"a [ROSGateway] section connects one topic, service "
                                           f"or action: one of the key sets {sets}"
                          + (f"; it has keys of {' and '.join(present)}" if present else ""))
    kind = present[0]
    for key in GATEWAY_KINDS[kind]:
        if key not in sec.values:
            raise ConfigError(sec.where(file), f"missing required key {key!r} (a {kind} "
                                               f"gateway has {', '.join(GATEWAY_KINDS[kind])})")
    return kind


def _gateway(sec, file, tid, slots, resources, groups):
    """A ``[ROSGateway@N]``: group ``N_ressourcegroup`` (docs/topics.md, docs/services.md)."""
    name, _ = _name_after_at(sec, file, ranged=False)
    tslots = _match_slots(sec, "Slot", slots, file)
    kind = _gateway_kind(sec, file)
    hw_key, sw_key, type_key = GATEWAY_KINDS[kind]
    typename = sec.values[type_key].strip()
    if typename.count("/") != 1:
        raise ConfigError(sec.where(file, type_key), f"expected 'pkg/Type', found {typename!r}")
    pkg, typ = (part.strip() for part in typename.split("/"))
    sw = sec.values[sw_key].strip()
    hwt = sec.values[hw_key].strip()
    group = f"{name}_ressourcegroup"
    where = sec.where(file)
    node = ("node", f'rosnode, "{name}_rosnode"')
    if kind == "service":
        lines = [node, ("srv_msg", f"rossrvmsg, {pkg}, srv, {typ}"),
                 ("srvs", f"rossrvs, node, srv_msg, {sw}, 10000"),
                 ("srvc", f"rossrvc, node, srv_msg, {hwt}, hw")]
        info = {"kind": kind, "sw_service": unquote(sw), "hw_service": unquote(hwt),
                "srvtype": f"{pkg}/srv/{typ}"}
    elif kind == "action":
        lines = [node, ("action_msg", f"rosactionmsg, {pkg}, action, {typ}"),
                 ("server", f"rosactions, node, action_msg, {sw}, 10000"),
                 ("client", f"rosactionc, node, action_msg, {hwt}, hw")]
        info = {"kind": kind, "sw_action": unquote(sw), "hw_action": unquote(hwt),
                "actiontype": f"{pkg}/action/{typ}"}
    else:
        lines = [node, ("msg_in", f"rosmsg, {pkg}, msg, {typ}"),
                 ("msg_out", f"rosmsg, {pkg}, msg, {typ}"),
                 ("pub", f"rospub, node, msg_out, {sw}"),
                 ("sub", f"rossub, node, msg_in, {sw}, 1000"),
                 ("hwsub", f"rossub, node, {typename}, {hwt}, hw"),
                 ("hwpub", f"rospub, node, {typename}, {hwt}, hw")]
        info = {"kind": kind, "sw_topic": unquote(sw), "hw_topic": unquote(hwt),
                "msgtype": f"{pkg}/msg/{typ}"}
    members = []
    for key, value in lines:
        members.extend(_resource(key, value, group, where))
    _check_references(members)
    first = 128 + len(resources)
    for i, r in enumerate(members):
        r.id = first + i
    resources.extend(members)
    groups[group] = members
    thread = Thread(name, tid, tslots, "gateway", None, [group], [], [], True, where,
                    gateway=info)
    _thread_resources(thread, resources)
    return thread


def _hw_topics(threads):
    topics = {}
    for t in threads:
        both = {e.topic for e in t.endpoints if e.direction == "pub"} & \
               {e.topic for e in t.endpoints if e.direction == "sub"}
        for e in t.endpoints:
            e.port = (f"{e.topic}_{'in' if e.direction == 'sub' else 'out'}"
                      if e.topic in both else e.topic)
            topic = topics.setdefault(e.topic, HwTopic(e.topic, e.msgtype, [], []))
            if e.msgtype != topic.msgtype:
                raise ConfigError(e.where, f"hardware topic {e.topic!r} carries "
                                           f"{topic.msgtype}, not {e.msgtype}")
            (topic.pubs if e.direction == "pub" else topic.subs).append(e)
    for topic in topics.values():
        if not topic.pubs or not topic.subs:
            missing = "publisher" if not topic.pubs else "subscriber"
            ep = (topic.pubs + topic.subs)[0]
            raise ConfigError(ep.where, f"hardware topic {topic.name!r} has no {missing} "
                                        "(every hardware topic needs both)")
    return topics


def check_messages(project, library):
    """Every message type the project names is defined (standard interfaces or the project's
    ``msg`` folder); raise a :class:`ConfigError` at the first one that is not."""
    for r in project.resources:
        if getattr(r, "interface_ref", None) is not None:
            parts = ("Request", "Response") if "/srv/" in r.msgtype else ("Goal", "Result")
            missing = [f"{r.msgtype}_{p}" for p in parts if f"{r.msgtype}_{p}" not in library]
            if missing:
                raise ConfigError(r.where, f"interface {r.msgtype} is not defined (no "
                                           f"{missing[0]}; standard ROS 2 interfaces and "
                                           f"{', '.join(map(str, project.msg_dirs))})")
        elif r.msgtype is not None and r.msgtype not in library:
            raise ConfigError(r.where, f"message type {r.msgtype} is not defined (standard "
                                       f"ROS 2 interfaces and {', '.join(map(str, project.msg_dirs))})")


def load_project(path, *, msg_dirs=None, check=True):
    """Read and check the ReconROS project file ``path``.

    Parameters
    ----------
    path : path-like
        The ``build.cfg``.
    msg_dirs : list of paths, optional
        Folders of the project's own message packages (default: ``<project>/msg``, where
        ReconROS keeps them).
    check : bool
        Also check that every message type exists.

    Raises
    ------
    ConfigError
        With the file, line, section and key of the first problem.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError(Location(str(path), 0, "-"), f"cannot read: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        line = path.read_bytes()[:exc.start].count(b"\n") + 1
        raise ConfigError(Location(str(path), line, "-"),
                          f"not a text file (byte {exc.start} is not UTF-8); a build.cfg is an "
                          f"INI text file") from None
    project = parse_project(text, path, msg_dirs=msg_dirs)
    if check:
        check_messages(project, project_library(project))
    return project


def project_library(project):
    """The message library of ``project``: standard ROS 2 interfaces plus its msg folders."""
    from gen.msg import MessageLibrary
    return MessageLibrary([d for d in project.msg_dirs if Path(d).is_dir()],
                          store="ros2_humble")
