"""The shared test bench of the ``reconos`` top: clock, reset, the three AXI4-Lite masters,
process memory behind the AXI4 port, and the software model of :mod:`tb.models.reconos_sw`."""

import logging
from pathlib import Path

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles
from cocotbext.axi import AxiBus, AxiLiteBus, AxiLiteMaster, AxiRam

from hdl.reconos.protocol import arch as get_arch

from .harness import bench_params
from .models.reconos_sw import Broker, MessageMemory, ProcessMemory, ReconosRuntime

__all__ = ["ReconosTB", "RAM_SIZE", "system_configs", "apps_configs", "struct_offsets", "slot_of"]

RAM_SIZE = 1 << 25
#: message packages of the examples (sorter_msgs, application_msgs, ...)
EXAMPLE_MESSAGES = [str(Path(__file__).resolve().parent.parent / "examples" / d)
                    for d in ("messages", "sobel_dip/msg")]


def _system(arch):
    """One system per architecture for every ``reconos`` bench module (one build each):
    0 echo node (in its own clock: the slot's FIFOs cross clock domains), 1 copy node, 2 a thread making bad calls, 3 and 4 memory-test threads,
    5 the OS-call sequencer of the compatibility bench."""
    from .test_reconos_calls import program
    from .test_reconos_pingpong import BAD_PROGRAM
    # sensor_msgs/Image.data (spec §6: 72 on arm64, 48 on arm32)
    offset = struct_offsets(arch, "sensor_msgs/msg/Image")["data"]
    return {"arch": arch, "async_slots": [0], "threads": [
        {"kind": "echo", "h_sub": 1, "h_pub": 2, "h_msg": 3},
        {"kind": "copy", "h_sub": 1, "h_pub": 2, "h_msg_in": 3, "h_msg_out": 4,
         "data_offset": offset},
        {"kind": "calls", "program": BAD_PROGRAM, "h_report": 0},
        {"kind": "memtest", "h_cmd": 0, "h_result": 1},
        {"kind": "memtest", "h_cmd": 0, "h_result": 1},
        {"kind": "calls", "program": program(arch)},
    ]}


def system_configs():
    return {f"system_{arch}": _system(arch) for arch in ("r64", "r32")}


def struct_offsets(arch, type_name, library=None):
    """Member offsets of ``type_name`` in the rosidl C layout of ``arch`` (spec §6)."""
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
    sequencer) of the sort action server."""
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
         "image_offsets": image_offsets},
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


class ReconosTB:
    def __init__(self, dut, *, ram_size=RAM_SIZE):
        self.dut = dut
        self.params = bench_params()
        self.arch = get_arch(self.params.get("arch", "r64"))
        self.num_hwts = len(self.params["threads"])
        cocotb.start_soon(Clock(dut.aclk, self.params.get("clock_ns", 10), unit="ns").start())
        for i in self.params.get("async_slots", ()):
            # a slot clock unrelated to the system clock (ReconROS: a reconos_clock output)
            period = self.params.get("slot_clock_ns", {}).get(str(i), 13.7)
            cocotb.start_soon(Clock(getattr(dut, f"slot{i}_clk"), period, unit="ns").start())
        self.osif = AxiLiteMaster(AxiLiteBus.from_prefix(dut, "s_axi_osif"), dut.aclk,
                                  dut.aresetn, reset_active_level=False)
        self.intc = AxiLiteMaster(AxiLiteBus.from_prefix(dut, "s_axi_intc"), dut.aclk,
                                  dut.aresetn, reset_active_level=False)
        self.proc = AxiLiteMaster(AxiLiteBus.from_prefix(dut, "s_axi_proc"), dut.aclk,
                                  dut.aresetn, reset_active_level=False)
        self.ram = AxiRam(AxiBus.from_prefix(dut, "m_axi_mem"), dut.aclk, dut.aresetn,
                          reset_active_level=False, size=ram_size)
        for m in (self.osif, self.intc, self.proc, self.ram):
            for part in ("write_if", "read_if"):
                if hasattr(m, part):
                    getattr(m, part).log.setLevel(logging.WARNING)
            m.log.setLevel(logging.WARNING) if hasattr(m, "log") else None
        self.ram_size = ram_size
        self._decode_window(ram_size)
        self.memory = ProcessMemory(self.arch, self.ram, ram_size)
        self.broker = Broker()
        self.messages = None
        self.runtime = None

    def _decode_window(self, size):
        """AxiRam wraps addresses modulo its size; a real interconnect answers an access with
        no memory behind it with an error. Accesses at or above ``size`` raise here, which
        cocotbext-axi answers with SLVERR."""
        for port, name in ((self.ram.read_if, "_read"), (self.ram.write_if, "_write")):
            inner = getattr(port, name)

            async def checked(address, arg, _inner=inner):
                if address >= size:
                    raise IndexError(f"no memory at 0x{address:x}")
                return await _inner(address, arg)
            setattr(port, name, checked)

    async def reset(self):
        self.dut.aresetn.value = 0
        await ClockCycles(self.dut.aclk, 5)
        self.dut.aresetn.value = 1
        await ClockCycles(self.dut.aclk, 2)

    async def start_runtime(self, library=None):
        from gen.msg import MessageLibrary
        library = library or MessageLibrary([], store="ros2_humble")
        self.messages = MessageMemory(self.memory, library)
        self.runtime = ReconosRuntime(
            self.arch, osif=self.osif, intc=self.intc, proc=self.proc,
            irq_osif=self.dut.irq_osif, irq_pgf=self.dut.irq_pgf, clock=self.dut.aclk,
            memory=self.memory, messages=self.messages, broker=self.broker,
            num_hwts=self.num_hwts)
        await self.runtime.start()
        return self.runtime
