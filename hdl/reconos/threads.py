"""Example hardware threads: the ReconROS ping-pong nodes and an OS-call sequencer used by the
compatibility tests. They are written with the thread API only (no word counting)."""

from amaranth.hdl import Cat, Const, Module, Mux, ResetInserter, Signal, Value
from amaranth.lib import wiring

from .hwt import HardwareThread
from .protocol import CALLS

__all__ = ["EchoThread", "CopyThread", "CallSequenceThread", "MemoryTestThread", "REPORT_MBOX",
           "SortSteps", "SortServiceThread", "SortActionThread", "MailboxSortThread",
           "SharedCounterThread", "SobelServerThread", "DipThread", "WordKernelNode",
           "MailboxPublisher", "ServoNode"]


class EchoThread(HardwareThread):
    """The paper's echo node: take a message, publish the same message, repeat.

    Parameters
    ----------
    arch : str
    h_sub, h_pub, h_msg : int
        Thread-local handles of the subscriber, the publisher and the message object.
    """

    def __init__(self, arch, *, h_sub, h_pub, h_msg):
        self.handles = (h_sub, h_pub, h_msg)
        super().__init__(arch)

    def elaborate(self, platform):
        m = Module()
        os, _ = self.os_and_memory(m)
        h_sub, h_pub, h_msg = self.handles
        ptr = Signal(self.arch.word_bits)
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="TAKE")
            with m.State("TAKE"):
                os.ros_take(h_sub, h_msg, ptr=ptr, then="PUBLISH")
            with m.State("PUBLISH"):
                os.ros_publish(h_pub, h_msg, then="TAKE")
        return m


class CopyThread(HardwareThread):
    """The paper's copy node: take a message, copy its payload sequence through MEMIF into a
    second message (sized with ROS_MESSAGE_SET_SIZE), publish that one, repeat.

    The payload is ``data_offset`` bytes into the message struct (a ``uint8[]``, e.g.
    ``sensor_msgs/Image.data``: 72 on arm64, 48 on arm32). Whole words are streamed; a tail of
    fewer than W bytes is merged into the destination word by read-modify-write, so no byte
    past the payload changes.

    Parameters
    ----------
    arch : str
    h_sub, h_pub, h_msg_in, h_msg_out : int
        Handles.
    data_offset : int
        Byte offset of the payload's ``{data, size, capacity}`` in the message struct.
    """

    def __init__(self, arch, *, h_sub, h_pub, h_msg_in, h_msg_out, data_offset):
        self.handles = (h_sub, h_pub, h_msg_in, h_msg_out)
        self.data_offset = data_offset
        super().__init__(arch)

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        h_sub, h_pub, h_in, h_out = self.handles
        w = self.arch.word_bits
        in_ptr, src, size, dst = (Signal(w, name=n) for n in ("in_ptr", "src", "size", "dst"))
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="TAKE")
            with m.State("TAKE"):
                os.ros_take(h_sub, h_in, ptr=in_ptr, then="HEADER")
            with m.State("HEADER"):
                mem.read_words(in_ptr + self.data_offset, [src, size], then="SET_SIZE")
            with m.State("SET_SIZE"):
                os.ros_message_set_size(h_out, self.data_offset, 1, size, ptr=dst, then="COPY")
            mem.copy_bytes_states("COPY", src, dst, size, then="PUBLISH")
            with m.State("PUBLISH"):
                os.ros_publish(h_pub, h_out, then="TAKE")
        return m


#: The mailbox handle :class:`CallSequenceThread` reports replies to.
REPORT_MBOX = 0x7E


class CallSequenceThread(HardwareThread):
    """Calls OS functions in a fixed order and reports every reply through MBOX_PUT to
    :data:`REPORT_MBOX`, so a test sees both the words the thread sends and the values it
    received. After the program it calls THREAD_EXIT.

    Parameters
    ----------
    arch : str
    program : list of (method, [args])
        Method names of :data:`~hdl.reconos.protocol.CALLS` (plus
        ``ros_take_interruptable_check``, and ``command`` whose first argument is any command
        word, expecting one reply) and their constant arguments.
    h_report : int
        Mailbox handle for the reports (default :data:`REPORT_MBOX`).
    """

    def __init__(self, arch, *, program, h_report=REPORT_MBOX):
        self.program = [(name, tuple(args)) for name, args in program]
        self.h_report = h_report
        for name, args in self.program:
            if name in ("ros_take_interruptable_check", "command"):
                continue
            if name not in CALLS:
                raise ValueError(f"unknown OS call {name!r} in the program")
        super().__init__(arch)

    def elaborate(self, platform):
        m = Module()
        os, _ = self.os_and_memory(m)
        w = self.arch.word_bits
        regs = [Signal(w, name=f"reply{i}") for i in range(2)]
        got = Signal()
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(signal=regs[0], then="REPORT_INIT")
            with m.State("REPORT_INIT"):
                os.mbox_put(self.h_report, regs[0], then="CALL0")
            for i, (name, args) in enumerate(self.program):
                nxt = f"CALL{i + 1}" if i + 1 < len(self.program) else "EXIT"
                with m.State(f"CALL{i}"):
                    if name in ("ros_take_interruptable_check", "ros_take_interruptable_cancel"):
                        getattr(os, name)(ptr=regs[0], got=got, then=f"REPORT{i}_0")
                        replies = [regs[0], got]
                    elif name == "command":
                        os.command(*args, nreplies=1, replies=[regs[0]], then=f"REPORT{i}_0")
                        replies = [regs[0]]
                    else:
                        c = CALLS[name]
                        getattr(os, name)(*args, then=f"REPORT{i}_0" if c.replies else nxt,
                                          **{r: regs[k] for k, r in enumerate(c.replies)})
                        replies = regs[:len(c.replies)]
                for k, reg in enumerate(replies):
                    after = f"REPORT{i}_{k + 1}" if k + 1 < len(replies) else nxt
                    with m.State(f"REPORT{i}_{k}"):
                        os.mbox_put(self.h_report, reg, then=after)
            with m.State("EXIT"):
                os.thread_exit()
        return m


