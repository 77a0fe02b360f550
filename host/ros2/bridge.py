"""The DDS bridge of ``rosgate sim --ros2``: the co-simulated system's topics and services on
a Cyclone DDS domain, as a ROS 2 node built on rmw_cyclonedds_cpp would show them.

:class:`Ros2Bridge` runs inside the cocotb test, in the simulator's thread: :meth:`poll`
moves what arrived from DDS into the in-process graph (:class:`host.reconos.Broker`) and what
the graph published onto DDS, and :meth:`wait` blocks the simulator (simulated time stands
still) until DDS has data, when the system has nothing to do.

Samples cross as bytes, never as Python objects: each one is checked by decoding it with the
message library (:func:`gen.msg.wire.decode_cdr`) and the project's own bound check, and
written back with :func:`gen.msg.wire.encode_cdr`, so what DDS carries is byte for byte what
rosbags serializes. A sample that does not decode, breaks a bound of its type, or is refused
by the hardware's limits is dropped with one log line and counted; nothing else changes.
"""

import collections
import os
import time

from gen.msg.parser import parse_srv
from gen.msg.wire import CDR_LE_HEADER, WireError, decode_cdr, default_value, encode_cdr
from hdl.dds.action import CancelStatus, GoalStatus

from .graph import dds_topic_name, service_topic_names
from .types import DdsTypes, pack_request_header, unpack_request_header

__all__ = ["Ros2Bridge", "BridgeQos", "LOOPBACK_CONFIG", "DOMAIN_IDS", "default_domain"]

#: the domain ids a DDS participant can join (the RTPS port mapping ends at 232)
DOMAIN_IDS = range(233)

#: a Cyclone DDS configuration that keeps a domain on this machine's loopback interface
LOOPBACK_CONFIG = (
    '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/>'
    '</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>'
    '<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>60'
    '</MaxAutoParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers></Discovery>'
    '</Domain></CycloneDDS>')


def default_domain():
    """``ROS_DOMAIN_ID`` if set (checked), else 0."""
    text = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return 0
    if not text.isdigit() or int(text) not in DOMAIN_IDS:
        raise ValueError(f"ROS_DOMAIN_ID={text!r}: expected a DDS domain id 0..{DOMAIN_IDS[-1]}")
    return int(text)


#: action_msgs/srv/CancelGoal (ROS 2's action_msgs; rosbags' type stores lack services)
CANCEL_GOAL_SRV = """\
action_msgs/GoalInfo goal_info
---
int8 ERROR_NONE=0
int8 ERROR_REJECTED=1
int8 ERROR_UNKNOWN_GOAL_ID=2
int8 ERROR_GOAL_TERMINATED=3
int8 return_code
action_msgs/GoalInfo[] goals_canceling
"""
CANCEL_GOAL = "action_msgs/srv/CancelGoal"
#: the bridge's origin in the in-process graph (host.reconos.Broker)
ORIGIN = "ros2 bridge"
#: action_msgs/msg/GoalStatus
STATUS_UNKNOWN, STATUS_ACCEPTED, STATUS_EXECUTING, STATUS_CANCELING = (
    GoalStatus.UNKNOWN, GoalStatus.ACCEPTED, GoalStatus.EXECUTING, GoalStatus.CANCELING)
STATUS_SUCCEEDED, STATUS_CANCELED, STATUS_ABORTED = (
    GoalStatus.SUCCEEDED, GoalStatus.CANCELED, GoalStatus.ABORTED)
#: rcl_action's default result timeout: a finished goal leaves the status list after it
RESULT_TIMEOUT_S = 900.0
#: what the bridge does with a goal while the hardware serves others (``--goal-policy``)
GOAL_POLICIES = ("queue", "reject")
#: action_msgs/srv/CancelGoal return codes
CANCEL_NONE = CancelStatus.ERROR_NONE
CANCEL_UNKNOWN_GOAL_ID, CANCEL_GOAL_TERMINATED = (CancelStatus.ERROR_UNKNOWN_GOAL_ID,
                                                  CancelStatus.ERROR_GOAL_TERMINATED)


#: the ROS graph's topic and type (rmw_dds_common), the size of a gid, the bridge's own node
DISCOVERY_TOPIC = "ros_discovery_info"
DISCOVERY_TYPE = "rmw_dds_common/msg/ParticipantEntitiesInfo"
GID_SIZE = 24
BRIDGE_NODE = "/rosgate_sim"
#: the simulated clock's topic and type (ROS 2's ``use_sim_time``)
CLOCK_TOPIC, CLOCK_TYPE = "/clock", "rosgraph_msgs/msg/Clock"
#: calls of one service the bridge holds for the hardware by default (``--service-queue``)
SERVICE_QUEUE = 1000


def ros_time(ns):
    """``builtin_interfaces/msg/Time`` of ``ns`` nanoseconds."""
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


