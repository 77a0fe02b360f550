"""ReconOS/ReconROS protocol facts, defined once (docs/reconos.md).

Everything here is plain Python: the hardware (:mod:`hdl.reconos`), the software model
(:mod:`host.reconos`) and the compatibility tests import the same tables. Nothing in
this module depends on the RTL.
"""

import enum
from dataclasses import dataclass

from ..params import check_choice

__all__ = [
    "Arch", "ARCHS", "arch", "Command", "SIGNAL_THREAD_START", "SIGNAL_THREAD_RESUME",
    "INTERRUPTED_REPLY", "CMD_MASK", "YIELD_MASK", "Call", "CALLS", "call", "MemifOp",
    "MEMIF_CHUNK", "memif_command", "memif_decode", "memif_split", "OsifRegister",
    "osif_register_offset", "ProcControlRegister", "proc_control_offset", "ResourceType",
    "MemStatus",
]


@dataclass(frozen=True)
class Arch:
    """One ReconOS hardware flavour.

    Attributes
    ----------
    name : str
        ``"r32"`` (Zynq-7000, ARMv7 MMU) or ``"r64"`` (ZynqMP, ARMv8 MMU).
    word_bits : int
        OSIF/MEMIF word width W*8.
    addr_bits : int
        Physical address width of the AXI4 memory port (r64: the controller's ``ADDR 40``).
    osif_base, intc_base, proc_control_base : int
        Default AXI-Lite base addresses (docs/reconos.md).
    axcache, axprot, axuser : int
        Attributes of every memory burst (docs/reconos.md; r64: coherent through HPC0; r32: the
        ``axi_master_burst`` defaults, cache and user all ones). AxUSER is 2 bits wide.
    """

    name: str
    word_bits: int
    addr_bits: int
    osif_base: int
    intc_base: int
    proc_control_base: int
    axcache: int
    axprot: int
    axuser: int

    @property
    def word_bytes(self):
        return self.word_bits // 8

    @property
    def chunk_words(self):
        return MEMIF_CHUNK // self.word_bytes

    @property
    def length_bits(self):
        """Width of the MEMIF length field (r32 24, r64 56)."""
        return self.word_bits - 8


ARCHS = {
    "r32": Arch("r32", 32, 32, 0x75A0_0000, 0x7B40_0000, 0x6FE0_0000,
                axcache=0b1111, axprot=0b000, axuser=0b11),
    "r64": Arch("r64", 64, 40, 0xA010_0000, 0xA011_0000, 0xA012_0000,
                axcache=0b1111, axprot=0b010, axuser=0b01),
}


def arch(name):
    """The :class:`Arch` named ``name`` (``"r32"`` or ``"r64"``); an :class:`Arch` passes."""
    if isinstance(name, Arch):
        return name
    return ARCHS[check_choice("arch", name, tuple(ARCHS))]