class MemoryTestThread(HardwareThread):
    """A thread that executes memory operations sent by software through a mailbox, for
    testing the MEMIF path with requests a well-behaved thread never makes.

    Each operation is a sequence of words on mailbox ``h_cmd``; results go to ``h_result``:

    * ``0, addr, length``: one raw MEMIF read request (no splitting, any length); the
      ``ceil(length/W)`` words that come back are put into ``h_result``;
    * ``1, addr, length, seed``: one raw write request with data words ``seed + k``; then 0;
    * ``2, src, dst, length``: a copy through the :class:`~hdl.reconos.hwt.MemifEngine`
      (split, full rate); then 0.

    Parameters
    ----------
    arch : str
    h_cmd, h_result : int
        Mailbox handles.
    """

    def __init__(self, arch, *, h_cmd, h_result):
        self.handles = (h_cmd, h_result)
        super().__init__(arch)

    def elaborate(self, platform):
        from amaranth.lib import wiring as _w
        from .hwt import MemCalls, MemifEngine, OsifCalls, OsifEngine
        from .memif import request_words
        from .protocol import MemifOp
        m = Module()
        a = self.arch
        w = a.word_bits
        m.submodules.osif = osif = OsifEngine(a)
        for name in ("osif_sw2hw", "osif_hw2sw"):
            _w.connect(m, _w.flipped(getattr(self, name)), getattr(osif, name))
        m.d.comb += osif.hwt_signal.eq(self.hwt_signal)
        os = OsifCalls(m, osif)
        m.submodules.memif = engine = MemifEngine(a)
        mem = MemCalls(m, engine)
        raw = Signal()
        h2m, m2h = self.memif_hwt2mem, self.memif_mem2hwt
        raw_we = Signal()
        raw_data = Signal(w)
        raw_re = Signal()
        m.d.comb += [
            h2m.we.eq(Mux(raw, raw_we, engine.memif_hwt2mem.we)),
            h2m.data.eq(Mux(raw, raw_data, engine.memif_hwt2mem.data)),
            engine.memif_hwt2mem.full.eq(h2m.full | raw),
            m2h.re.eq(Mux(raw, raw_re, engine.memif_mem2hwt.re)),
            engine.memif_mem2hwt.data.eq(m2h.data),
            engine.memif_mem2hwt.empty.eq(m2h.empty | raw),
        ]
        h_cmd, h_res = self.handles
        op, x, y, z, word = (Signal(w, name=n) for n in ("op", "x", "y", "z", "word"))
        count = Signal(w)
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="OP")
            with m.State("OP"):
                os.mbox_get(h_cmd, data=op, then="X")
            with m.State("X"):
                os.mbox_get(h_cmd, data=x, then="Y")
            with m.State("Y"):
                with m.If(op == 0):
                    os.mbox_get(h_cmd, data=y, then="RAW_CMD")
                with m.Else():
                    os.mbox_get(h_cmd, data=y, then="Z")
            with m.State("Z"):
                with m.If(op == 2):
                    os.mbox_get(h_cmd, data=z, then="COPY")
                with m.Else():
                    os.mbox_get(h_cmd, data=z, then="RAW_CMD")
            with m.State("RAW_CMD"):
                length = y[:a.length_bits]
                m.d.comb += [raw.eq(1), raw_we.eq(1),
                             raw_data.eq(Mux(op == 0, MemifOp.READ, MemifOp.WRITE) << a.length_bits
                                         | length)]
                with m.If(~h2m.full):
                    m.d.sync += count.eq(request_words(a, length))
                    m.next = "RAW_ADDR"
            with m.State("RAW_ADDR"):
                m.d.comb += [raw.eq(1), raw_we.eq(1), raw_data.eq(x)]
                with m.If(~h2m.full):
                    with m.If(count == 0):
                        m.next = "RESULT"
                    with m.Elif(op == 0):
                        m.next = "RAW_READ"
                    with m.Else():
                        m.next = "RAW_WRITE"
            with m.State("RAW_WRITE"):
                m.d.comb += [raw.eq(1), raw_we.eq(1), raw_data.eq(z)]
                with m.If(~h2m.full):
                    m.d.sync += [z.eq(z + 1), count.eq(count - 1)]
                    with m.If(count == 1):
                        m.next = "RESULT"
            with m.State("RAW_READ"):
                m.d.comb += [raw.eq(1), raw_re.eq(1)]
                with m.If(~m2h.empty):
                    m.d.sync += [word.eq(m2h.data), count.eq(count - 1)]
                    m.next = "RAW_REPORT"
            with m.State("RAW_REPORT"):
                with m.If(count == 0):
                    os.mbox_put(h_res, word, then="OP")
                with m.Else():
                    os.mbox_put(h_res, word, then="RAW_READ")
            with m.State("COPY"):
                mem.copy(x, y, z, then="RESULT")
            with m.State("RESULT"):
                os.mbox_put(h_res, 0, then="OP")
        return m