class BridgeQos:
    """ROS 2's default QoS profile for topics and services (rmw_qos_profile_default):
    reliable, keep last ``depth``, volatile."""

    def __init__(self, depth=10, service_queue=SERVICE_QUEUE):
        if not isinstance(depth, int) or depth < 1:
            raise ValueError(f"QoS history depth {depth!r}: expected an integer >= 1")
        if not isinstance(service_queue, int) or service_queue < 1:
            raise ValueError(f"service queue {service_queue!r}: expected an integer >= 1")
        self.depth = depth
        #: calls of one service the bridge holds for the hardware; more are refused
        self.service_queue = service_queue

    def discovery(self):
        """``ros_discovery_info``'s profile (rmw_cyclonedds_cpp): reliable, keep last 1,
        transient local, so a participant that joins later still gets the graph."""
        return self.dds(status=True)

    def clock(self):
        """``/clock``'s profile: reliable, keep last 1, volatile (rclcpp's clock subscription,
        best effort keep last 1, matches it)."""
        from cyclonedds.core import Policy, Qos
        return Qos(Policy.Durability.Volatile, base=self.dds(status=True))

    def dds(self, status=False, keep_all=False):
        """The profile; ``status``: an action's status topic (transient local, keep last 1,
        as rcl_action's status profile); ``keep_all``: a gateway's topic, whose hardware topic
        keeps every message."""
        from cyclonedds.core import Policy, Qos
        from cyclonedds.util import duration
        history = Policy.History.KeepAll if keep_all else \
            Policy.History.KeepLast(1 if status else self.depth)
        return Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), history,
                   Policy.Durability.TransientLocal if status else Policy.Durability.Volatile,
                   Policy.IgnoreLocal.Participant)


class _Endpoint:
    """One direction of one interface on DDS: a reader or a writer and what it carries."""

    def __init__(self, name, typename, entity, key):
        self.name = name            # the ROS 2 name (for log lines and counters)
        self.typename = typename    # the ROS 2 type of the message part
        self.entity = entity
        self.key = key              # the broker's name


class _GoalRecord:
    """A goal a DDS client sent to a hardware action server."""

    def __init__(self, goal, stamp, result_type, status=STATUS_EXECUTING):
        from cocotb.triggers import Event
        self.goal = goal
        self.stamp = stamp
        self.result_type = result_type       # <Action>_GetResult_Response
        self.status = status
        self.result = None
        self.done = Event()
        self.finished_s = None       # wall time the result came (for the result timeout)

    @property
    def active(self):
        return self.status in (STATUS_ACCEPTED, STATUS_EXECUTING, STATUS_CANCELING)