class Command(enum.IntEnum):
    """OSIF command words (docs/reconos.md). The delegate dispatches on ``word & CMD_MASK``."""

    THREAD_GET_INIT_DATA = 0x0A0
    THREAD_GET_STATE_ADDR = 0x0A1
    THREAD_EXIT = 0x0A2
    THREAD_YIELD = 0x0A3
    THREAD_CLEAR_SIGNAL = 0x0A4
    SEM_POST = 0x0B0
    SEM_WAIT = 0x0B1
    MUTEX_LOCK = 0x0C0
    MUTEX_UNLOCK = 0x0C1
    MUTEX_TRYLOCK = 0x0C2
    COND_WAIT = 0x0D0
    COND_SIGNAL = 0x0D1
    COND_BROADCAST = 0x0D2
    MBOX_GET = 0x0F0
    MBOX_PUT = 0x0F1
    MBOX_TRYGET = 0x0F2
    MBOX_TRYPUT = 0x0F3
    MEMORY_MALLOC = 0x0F4
    MEMORY_FREE = 0x0F5
    MEMORY_GETOBJADDR = 0x0F6
    MEMORY_GETMEMADDR = 0x0F7
    OSIF_INTERRUPTED = 0x0FF
    ROS_PUBLISH = 0x900
    ROS_TAKE = 0x901
    ROS_TRYTAKE = 0x902
    ROS_TAKE_INTERRUPTABLE = 0x903
    ROS_TAKE_INTERRUPTABLE_CANCEL = 0x904
    ROS_SERVICES_RESPONSE = 0x910
    ROS_SERVICES_TRYTAKE = 0x911
    ROS_SERVICES_TAKE = 0x912
    ROS_ACTIONS_GOAL_TAKE = 0x920
    ROS_ACTIONS_GOAL_TRYTAKE = 0x921
    ROS_ACTIONS_GOAL_DECIDE = 0x922
    ROS_ACTIONS_RESULT_TAKE = 0x923
    ROS_ACTIONS_RESULT_TRYTAKE = 0x924
    ROS_ACTIONS_RESULT_SEND = 0x925
    ROS_ACTIONS_FEEDBACK = 0x926
    ROS_ACTIONS_CANCEL_TAKE = 0x927
    ROS_ACTIONS_CANCEL_TRYTAKE = 0x928
    ROS_ACTIONS_CANCEL_SEND = 0x929
    ROS_SERVICEC_REQUEST = 0x930
    ROS_SERVICEC_TRYTAKE = 0x931
    ROS_SERVICEC_TAKE = 0x932
    ROS_ACTIONC_GOAL_SEND = 0x940
    ROS_ACTIONC_GOAL_TRYTAKE = 0x941
    ROS_ACTIONC_GOAL_TAKE = 0x942
    ROS_ACTIONC_RESULT_SEND = 0x943
    ROS_ACTIONC_RESULT_TAKE = 0x944
    ROS_ACTIONC_RESULT_TRYTAKE = 0x945
    ROS_ACTIONC_FEEDBACK_TAKE = 0x946
    ROS_ACTIONC_FEEDBACK_TRYTAKE = 0x947
    ROS_ACTIONC_CANCEL_SEND = 0x948
    ROS_ACTIONC_CANCEL_TAKE = 0x949
    ROS_ACTIONC_CANCEL_TRYTAKE = 0x950
    ROS_MESSAGE_SET_SIZE = 0x9F0


#: SW -> HW: the first word after a slot reset that starts a thread.
SIGNAL_THREAD_START = 0x0100_0000
#: SW -> HW: the first word after a slot reset that resumes a suspended thread.
SIGNAL_THREAD_RESUME = 0x0100_0001
#: The delegate's dispatch mask and the (ignored) yield flag.
CMD_MASK = 0xFFF
YIELD_MASK = 0x8000_0000


def INTERRUPTED_REPLY(word_bits):
    """The all-ones reply that ends an interruptible take without a message
    (docs/reconos.md)."""
    return (1 << word_bits) - 1


@dataclass(frozen=True)
class Call:
    """The word sequence of one OS call (docs/reconos.md): ``cmd, args... => replies...``.

    ``method`` is the name of the hardware-thread API method and of the software model's
    handler. ``args`` and ``replies`` name the words in order. A call with ``blocking=False``
    only writes its words; its reply, if any, is collected by a later call (interruptible take).
    """

    method: str
    command: Command | None
    args: tuple
    replies: tuple
    blocking: bool = True


def _c(method, command, args=(), replies=(), blocking=True):
    return Call(method, command, tuple(args), tuple(replies), blocking)


