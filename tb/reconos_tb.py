"""The shared test bench of the ``reconos`` top: the software side of
:class:`host.reconos.ReconosCosim` configured from the bench parameters, the systems the
``reconos`` benches build, and the OS-call programs their call sequencers run."""

from pathlib import Path

from hdl.reconos.protocol import CALLS
from host.reconos import RAM_SIZE, ReconosCosim

from .harness import bench_params

__all__ = ["ReconosTB", "RAM_SIZE", "system_configs", "apps_configs", "struct_offsets", "slot_of",
           "call_program", "BAD_PROGRAM", "BLOCKED_SEM", "SKIP"]

#: message packages of the examples (sorter_msgs, application_msgs, ...)
EXAMPLE_MESSAGES = [str(Path(__file__).resolve().parent.parent / "examples" / d)
                    for d in ("messages", "sobel_dip/msg")]

#: calls the compatibility program leaves out (the sequencer issues them itself, or they are
#: sent separately below)
SKIP = {"thread_init", "thread_exit", "ros_take_interruptable", "ros_take_interruptable_cancel"}
BLOCKED_SEM = 0x63


def argument(i, k, wide):
    """A distinct argument value; on r64 some are wider than 32 bits."""
    base = (i + 1) * 16 + k + 1
    return base | (0x1234_5678 << 32) if wide and k == 0 and i % 3 == 0 else base


def call_program(arch):
    """Every OS call once with distinct arguments, then the interruptible take and a blocking
    semaphore wait."""
    wide = arch == "r64"
    out = []
    for i, (name, c) in enumerate(CALLS.items()):
        if name in SKIP:
            continue
        out.append((name, [argument(i, k, wide) for k in range(len(c.args))]))
    out += [("ros_take_interruptable", [5, 6]), ("ros_take_interruptable_cancel", []),
            ("ros_take_interruptable", [7, 8]), ("ros_take_interruptable_cancel", []),
            ("sem_wait", [BLOCKED_SEM])]
    return out


#: slot 2: post semaphore 1, post semaphore 2, then an unknown command word
BAD_PROGRAM = [["sem_post", [1]], ["sem_post", [2]], ["command", [0x123]]]


def _system(arch):
    """One system per architecture for every ``reconos`` bench module (one build each):
    0 echo node (in its own clock: the slot's FIFOs cross clock domains), 1 copy node, 2 a
    thread making bad calls, 3 and 4 memory-test threads,
    5 the OS-call sequencer of the compatibility bench."""
    # sensor_msgs/Image.data (docs/reconos.md: 72 on arm64, 48 on arm32)
    offset = struct_offsets(arch, "sensor_msgs/msg/Image")["data"]
    return {"arch": arch, "async_slots": [0], "threads": [
        {"kind": "echo", "h_sub": 1, "h_pub": 2, "h_msg": 3},
        {"kind": "copy", "h_sub": 1, "h_pub": 2, "h_msg_in": 3, "h_msg_out": 4,
         "data_offset": offset},
        {"kind": "calls", "program": BAD_PROGRAM, "h_report": 0},
        {"kind": "memtest", "h_cmd": 0, "h_result": 1},
        {"kind": "memtest", "h_cmd": 0, "h_result": 1},
        {"kind": "calls", "program": call_program(arch)},
    ]}


def system_configs():
    return {f"system_{arch}": _system(arch) for arch in ("r64", "r32")}


def struct_offsets(arch, type_name, library=None):
    """Member offsets of ``type_name`` in the rosidl C layout of ``arch`` (docs/reconos.md)."""
    from gen.msg import MessageLibrary
    from gen.msg.layout import CLayout
    library = library or MessageLibrary(EXAMPLE_MESSAGES, store="ros2_humble")
    layout = CLayout(library, "arm64" if arch == "r64" else "arm32")
    return {m.name: m.offset for m in layout.struct(type_name).members}


#: a hardware action client (slot 7 of the apps system): send the goal in message 2 on client
#: 1, wait for the decision, request the result, take one feedback, take the result (into
#: message 3), exit; every reply reported to mailbox 0
ACTION_CLIENT_PROGRAM = [
    ["ros_actionc_goal_send", [1, 2]], ["ros_actionc_goal_take", [1]],
    ["ros_actionc_result_send", [1]], ["ros_actionc_feedback_take", [1, 4]],
    ["ros_actionc_feedback_trytake", [1, 4]], ["ros_actionc_result_take", [1, 3]],
    ["ros_actionc_result_trytake", [1, 3]],
]


def _apps_system(arch):
    """The ReconROS demo nodes of :mod:`tb.test_reconos_apps`: 0 sort service server, 1 sort
    action server, 2 the mailbox sort thread, 3 and 4 shared-counter threads, 5 the Sobel
    service server, 6 the DIP node (Listings 2 and 3 of the paper), 7 an action client (a call
    sequencer) of the sort action server. The Sobel server runs the paper's per-byte-lane
    filter; its OpenCV mode is tested through the sobel_dip project (tb/test_project_sim.py)."""
    img = struct_offsets(arch, "sensor_msgs/msg/Image")
    image_offsets = {k: img[k] for k in ("height", "encoding", "is_bigendian", "step", "data")}
    goal = struct_offsets(arch, "sorter_msgs/action/Sort_SendGoal_Request")["goal"]
    result = struct_offsets(arch, "sorter_msgs/action/Sort_GetResult_Response")["result"]
    fb = struct_offsets(arch, "sorter_msgs/action/Sort_FeedbackMessage")["feedback"]
    return {"arch": arch, "threads": [
        {"kind": "sort_service", "h_srvs": 2, "h_req": 1, "h_res": 3},
        {"kind": "sort_action", "h_as": 4, "h_goal": 1, "h_res": 2, "h_fb": 3,
         "goal_offset": goal, "res_offset": result, "fb_offset": fb},
        {"kind": "mbox_sort", "h_in": 0, "h_out": 1},
        {"kind": "counter", "h_cmd": 0, "h_mutex": 1, "h_done": 2},
        {"kind": "counter", "h_cmd": 0, "h_mutex": 1, "h_done": 2},
        {"kind": "sobel_server", "h_srvs": 2, "h_req": 1, "h_res": 3,
         "image_offsets": image_offsets, "mode": "reconros"},
        {"kind": "dip", "h_sub": 1, "h_pub": 2, "h_img": 3, "h_srvc": 5, "h_req": 4,
         "h_res": 6, "image_offsets": image_offsets},
        {"kind": "calls", "program": ACTION_CLIENT_PROGRAM, "h_report": 0},
    ]}


def apps_configs():
    return {"apps_r64": _apps_system("r64"),
            "apps_r32": _apps_system("r32")}


def slot_of(params, kind, nth=0, **match):
    """Index of the ``nth`` thread of ``kind`` (with the given parameters) in a config."""
    found = [i for i, t in enumerate(params["threads"]) if t["kind"] == kind and
             all(t.get(k, "absent") == v for k, v in match.items())]
    return found[nth]


class ReconosTB(ReconosCosim):
    """:class:`~host.reconos.ReconosCosim` for the system the bench parameters describe."""

    def __init__(self, dut, *, ram_size=RAM_SIZE):
        self.params = bench_params()
        super().__init__(dut, arch=self.params.get("arch", "r64"),
                         num_hwts=len(self.params["threads"]),
                         clock_ns=self.params.get("clock_ns", 10),
                         slot_clocks={i: self.params.get("slot_clock_ns", {}).get(str(i), 13.7)
                                      for i in self.params.get("async_slots", ())},
                         ram_size=ram_size)