class SortSteps:
    """FSM helpers that move a block of unsigned 32-bit elements between process memory and
    a :class:`~hdl.kernels.MergeSorter` (W/32 elements per MEMIF word, little-endian).

    Use :meth:`load` inside a state; :meth:`store_states` emits its own states. ``n`` is the
    element count (1..block size), held stable from :meth:`load` to the end of the store.
    """

    def __init__(self, m, mem, sorter, arch, n):
        self._m, self._mem, self._sorter, self._arch = m, mem, sorter, arch
        self._n = n = Value.cast(n)
        self._per_word = arch.word_bits // 32
        self._tail = Signal(32, name="sort_tail")
        self._dst_word = Signal(arch.word_bits, name="sort_dst_word")
        m.d.comb += sorter.length.eq(n)

    def load(self, addr, *, then):
        """Read ``n`` elements from ``addr`` into the sorter (whole words are read)."""
        wb = self._arch.word_bytes
        length = ((self._n << 2) + wb - 1) & ~(wb - 1)
        self._mem.read_stream(addr, length, self._sorter.i, count=self._n, then=then)

    def store_states(self, name, addr, *, then):
        """States ``name`` (+ ``name_TAIL_*`` on r64): stream the sorted block to ``addr``;
        an odd last element is merged into its word by read-modify-write, so nothing past
        the block changes."""
        m, mem, o, n = self._m, self._mem, self._sorter.o, self._n
        per, wb = self._per_word, self._arch.word_bytes
        full = n >> (per.bit_length() - 1)             # whole words
        with m.State(name):
            mem.write_stream(addr, full * wb, o, then=f"{name}_TAIL" if per > 1 else then)
        if per == 1:
            return
        with m.State(f"{name}_TAIL"):
            with m.If(n[0]):
                m.d.comb += o.tready.eq(1)
                with m.If(o.tvalid):
                    m.d.sync += self._tail.eq(o.tdata)
                    m.next = f"{name}_TAIL_READ"
            with m.Else():
                m.next = then
        with m.State(f"{name}_TAIL_READ"):
            mem.read_word(addr + full * wb, self._dst_word, then=f"{name}_TAIL_WRITE")
        with m.State(f"{name}_TAIL_WRITE"):
            mem.write_word(addr + full * wb, Cat(self._tail, self._dst_word[32:]), then=then)


class _SortingThread(HardwareThread):
    """A thread around a :class:`~hdl.kernels.MergeSorter` of ``block_size`` elements."""

    def __init__(self, arch, block_size):
        self.block_size = block_size
        super().__init__(arch)

    def _with_sorter(self, m, n, abort=None):
        """``(os, mem, sorter, steps)`` for a block of ``n`` elements; ``abort`` (a signal)
        resets the sorter, dropping what it holds."""
        from ..kernels import MergeSorter
        os, mem = self.os_and_memory(m)
        sorter = MergeSorter(self.block_size)
        m.submodules.sorter = sorter if abort is None else ResetInserter(abort)(sorter)
        return os, mem, sorter, SortSteps(m, mem, sorter, self.arch, n)


class SortServiceThread(_SortingThread):
    """The ReconROS sort service server (``sorter_msgs/srv/Sort``, docs/reconos.md), with
    defect 14
    fixed: the response carries the sorted data.

    Loop: SERVICES_TAKE the request; read ``unsorted``'s data pointer and size; sort; size
    the response's ``sorted`` with ROS_MESSAGE_SET_SIZE; write it; SERVICES_RESPONSE.
    A request with 0 or more than ``block_size`` elements is answered with an empty
    ``sorted``.

    Parameters
    ----------
    arch : str
    h_srvs, h_req, h_res : int
        Handles of the service server and its request and response messages.
    req_offset, res_offset : int
        Byte offsets of the ``uint32[]`` in the request and in the response (0 and 0).
    block_size : int
        Largest request (default 2048, the ReconROS demo's size).
    """

    def __init__(self, arch, *, h_srvs, h_req, h_res, req_offset=0, res_offset=0,
                 block_size=2048):
        self.handles = (h_srvs, h_req, h_res)
        self.offsets = (req_offset, res_offset)
        super().__init__(arch, block_size)

    def elaborate(self, platform):
        m = Module()
        n = Signal(range(self.block_size + 1))
        os, mem, _, steps = self._with_sorter(m, n)
        h_srvs, h_req, h_res = self.handles
        req_off, res_off = self.offsets
        w = self.arch.word_bits
        req, src, size, dst = (Signal(w, name=nm) for nm in ("req", "src", "size", "dst"))
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="TAKE")
            with m.State("TAKE"):
                os.ros_services_take(h_srvs, h_req, ptr=req, then="HEADER")
            with m.State("HEADER"):
                mem.read_words(req + req_off, [src, size], then="CHECK")
            with m.State("CHECK"):
                with m.If((size == 0) | (size > self.block_size)):
                    m.d.sync += n.eq(0)
                    m.next = "SET_SIZE"
                with m.Else():
                    m.d.sync += n.eq(size)
                    m.next = "LOAD"
            with m.State("LOAD"):
                steps.load(src, then="SET_SIZE")
            with m.State("SET_SIZE"):
                os.ros_message_set_size(h_res, res_off, 4, n, ptr=dst, then="STORE")
            with m.State("STORE"):
                m.next = "RESPOND"
                with m.If(n != 0):
                    m.next = "STORE_SORTED"
            steps.store_states("STORE_SORTED", dst, then="RESPOND")
            with m.State("RESPOND"):
                os.ros_services_response(h_srvs, h_res, then="TAKE")
        return m


def _float32_bits(value):
    import struct
    return struct.unpack("<I", struct.pack("<f", value))[0]


