"""The ROS 2 interfaces of a ReconROS project: every topic, service and action its build.cfg
names for the software path (ReconOS topics through memory, gateways' software sides), with
the threads on each end, and their names on DDS (ROS 2's "Topic and Service name mapping to
DDS": topic ``/x`` is ``rt/x``, type ``pkg/msg/T`` is ``pkg::msg::dds_::T_``; a service
``/s`` is the request topic ``rq/sRequest`` and the reply topic ``rr/sReply``)."""

from dataclasses import dataclass, field

__all__ = ["TopicInterface", "ServiceInterface", "ActionInterface", "RosInterfaces",
           "ros_interfaces", "absolute_name", "dds_topic_name", "dds_type_name",
           "service_topic_names"]


def absolute_name(name, where=None):
    """``name`` as an absolute ROS 2 name (a relative name is resolved in the root
    namespace, as a node without a namespace does)."""
    text = name.strip()
    if not text or text == "/" or "//" in text or text.endswith("/") or \
            not all(c.isalnum() or c in "_/~" for c in text) or text.lstrip("/")[0].isdigit():
        raise ValueError(f"{where + ': ' if where else ''}{name!r} is not a valid ROS 2 topic "
                         f"or service name")
    return text if text.startswith("/") else "/" + text


def dds_topic_name(topic, prefix="rt"):
    """The DDS topic of ROS 2 topic ``topic`` (``/x`` -> ``rt/x``)."""
    return prefix + absolute_name(topic)


def dds_type_name(typename):
    """The DDS type name of ROS 2 type ``pkg/msg/T`` (``pkg::msg::dds_::T_``); service and
    action parts keep their interface kind (``pkg/srv/S_Request`` ->
    ``pkg::srv::dds_::S_Request_``)."""
    parts = typename.split("/")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"{typename!r} is not a ROS 2 type name 'pkg/msg/Type'")
    pkg, kind, name = parts
    return f"{pkg}::{kind}::dds_::{name}_"


def service_topic_names(service):
    """(request topic, reply topic) of service ``service`` as rmw_cyclonedds_cpp names them."""
    name = absolute_name(service)
    return f"rq{name}Request", f"rr{name}Reply"


@dataclass
class TopicInterface:
    """A topic on the software path: its ROS 2 type and the threads publishing and
    subscribing it in the build.cfg."""
    name: str
    msgtype: str
    publishers: list = field(default_factory=list)
    subscribers: list = field(default_factory=list)
    where: object = None
    #: the hardware topic a ROS gateway connects this topic to (its QoS applies on DDS)
    hardware_topic: str = None
    #: the name as the build.cfg writes it (the software runtime's key)
    key: str = None


@dataclass
class ServiceInterface:
    """A service: ``srvtype`` is ``pkg/srv/S``; the threads serving and calling it."""
    name: str
    srvtype: str
    servers: list = field(default_factory=list)
    clients: list = field(default_factory=list)
    where: object = None
    #: the name as the build.cfg writes it (the software runtime's key)
    key: str = None

    @property
    def request_type(self):
        return f"{self.srvtype}_Request"

    @property
    def response_type(self):
        return f"{self.srvtype}_Response"


@dataclass
class ActionInterface:
    """An action: ``actiontype`` is ``pkg/action/A``; the threads serving and using it."""
    name: str
    actiontype: str
    servers: list = field(default_factory=list)
    clients: list = field(default_factory=list)
    where: object = None
    #: the name as the build.cfg writes it (the software runtime's key)
    key: str = None


@dataclass
class RosInterfaces:
    topics: dict
    services: dict
    actions: dict
    #: (kind, ROS 2 name, role) -> the names of the ROS nodes (``rosnode`` resources) of the
    #: threads in that role, e.g. ``("topic", "/image_in", "subscribers") -> ["/echo"]``
    nodes: dict = field(default_factory=dict)


def _interface_type(thread, resource, suffix):
    """The ROS 2 type a publisher, subscriber, server or client names through its message
    resource (``suffix``: ``""`` for a message, ``_req`` for a service, ``_goal_req`` for
    an action)."""
    from gen.config import ConfigError
    key = resource.args[1].strip()
    try:
        msg = thread.resource(key + suffix)
    except KeyError:
        raise ConfigError(resource.where, f"{resource.type} {resource.name}: no message "
                                          f"resource {key!r} in its group") from None
    if msg.msgtype is None:
        raise ConfigError(resource.where, f"{resource.type} {resource.name}: {key!r} is a "
                                          f"{msg.type}, not a message")
    return msg.msgtype


def ros_interfaces(project):
    """The :class:`RosInterfaces` of ``project`` (a :class:`gen.config.Project`)."""
    from gen.config import ConfigError, unquote
    topics, services, actions, nodes = {}, {}, {}, {}

    def add(table, raw, kind, typename, thread, role, where, make, node_resource):
        name = absolute_name(raw, str(where))
        entry = table.setdefault(name, make(name, typename, where=where, key=raw))
        if entry.key != raw:
            raise ConfigError(where, f"{kind} {name!r} is written {entry.key!r} elsewhere in "
                                     f"the build.cfg and {raw!r} here; write it one way")
        type_attr = {"topic": "msgtype", "service": "srvtype", "action": "actiontype"}[kind]
        if getattr(entry, type_attr) != typename:
            raise ConfigError(where, f"{kind} {name!r} carries {getattr(entry, type_attr)} "
                                     f"elsewhere in the build.cfg, not {typename}")
        getattr(entry, role).append(thread.name)
        node = _node_name(thread, node_resource)
        names = nodes.setdefault((kind, name, role), [])
        if node not in names:
            names.append(node)
        return name

    for thread in project.threads:
        gateway = thread.gateway
        for r in thread.resources:
            if r.type in ("rossub", "rospub"):
                name = add(topics, unquote(r.args[2]), "topic", _interface_type(thread, r, ""),
                           thread, "subscribers" if r.type == "rossub" else "publishers",
                           r.where, TopicInterface, r.args[0])
                if gateway is not None:
                    topics[name].hardware_topic = gateway["hw_topic"]
            elif r.type in ("rossrvs", "rossrvc"):
                raw = unquote(r.args[2]) if len(r.args) > 2 else r.name
                srvtype = _interface_type(thread, r, "_req").removesuffix("_Request")
                add(services, raw, "service", srvtype, thread,
                    "servers" if r.type == "rossrvs" else "clients", r.where, ServiceInterface,
                    r.args[0])
            elif r.type in ("rosactions", "rosactionc"):
                goal = _interface_type(thread, r, "_goal_req")
                add(actions, unquote(r.args[2]), "action",
                    goal.removesuffix("_SendGoal_Request"), thread,
                    "servers" if r.type == "rosactions" else "clients", r.where,
                    ActionInterface, r.args[0])
    return RosInterfaces(topics, services, actions, nodes)


def _node_name(thread, resource_name):
    """The absolute name of the ROS node a thread's endpoint belongs to: the ``rosnode``
    resource its first argument names (``node_1 = rosnode, "filternode"`` -> ``/filternode``);
    the thread's name when the argument names no rosnode."""
    from gen.config import unquote
    try:
        node = thread.resource(resource_name.strip())
    except KeyError:
        node = None
    if node is None or node.type != "rosnode" or not node.args:
        return absolute_name(thread.name.lower())
    return absolute_name(unquote(node.args[0]))