#: Every OS call a hardware thread can make, by method name. Defects 1-3 of ReconROS
# (docs/reconos.md) are fixed
#: here: COND_WAIT sends (cond, mutex); ACTIONC_RESULT_TRYTAKE reads (ptr, ret);
#: ACTIONC_CANCEL_TRYTAKE sends (h_ac, h_msg).
CALLS = {c.method: c for c in [
    _c("thread_init", None, (), ("signal",)),
    _c("get_init_data", Command.THREAD_GET_INIT_DATA, (), ("init_data",)),
    _c("get_state_addr", Command.THREAD_GET_STATE_ADDR, (), ("state_addr",)),
    _c("thread_clear_signal", Command.THREAD_CLEAR_SIGNAL, (), ()),
    _c("thread_exit", Command.THREAD_EXIT, (), ()),
    _c("sem_post", Command.SEM_POST, ("h_sem",), ("ret",)),
    _c("sem_wait", Command.SEM_WAIT, ("h_sem",), ("ret",)),
    _c("mutex_lock", Command.MUTEX_LOCK, ("h_mutex",), ("ret",)),
    _c("mutex_unlock", Command.MUTEX_UNLOCK, ("h_mutex",), ("ret",)),
    _c("mutex_trylock", Command.MUTEX_TRYLOCK, ("h_mutex",), ("ret",)),
    _c("cond_wait", Command.COND_WAIT, ("h_cond", "h_mutex"), ("ret",)),
    _c("cond_signal", Command.COND_SIGNAL, ("h_cond",), ("ret",)),
    _c("cond_broadcast", Command.COND_BROADCAST, ("h_cond",), ("ret",)),
    _c("mbox_get", Command.MBOX_GET, ("h_mbox",), ("data",)),
    _c("mbox_put", Command.MBOX_PUT, ("h_mbox", "data"), ("ret",)),
    _c("mbox_tryget", Command.MBOX_TRYGET, ("h_mbox",), ("data", "ret")),
    _c("mbox_tryput", Command.MBOX_TRYPUT, ("h_mbox", "data"), ("ret",)),
    _c("memory_malloc", Command.MEMORY_MALLOC, ("pdst", "length"), ("ptr",)),
    _c("memory_free", Command.MEMORY_FREE, ("ptr",), ()),
    _c("memory_getobjaddr", Command.MEMORY_GETOBJADDR, ("h",), ("ptr",)),
    _c("memory_getmemaddr", Command.MEMORY_GETMEMADDR, ("h_mem",), ("ptr",)),
    _c("ros_message_set_size", Command.ROS_MESSAGE_SET_SIZE,
       ("h_msg", "offset", "elem_size", "count"), ("ptr",)),
    _c("ros_publish", Command.ROS_PUBLISH, ("h_pub", "h_msg"), ("ret",)),
    _c("ros_take", Command.ROS_TAKE, ("h_sub", "h_msg"), ("ptr",)),
    _c("ros_trytake", Command.ROS_TRYTAKE, ("h_sub", "h_msg"), ("ptr", "ret")),
    _c("ros_take_interruptable", Command.ROS_TAKE_INTERRUPTABLE, ("h_sub", "h_msg"), (),
       blocking=False),
    _c("ros_take_interruptable_cancel", Command.ROS_TAKE_INTERRUPTABLE_CANCEL, (), ("ptr",)),
    _c("ros_services_take", Command.ROS_SERVICES_TAKE, ("h_srvs", "h_req"), ("ptr",)),
    _c("ros_services_trytake", Command.ROS_SERVICES_TRYTAKE, ("h_srvs", "h_req"),
       ("ptr", "ret")),
    _c("ros_services_response", Command.ROS_SERVICES_RESPONSE, ("h_srvs", "h_res"), ("ret",)),
    _c("ros_servicec_request", Command.ROS_SERVICEC_REQUEST, ("h_srvc", "h_req"), ("ret",)),
    _c("ros_servicec_take", Command.ROS_SERVICEC_TAKE, ("h_srvc", "h_res"), ("ptr",)),
    _c("ros_servicec_trytake", Command.ROS_SERVICEC_TRYTAKE, ("h_srvc", "h_res"),
       ("ptr", "ret")),
    _c("ros_actions_goal_take", Command.ROS_ACTIONS_GOAL_TAKE, ("h_as", "h_goal"), ("ptr",)),
    _c("ros_actions_goal_trytake", Command.ROS_ACTIONS_GOAL_TRYTAKE, ("h_as", "h_goal"),
       ("ptr", "ret")),
    _c("ros_actions_goal_decide", Command.ROS_ACTIONS_GOAL_DECIDE, ("h_as", "accept"),
       ("ret",)),
    _c("ros_actions_result_take", Command.ROS_ACTIONS_RESULT_TAKE, ("h_as",), ("ret",)),
    _c("ros_actions_result_trytake", Command.ROS_ACTIONS_RESULT_TRYTAKE, ("h_as",),
       ("ptr", "ret")),
    _c("ros_actions_result_send", Command.ROS_ACTIONS_RESULT_SEND, ("h_as", "h_res"),
       ("ret",)),
    _c("ros_actions_feedback", Command.ROS_ACTIONS_FEEDBACK, ("h_as", "h_fb"), ("ret",)),
    _c("ros_actions_cancel_take", Command.ROS_ACTIONS_CANCEL_TAKE, ("h_as",), ("ret",)),
    _c("ros_actions_cancel_trytake", Command.ROS_ACTIONS_CANCEL_TRYTAKE, ("h_as",), ("ret",)),
    _c("ros_actions_cancel_send", Command.ROS_ACTIONS_CANCEL_SEND, ("h_as",), ("ret",)),
    _c("ros_actionc_goal_send", Command.ROS_ACTIONC_GOAL_SEND, ("h_ac", "h_goal"), ("ret",)),
    _c("ros_actionc_goal_take", Command.ROS_ACTIONC_GOAL_TAKE, ("h_ac",), ("accept", "ret")),
    _c("ros_actionc_goal_trytake", Command.ROS_ACTIONC_GOAL_TRYTAKE, ("h_ac",),
       ("accept", "ret")),
    _c("ros_actionc_result_send", Command.ROS_ACTIONC_RESULT_SEND, ("h_ac",), ("ret",)),
    _c("ros_actionc_result_take", Command.ROS_ACTIONC_RESULT_TAKE, ("h_ac", "h_res"),
       ("ptr",)),
    _c("ros_actionc_result_trytake", Command.ROS_ACTIONC_RESULT_TRYTAKE, ("h_ac", "h_res"),
       ("ptr", "ret")),
    _c("ros_actionc_feedback_take", Command.ROS_ACTIONC_FEEDBACK_TAKE, ("h_ac", "h_fb"),
       ("ret",)),
    _c("ros_actionc_feedback_trytake", Command.ROS_ACTIONC_FEEDBACK_TRYTAKE, ("h_ac", "h_fb"),
       ("ret",)),
    _c("ros_actionc_cancel_send", Command.ROS_ACTIONC_CANCEL_SEND, ("h_ac",), ("ret",)),
    _c("ros_actionc_cancel_take", Command.ROS_ACTIONC_CANCEL_TAKE, ("h_ac",), ("ret",)),
    _c("ros_actionc_cancel_trytake", Command.ROS_ACTIONC_CANCEL_TRYTAKE, ("h_ac", "h_msg"),
       ("ret",)),
]}