class SortActionThread(_SortingThread):
    """The ReconROS sort action server (``sorter_msgs/action/Sort``, docs/reconos.md): goal,
    feedback, result.

    Loop: ACTIONS_GOAL_TAKE; read ``goal.unsorted``; ACTIONS_GOAL_DECIDE (accept when it has
    1..``block_size`` elements, else reject); ACTIONS_RESULT_TAKE (waits for the client's
    result request); sort, sending ACTIONS_FEEDBACK with ``feedback.percent`` = merge passes
    done / all passes x 100 whenever the sorter has finished a pass since the last feedback
    (always ending with 100.0); ROS_MESSAGE_SET_SIZE on ``result.sorted``; write it;
    ACTIONS_RESULT_SEND. After each feedback but the last, ACTIONS_CANCEL_TRYTAKE: when a
    cancel was asked for, the sorter is reset and the goal ended with ACTIONS_CANCEL_SEND.

    Parameters
    ----------
    arch : str
    h_as, h_goal, h_res, h_fb : int
        Handles of the action server, its goal request, result response and feedback
        message.
    goal_offset, res_offset, fb_offset : int
        Byte offsets of ``goal.unsorted`` in the goal request, ``result.sorted`` in the result
        response and ``feedback.percent`` in the feedback message (docs/reconos.md).
    block_size : int
        Largest goal (default 2048).
    """

    def __init__(self, arch, *, h_as, h_goal, h_res, h_fb, goal_offset, res_offset, fb_offset,
                 block_size=2048):
        self.handles = (h_as, h_goal, h_res, h_fb)
        self.offsets = (goal_offset, res_offset, fb_offset)
        super().__init__(arch, block_size)

    def elaborate(self, platform):
        m = Module()
        n = Signal(range(self.block_size + 1))
        abort = Signal()
        os, mem, sorter, steps = self._with_sorter(m, n, abort)
        h_as, h_goal, h_res, h_fb = self.handles
        goal_off, res_off, fb_off = self.offsets
        a = self.arch
        w = a.word_bits
        goal, src, size, dst, fb, fb_word = (
            Signal(w, name=nm) for nm in ("goal", "src", "size", "dst", "fb", "fb_word"))
        accept = Signal()
        canceled = Signal()         # the reply's low bit: 0, a cancel was asked for
        reported = Signal(range(sorter.passes + 1))
        fb_addr = fb + (fb_off & ~(a.word_bytes - 1))
        lane = (fb_off % a.word_bytes) // 4
        percent = Signal(32)
        with m.Switch(reported):
            for k in range(sorter.passes + 1):
                with m.Case(k):
                    m.d.comb += percent.eq(_float32_bits(100.0 * k / sorter.passes))
        fb_new = Signal(w)
        m.d.comb += fb_new.eq(fb_word)
        m.d.comb += fb_new.word_select(lane, 32).eq(percent)
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="FB_ADDR")
            with m.State("FB_ADDR"):
                os.memory_getobjaddr(h_fb, ptr=fb, then="GOAL")
            with m.State("GOAL"):
                os.ros_actions_goal_take(h_as, h_goal, ptr=goal, then="HEADER")
            with m.State("HEADER"):
                mem.read_words(goal + goal_off, [src, size], then="CHECK")
            with m.State("CHECK"):
                m.d.sync += [accept.eq((size != 0) & (size <= self.block_size)),
                             n.eq(size[:n.shape().width]), reported.eq(0)]
                m.next = "DECIDE"
            with m.State("DECIDE"):
                with m.If(accept):
                    os.ros_actions_goal_decide(h_as, 1, then="RESULT_TAKE")
                with m.Else():
                    os.ros_actions_goal_decide(h_as, 0, then="GOAL")
            with m.State("RESULT_TAKE"):
                os.ros_actions_result_take(h_as, then="LOAD")
            with m.State("LOAD"):
                steps.load(src, then="PROGRESS")
            with m.State("PROGRESS"):
                with m.If(reported == sorter.passes):
                    m.next = "SET_SIZE"
                with m.Elif(sorter.progress > reported):
                    m.d.sync += reported.eq(sorter.progress)
                    m.next = "FB_READ"
            with m.State("FB_READ"):
                mem.read_word(fb_addr, fb_word, then="FB_WRITE")
            with m.State("FB_WRITE"):
                mem.write_word(fb_addr, fb_new, then="FEEDBACK")
            with m.State("FEEDBACK"):
                with m.If(reported == sorter.passes):
                    os.ros_actions_feedback(h_as, h_fb, then="PROGRESS")
                with m.Else():
                    os.ros_actions_feedback(h_as, h_fb, then="CANCEL_CHECK")
            with m.State("CANCEL_CHECK"):
                os.ros_actions_cancel_trytake(h_as, ret=canceled, then="CANCEL_DECIDE")
            with m.State("CANCEL_DECIDE"):
                with m.If(canceled == 0):
                    m.d.comb += abort.eq(1)
                    m.next = "CANCEL_SEND"
                with m.Else():
                    m.next = "PROGRESS"
            with m.State("CANCEL_SEND"):
                os.ros_actions_cancel_send(h_as, then="GOAL")
            with m.State("SET_SIZE"):
                os.ros_message_set_size(h_res, res_off, 4, n, ptr=dst, then="STORE")
            steps.store_states("STORE", dst, then="SEND")
            with m.State("SEND"):
                os.ros_actions_result_send(h_as, h_res, then="GOAL")
        return m


class MailboxSortThread(_SortingThread):
    """The ReconOS sort demo's hardware thread (the VHDL variant of docs/reconos.md): get an
    address from mailbox ``h_in``, sort the ``block_size`` unsigned 32-bit words there in
    place, put the address into mailbox ``h_out``; an all-ones address ends the thread
    (THREAD_EXIT).

    Parameters
    ----------
    arch : str
    h_in, h_out : int
        Mailbox handles.
    block_size : int
        Words per block (default 2048).
    """

    def __init__(self, arch, *, h_in, h_out, block_size=2048):
        self.handles = (h_in, h_out)
        super().__init__(arch, block_size)

    def elaborate(self, platform):
        m = Module()
        os, mem, _, steps = self._with_sorter(m, self.block_size)
        h_in, h_out = self.handles
        addr = Signal(self.arch.word_bits)
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="GET")
            with m.State("GET"):
                os.mbox_get(h_in, data=addr, then="CHECK")
            with m.State("CHECK"):
                with m.If(addr == (1 << self.arch.word_bits) - 1):
                    m.next = "EXIT"
                with m.Else():
                    m.next = "LOAD"
            with m.State("LOAD"):
                steps.load(addr, then="STORE")
            steps.store_states("STORE", addr, then="PUT")
            with m.State("PUT"):
                os.mbox_put(h_out, addr, then="GET")
            with m.State("EXIT"):
                os.thread_exit()
        return m


