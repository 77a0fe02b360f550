"""A Python model of the software side of ReconROS, for co-simulation of hardware threads.

Written from the spec (docs/reconos.md), not from the RTL:

* :class:`~host.reconos.memory.ProcessMemory`: the process's virtual memory;
* :class:`~host.reconos.messages.MessageMemory`: ROS messages as rosidl C structs in it;
* :class:`~host.reconos.broker.Broker`: an in-process ROS graph;
* :class:`ReconosRuntime`: the runtime: thread create/suspend/resume through proc_control,
  one delegate per slot that reads OSIF commands through the reconos_osif registers (waiting
  for the osif_intc interrupt as the Linux driver does) and answers with the spec's words.
"""

import collections

import cocotb
from cocotb.triggers import Event, First, RisingEdge, Timer

from hdl.reconos.protocol import (
    CMD_MASK,
    INTERRUPTED_REPLY,
    SIGNAL_THREAD_RESUME,
    SIGNAL_THREAD_START,
    Command,
    OsifRegister,
    ProcControlRegister,
    ResourceType,
    call,
    osif_register_offset,
    proc_control_offset,
)
from hdl.dds.action import GoalStatus
from hdl.reconos.protocol import arch as get_arch

from .broker import Queue

__all__ = ["Resource", "ReconosRuntime", "ProtocolError"]


class ProtocolError(AssertionError):
    """The hardware broke the ReconOS protocol (the real delegate would panic)."""


class Resource:
    """One entry of a thread's resource list (its index is the handle, docs/reconos.md).

    ``kind`` is a :class:`ResourceType` name in lower case (``"mbox"``, ``"sem"``,
    ``"mutex"``, ``"cond"``, ``"mem"``, ``"rosnode"``, ``"rosmsg"``, ``"rossub"``, ``"rospub"``,
    ``"rossrvmsgreq"``, ``"rossrvmsgres"``, ``"rossrvs"``, ``"rossrvc"``, ``"rosactions"``,
    ``"rosactionmsggoalreq"``, ``"rosactionmsgresultres"``, ``"rosactionmsgfeedback"``);
    ``args`` as in build.cfg (message type for a message, topic for a subscriber or
    publisher, size for a mailbox or memory, initial value for a semaphore, service or
    action name for servers/clients).
    """

    def __init__(self, kind, *args, name=None):
        self.kind = kind
        self.type = ResourceType[kind.upper()]
        self.args = args
        self.name = name or kind
        self.ptr = 0          # resources[h].ptr (GETOBJADDR)
        self.state = None
        #: a subscriber does not get what a publisher of the same origin publishes (None:
        #: gets everything); the ROS gateway's node ignores its own publications
        self.origin = None

    def __repr__(self):
        return f"Resource({self.kind}, {', '.join(map(repr, self.args))})"


class _Semaphore:
    def __init__(self, value):
        self.value = value
        self.event = Event()

    async def wait(self):
        while self.value == 0:
            self.event.clear()
            await self.event.wait()
        self.value -= 1

    def post(self):
        self.value += 1
        self.event.set()


class _Mutex:
    def __init__(self):
        self.owner = None
        self.event = Event()

    async def lock(self, who):
        while self.owner is not None:
            self.event.clear()
            await self.event.wait()
        self.owner = who

    def trylock(self, who):
        if self.owner is None:
            self.owner = who
            return True
        return False

    def unlock(self):
        self.owner = None
        self.event.set()


class _Cond:
    def __init__(self):
        self.waiters = []

    async def wait(self, mutex, who):
        ev = Event()
        self.waiters.append(ev)
        mutex.unlock()
        await ev.wait()
        await mutex.lock(who)

    def signal(self):
        if self.waiters:
            self.waiters.pop(0).set()

    def broadcast(self):
        while self.waiters:
            self.waiters.pop(0).set()