def call(command):
    """The :class:`Call` of a command word (masked with :data:`CMD_MASK`), or ``None``."""
    code = command & CMD_MASK
    for c in CALLS.values():
        if c.command is not None and c.command == code:
            return c
    return None


class MemifOp(enum.IntEnum):
    """MEMIF operation byte (docs/reconos.md), in the top byte of request word 0."""

    READ = 0x00
    WRITE = 0xF0


#: Largest MEMIF request; requests never cross a multiple of it (docs/reconos.md).
MEMIF_CHUNK = 256


def memif_command(arch_, op, length):
    """Request word 0: ``op << (W*8-8) | length``."""
    a = arch(arch_)
    if not 0 <= length < (1 << a.length_bits):
        raise ValueError(f"MEMIF length {length} does not fit {a.length_bits} bits")
    return (int(op) << a.length_bits) | length


def memif_decode(arch_, word):
    """``(op byte, length)`` of request word 0."""
    a = arch(arch_)
    return word >> a.length_bits, word & ((1 << a.length_bits) - 1)


def memif_split(addr, length):
    """The ReconOS split of a memory access into ``(addr, length)`` requests
    (docs/reconos.md)."""
    out = []
    while length > 0:
        n = min(length, MEMIF_CHUNK - (addr % MEMIF_CHUNK))
        out.append((addr, n))
        addr += n
        length -= n
    return out