class SharedCounterThread(HardwareThread):
    """Increments a counter in shared memory under a mutex: get a count ``k`` from mailbox
    ``h_cmd`` (0 ends the thread); ``k`` times MUTEX_LOCK, read the word at the init-data
    address, add 1, write it back, MUTEX_UNLOCK; then SEM_POST ``h_done``. Several slots
    running it contend for the mutex and for memory; the final count shows whether every
    increment was exclusive.

    Parameters
    ----------
    arch : str
    h_cmd, h_mutex, h_done : int
        Mailbox, mutex and semaphore handles.
    """

    def __init__(self, arch, *, h_cmd, h_mutex, h_done):
        self.handles = (h_cmd, h_mutex, h_done)
        super().__init__(arch)

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        h_cmd, h_mutex, h_done = self.handles
        w = self.arch.word_bits
        addr, k, value = (Signal(w, name=nm) for nm in ("addr", "k", "value"))
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="INIT_DATA")
            with m.State("INIT_DATA"):
                os.get_init_data(init_data=addr, then="CMD")
            with m.State("CMD"):
                os.mbox_get(h_cmd, data=k, then="CHECK")
            with m.State("CHECK"):
                with m.If(k == 0):
                    m.next = "EXIT"
                with m.Else():
                    m.next = "LOCK"
            with m.State("LOCK"):
                os.mutex_lock(h_mutex, then="READ")
            with m.State("READ"):
                mem.read_word(addr, value, then="WRITE")
            with m.State("WRITE"):
                mem.write_word(addr, value + 1, then="UNLOCK")
            with m.State("UNLOCK"):
                os.mutex_unlock(h_mutex, then="NEXT")
            with m.State("NEXT"):
                m.d.sync += k.eq(k - 1)
                with m.If(k == 1):
                    m.next = "DONE"
                with m.Else():
                    m.next = "LOCK"
            with m.State("DONE"):
                os.sem_post(h_done, then="CMD")
            with m.State("EXIT"):
                os.thread_exit()
        return m


def _image_offsets(offsets, arch):
    """Check the ``sensor_msgs/Image`` offsets a Sobel-pair thread copies by MEMIF words."""
    need = ("height", "encoding", "is_bigendian", "step", "data")
    missing = [k for k in need if k not in offsets]
    if missing:
        raise ValueError(f"image_offsets lacks {', '.join(missing)}; it needs {', '.join(need)}")
    wb = arch.word_bytes
    for a, b in (("height", "encoding"), ("is_bigendian", "data")):
        if offsets[a] % wb or offsets[b] % wb:
            raise ValueError(f"image_offsets: {a} ({offsets[a]}) and {b} ({offsets[b]}) must be "
                             f"multiples of the {wb}-byte word")
    out = {k: int(offsets[k]) for k in need}
    # rosidl: ``uint32 width`` follows ``uint32 height`` (in the same word on r64)
    out["width"] = out["height"] + 4
    return out


def _image_geometry_states(m, mem, name, src, dst, off, *, then):
    """States ``name`` and ``name_LAYOUT``: copy an Image's ``height``, ``width`` and
    ``is_bigendian``, ``step`` words from the image at ``src`` to the one at ``dst``, leaving
    ``encoding`` (a pointer) and the header alone."""
    with m.State(name):
        mem.copy(src + off["height"], dst + off["height"], off["encoding"] - off["height"],
                 then=f"{name}_LAYOUT")
    with m.State(f"{name}_LAYOUT"):
        mem.copy(src + off["is_bigendian"], dst + off["is_bigendian"],
                 off["data"] - off["is_bigendian"], then=then)