class Ros2Bridge:
    """A participant on DDS domain ``domain`` for the interfaces of a project.

    Parameters
    ----------
    interfaces : host.ros2.graph.RosInterfaces
    library : gen.msg.MessageLibrary
    broker : host.reconos.Broker
    domain : int
    log : callable
        ``log(text)`` for the bridge's lines (joins, rejections).
    accepts : callable or None
        ``accepts(name, value)`` -> ``None`` or the reason the hardware cannot take a
        message arriving from DDS on topic or service ``name``.
    qos : BridgeQos
    spawn : callable
        Starts a coroutine beside the simulation (``cocotb.start_soon``), for service calls
        into the graph.
    now_ns : callable
        The bridge's clock in ns (simulated time), for the stamps of action goals.
    publish_clock : bool
        Write ``/clock`` (:meth:`write_clock`).
    goal_policy : str
        A goal that arrives while the hardware serves as many goals as it has servers:
        ``"queue"`` accepts it at once and hands it to the hardware when a server is free,
        ``"reject"`` refuses it at once.
    result_timeout_s : float
        Wall seconds a finished goal stays in the status list and its result can be asked
        for (rcl_action's default: 900).
    """

    def __init__(self, interfaces, library, broker, *, domain, log, spawn, accepts=None,
                 qos=None, now_ns=time.monotonic_ns, publish_clock=False, goal_policy="queue",
                 result_timeout_s=RESULT_TIMEOUT_S):
        if not isinstance(domain, int) or domain not in DOMAIN_IDS:
            raise ValueError(f"DDS domain {domain!r}: expected an integer 0..{DOMAIN_IDS[-1]}")
        self.interfaces = interfaces
        self.library = library
        self.broker = broker
        self.domain = domain
        self.log = log
        self.spawn = spawn
        self.accepts = accepts
        self.now_ns = now_ns
        self.publish_clock = publish_clock
        if goal_policy not in GOAL_POLICIES:
            raise ValueError(f"goal policy {goal_policy!r}: expected one of "
                             f"{', '.join(GOAL_POLICIES)}")
        self.goal_policy = goal_policy
        self.result_timeout_s = float(result_timeout_s)
        self._clock = None
        #: node name -> (the bridge's readers, writers) that stand for its endpoints on DDS
        self._graph = {}
        self._served_goals = []      # (goals by uuid, status writer) of each served action
        self.qos = qos or BridgeQos()
        self.types = DdsTypes(library)
        #: per ROS 2 name: samples taken from DDS, delivered, rejected, and written to DDS
        self.counts = collections.defaultdict(lambda: {"received": 0, "delivered": 0,
                                                       "rejected": 0, "sent": 0})
        self.rejections = []
        self._inbound = []           # (endpoint, handler)
        self._outbound = []          # (broker queue, endpoint)
        self._clients = []           # (broker server queue, reply endpoint) per called service
        self._action_clients = []    # state of each action the hardware uses on DDS
        self._calls = 0              # service calls into the graph still running
        self._guid = int.from_bytes(os.urandom(8), "little") or 1
        self._seq = 0
        self.participant = None
        #: the last TIMELINE messages across the bridge with wall-clock times
        #: (``time.monotonic_ns``): ``in`` when handed to the system, ``out`` when the
        #: system published it and when it was written to DDS
        self.timeline = collections.deque(maxlen=self.TIMELINE)
        self._published = {}
        self._published_keys = set()   # broker names of the topics written to DDS

    TIMELINE = 1000

    # --- set-up --------------------------------------------------------------------------
    def start(self):
        """Join the domain and create a reader or writer for every interface; returns the
        names of what appears on DDS."""
        from cyclonedds.core import WaitSet
        from cyclonedds.domain import DomainParticipant
        self.participant = DomainParticipant(self.domain)
        self.waitset = WaitSet(self.participant)
        shown = []
        self.broker.observers.append(self._observe)
        for topic in self.interfaces.topics.values():
            keep_all = topic.hardware_topic is not None
            if topic.subscribers:
                ep = self._reader(dds_topic_name(topic.name), self.types.message(topic.msgtype),
                                  topic.name, topic.msgtype, topic.key, keep_all=keep_all)
                self._inbound.append((ep, self._topic_sample))
                self._own(("topic", topic.name, "subscribers"), ep)
            if topic.publishers:
                ep = self._writer(dds_topic_name(topic.name), self.types.message(topic.msgtype),
                                  topic.name, topic.msgtype, topic.key, keep_all=keep_all)
                self._own(("topic", topic.name, "publishers"), ep)
                # what the bridge itself publishes does not come back to it (the broker's
                # origin rule): DDS samples are not echoed onto DDS
                self._outbound.append((self.broker.subscribe(topic.key, ORIGIN), ep))
                self._published_keys.add(topic.key)
            shown.append(f"{topic.name} [{topic.msgtype}]")
        for service in self.interfaces.services.values():
            request, reply = service_topic_names(service.name)
            req_type = self.types.service_part(service.request_type)
            res_type = self.types.service_part(service.response_type)
            if service.servers:
                # every request is kept until the bridge takes it (history KEEP_ALL, reliable:
                # a burst makes the clients wait, it does not overwrite requests)
                ep = self._reader(request, req_type, service.name, service.request_type,
                                  service.key, keep_all=True)
                ep.queued = 0
                ep.reply = self._writer(reply, res_type, service.name, service.response_type,
                                        service.key)
                self._inbound.append((ep, self._service_request))
                self._own(("service", service.name, "servers"), ep, ep.reply)
                shown.append(f"{service.name} [{service.srvtype}] (served in hardware)")
            elif service.key not in self.broker._services:
                ep = self._reader(reply, res_type, service.name, service.response_type,
                                  service.key)
                ep.reply = self._writer(request, req_type, service.name,
                                        service.request_type, service.key)
                ep.pending = {}
                self._own(("service", service.name, "clients"), ep, ep.reply)
                self._inbound.append((ep, self._service_reply))
                self._clients.append((self.broker.server_queue(service.key), ep))
                shown.append(f"{service.name} [{service.srvtype}] (called from hardware)")
        if self.publish_clock:
            self._clock = self._writer(dds_topic_name(CLOCK_TOPIC), self.types.message(CLOCK_TYPE),
                                       CLOCK_TOPIC, CLOCK_TYPE, None, qos=self.qos.clock())
            self._graph.setdefault(BRIDGE_NODE, ([], []))[1].append(self._clock)
            shown.append(f"{CLOCK_TOPIC} [{CLOCK_TYPE}] (simulated time)")
        for action in self.interfaces.actions.values():
            if action.servers:
                self._serve_action(action)
                shown.append(f"{action.name} [{action.actiontype}] (action served in hardware)")
            elif action.key not in self.broker._actions:
                self._call_action(action)
                shown.append(f"{action.name} [{action.actiontype}] (action used from hardware)")
        self._write_discovery_info()
        return shown

    def _own(self, role, *endpoints):
        """Count ``endpoints`` (the bridge's readers and writers) as those of the hardware
        nodes in ``role`` (``(kind, name, role)`` of :attr:`RosInterfaces.nodes`)."""
        for node in self.interfaces.nodes.get(role, ()):
            readers, writers = self._graph.setdefault(node, ([], []))
            for ep in endpoints:
                (writers if hasattr(ep.entity, "write") else readers).append(ep)

    def _write_discovery_info(self):
        """``ros_discovery_info`` as rmw_cyclonedds_cpp writes it: this participant's gid and,
        per hardware node, the gids of its readers and writers (a DDS GUID and 8 zero bytes),
        so ``ros2 node list`` and ``ros2 topic info -v`` name the hardware nodes."""
        def gid(entity):
            return {"data": entity.guid.bytes + bytes(GID_SIZE - 16)}
        nodes = []
        for name, (readers, writers) in sorted(self._graph.items()):
            namespace, _, node = name.rpartition("/")
            nodes.append({"node_namespace": namespace or "/", "node_name": node,
                          "reader_gid_seq": [gid(ep.entity) for ep in readers],
                          "writer_gid_seq": [gid(ep.entity) for ep in writers]})
        value = {"gid": gid(self.participant), "node_entities_info_seq": nodes}
        # kept: the writer holds the transient-local sample for participants joining later
        self._discovery = self._writer(DISCOVERY_TOPIC, self.types.message(DISCOVERY_TYPE),
                                       DISCOVERY_TOPIC, DISCOVERY_TYPE, None,
                                       qos=self.qos.discovery(), counted=False)
        self._write(self._discovery, encode_cdr(self.library, DISCOVERY_TYPE, value))

    def _action_endpoints(self, action, client):
        """The action's three services (request and reply sides swapped for a client) and
        its feedback topic, as (service endpoints by name, feedback endpoint)."""
        if CANCEL_GOAL + "_Request" not in self.library:
            for definition in parse_srv(CANCEL_GOAL_SRV, CANCEL_GOAL, "<action_msgs>"):
                self.library.add(definition)
        base, a = f"{action.name}/_action/", action.actiontype
        services = {}
        for service, srvtype in (("send_goal", f"{a}_SendGoal"),
                                 ("get_result", f"{a}_GetResult"),
                                 ("cancel_goal", CANCEL_GOAL)):
            request, reply = service_topic_names(base + service)
            parts = [(request, srvtype + "_Request"), (reply, srvtype + "_Response")]
            incoming, outgoing = parts[::-1] if client else parts
            ep = self._reader(incoming[0], self.types.service_part(incoming[1]),
                              base + service, incoming[1], action.key)
            ep.reply = self._writer(outgoing[0], self.types.service_part(outgoing[1]),
                                    base + service, outgoing[1], action.key)
            services[service] = ep
        feedback_type = f"{a}_FeedbackMessage"
        make = self._reader if client else self._writer
        feedback = make(dds_topic_name(base + "feedback"), self.types.message(feedback_type),
                        base + "feedback", feedback_type, action.key)
        return services, feedback

    def _call_action(self, action):
        """An action the hardware uses and nobody in the build.cfg serves: the bridge is
        its server in the graph and a client of it on DDS, as rcl_action's client."""
        services, feedback = self._action_endpoints(action, client=True)
        state = {"goals": self.broker.action_server_queue(action.key), "sent": {},
                 "by_uuid": {}, "results": {}, "services": services}
        for name in ("send_goal", "get_result"):
            services[name].state = state
        # feedback before results: feedback a server sent before the result is delivered
        # even when both arrive in one poll
        self._inbound += [(services["send_goal"], self._goal_reply),
                          (feedback, self._goal_feedback_in),
                          (services["get_result"], self._result_reply)]
        feedback.state = state
        self._action_clients.append(state)
        self._own(("action", action.name, "clients"), feedback,
                  *(e for ep in services.values() for e in (ep, ep.reply)))

    def _serve_action(self, action):
        """An action served in hardware, as rcl_action shows it: the services send_goal,
        get_result and cancel_goal and the topics feedback and status under
        ``<action>/_action/``."""
        services, feedback = self._action_endpoints(action, client=False)
        status = self._writer(dds_topic_name(f"{action.name}/_action/status"),
                              self.types.message("action_msgs/msg/GoalStatusArray"),
                              f"{action.name}/_action/status",
                              "action_msgs/msg/GoalStatusArray", action.key, status=True)
        goals = {}
        self._served_goals.append((goals, status))
        for name, handler in (("send_goal", self._send_goal),
                              ("get_result", self._get_result),
                              ("cancel_goal", self._cancel_goal)):
            ep = services[name]
            ep.goals, ep.feedback, ep.status = goals, feedback, status
            ep.servers = max(1, len(action.servers))
            self._inbound.append((ep, handler))
        self._own(("action", action.name, "servers"), feedback, status,
                  *(e for ep in services.values() for e in (ep, ep.reply)))

    def _observe(self, key, value):
        if key in self._published_keys:
            self._published[id(value)] = (value, time.monotonic_ns())

    def _topic(self, name, idl, keep_all=False, qos=None):
        from cyclonedds.topic import Topic
        return Topic(self.participant, name, idl, qos=qos or self.qos.dds(keep_all=keep_all))

    def _reader(self, dds_name, idl, name, typename, key, keep_all=False):
        from cyclonedds.core import ReadCondition, SampleState, ViewState, InstanceState
        from cyclonedds.sub import DataReader
        reader = DataReader(self.participant, self._topic(dds_name, idl, keep_all=keep_all),
                            qos=self.qos.dds(keep_all=keep_all))
        self.counts.setdefault(name, self.counts.default_factory())   # listed even if idle
        condition = ReadCondition(reader, SampleState.NotRead | ViewState.Any |
                                  InstanceState.Any)
        self.waitset.attach(condition)
        return _Endpoint(name, typename, reader, key)

    def _writer(self, dds_name, idl, name, typename, key, status=False, keep_all=False,
                qos=None, counted=True):
        """A writer with the default profile (``status``, ``keep_all`` as
        :meth:`BridgeQos.dds`) or ``qos``; ``counted``: listed in :meth:`summary`."""
        from cyclonedds.pub import DataWriter
        qos = qos or self.qos.dds(status, keep_all)
        writer = DataWriter(self.participant, self._topic(dds_name, idl, qos=qos), qos=qos)
        if counted:
            self.counts.setdefault(name, self.counts.default_factory())
        return _Endpoint(name, typename, writer, key)

    def close(self):
        """Leave the domain (deletes the participant and everything it made)."""
        participant, self.participant = self.participant, None
        if participant is not None:
            self.waitset = None
            participant.__del__()     # dds_delete of the participant and all it contains

    def summary(self):
        """Counts per interface and every rejection, for ``sim_results.json``."""
        dropped = {t.name: sum(q.dropped for q in self.broker._subs.get(t.key, ()))
                   for t in self.interfaces.topics.values() if t.subscribers}
        return {"domain": self.domain, "counts": {k: dict(v) for k, v in self.counts.items()},
                "dropped_by_history": dropped,
                "rejected": sum(v["rejected"] for v in self.counts.values()),
                "rejections": list(self.rejections), "timeline": list(self.timeline)}

    # --- running -------------------------------------------------------------------------
    def write_clock(self, ns):
        """Publish ``ns`` (the bridge's clock: simulated time, from zero or from the wall
        time at the start) on ``/clock`` as a ``rosgraph_msgs/msg/Clock``."""
        if self._clock is None:
            return
        value = {"clock": ros_time(ns)}
        self._write(self._clock, encode_cdr(self.library, CLOCK_TYPE, value))

    @property
    def busy(self):
        """A service call this bridge started into the graph is still running."""
        return self._calls > 0

    def poll(self):
        """Move everything that is waiting, both ways; return how many messages moved."""
        from cyclonedds._clayer import ddspy_take
        from cyclonedds.core import InstanceState, SampleState, ViewState
        moved = 0
        mask = SampleState.Any | ViewState.Any | InstanceState.Any
        for ep, handler in self._inbound:
            taken = ddspy_take(ep.entity._ref, mask, 64)
            if isinstance(taken, int):
                raise RuntimeError(f"DDS take on {ep.name} failed with code {taken}")
            for data, info in taken:
                if info.valid_data:
                    self.counts[ep.name]["received"] += 1
                    handler(ep, bytes(data))
                    moved += 1
        for queue, ep in self._outbound:
            while (value := queue.get_nowait()) is not None:
                held, published = self._published.pop(id(value), (None, None))
                published = published if held is value else None
                data = encode_cdr(self.library, ep.typename, value)
                self._write(ep, data)
                self.timeline.append({"direction": "out", "name": ep.name, "bytes": len(data),
                                      "published_ns": published,
                                      "written_ns": time.monotonic_ns()})
                moved += 1
        for state in self._action_clients:
            moved += self._poll_action_client(state)
        self._expire_goals()
        for queue, ep in self._clients:
            # a request waits until a server is there (rclcpp's wait_for_service): a volatile
            # request written before the match would be lost
            while len(queue) and self._matched(ep.reply) and \
                    (item := queue.get_nowait()) is not None:
                request, reply_queue = item
                ep.pending[self._call(ep, request)] = reply_queue
                moved += 1
        return moved

    @staticmethod
    def _matched(ep):
        return ep.entity.get_publication_matched_status().current_count > 0

    def wait(self, seconds):
        """Block until a reader has data or ``seconds`` pass."""
        from cyclonedds.util import duration
        self.waitset.wait(duration(seconds=seconds))

    def _write(self, ep, data):
        from cyclonedds._clayer import ddspy_write
        # DDS samples are whole 4-byte words; the options' low bits count the padding
        pad = -len(data) % 4
        if pad:
            data = data[:3] + bytes([data[3] | pad]) + data[4:] + bytes(pad)
        result = ddspy_write(ep.entity._ref, data)
        if result < 0:
            raise RuntimeError(f"DDS write on {ep.name} failed with code {result}")
        if ep.name in self.counts:
            self.counts[ep.name]["sent"] += 1

    def _reject(self, ep, reason):
        self.counts[ep.name]["rejected"] += 1
        self.rejections.append({"name": ep.name, "reason": reason})
        self.log(f"ros2 bridge: {ep.name}: rejected a {ep.typename} from DDS: {reason}")

    def _decode(self, ep, data):
        """The sample's value, or ``None`` after rejecting it."""
        value, reason = self._check(ep, data)
        if reason:
            self._reject(ep, reason)
            return None
        return value

    def _check(self, ep, data):
        """(value, ``None``), or (``None``, why the hardware cannot take the sample): its
        bytes are not the type's CDR, or ``sim.py``'s ``accepts`` refuses it."""
        try:
            value = decode_cdr(self.library, ep.typename, data, padded=True)
        except WireError as exc:
            return None, str(exc)
        reason = self.accepts(ep.name, value) if self.accepts is not None else None
        return (None, reason) if reason else (value, None)

    def _topic_sample(self, ep, data):
        value = self._decode(ep, data)
        if value is not None:
            self.timeline.append({"direction": "in", "name": ep.name, "bytes": len(data),
                                  "ingress_ns": time.monotonic_ns()})
            self.broker.publish(ep.key, value, ORIGIN)
            self._published.pop(id(value), None)     # it will not come back to the bridge
            self.counts[ep.name]["delivered"] += 1

    def _split(self, ep, data):
        """(guid, seq, the message's own CDR) of a service sample, or ``None``."""
        try:
            guid, seq = unpack_request_header(data[4:])
        except ValueError as exc:
            self._reject(ep, str(exc))
            return None
        return guid, seq, data[:4] + data[20:]

    def _service_request(self, ep, data):
        request = self._request(ep, data, refuse=lambda *call: self._refuse_call(ep, *call))
        if request is None:
            return
        guid, seq, value = request
        if ep.queued >= self.qos.service_queue:
            return self._refuse_call(ep, guid, seq, f"{ep.queued} calls wait for the hardware "
                                                    f"already (the bridge's service queue, "
                                                    f"--service-queue {self.qos.service_queue})")
        self.counts[ep.name]["delivered"] += 1
        self._calls += 1
        ep.queued += 1

        async def call():
            # the hardware takes the calls in the order they came (the broker's queue)
            try:
                self._reply(ep, guid, seq, await self.broker.call(ep.key, value))
            finally:
                self._calls -= 1
                ep.queued -= 1
        self.spawn(call())

    def _refuse_call(self, ep, guid, seq, reason):
        """A request the hardware cannot take: counted and logged as rejected, and answered
        with the response type's default value (empty sequences, zeros), so that the
        client does not wait for ever."""
        self._reject(ep, reason)
        response = ep.reply.typename
        self._reply(ep, guid, seq, default_value(self.library, response))

    def _service_reply(self, ep, data):
        got = self._client_reply(ep, data, ep.pending)
        if got is not None:
            reply_queue, value = got
            reply_queue.put(value)

    def _send(self, writer, guid, seq, value):
        """``value`` with rmw_cyclonedds_cpp's request header on ``writer``."""
        body = encode_cdr(self.library, writer.typename, value)
        self._write(writer, CDR_LE_HEADER + pack_request_header(guid, seq) + body[4:])

    def _reply(self, ep, guid, seq, value):
        """Answer the request ``(guid, seq)`` that came in on ``ep``."""
        self._send(ep.reply, guid, seq, value)

    def _call(self, ep, value):
        """Send a request on ``ep.reply`` (a client side); return its sequence number."""
        self._seq += 1
        self._send(ep.reply, self._guid, self._seq, value)
        return self._seq

    def _request(self, ep, data, refuse=None):
        """(guid, seq, value) of a request, or ``None`` after rejecting it; ``refuse(guid,
        seq, reason)``, if given, rejects and answers a request the hardware cannot take."""
        split = self._split(ep, data)
        if split is None:
            return None                  # no request header: nobody to answer
        guid, seq, body = split
        value, reason = self._check(ep, body)
        if reason:
            if refuse is None:
                self._reject(ep, reason)
            else:
                refuse(guid, seq, reason)
            return None
        return guid, seq, value

    def _client_reply(self, ep, data, table):
        """(the waiting item, value) of a reply to one of this bridge's calls, or None."""
        split = self._split(ep, data)
        if split is None:
            return None
        guid, seq, body = split
        if guid != self._guid:
            return None                     # another client's reply
        if seq not in table:
            self._reject(ep, f"a reply to call {seq}, which this bridge did not make or "
                             f"already has")
            return None
        value = self._decode(ep, body)
        if value is None:
            return None
        self.counts[ep.name]["delivered"] += 1
        return table.pop(seq), value

    # --- actions served in hardware ------------------------------------------------------
    def _stamp(self):
        return ros_time(int(self.now_ns()))

    def _publish_status(self, ep):
        self._write_status(ep.goals, ep.status)

    def _write_status(self, goals, writer):
        status_list = [{"goal_info": {"goal_id": {"uuid": uuid}, "stamp": r.stamp},
                        "status": r.status} for uuid, r in goals.items()]
        self._write(writer, encode_cdr(self.library, writer.typename,
                                       {"status_list": status_list}))

    def _send_goal(self, ep, data):
        """A goal from DDS, answered at once as rclcpp_action answers: the hardware decides
        when it has a free server (its GOAL_DECIDE comes within cycles); otherwise the goal
        policy accepts it into the queue or refuses it. An accepted goal executes at once:
        the bridge asks the hardware for its result on acceptance (ReconROS' servers wait in
        ACTIONS_RESULT_TAKE), and keeps it for the client's get_result."""
        request = self._request(ep, data, refuse=lambda *call: self._refuse_goal(ep, *call))
        if request is None:
            return
        guid, seq, value = request
        uuid = bytes(value["goal_id"]["uuid"])
        if uuid in ep.goals:
            return self._refuse_goal(ep, guid, seq, f"goal id {uuid.hex()} is already in use")
        busy = sum(r.active for r in ep.goals.values()) >= ep.servers
        if busy and self.goal_policy == "reject":
            return self._refuse_goal(ep, guid, seq, f"the hardware serves {ep.servers} goal(s) "
                                                    f"already (--goal-policy reject)")
        goal = self.broker.send_goal(ep.key, value["goal"], uuid)
        result_type = ep.reply.typename.replace("_SendGoal_Response", "_GetResult_Response")
        record = ep.goals[uuid] = _GoalRecord(goal, self._stamp(), result_type,
                                              STATUS_ACCEPTED)
        self._calls += 1
        if busy:
            self.counts[ep.name]["delivered"] += 1
            self._reply(ep, guid, seq, {"accepted": True, "stamp": record.stamp})
            self._publish_status(ep)

        async def decide():
            try:
                accepted = await goal.accepted.get()
                if record.status == STATUS_CANCELED:
                    return               # taken out of the queue before the hardware saw it
                if not accepted and not busy:
                    # refused by the hardware while the client still waits: a refusal
                    del ep.goals[uuid]
                    self._reject(ep, "the hardware server refused the goal")
                    self._reply(ep, guid, seq, {"accepted": False, "stamp": self._stamp()})
                    return
                if not accepted:
                    # accepted into the queue, refused when its turn came
                    self._finish(ep, record, STATUS_ABORTED)
                    self.log(f"ros2 bridge: {ep.name}: goal {uuid.hex()} aborted: the "
                             f"hardware server refused it when its turn came")
                    return
                if record.status == STATUS_ACCEPTED:
                    record.status = STATUS_EXECUTING
                goal.request_result()
                self.spawn(self._goal_feedback(ep, goal))
                self.spawn(self._goal_result(ep, record))
                if not busy:
                    self.counts[ep.name]["delivered"] += 1
                    self._reply(ep, guid, seq, {"accepted": True, "stamp": record.stamp})
                self._publish_status(ep)
            finally:
                self._calls -= 1
        self.spawn(decide())

    def _refuse_goal(self, ep, guid, seq, reason):
        self._reject(ep, reason)
        self._reply(ep, guid, seq, {"accepted": False, "stamp": self._stamp()})

    def _finish(self, ep, record, status):
        """End ``record`` without a hardware result: ``status`` and the empty result."""
        result = default_value(self.library, record.result_type)
        record.result = {**result, "status": status}
        record.status = status
        record.finished_s = time.monotonic()
        record.done.set()
        self._publish_status(ep)

    async def _goal_feedback(self, ep, goal):
        while True:
            value = await goal.feedback.get()
            self._write(ep.feedback, encode_cdr(self.library, ep.feedback.typename, value))

    async def _goal_result(self, ep, record):
        response = await record.goal.result.get()
        # ReconROS' ACTIONS_RESULT_SEND is rclc_action_send_result with GOAL_STATE_SUCCEEDED,
        # ACTIONS_CANCEL_SEND ends the goal CANCELED with the empty result
        record.result = {**default_value(self.library, record.result_type), **response,
                         "status": response.get("status") or STATUS_SUCCEEDED}
        record.status = record.result["status"]
        record.finished_s = time.monotonic()
        record.done.set()
        self._publish_status(ep)

    def _get_result(self, ep, data):
        request = self._request(ep, data)
        if request is None:
            return
        guid, seq, value = request
        uuid = bytes(value["goal_id"]["uuid"])
        record = ep.goals.get(uuid)
        if record is None:
            self._reject(ep, f"result of unknown goal {uuid.hex()}; answered STATUS_UNKNOWN")
            self._reply(ep, guid, seq, default_value(self.library, ep.reply.typename))
            return
        self.counts[ep.name]["delivered"] += 1
        self._calls += 1

        async def answer():
            try:
                await record.done.wait()
                self._reply(ep, guid, seq, record.result)
            finally:
                self._calls -= 1
        self.spawn(answer())

    def _cancel_goal(self, ep, data):
        request = self._request(ep, data)
        if request is None:
            return
        guid, seq, value = request
        info = value["goal_info"]
        uuid = bytes(info["goal_id"]["uuid"])
        record = ep.goals.get(uuid)
        if record is None and any(uuid):
            self._reject(ep, f"cancel of unknown goal {uuid.hex()}; answered "
                             f"ERROR_UNKNOWN_GOAL_ID")
            self._reply(ep, guid, seq, {"return_code": CANCEL_UNKNOWN_GOAL_ID,
                                        "goals_canceling": []})
            return
        self.counts[ep.name]["delivered"] += 1
        if record is not None and not record.active:
            self._reply(ep, guid, seq, {"return_code": CANCEL_GOAL_TERMINATED,
                                        "goals_canceling": []})
            return
        # one goal, or every goal not finished (a zero goal id)
        targets = [(uuid, record)] if record is not None else \
            [(u, r) for u, r in ep.goals.items() if r.active]
        for goal_uuid, goal_record in targets:
            if goal_record.status == STATUS_ACCEPTED and \
                    self.broker.withdraw_goal(ep.key, goal_record.goal):
                # still in the queue, not taken by the hardware: canceled here (and the
                # goal's decision ends, so no call is left running)
                self._finish(ep, goal_record, STATUS_CANCELED)
                goal_record.goal.accepted.put(False)
            else:
                # the hardware has it: its thread sees the request (ACTIONS_CANCEL_TRYTAKE or
                # _TAKE) and ends the goal with ACTIONS_CANCEL_SEND (CANCELED); a thread
                # without a cancel path finishes it (SUCCEEDED), as an rclcpp server may
                goal_record.status = STATUS_CANCELING
                goal_record.goal.cancel()
        self._reply(ep, guid, seq, {
            "return_code": CANCEL_NONE,
            "goals_canceling": [{"goal_id": {"uuid": list(u)}, "stamp": r.stamp}
                                for u, r in targets]})
        self._publish_status(ep)

    def _expire_goals(self):
        """Drop finished goals older than the result timeout from their status lists."""
        now = time.monotonic()
        for goals, status in self._served_goals:
            old = [u for u, r in goals.items()
                   if r.finished_s is not None and now - r.finished_s > self.result_timeout_s]
            for uuid in old:
                del goals[uuid]
            if old:
                self._write_status(goals, status)

    # --- actions used from hardware ------------------------------------------------------
    def _poll_action_client(self, state):
        moved = 0
        send, get = state["services"]["send_goal"], state["services"]["get_result"]
        # goals wait until a server is there (rcl_action's wait_for_action_server)
        while len(state["goals"]) and self._matched(send.reply) and \
                (goal := state["goals"].get_nowait()) is not None:
            seq = self._call(send, goal.request)
            state["sent"][seq] = goal
            moved += 1
        for uuid, goal in list(state["by_uuid"].items()):
            if goal.result_requested.is_set() and uuid not in state["results"]:
                state["results"][uuid] = self._call(get, {"goal_id": {"uuid": uuid}})
                moved += 1
        return moved

    def _goal_reply(self, ep, data):
        got = self._client_reply(ep, data, ep.state["sent"])
        if got is not None:
            goal, value = got
            if value["accepted"]:
                ep.state["by_uuid"][goal.goal_id] = goal
            goal.accepted.put(bool(value["accepted"]))

    def _result_reply(self, ep, data):
        state = ep.state
        pending = {seq: uuid for uuid, seq in state["results"].items()
                   if uuid in state["by_uuid"]}
        got = self._client_reply(ep, data, pending)
        if got is not None:
            uuid, value = got
            state["by_uuid"].pop(uuid).result.put(value)

    def _goal_feedback_in(self, ep, data):
        value = self._decode(ep, data)
        if value is None:
            return
        goal = ep.state["by_uuid"].get(bytes(value["goal_id"]["uuid"]))
        if goal is None:
            return                          # another client's goal
        goal.feedback.put(value)
        self.counts[ep.name]["delivered"] += 1
