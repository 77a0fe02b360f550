"""An independent ROS 2 participant for the bridge's tests: Cyclone DDS with DDS types
written here by hand from the ROS 2 interface definitions and ROS 2's DDS naming (not from
the project's type generation), rmw_cyclonedds_cpp's service request header
(``uint64 guid, int64 seq`` before the request's fields), and ``rosgate sim --ros2`` run as a
user runs it, in its own process, stopped with SIGTERM."""

import contextlib
import itertools
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t
from cyclonedds.idl.annotations import final

from host.ros2.bridge import LOOPBACK_CONFIG

ROOT = Path(__file__).resolve().parents[2]
_domains = itertools.count()


def unique_domain():
    """A DDS domain id no other test process of this run uses: pytest-xdist worker ``gwK``
    of ``N`` takes ids from its own slice of 1..230 in turn (a pid-based id could collide
    between two workers); outside xdist the pid picks the start."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    if worker.startswith("gw") and worker[2:].isdigit():
        size = 230 // max(workers, 1)
        return 1 + int(worker[2:]) % workers * size + next(_domains) % size
    return 1 + (os.getpid() + next(_domains)) % 230


def loopback_environment():
    os.environ["CYCLONEDDS_URI"] = LOOPBACK_CONFIG
    return dict(os.environ)


@dataclass
@final
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
@final
class Clock(IdlStruct, typename="rosgraph_msgs::msg::dds_::Clock_"):
    clock: Time


@dataclass
@final
class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: t.array[t.uint8, 24]


@dataclass
@final
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: t.bounded_str[256]
    node_name: t.bounded_str[256]
    reader_gid_seq: t.sequence[Gid]
    writer_gid_seq: t.sequence[Gid]


@dataclass
@final
class ParticipantEntitiesInfo(IdlStruct,
                              typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"):
    gid: Gid
    node_entities_info_seq: t.sequence[NodeEntitiesInfo]


@dataclass
@final
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
@final
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header
    height: t.uint32
    width: t.uint32
    encoding: str
    is_bigendian: t.uint8
    step: t.uint32
    data: t.sequence[t.uint8]


@dataclass
@final
class ImageWideFlag(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    """A wrong layout of Image, ``is_bigendian`` as uint32 (for raw bytes only)."""
    header: Header
    height: t.uint32
    width: t.uint32
    encoding: str
    is_bigendian: t.uint32
    step: t.uint32
    data: t.sequence[t.uint8]


@dataclass
@final
class SobelSrvRequest(IdlStruct, typename="application_msgs::srv::dds_::SobelSrv_Request_"):
    guid: t.uint64
    seq: t.int64
    img: Image


@dataclass
@final
class SobelSrvResponse(IdlStruct, typename="application_msgs::srv::dds_::SobelSrv_Response_"):
    guid: t.uint64
    seq: t.int64
    img: Image


# sorter_msgs/action/Sort as rcl_action puts it on DDS (goal, result and feedback parts;
# the send_goal and get_result services; action_msgs' status and cancel)

@dataclass
@final
class UUID(IdlStruct, typename="unique_identifier_msgs::msg::dds_::UUID_"):
    uuid: t.array[t.uint8, 16]


@dataclass
@final
class SortGoal(IdlStruct, typename="sorter_msgs::action::dds_::Sort_Goal_"):
    unsorted: t.sequence[t.uint32]


@dataclass
@final
class SortResult(IdlStruct, typename="sorter_msgs::action::dds_::Sort_Result_"):
    sorted: t.sequence[t.uint32]


@dataclass
@final
class SortFeedback(IdlStruct, typename="sorter_msgs::action::dds_::Sort_Feedback_"):
    percent: t.float32


@dataclass
@final
class SortSendGoalRequest(IdlStruct,
                          typename="sorter_msgs::action::dds_::Sort_SendGoal_Request_"):
    guid: t.uint64
    seq: t.int64
    goal_id: UUID
    goal: SortGoal


@dataclass
@final
class SortSendGoalResponse(IdlStruct,
                           typename="sorter_msgs::action::dds_::Sort_SendGoal_Response_"):
    guid: t.uint64
    seq: t.int64
    accepted: bool
    stamp: Time


@dataclass
@final
class SortGetResultRequest(IdlStruct,
                           typename="sorter_msgs::action::dds_::Sort_GetResult_Request_"):
    guid: t.uint64
    seq: t.int64
    goal_id: UUID


@dataclass
@final
class SortGetResultResponse(IdlStruct,
                            typename="sorter_msgs::action::dds_::Sort_GetResult_Response_"):
    guid: t.uint64
    seq: t.int64
    status: t.int8
    result: SortResult


@dataclass
@final
class SortFeedbackMessage(IdlStruct,
                          typename="sorter_msgs::action::dds_::Sort_FeedbackMessage_"):
    goal_id: UUID
    feedback: SortFeedback


FIB = "example_interfaces::action::dds_::Fibonacci_"


@dataclass
@final
class FibonacciGoal(IdlStruct, typename=FIB + "Goal_"):
    order: t.int32


@dataclass
@final
class FibonacciSequence(IdlStruct, typename=FIB + "Result_"):
    sequence: t.sequence[t.int32]


@dataclass
@final
class FibonacciFeedback(IdlStruct, typename=FIB + "Feedback_"):
    sequence: t.sequence[t.int32]


@dataclass
@final
class FibonacciSendGoalRequest(IdlStruct, typename=FIB + "SendGoal_Request_"):
    guid: t.uint64
    seq: t.int64
    goal_id: UUID
    goal: FibonacciGoal


@dataclass
@final
class FibonacciSendGoalResponse(IdlStruct, typename=FIB + "SendGoal_Response_"):
    guid: t.uint64
    seq: t.int64
    accepted: bool
    stamp: Time


@dataclass
@final
class FibonacciGetResultRequest(IdlStruct, typename=FIB + "GetResult_Request_"):
    guid: t.uint64
    seq: t.int64
    goal_id: UUID


@dataclass
@final
class FibonacciGetResultResponse(IdlStruct, typename=FIB + "GetResult_Response_"):
    guid: t.uint64
    seq: t.int64
    status: t.int8
    result: FibonacciSequence


@dataclass
@final
class FibonacciFeedbackMessage(IdlStruct, typename=FIB + "FeedbackMessage_"):
    goal_id: UUID
    feedback: FibonacciFeedback


@dataclass
@final
class GoalInfo(IdlStruct, typename="action_msgs::msg::dds_::GoalInfo_"):
    goal_id: UUID
    stamp: Time


@dataclass
@final
class GoalStatus(IdlStruct, typename="action_msgs::msg::dds_::GoalStatus_"):
    goal_info: GoalInfo
    status: t.int8


@dataclass
@final
class GoalStatusArray(IdlStruct, typename="action_msgs::msg::dds_::GoalStatusArray_"):
    status_list: t.sequence[GoalStatus]


@dataclass
@final
class CancelGoalRequest(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Request_"):
    guid: t.uint64
    seq: t.int64
    goal_info: GoalInfo


@dataclass
@final
class CancelGoalResponse(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Response_"):
    guid: t.uint64
    seq: t.int64
    return_code: t.int8
    goals_canceling: t.sequence[GoalInfo]


@dataclass
@final
class SortRequest(IdlStruct, typename="my_reconros_services::srv::dds_::Sort_Request_"):
    guid: t.uint64
    seq: t.int64
    unsorted: t.sequence[t.uint32]


@dataclass
@final
class SortResponse(IdlStruct, typename="my_reconros_services::srv::dds_::Sort_Response_"):
    guid: t.uint64
    seq: t.int64
    sorted: t.sequence[t.uint32]


def image(pixels, sec=0, frame_id="camera"):
    height, width = pixels.shape[:2]
    return Image(Header(Time(sec, 0), frame_id), height, width, "bgr8", 0, width * 3,
                 list(pixels.tobytes()))


class Peer:
    """A participant on ``domain`` with reliable keep-last-10 volatile QoS (ROS 2's
    default)."""

    def __init__(self, domain):
        from cyclonedds.core import Policy, Qos
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.util import duration
        self.participant = DomainParticipant(domain)
        self.qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                       Policy.History.KeepLast(10))
        self._waitsets = {}

    def writer(self, name, idl):
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic
        return DataWriter(self.participant, Topic(self.participant, name, idl), qos=self.qos)

    def reader(self, name, idl, qos=None):
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic
        return DataReader(self.participant, Topic(self.participant, name, idl),
                          qos=qos or self.qos)

    def status_reader(self, name, idl):
        """A reader with rcl_action's status profile (transient local, keep last 1)."""
        from cyclonedds.core import Policy, Qos
        from cyclonedds.util import duration
        return self.reader(name, idl, Qos(Policy.Reliability.Reliable(duration(seconds=1)),
                                          Policy.History.KeepLast(1),
                                          Policy.Durability.TransientLocal))

    @staticmethod
    def wait_matched(*entities, timeout=60):
        """Wait until every reader and writer has matched a peer."""
        deadline = time.monotonic() + timeout
        for entity in entities:
            status = (entity.get_publication_matched_status if hasattr(entity, "write")
                      else entity.get_subscription_matched_status)
            while status().current_count == 0:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"no match on {entity.topic.name} within {timeout} s")
                time.sleep(0.02)

    def take_raw(self, reader, timeout=120, missing_ok=False):
        """The next sample's bytes as they came from DDS (waits on a WaitSet); ``None`` after
        ``timeout`` with ``missing_ok``."""
        from cyclonedds._clayer import ddspy_take
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
        from cyclonedds.util import duration
        mask = SampleState.Any | ViewState.Any | InstanceState.Any
        if id(reader) not in self._waitsets:
            waitset = WaitSet(self.participant)
            waitset.attach(ReadCondition(reader, mask))
            self._waitsets[id(reader)] = waitset
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            got = ddspy_take(reader._ref, mask, 1)
            if got and got[0][1].valid_data:
                return bytes(got[0][0])
            self._waitsets[id(reader)].wait(duration(milliseconds=100))
        if missing_ok:
            return None
        raise TimeoutError(f"nothing on {reader.topic.name} within {timeout} s")

    @staticmethod
    def write_raw(writer, data):
        from cyclonedds._clayer import ddspy_write
        data = bytes(data) + bytes(-len(data) % 4)
        assert ddspy_write(writer._ref, data) >= 0


@contextlib.contextmanager
def ros2_sim(build_cfg, sim, out, domain, *extra, ready_timeout=900):
    """``rosgate sim <build_cfg> --ros2`` in its own process until the bridge has joined;
    SIGTERM on leaving, which must end it cleanly (exit 0, results written)."""
    env = loopback_environment()
    command = [sys.executable, "-m", "host.cli", "sim", str(build_cfg), "--sim", sim, "--ros2",
               "--domain", str(domain), "-o", str(out), *extra]
    console = Path(out).parent / f"{Path(out).name}.console"
    log = open(console, "w")
    process = subprocess.Popen(command, cwd=ROOT, env=env, stdout=log,
                               stderr=subprocess.STDOUT, start_new_session=True)
    progress = Path(out) / "sim_progress.jsonl"
    deadline = time.monotonic() + ready_timeout
    try:
        while not (progress.is_file() and "joined DDS domain" in progress.read_text()):
            if process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"rosgate sim --ros2 did not start: {console.read_text()}")
            time.sleep(0.2)
        yield process
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=120)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            raise
        log.close()


def results(out):
    return json.loads((Path(out) / "sim_results.json").read_text())