def _lane32(word, offset, wb):
    return word.word_select((offset % wb) // 4, 32) if wb > 4 else word


class SobelServerThread(HardwareThread):
    """The "Sobel" node of the ReconROS paper (Listing 2): a service server that filters
    the request's image and answers with the filtered image.

    Loop: SERVICES_TAKE; read the request image's ``height``, ``width``, ``step`` and
    payload; copy ``height``, ``width``, ``is_bigendian`` and ``step`` into the response image
    (its ``encoding`` and header are left as software set them); ROS_MESSAGE_SET_SIZE the
    response payload; stream the payload through the filter into it; SERVICES_RESPONSE.
    Unlike Listing 2 the result goes into the response, not back over the request.

    Modes:

    ``"opencv"`` (default)
        The edge image OpenCV computes for a ``bgr8`` image: per channel
        ``cv2.add(cv2.convertScaleAbs(Sobel(dx=1)), cv2.convertScaleAbs(Sobel(dy=1)))``,
        3 x 3, ``BORDER_REFLECT_101`` (:class:`~hdl.kernels.Sobel`), one pixel per cycle, any
        width and height from 3 to ``max_width`` x ``max_height``. The image's ``step`` must be
        ``3 * width`` (no row padding).
    ``"reconros"``
        The paper's filter: each byte lane of the 32-bit word grid filtered on its own,
        ``(|gx| + |gy|) >> 3`` (:class:`~hdl.kernels.SobelByteLanes`), rows of 3 to
        ``max_words`` words, ``step`` a multiple of W (native border: the border words are
        0 where ReconROS leaves them unwritten).

    A request the mode cannot take (a size or ``step`` outside these rules, fewer than 3
    rows, or a payload that is not ``height * step`` bytes) is answered with an empty payload.

    Parameters
    ----------
    arch : str
    h_srvs, h_req, h_res : int
        Handles of the service server and its request and response messages.
    image_offsets : dict
        Byte offsets in ``sensor_msgs/Image`` of ``height``, ``encoding``,
        ``is_bigendian``, ``step`` and ``data`` for the target ABI (docs/reconos.md).
    req_image_offset, res_image_offset : int
        Offset of the image in the request and in the response (``img``: 0 and 0).
    mode : str
        ``"opencv"`` or ``"reconros"``.
    max_width, max_height : int
        ``opencv``: the largest image, in pixels (default 640 x 480).
    max_words : int
        ``reconros``: the longest row in 32-bit words (default 480: 640 ``bgr8`` pixels).
    """

    MODES = ("opencv", "reconros")

    def __init__(self, arch, *, h_srvs, h_req, h_res, image_offsets, req_image_offset=0,
                 res_image_offset=0, mode="opencv", max_width=640, max_height=480,
                 max_words=480):
        from ..params import check_choice, check_int
        self.mode = check_choice("mode", mode, self.MODES)
        self.max_width = check_int("max_width", max_width, 3, 1 << 14)
        self.max_height = check_int("max_height", max_height, 3, 1 << 14)
        self.max_words = check_int("max_words", max_words, 3, 8192)
        self.handles = (h_srvs, h_req, h_res)
        super().__init__(arch)
        self.offsets = _image_offsets(image_offsets, self.arch)
        self.image_at = (req_image_offset, res_image_offset)

    @property
    def min_width(self):
        """The narrowest image the mode takes, in pixels."""
        return 3 if self.mode == "opencv" else 4

    def accepts(self, width, height):
        """Whether a ``bgr8`` image of ``width`` x ``height`` pixels (``step = 3 * width``)
        is filtered rather than refused."""
        if height < 3:
            return False
        if self.mode == "opencv":
            return 3 <= width <= self.max_width and height <= self.max_height
        step = 3 * width
        wb = self.arch.word_bytes
        return step % wb == 0 and 12 <= step <= 4 * self.max_words

    def elaborate(self, platform):
        from ..kernels import Sobel, SobelByteLanes
        from ..stream import RegisterSlice, StreamRepacker
        m = Module()
        os, mem = self.os_and_memory(m)
        h_srvs, h_req, h_res = self.handles
        off = self.offsets
        ri, so = self.image_at
        a = self.arch
        w, wb = a.word_bits, a.word_bytes
        req, res, src, size, dst, dims, widths, steps = (
            Signal(w, name=nm) for nm in ("req", "res", "src", "size", "dst", "dims", "widths",
                                          "steps"))
        height, width, step = Signal(32), Signal(32), Signal(32)
        n = Signal(w)
        # the payload size the geometry implies, registered: a 32 x 32 multiplication and a
        # comparison in one cycle do not meet 100 MHz
        area = Signal(64)
        shape_ok = Signal()
        width_at = off["width"]
        m.d.comb += [height.eq(_lane32(dims, off["height"], wb)),
                     width.eq(_lane32(widths, width_at, wb)),
                     step.eq(_lane32(steps, off["step"], wb))]
        if self.mode == "opencv":
            m.submodules.sobel = sobel = Sobel("opencv", channels=3, pixels_per_beat=1,
                                               max_width=self.max_width,
                                               max_height=self.max_height)
            m.submodules.to_pixels = to_pixels = StreamRepacker(wb, 3)
            m.submodules.to_words = to_words = StreamRepacker(3, wb)
            # register slices on both sides of the filter: its ready reaches from its output
            # to its input, and the memory copy's control drives both repackers
            m.submodules.pixel_slice = pixel_slice = RegisterSlice(
                to_pixels.signature.members["m_axis"].signature)
            m.submodules.result_slice = result_slice = RegisterSlice(
                to_words.signature.members["s_axis"].signature.flip())
            # and after the word repacker: the memory write's ready does not reach its buffer
            m.submodules.word_slice = word_slice = RegisterSlice(
                to_words.signature.members["m_axis"].signature)
            wiring.connect(m, to_pixels.m_axis, pixel_slice.s_axis)
            wiring.connect(m, result_slice.m_axis, to_words.s_axis)
            wiring.connect(m, to_words.m_axis, word_slice.s_axis)
            pixels, results = pixel_slice.m_axis, result_slice.s_axis
            m.d.comb += [sobel.width.eq(width), sobel.height.eq(height),
                         sobel.i.tdata.eq(pixels.tdata),
                         sobel.i.tlast.eq(pixels.tlast),
                         sobel.i.tvalid.eq(pixels.tvalid),
                         pixels.tready.eq(sobel.i.tready),
                         results.tdata.eq(sobel.o.tdata),
                         results.tlast.eq(sobel.o.tlast),
                         results.tkeep.eq(0b111),
                         results.tvalid.eq(sobel.o.tvalid),
                         sobel.o.tready.eq(results.tready)]
            ok = ((step == width + (width << 1)) & (width >= 3) & (width <= self.max_width) &
                  (height >= 3) & (height <= self.max_height))
        else:
            m.submodules.sobel = sobel = SobelByteLanes(self.max_words)
            m.d.comb += [sobel.words.eq(step >> 2), sobel.height.eq(height)]
            ok = ((step[:(wb - 1).bit_length()] == 0) & (step >= 12) &
                  (step <= 4 * self.max_words) & (height >= 3))

        def aligned(o):
            return o & ~(wb - 1)
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="RES_ADDR")
            with m.State("RES_ADDR"):
                os.memory_getobjaddr(h_res, ptr=res, then="TAKE")
            with m.State("TAKE"):
                os.ros_services_take(h_srvs, h_req, ptr=req, then="PAYLOAD")
            with m.State("PAYLOAD"):
                mem.read_words(req + ri + off["data"], [src, size], then="DIMS")
            with m.State("DIMS"):
                mem.read_word(req + ri + aligned(off["height"]), dims, then="WIDTH")
            with m.State("WIDTH"):
                mem.read_word(req + ri + aligned(width_at), widths, then="STEP")
            with m.State("STEP"):
                mem.read_word(req + ri + aligned(off["step"]), steps, then="AREA")
            with m.State("AREA"):
                m.d.sync += [area.eq(height * step), shape_ok.eq(ok)]
                m.next = "CHECK"
            with m.State("CHECK"):
                m.d.sync += n.eq(Mux(shape_ok & (size == area), size, 0))
                m.next = "GEOMETRY"
            _image_geometry_states(m, mem, "GEOMETRY", req + ri, res + so, off, then="SET_SIZE")
            with m.State("SET_SIZE"):
                os.ros_message_set_size(h_res, so + off["data"], 1, n, ptr=dst, then="FILTER?")
            with m.State("FILTER?"):
                m.next = "RESPOND"
                with m.If(n != 0):
                    m.next = "FILTER"
            if self.mode == "opencv":
                mem.transform_bytes_states("FILTER", src, dst, n, to_pixels.s_axis,
                                           word_slice.m_axis, then="RESPOND")
            else:
                with m.State("FILTER"):
                    mem.transform(src, dst, n, sobel.i, sobel.o, then="RESPOND")
            with m.State("RESPOND"):
                os.ros_services_response(h_srvs, h_res, then="TAKE")
        return m