class OsifRegister(enum.IntEnum):
    """The four reconos_osif registers of one hardware thread (docs/reconos.md)."""

    HW2SW_DATA = 0   # read pops the hw2sw FIFO
    SW2HW_DATA = 1   # write pushes the sw2hw FIFO
    HW2SW_EMPTY = 2  # MSB = hw2sw empty; low 16 bits: hw2sw fill (rosgate addition)
    SW2HW_FULL = 3   # MSB = sw2hw full; low 16 bits: sw2hw free entries (rosgate addition)


def osif_register_offset(arch_, thread, register):
    """Byte offset of ``register`` of ``thread`` in reconos_osif: ``(4*thread + k) * W``."""
    return (4 * thread + int(register)) * arch(arch_).word_bytes


class ProcControlRegister(enum.IntEnum):
    """reconos_proc_control register indices (r64 layout, docs/reconos.md; offset = 8*index).

    Indices 8-10 are rosgate additions (defects 6, 8, 9 of ReconROS (docs/reconos.md)).
    """

    NUM_HWTS = 0
    PGD = 1              # write also flushes the TLB
    FAULT_ADDR = 2       # read clears the page-fault interrupt; write = retry
    TLB_HITS = 3         # counts TLB hits (read-only counter)
    TLB_MISSES = 4       # counts TLB misses (read-only counter)
    SYS_RESET = 5        # write: 16-cycle system reset of arbiter, MMU, TLB, controller
    HWT_RESET = 6        # per-thread reset mask, reset value all ones
    HWT_SIGNAL = 7       # per-thread signal mask
    TLB_FLUSH = 8        # write: invalidate every TLB entry
    MEM_STATUS = 9       # memory-path error status (MemStatus bits); read clears
    MEM_ERROR_ADDR = 10  # address of the first failed request since the last clear
    FAULT_ABORT = 11     # write: give up the faulting request (completed as a bad request)


def proc_control_offset(arch_, register, num_hwts=1):
    """Byte offset of a proc_control register.

    r64: ``8 * index``. r32 (docs/reconos.md): 0x00..0x14 for indices 0..5, then one 32-bit
    word per
    32 threads for the reset masks, as many for the signal masks, then the rosgate additions.
    Masks of threads 32 and up are not exposed by this function (rosgate supports up to 32
    slots per proc_control).
    """
    a = arch(arch_)
    r = ProcControlRegister(register)
    if a.name == "r64":
        return 8 * int(r)
    words = -(-num_hwts // 32)
    if r <= ProcControlRegister.SYS_RESET:
        return 4 * int(r)
    if r == ProcControlRegister.HWT_RESET:
        return 0x18
    if r == ProcControlRegister.HWT_SIGNAL:
        return 0x18 + 4 * words
    return 0x18 + 8 * words + 4 * (int(r) - int(ProcControlRegister.TLB_FLUSH))


class MemStatus(enum.IntFlag):
    """Bits of ``MEM_STATUS``: what went wrong on the memory path since the last read."""

    AXI_SLVERR = 1 << 0    # a burst ended with SLVERR
    AXI_DECERR = 1 << 1    # a burst ended with DECERR
    BAD_REQUEST = 1 << 2   # a request of length 0, not a multiple of W, over 256 B, or
                           # crossing a 256-B boundary was rejected (read: zeros returned;
                           # write: data words drained)
    PAGE_FAULT = 1 << 3    # a page fault happened (also signalled by the interrupt)


class ResourceType(enum.IntEnum):
    """ReconOS resource type codes (docs/reconos.md)."""

    MBOX = 0x1
    SEM = 0x2
    MUTEX = 0x4
    COND = 0x8
    ROSNODE = 0x10
    ROSSUB = 0x20
    ROSPUB = 0x40
    ROSMSG = 0x80
    ROSSRVS = 0x100
    ROSSRVC = 0x200
    ROSSRVMSGREQ = 0x400
    ROSSRVMSGRES = 0x800
    ROSACTIONS = 0x1000
    ROSACTIONC = 0x2000
    ROSACTIONMSGGOALREQ = 0x4000
    ROSTMR = 0x80000
    ROSACTIONMSGRESULTRES = 0x20000
    ROSACTIONMSGFEEDBACK = 0x40000
    MEM = 0x100000