class ReconosRuntime:
    """The ReconOS runtime on the CPU, talking to a :class:`~hdl.reconos.ReconosSystem` in
    simulation through its three AXI4-Lite ports and interrupts.

    Parameters
    ----------
    arch : str
    osif, intc, proc : cocotbext.axi.AxiLiteMaster
        Masters on ``s_axi_osif``, ``s_axi_intc``, ``s_axi_proc``.
    irq_osif, irq_pgf : cocotb handles
        The interrupt outputs.
    clock : cocotb handle
    memory : ProcessMemory
    messages : MessageMemory
    broker : Broker
    num_hwts : int
    """

    def __init__(self, arch, *, osif, intc, proc, irq_osif, irq_pgf, clock, memory, messages,
                 broker, num_hwts):
        self.arch = get_arch(arch)
        self.w = self.arch.word_bits
        self.osif, self.intc, self.proc = osif, intc, proc
        self.irq_osif, self.irq_pgf, self.clock = irq_osif, irq_pgf, clock
        self.mem = memory
        self.msgs = messages
        self.broker = broker
        self.n = num_hwts
        self.log = collections.defaultdict(list)   # slot -> [(command name, args, replies)]
        self.ignored = collections.defaultdict(list)  # slot -> unknown command words
        self.exited = {i: Event() for i in range(num_hwts)}
        self._wakeup = {i: Event() for i in range(num_hwts)}
        self._enabled = 0
        self._reset_mask = (1 << num_hwts) - 1
        self._signal_mask = 0
        self._delegates = {}
        self._subs = {}
        self.unresolved_faults = []
        self.errors = []
        #: OS calls read so far, and the call each slot's delegate is serving now
        self.commands = 0
        #: register reads and writes on the AXI-Lite buses (a measure of progress)
        self.bus_accesses = 0
        self.pending = {}
        self._threads = {}
        #: set when a delegate fails for a reason other than the hardware's protocol (the
        #: model ran out of memory, say): the exception, and the event a run waits on
        self.fatal = None
        self.failed = Event()

    # ---- registers ----
    async def _read(self, bus, offset):
        self.bus_accesses += 1
        resp = await bus.read(offset, self.arch.word_bytes)
        return int.from_bytes(resp.data, "little")

    async def _write(self, bus, offset, value):
        self.bus_accesses += 1
        await bus.write(offset, (value & ((1 << self.w) - 1)).to_bytes(self.arch.word_bytes,
                                                                      "little"))

    def proc_offset(self, register):
        return proc_control_offset(self.arch, register, self.n)

    async def proc_read(self, register):
        return await self._read(self.proc, self.proc_offset(register))

    async def proc_write(self, register, value):
        await self._write(self.proc, self.proc_offset(register), value)

    async def osif_write(self, slot, word):
        while (await self._read(self.osif, osif_register_offset(
                self.arch, slot, OsifRegister.SW2HW_FULL))) >> (self.w - 1):
            await RisingEdge(self.clock)
        await self._write(self.osif, osif_register_offset(self.arch, slot,
                                                          OsifRegister.SW2HW_DATA), word)

    async def hw2sw_empty(self, slot):
        return (await self._read(self.osif, osif_register_offset(
            self.arch, slot, OsifRegister.HW2SW_EMPTY))) >> (self.w - 1)

    async def osif_read(self, slot):
        """``reconos_osif_read``: wait for the slot's interrupt as the driver does, then pop."""
        while True:
            if not await self.hw2sw_empty(slot):
                return await self._read(self.osif, osif_register_offset(
                    self.arch, slot, OsifRegister.HW2SW_DATA))
            ev = self._wakeup[slot]
            ev.clear()
            await self._intc_enable(slot, True)
            await ev.wait()

    async def _intc_enable(self, slot, on):
        if on:
            self._enabled |= 1 << slot
        else:
            self._enabled &= ~(1 << slot)
        await self._write(self.intc, 0, self._enabled)

    async def _intc_isr(self):
        """The osif_intc ISR: read pending, disable the active bits, wake their waiters."""
        while True:
            if not int(self.irq_osif.value):
                await RisingEdge(self.irq_osif)
            pending = await self._read(self.intc, 0) & 0xFFFF_FFFF
            self._enabled &= ~pending
            await self._write(self.intc, 0, self._enabled)
            for i in range(self.n):
                if pending >> i & 1:
                    self._wakeup[i].set()
            await RisingEdge(self.clock)

    async def _pgf_handler(self):
        """``proc_pgfhandler``: read the fault address, map the page, retry (or abort)."""
        while True:
            if not int(self.irq_pgf.value):
                await RisingEdge(self.irq_pgf)
            va = await self.proc_read(ProcControlRegister.FAULT_ADDR)
            if self.mem.handle_fault(va):
                await self.proc_write(ProcControlRegister.FAULT_ADDR, 0)
            else:
                self.unresolved_faults.append(va)
                await self.proc_write(ProcControlRegister.FAULT_ABORT, 0)
            await RisingEdge(self.clock)

    async def start(self):
        """Driver init: system reset, page table base, interrupt handlers."""
        await self.proc_write(ProcControlRegister.SYS_RESET, 1)
        await self.proc_write(ProcControlRegister.PGD, self.mem.pgd)
        cocotb.start_soon(self._intc_isr())
        cocotb.start_soon(self._pgf_handler())

    # ---- threads ----
    async def _set_reset(self, slot, value):
        self._reset_mask = (self._reset_mask & ~(1 << slot)) | (int(value) << slot)
        await self.proc_write(ProcControlRegister.HWT_RESET, self._reset_mask)

    async def _set_signal(self, slot, value):
        self._signal_mask = (self._signal_mask & ~(1 << slot)) | (int(value) << slot)
        await self.proc_write(ProcControlRegister.HWT_SIGNAL, self._signal_mask)

    async def start_slot(self, slot, first_word=SIGNAL_THREAD_START):
        """Reset the slot and write its first word, without a delegate (for tests that play
        the delegate themselves)."""
        await self._set_reset(slot, 1)
        await self._set_signal(slot, 0)
        await self._set_reset(slot, 0)
        await self.osif_write(slot, first_word)

    async def create_thread(self, slot, resources, init_data=0, *, resume=False, state=None):
        """``reconos_hwt_create``: reset pulse, signal low, START (or RESUME) word, delegate."""
        self._threads[slot] = {"resources": resources, "init_data": init_data,
                               "state": state or 0}
        for r in resources:
            self._prepare(r)
        self.exited[slot].clear()
        await self._set_reset(slot, 1)
        await self._set_signal(slot, 0)
        await self._set_reset(slot, 0)
        await self.osif_write(slot, SIGNAL_THREAD_RESUME if resume else SIGNAL_THREAD_START)
        self._delegates[slot] = cocotb.start_soon(self._delegate(slot))

    async def suspend_thread(self, slot):
        """``reconos_hwt_suspend``: stop the delegate (the runtime's SIGUSR1), set HWT_Signal;
        the thread writes THREAD_EXIT while it waits for a reply; then hold it in reset.
        Words the thread sent before the exit belong to the abandoned call and are dropped."""
        task = self._delegates.pop(slot, None)
        if task is not None and not task.done():
            task.cancel()
        await self._set_signal(slot, 1)
        while True:
            word = await self.osif_read(slot)
            if word & CMD_MASK == Command.THREAD_EXIT:
                break
            self.ignored[slot].append(word)
        self.log[slot].append(("thread_exit", (), ()))
        await self._set_reset(slot, 1)
        await self._set_signal(slot, 0)
        self.exited[slot].set()

    async def resume_thread(self, slot):
        t = self._threads[slot]
        await self.create_thread(slot, t["resources"], t["init_data"], resume=True,
                                 state=t["state"])

    def _prepare(self, r):
        if r.state is not None:
            return
        k = r.kind
        if k == "mbox":
            r.state = Queue(maxsize=int(r.args[0]))
        elif k == "sem":
            r.state = _Semaphore(int(r.args[0]) if r.args else 0)
        elif k == "mutex":
            r.state = _Mutex()
        elif k == "cond":
            r.state = _Cond()
        elif k == "mem":
            r.ptr = self.mem.malloc(int(r.args[0]))
        elif k in ("rosmsg", "rossrvmsgreq", "rossrvmsgres"):
            r.ptr = self.msgs.create(r.args[0])
        elif k == "rossub":
            r.state = self.broker.subscribe(r.args[0], r.origin)
        elif k == "rossrvs":
            r.state = {"queue": self.broker.server_queue(r.args[0]), "pending": None}
        elif k == "rossrvc":
            r.state = {"reply": None}
        elif k == "rosactions":
            r.state = {"queue": self.broker.action_server_queue(r.args[0]), "goal": None}
        elif k == "rosactionc":
            r.state = {"goal": None}
        elif k in ("rosactionmsggoalreq", "rosactionmsgresultres", "rosactionmsgfeedback"):
            r.ptr = self.msgs.create(r.args[0])
        if not r.ptr:
            r.ptr = self.mem.malloc(64)   # a stand-in object address for GETOBJADDR

    def _resource(self, slot, handle, *kinds):
        res = self._threads[slot]["resources"]
        if not 0 <= handle < len(res) or res[handle].kind not in kinds:
            got = res[handle].kind if 0 <= handle < len(res) else "no resource"
            raise ProtocolError(f"slot {slot}: handle {handle} is {got}, expected "
                                f"{' or '.join(kinds)}")
        return res[handle]

    async def _delegate(self, slot):
        """``dt_delegate``: read a command, dispatch on ``cmd & 0xFFF``, answer."""
        while True:
            word = await self.osif_read(slot)
            c = call(word)
            if word & CMD_MASK == Command.THREAD_EXIT:
                self.log[slot].append(("thread_exit", (), ()))
                await self._set_reset(slot, 1)
                await self._set_signal(slot, 0)
                self.exited[slot].set()
                return
            if c is None or c.method == "ros_take_interruptable_cancel":
                # Unknown codes, OSIF_INTERRUPTED and a stray 0x904 are ignored (no reply):
                # 0x904 is read inside an interruptible take, and one sent after the reply
                # arrives here (docs/reconos.md, defect 25).
                self.ignored[slot].append(word)
                continue
            args = [await self.osif_read(slot) for _ in c.args]
            handler = getattr(self, "do_" + c.method, None)
            self.commands += 1
            self.pending[slot] = (c.method, tuple(args))
            try:
                if handler is None:
                    raise ProtocolError(f"slot {slot}: {c.method} is not modelled")
                replies = await handler(slot, *args)
            except ProtocolError as exc:
                self.ignored[slot].append((word, args, str(exc)))
                self.errors.append(str(exc))
                continue
            except Exception as exc:
                # the delegate cannot go on: the run ends with this exception, not a crash
                # of the simulator's task
                self.fatal = exc
                self.failed.set()
                return
            finally:
                self.pending.pop(slot, None)
            self.log[slot].append((c.method, tuple(args), tuple(replies)))
            for r in replies:
                await self.osif_write(slot, r & ((1 << self.w) - 1))

    # ---- handlers: return the reply words ----
    async def do_get_init_data(self, slot):
        return [self._threads[slot]["init_data"]]

    async def do_get_state_addr(self, slot):
        return [self._threads[slot]["state"]]

    async def do_thread_clear_signal(self, slot):
        await self._set_signal(slot, 0)
        return []

    async def do_sem_post(self, slot, h):
        self._resource(slot, h, "sem").state.post()
        return [0]

    async def do_sem_wait(self, slot, h):
        await self._resource(slot, h, "sem").state.wait()
        return [0]

    async def do_mutex_lock(self, slot, h):
        await self._resource(slot, h, "mutex").state.lock(slot)
        return [0]

    async def do_mutex_unlock(self, slot, h):
        self._resource(slot, h, "mutex").state.unlock()
        return [0]

    async def do_mutex_trylock(self, slot, h):
        return [0 if self._resource(slot, h, "mutex").state.trylock(slot) else 16]

    async def do_cond_wait(self, slot, hc, hm):
        cond = self._resource(slot, hc, "cond").state
        await cond.wait(self._resource(slot, hm, "mutex").state, slot)
        return [0]

    async def do_cond_signal(self, slot, h):
        self._resource(slot, h, "cond").state.signal()
        return [0]

    async def do_cond_broadcast(self, slot, h):
        self._resource(slot, h, "cond").state.broadcast()
        return [0]

    async def do_mbox_get(self, slot, h):
        return [await self._resource(slot, h, "mbox").state.get()]

    async def do_mbox_put(self, slot, h, value):
        await self._resource(slot, h, "mbox").state.put_wait(value)
        return [0]

    async def do_mbox_tryget(self, slot, h):
        q = self._resource(slot, h, "mbox").state
        if len(q):
            return [q.get_nowait(), 1]
        return [0, 0]

    async def do_mbox_tryput(self, slot, h, value):
        return [1 if self._resource(slot, h, "mbox").state.put_nowait(value) else 0]

    async def do_memory_malloc(self, slot, pdst, length):
        ptr = self.mem.malloc(length)
        self.mem.write(pdst, ptr.to_bytes(self.arch.word_bytes, "little"))
        return [ptr]

    async def do_memory_free(self, slot, ptr):
        if not self.mem.owns(ptr):
            raise ProtocolError(f"slot {slot}: MEMORY_FREE of 0x{ptr:x}, which no MEMORY_MALLOC "
                                f"returned (or already freed)")
        self.mem.free(ptr)
        return []

    async def do_memory_getobjaddr(self, slot, h):
        return [self._resource(slot, h, *_ALL_KINDS).ptr]

    async def do_memory_getmemaddr(self, slot, h):
        return [self._resource(slot, h, "mem").ptr]

    async def do_ros_message_set_size(self, slot, h, offset, elem_size, count):
        r = self._resource(slot, h, *_MESSAGE_KINDS)
        return [self.msgs.set_sequence(r.ptr + offset, elem_size, count)]

    async def do_ros_publish(self, slot, hp, hm):
        pub = self._resource(slot, hp, "rospub")
        msg = self._resource(slot, hm, "rosmsg")
        self.broker.publish(pub.args[0], self.msgs.read(msg.ptr, msg.args[0]), pub.origin)
        return [0]

    async def do_ros_take(self, slot, hs, hm):
        sub = self._resource(slot, hs, "rossub")
        msg = self._resource(slot, hm, "rosmsg")
        value = await sub.state.get()
        self.msgs.write(msg.ptr, msg.args[0], value)
        return [msg.ptr]

    async def do_ros_trytake(self, slot, hs, hm):
        sub = self._resource(slot, hs, "rossub")
        msg = self._resource(slot, hm, "rosmsg")
        value = sub.state.get_nowait()
        if value is None:
            return [0, 1]
        self.msgs.write(msg.ptr, msg.args[0], value)
        return [msg.ptr, 0]

    async def do_ros_take_interruptable(self, slot, hs, hm):
        """Loop: a message -> its pointer; any word from the thread -> all ones
        (docs/reconos.md)."""
        sub = self._resource(slot, hs, "rossub")
        msg = self._resource(slot, hm, "rosmsg")
        while True:
            value = sub.state.get_nowait()
            if value is not None:
                self.msgs.write(msg.ptr, msg.args[0], value)
                return [msg.ptr]
            if not await self.hw2sw_empty(slot):
                word = await self.osif_read(slot)   # the cancel word
                if word != Command.ROS_TAKE_INTERRUPTABLE_CANCEL:
                    raise ProtocolError(f"slot {slot}: 0x{word:x} during an interruptible take")
                return [INTERRUPTED_REPLY(self.w)]
            await First(sub.state._event.wait(), Timer(1, "us"))

    async def do_ros_services_take(self, slot, hs, hm):
        srv = self._resource(slot, hs, "rossrvs")
        req = self._resource(slot, hm, "rossrvmsgreq")
        request, reply = await srv.state["queue"].get()
        srv.state["pending"] = reply
        self.msgs.write(req.ptr, req.args[0], request)
        return [req.ptr]

    async def do_ros_services_trytake(self, slot, hs, hm):
        srv = self._resource(slot, hs, "rossrvs")
        req = self._resource(slot, hm, "rossrvmsgreq")
        item = srv.state["queue"].get_nowait()
        if item is None:
            return [0, 1]
        srv.state["pending"] = item[1]
        self.msgs.write(req.ptr, req.args[0], item[0])
        return [req.ptr, 0]

    async def do_ros_services_response(self, slot, hs, hm):
        srv = self._resource(slot, hs, "rossrvs")
        res = self._resource(slot, hm, "rossrvmsgres")
        if srv.state["pending"] is None:
            raise ProtocolError(f"slot {slot}: a service response without a request")
        srv.state["pending"].put(self.msgs.read(res.ptr, res.args[0]))
        srv.state["pending"] = None
        return [0]

    async def do_ros_servicec_request(self, slot, hc, hm):
        cli = self._resource(slot, hc, "rossrvc")
        req = self._resource(slot, hm, "rossrvmsgreq")
        reply = Queue()
        self.broker._services[cli.args[0]].put((self.msgs.read(req.ptr, req.args[0]), reply))
        cli.state["reply"] = reply
        return [0]

    async def do_ros_servicec_take(self, slot, hc, hm):
        cli = self._resource(slot, hc, "rossrvc")
        res = self._resource(slot, hm, "rossrvmsgres")
        value = await cli.state["reply"].get()
        self.msgs.write(res.ptr, res.args[0], value)
        return [res.ptr]

    async def do_ros_servicec_trytake(self, slot, hc, hm):
        cli = self._resource(slot, hc, "rossrvc")
        res = self._resource(slot, hm, "rossrvmsgres")
        value = cli.state["reply"].get_nowait() if cli.state["reply"] else None
        if value is None:
            return [0, 1]
        self.msgs.write(res.ptr, res.args[0], value)
        return [res.ptr, 0]


    # ---- action server (rclc action server semantics, docs/reconos.md) ----
    def _goal(self, slot, ha):
        srv = self._resource(slot, ha, "rosactions")
        if srv.state["goal"] is None:
            raise ProtocolError(f"slot {slot}: no goal taken on action server handle {ha}")
        return srv.state["goal"]

    def _take_goal(self, slot, ha, hm, goal):
        srv = self._resource(slot, ha, "rosactions")
        msg = self._resource(slot, hm, "rosactionmsggoalreq")
        srv.state["goal"] = goal
        self.msgs.write(msg.ptr, msg.args[0], goal.request)
        return msg.ptr

    async def do_ros_actions_goal_take(self, slot, ha, hm):
        goal = await self._resource(slot, ha, "rosactions").state["queue"].get()
        return [self._take_goal(slot, ha, hm, goal)]

    async def do_ros_actions_goal_trytake(self, slot, ha, hm):
        goal = self._resource(slot, ha, "rosactions").state["queue"].get_nowait()
        if goal is None:
            return [0, 1]
        return [self._take_goal(slot, ha, hm, goal), 0]

    async def do_ros_actions_goal_decide(self, slot, ha, accept):
        goal = self._goal(slot, ha)
        goal.accepted.put(bool(accept))
        if not accept:
            self._resource(slot, ha, "rosactions").state["goal"] = None
        return [0]

    async def do_ros_actions_result_take(self, slot, ha):
        await self._goal(slot, ha).result_requested.wait()
        return [0]

    async def do_ros_actions_result_trytake(self, slot, ha):
        requested = self._goal(slot, ha).result_requested.is_set()
        return [0, 0 if requested else 1]

    async def do_ros_actions_feedback(self, slot, ha, hm):
        goal = self._goal(slot, ha)
        msg = self._resource(slot, hm, "rosactionmsgfeedback")
        value = self.msgs.read(msg.ptr, msg.args[0])
        # rclc_action_publish_feedback stamps the goal's id into the feedback message
        value["goal_id"] = goal.request["goal_id"]
        goal.feedback.put(value)
        return [0]

    async def do_ros_actions_result_send(self, slot, ha, hm):
        goal = self._goal(slot, ha)
        msg = self._resource(slot, hm, "rosactionmsgresultres")
        goal.result.put(self.msgs.read(msg.ptr, msg.args[0]))
        self._resource(slot, ha, "rosactions").state["goal"] = None
        return [0]

    async def do_ros_actions_cancel_take(self, slot, ha):
        await self._goal(slot, ha).cancel_requested.wait()
        return [0]

    async def do_ros_actions_cancel_trytake(self, slot, ha):
        return [0 if self._goal(slot, ha).cancel_requested.is_set() else 1]

    async def do_ros_actions_cancel_send(self, slot, ha):
        # rclc_action_send_result(goal, GOAL_STATE_CANCELED, ...): the goal ends canceled,
        # its result the empty one; the thread's next goal take is its next goal
        self._goal(slot, ha).result.put({"status": int(GoalStatus.CANCELED)})
        self._resource(slot, ha, "rosactions").state["goal"] = None
        return [0]


    # ---- action client (rclc action client semantics; cancel is not modelled) ----
    def _client_goal(self, slot, hc):
        cli = self._resource(slot, hc, "rosactionc")
        if cli.state["goal"] is None:
            raise ProtocolError(f"slot {slot}: no goal sent on action client handle {hc}")
        return cli.state["goal"]

    async def do_ros_actionc_goal_send(self, slot, hc, hm):
        cli = self._resource(slot, hc, "rosactionc")
        msg = self._resource(slot, hm, "rosactionmsggoalreq")
        value = self.msgs.read(msg.ptr, msg.args[0])
        cli.state["goal"] = self.broker.send_goal(cli.args[0], value["goal"],
                                                  bytes(value["goal_id"]["uuid"]))
        return [0]

    async def do_ros_actionc_goal_take(self, slot, hc):
        return [int(await self._client_goal(slot, hc).accepted.get()), 0]

    async def do_ros_actionc_goal_trytake(self, slot, hc):
        accepted = self._client_goal(slot, hc).accepted.get_nowait()
        return [0, 1] if accepted is None else [int(accepted), 0]

    async def do_ros_actionc_result_send(self, slot, hc):
        self._client_goal(slot, hc).request_result()
        return [0]

    def _client_message(self, slot, hm, kind, value):
        msg = self._resource(slot, hm, kind)
        self.msgs.write(msg.ptr, msg.args[0], value)
        return msg.ptr

    async def do_ros_actionc_result_take(self, slot, hc, hm):
        value = await self._client_goal(slot, hc).result.get()
        return [self._client_message(slot, hm, "rosactionmsgresultres", value)]

    async def do_ros_actionc_result_trytake(self, slot, hc, hm):
        value = self._client_goal(slot, hc).result.get_nowait()
        if value is None:
            return [0, 1]
        return [self._client_message(slot, hm, "rosactionmsgresultres", value), 0]

    async def do_ros_actionc_feedback_take(self, slot, hc, hm):
        value = await self._client_goal(slot, hc).feedback.get()
        self._client_message(slot, hm, "rosactionmsgfeedback", value)
        return [0]

    async def do_ros_actionc_feedback_trytake(self, slot, hc, hm):
        value = self._client_goal(slot, hc).feedback.get_nowait()
        if value is None:
            return [1]
        self._client_message(slot, hm, "rosactionmsgfeedback", value)
        return [0]


_ALL_KINDS = tuple(t.name.lower() for t in ResourceType)
_MESSAGE_KINDS = ("rosmsg", "rossrvmsgreq", "rossrvmsgres", "rosactionmsggoalreq",
                  "rosactionmsgresultres", "rosactionmsgfeedback")