class DipThread(HardwareThread):
    """The "DIP" node of the ReconROS paper (Listing 3): subscribe to images, have each
    filtered by a service, publish the result.

    Loop: ROS_TAKE an image; copy its geometry words and (ROS_MESSAGE_SET_SIZE, MEMIF copy)
    its payload into the service request's image; SERVICEC_REQUEST; SERVICEC_TAKE the
    response; copy the response payload over the taken image's payload (Listing 3, line
    23); ROS_PUBLISH the image. A response whose payload size differs from the image's
    (the server refused it) is not published.

    Parameters
    ----------
    arch : str
    h_sub, h_pub, h_img, h_srvc, h_req, h_res : int
        Handles of the image subscriber, the publisher, the image message, the service
        client and its request and response messages.
    image_offsets, req_image_offset, res_image_offset :
        As for :class:`SobelServerThread`.
    """

    def __init__(self, arch, *, h_sub, h_pub, h_img, h_srvc, h_req, h_res, image_offsets,
                 req_image_offset=0, res_image_offset=0):
        self.handles = (h_sub, h_pub, h_img, h_srvc, h_req, h_res)
        super().__init__(arch)
        self.offsets = _image_offsets(image_offsets, self.arch)
        self.image_at = (req_image_offset, res_image_offset)

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        h_sub, h_pub, h_img, h_srvc, h_req, h_res = self.handles
        off = self.offsets
        qi, si = self.image_at
        w = self.arch.word_bits
        img, req, res, src, size, rdst, rsrc, rsize = (
            Signal(w, name=nm) for nm in ("img", "req", "res", "src", "size", "rdst", "rsrc",
                                          "rsize"))
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="REQ_ADDR")
            with m.State("REQ_ADDR"):
                os.memory_getobjaddr(h_req, ptr=req, then="TAKE")
            with m.State("TAKE"):
                os.ros_take(h_sub, h_img, ptr=img, then="PAYLOAD")
            with m.State("PAYLOAD"):
                mem.read_words(img + off["data"], [src, size], then="GEOMETRY")
            _image_geometry_states(m, mem, "GEOMETRY", img, req + qi, off, then="SET_SIZE")
            with m.State("SET_SIZE"):
                os.ros_message_set_size(h_req, qi + off["data"], 1, size, ptr=rdst,
                                        then="TO_REQUEST")
            mem.copy_bytes_states("TO_REQUEST", src, rdst, size, then="REQUEST")
            with m.State("REQUEST"):
                os.ros_servicec_request(h_srvc, h_req, then="RESPONSE")
            with m.State("RESPONSE"):
                os.ros_servicec_take(h_srvc, h_res, ptr=res, then="RESULT")
            with m.State("RESULT"):
                mem.read_words(res + si + off["data"], [rsrc, rsize], then="CHECK")
            with m.State("CHECK"):
                m.next = "TAKE"
                with m.If(rsize == size):
                    m.next = "FROM_RESPONSE"
            mem.copy_bytes_states("FROM_RESPONSE", rsrc, src, size, then="PUBLISH")
            with m.State("PUBLISH"):
                os.ros_publish(h_pub, h_img, then="TAKE")
        return m


class WordKernelNode(HardwareThread):
    """A ROS node around a kernel of 32-bit words: take a message whose first member is a
    32-bit value (``std_msgs/UInt32``, ``Int32``, ``Float32``), give the value to the kernel,
    and publish every word the kernel answers with, up to the one with ``tlast``, in the
    output message's first member; repeat.

    ReconROS' single-word nodes (``rt_inverse``: ``/angle`` to ``legangle``) and the
    ball-on-plate chain are of this shape. The output message is written by
    read-modify-write of its first memory word, so its other bytes keep their values.

    Parameters
    ----------
    arch : str
    kernel : wiring.Component
        With ``i`` and ``o`` streams of 32-bit words (``tdata``, ``tlast`` on ``o``), for
        example :class:`~hdl.kernels.InverseKinematics` or :class:`~hdl.kernels.BallControl`.
    dropped : str or None
        The kernel's one-cycle error output that says it dropped the word without an answer
        (``"err_leg"`` of the inverse kinematics): the node then takes the next message.
    h_sub, h_pub, h_msg_in, h_msg_out : int
        Handles.
    """

    def __init__(self, arch, kernel, *, h_sub, h_pub, h_msg_in, h_msg_out, dropped=None):
        if dropped is not None and not hasattr(kernel, dropped):
            raise ValueError(f"dropped={dropped!r}: the kernel has no such member")
        self.kernel = kernel
        self.dropped = dropped
        self.handles = (h_sub, h_pub, h_msg_in, h_msg_out)
        super().__init__(arch)

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        m.submodules.kernel = kernel = self.kernel
        h_sub, h_pub, h_in, h_out = self.handles
        w = self.arch.word_bits
        in_ptr, out_ptr, word, out_word = (Signal(w, name=n) for n in
                                           ("in_ptr", "out_ptr", "word", "out_word"))
        answer = Signal(32)
        last = Signal()
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="OUT_ADDR")
            with m.State("OUT_ADDR"):
                os.memory_getobjaddr(h_out, ptr=out_ptr, then="OUT_READ")
            with m.State("OUT_READ"):
                mem.read_word(out_ptr, out_word, then="TAKE")
            with m.State("TAKE"):
                os.ros_take(h_sub, h_in, ptr=in_ptr, then="READ")
            with m.State("READ"):
                mem.read_word(in_ptr, word, then="FEED")
            with m.State("FEED"):
                m.d.comb += [kernel.i.tvalid.eq(1), kernel.i.tdata.eq(word[:32])]
                with m.If(kernel.i.tready):
                    m.next = "ANSWER"
            with m.State("ANSWER"):
                m.d.comb += kernel.o.tready.eq(1)
                with m.If(kernel.o.tvalid):
                    m.d.sync += [answer.eq(kernel.o.tdata), last.eq(kernel.o.tlast)]
                    m.next = "WRITE"
                if self.dropped is not None:
                    with m.Elif(getattr(kernel, self.dropped)):
                        m.next = "TAKE"
            with m.State("WRITE"):
                mem.write_word(out_ptr, Cat(answer, out_word[32:]), then="PUBLISH")
            with m.State("PUBLISH"):
                os.ros_publish(h_pub, h_out, then="NEXT")
            with m.State("NEXT"):
                with m.If(last):
                    m.next = "TAKE"
                with m.Else():
                    m.next = "ANSWER"
        return m


class MailboxPublisher(HardwareThread):
    """Publish every mailbox word as a message whose first member is a 32-bit value (a
    sensor's samples arriving through a mailbox: the ball-on-plate touch panel).

    Parameters
    ----------
    arch : str
    h_mbox, h_pub, h_msg : int
        Handles of the mailbox, the publisher and its message object.
    """

    def __init__(self, arch, *, h_mbox, h_pub, h_msg):
        self.handles = (h_mbox, h_pub, h_msg)
        super().__init__(arch)

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        h_mbox, h_pub, h_msg = self.handles
        w = self.arch.word_bits
        ptr, kept, sample = (Signal(w, name=n) for n in ("ptr", "kept", "sample"))
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="ADDR")
            with m.State("ADDR"):
                os.memory_getobjaddr(h_msg, ptr=ptr, then="KEEP")
            with m.State("KEEP"):
                mem.read_word(ptr, kept, then="GET")
            with m.State("GET"):
                os.mbox_get(h_mbox, data=sample, then="WRITE")
            with m.State("WRITE"):
                mem.write_word(ptr, Cat(sample[:32], kept[32:]), then="PUBLISH")
            with m.State("PUBLISH"):
                os.ros_publish(h_pub, h_msg, then="GET")
        return m


class ServoNode(HardwareThread):
    """Drives a :class:`~hdl.kernels.ServoPwm` from the leg angles of a topic and reports what
    the servos were given: the high time of every channel, measured on the PWM outputs over
    each whole period, goes to a mailbox as six words ``(leg << 24) | cycles`` (legs 0..5)
    after the period ends.

    The node polls the topic (``ROS_TRYTAKE``) between the reports, so a report never waits
    for a message. (On a board the PWM outputs would leave the slot as pins; the slot
    interface has none, so the report is how the co-simulated plant sees them.)

    Parameters
    ----------
    arch : str
    pwm : ServoPwm
    h_sub, h_msg, h_mbox : int
        Handles of the leg-angle subscription, its message object and the report mailbox.
    """

    def __init__(self, arch, pwm, *, h_sub, h_msg, h_mbox):
        self.pwm = pwm
        self.handles = (h_sub, h_msg, h_mbox)
        super().__init__(arch)

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        m.submodules.pwm = pwm = self.pwm
        h_sub, h_msg, h_mbox = self.handles
        w = self.arch.word_bits
        ptr, word, ret = (Signal(w, name=n) for n in ("ptr", "word", "ret"))
        high = [Signal(32, name=f"high{n}") for n in range(6)]
        report = [Signal(32, name=f"report{n}") for n in range(6)]
        fresh = Signal()           # a whole period's widths wait in ``report``
        started = Signal()         # a period start has been seen (counting whole periods)
        leg = Signal(range(6))
        taken = Signal()
        with m.If(pwm.period_start):
            m.d.sync += [started.eq(1), fresh.eq(started)]
            m.d.sync += [r.eq(h) for r, h in zip(report, high)]
            m.d.sync += [h.eq(0) for h in high]
        with m.Else():
            m.d.sync += [h.eq(h + pwm.pwm[n]) for n, h in enumerate(high)]
        with m.If(taken):
            m.d.sync += fresh.eq(0)
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="POLL")
            with m.State("POLL"):
                with m.If(fresh):
                    m.d.comb += taken.eq(1)
                    m.d.sync += leg.eq(0)
                    m.next = "REPORT"
                with m.Else():
                    m.next = "TRY"
            with m.State("TRY"):
                os.ros_trytake(h_sub, h_msg, ptr=ptr, ret=ret, then="TRIED")
            with m.State("TRIED"):
                with m.If(ret == 0):
                    m.next = "READ"
                with m.Else():
                    m.next = "POLL"
            with m.State("READ"):
                mem.read_word(ptr, word, then="FEED")
            with m.State("FEED"):
                m.d.comb += [pwm.i.tvalid.eq(1), pwm.i.tdata.eq(word[:32])]
                with m.If(pwm.i.tready):
                    m.next = "POLL"
            with m.State("REPORT"):
                value = Signal(32)
                with m.Switch(leg):
                    for n in range(6):
                        with m.Case(n):
                            m.d.comb += value.eq(Cat(report[n][:24], Const(n, 8)))
                os.mbox_put(h_mbox, value, then="REPORTED")
            with m.State("REPORTED"):
                with m.If(leg == 5):
                    m.next = "POLL"
                with m.Else():
                    m.d.sync += leg.eq(leg + 1)
                    m.next = "REPORT"
        return m
