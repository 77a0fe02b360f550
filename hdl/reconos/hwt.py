"""The hardware-thread API: slot ports, the OSIF call engine with per-call FSM helpers, and
the MEMIF read/write engine (docs/reconos.md).

A thread is a :class:`HardwareThread` (a component with the slot's ports). In its
``elaborate`` it calls :meth:`HardwareThread.os_and_memory` and writes an FSM whose states
call OS functions by name; the helpers emit the exact ReconOS word sequence::

    os, mem = self.os_and_memory(m)
    with m.FSM():
        with m.State("INIT"):
            os.thread_init(then="TAKE")
        with m.State("TAKE"):
            os.ros_take(H_SUB, H_MSG, ptr=msg_ptr, then="PUBLISH")
        with m.State("PUBLISH"):
            os.ros_publish(H_PUB, H_MSG, then="TAKE")

A call state drives the engine until the call's replies are in; then the named replies are
latched into the given signals and the FSM moves to ``then``. While a call waits for a reply
and ``HWT_Signal`` is high, the engine writes THREAD_EXIT and stops (the delegate then resets
the slot), as ReconOS' HLS library does.
"""

import enum

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.fifo import SyncFIFO, SyncFIFOBuffered
from amaranth.lib.wiring import In, Out

from ..logic import Countdown, kept
from ..params import check_int
from ..stream import PayloadRegisterSlice, ReadyRegisterSlice
from .fifo import MEMIF_FIFO_DEPTH, FifoReadSignature, FifoWriteSignature
from .protocol import (CALLS, INTERRUPTED_REPLY, MEMIF_CHUNK, Command, MemifOp,
                       arch as get_arch)

__all__ = ["ThreadSignature", "HardwareThread", "OsifEngine", "OsifMode", "OsifCalls",
           "MemifEngine", "MemCalls", "MAX_ARGS", "MAX_REPLIES"]

MAX_ARGS = 4
MAX_REPLIES = 2


def ThreadSignature(arch):
    """The slot ports of a hardware thread (entity ``rt_<name>``), seen from the thread.

    Members
    -------
    osif_sw2hw : Out(FifoReadSignature(W*8))
        Words from the delegate (``OSIF_Sw2Hw_Data/_Empty/_RE``).
    osif_hw2sw : Out(FifoWriteSignature(W*8))
        Words to the delegate (``OSIF_Hw2Sw_Data/_Full/_WE``).
    memif_hwt2mem : Out(FifoWriteSignature(W*8))
        MEMIF requests and write data.
    memif_mem2hwt : Out(FifoReadSignature(W*8))
        MEMIF read data.
    hwt_signal : In(1)
        ``HWT_Signal``: the software asks the thread to stop at its next OS call.
    """
    w = get_arch(arch).word_bits
    return wiring.Signature({
        "osif_sw2hw": Out(FifoReadSignature(w)),
        "osif_hw2sw": Out(FifoWriteSignature(w)),
        "memif_hwt2mem": Out(FifoWriteSignature(w)),
        "memif_mem2hwt": Out(FifoReadSignature(w)),
        "hwt_signal": In(1),
    })


class OsifMode(enum.IntEnum):
    CALL = 0     # write the command and arguments, then block for the replies
    POLL = 1     # take one reply word if there is one (interruptible take: check)
    CANCEL = 2   # take the reply if there; else write 0x904 and block (interruptible cancel)


class OsifEngine(wiring.Component):
    """Executes one OS call at a time on the OSIF FIFOs.

    Members
    -------
    osif_sw2hw, osif_hw2sw, hwt_signal :
        As in :func:`ThreadSignature`.
    start : In(1)
        Begin a call with the request members below (sampled while ``busy`` is low).
    mode : In(OsifMode)
    has_cmd : In(1)
        Write ``cmd`` first (THREAD_INIT writes nothing).
    cmd : In(W*8)
    args : In(W*8).array(4)
    nargs : In(range(5)), nreplies : In(range(3))
    busy : Out(1)
    done : Out(1)
        One-cycle pulse: the call is complete; ``replies`` and ``got`` are valid from now
        until the next call.
    replies : Out(W*8).array(2)
    got : Out(1)
        POLL: a reply was taken. CANCEL: the take delivered a message (reply not all ones).
    exited : Out(1)
        The thread wrote THREAD_EXIT (explicitly or because of ``hwt_signal``); the engine
        does nothing more until the slot is reset.
    """

    def __init__(self, arch):
        self._arch = a = get_arch(arch)
        w = a.word_bits
        slot = ThreadSignature(a).members
        super().__init__({
            "osif_sw2hw": slot["osif_sw2hw"], "osif_hw2sw": slot["osif_hw2sw"],
            "hwt_signal": slot["hwt_signal"],
            "start": In(1), "mode": In(2), "has_cmd": In(1), "cmd": In(w),
            "args": In(w).array(MAX_ARGS), "nargs": In(range(MAX_ARGS + 1)),
            "nreplies": In(range(MAX_REPLIES + 1)),
            "busy": Out(1), "done": Out(1), "replies": Out(w).array(MAX_REPLIES),
            "got": Out(1), "exited": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        w = self._arch.word_bits
        buf = [Signal(w, name=f"word{k}") for k in range(MAX_ARGS + 1)]  # cmd, args...
        k = Signal(range(MAX_ARGS + 2))
        end = Signal(range(MAX_ARGS + 2))
        nrep = Signal(range(MAX_REPLIES + 1))
        j = Signal(range(MAX_REPLIES + 1))
        mode = Signal(2)
        cancel_read = Signal()
        rx, tx = self.osif_sw2hw, self.osif_hw2sw

        current = Signal(w)
        for i, word in enumerate(buf):
            with m.If(k == i):
                m.d.comb += current.eq(word)
        m.d.comb += tx.data.eq(current)

        with m.FSM() as fsm:
            with m.State("IDLE"):
                with m.If(self.start):
                    m.d.sync += [buf[0].eq(self.cmd), k.eq(Mux(self.has_cmd, 0, 1)),
                                 end.eq(self.nargs + 1), nrep.eq(self.nreplies), j.eq(0),
                                 mode.eq(self.mode), cancel_read.eq(0), self.got.eq(0)]
                    m.d.sync += [buf[1 + i].eq(self.args[i]) for i in range(MAX_ARGS)]
                    with m.If(self.mode != OsifMode.CALL):
                        m.next = "POLL"
                    with m.Elif(self.has_cmd | (self.nargs != 0)):
                        m.next = "WRITE"
                    with m.Elif(self.nreplies != 0):
                        m.next = "READ"
                    with m.Else():
                        m.next = "DONE"
            with m.State("WRITE"):
                m.d.comb += tx.we.eq(1)
                with m.If(~tx.full):
                    m.d.sync += k.eq(k + 1)
                    with m.If(k + 1 == end):
                        with m.If((buf[0] == Command.THREAD_EXIT) & (end == 1)):
                            m.next = "EXITED"
                        with m.Elif(nrep != 0):
                            m.next = "READ"
                        with m.Else():
                            m.next = "DONE"
            with m.State("READ"):
                m.d.comb += rx.re.eq(1)
                with m.If(~rx.empty):
                    for i in range(MAX_REPLIES):
                        with m.If(j == i):
                            m.d.sync += self.replies[i].eq(rx.data)
                    m.d.sync += j.eq(j + 1)
                    with m.If(cancel_read):
                        m.d.sync += self.got.eq(rx.data != INTERRUPTED_REPLY(w))
                    with m.If(j + 1 == nrep):
                        m.next = "DONE"
                with m.Elif(self.hwt_signal):
                    m.d.sync += [buf[0].eq(Command.THREAD_EXIT), k.eq(0), end.eq(1)]
                    m.next = "SIGNAL_EXIT"
            with m.State("POLL"):
                m.d.comb += rx.re.eq(1)
                with m.If(~rx.empty):
                    m.d.sync += [self.replies[0].eq(rx.data), self.got.eq(1)]
                    m.next = "DONE"
                with m.Elif(mode == OsifMode.CANCEL):
                    m.d.sync += [buf[0].eq(Command.ROS_TAKE_INTERRUPTABLE_CANCEL), k.eq(0),
                                 end.eq(1), nrep.eq(1), cancel_read.eq(1)]
                    m.next = "WRITE"
                with m.Else():
                    m.next = "DONE"
            with m.State("SIGNAL_EXIT"):
                m.d.comb += tx.we.eq(1)
                with m.If(~tx.full):
                    m.next = "EXITED"
            with m.State("DONE"):
                m.d.comb += self.done.eq(1)
                m.next = "IDLE"
            with m.State("EXITED"):
                m.d.comb += self.exited.eq(1)
        m.d.comb += self.busy.eq(~fsm.ongoing("IDLE"))
        return m


class OsifCalls:
    """Per-call helpers for a thread's FSM, bound to an :class:`OsifEngine`.

    Every entry of :data:`~hdl.reconos.protocol.CALLS` is a method of the same name taking
    the call's arguments positionally (ints or Amaranth values), its replies as keyword
    arguments naming the signals that receive them (omitted replies are dropped), and
    ``then``, the next state. Use a method inside ``with m.State(...)`` only.

    Extra methods: :meth:`ros_take_interruptable_check` (non-blocking check of an
    interruptible take: ``ptr=``, ``got=``) and :meth:`ros_take_interruptable_cancel`
    (``ptr=``, ``got=``: whether a message was delivered after all).
    """

    def __init__(self, m, engine):
        self._m = m
        self._engine = engine
        self._w = engine._arch.word_bits

    def _drive(self, mode, command, args, nreplies):
        e = self._engine
        if len(args) > MAX_ARGS:
            raise ValueError(f"an OS call takes at most {MAX_ARGS} arguments, not {len(args)}")
        self._m.d.comb += [
            e.start.eq(~e.busy), e.mode.eq(mode),
            e.has_cmd.eq(command is not None), e.cmd.eq(0 if command is None else int(command)),
            e.nargs.eq(len(args)), e.nreplies.eq(nreplies),
        ]
        for i, arg in enumerate(args):
            self._m.d.comb += e.args[i].eq(arg)

    def _finish(self, outputs, then):
        e, m = self._engine, self._m
        with m.If(e.done):
            for target, value in outputs:
                m.d.sync += target.eq(value)
            if then is not None:
                m.next = then

    def _call(self, name, args, replies, then):
        c = CALLS[name]
        if len(args) != len(c.args):
            raise TypeError(f"{name}() takes the arguments ({', '.join(c.args)}), "
                            f"not {len(args)} values")
        unknown = set(replies) - set(c.replies)
        if unknown:
            raise TypeError(f"{name}() has no reply named {sorted(unknown)[0]!r}; its replies "
                            f"are ({', '.join(c.replies)})")
        if name == "thread_exit":
            self._drive(OsifMode.CALL, c.command, (), 0)
            return
        self._drive(OsifMode.CALL, c.command, args, len(c.replies) if c.blocking else 0)
        self._finish([(target, self._engine.replies[c.replies.index(r)])
                      for r, target in replies.items()], then)

    def command(self, word, *args, nreplies=0, replies=(), then=None):
        """Write ``word`` and ``args`` and read ``nreplies`` words into the signals
        ``replies``: an escape hatch for commands outside the ReconOS table."""
        self._drive(OsifMode.CALL, word, args, nreplies)
        self._finish([(t, self._engine.replies[k]) for k, t in enumerate(replies)], then)

    def _interruptable(self, mode, ptr, got, then):
        self._drive(mode, None, (), 1)
        self._finish([(t, v) for t, v in ((ptr, self._engine.replies[0]),
                                          (got, self._engine.got)) if t is not None], then)

    def ros_take_interruptable_check(self, *, ptr=None, got=None, then=None):
        self._interruptable(OsifMode.POLL, ptr, got, then)

    def ros_take_interruptable_cancel(self, *, ptr=None, got=None, then=None):
        self._interruptable(OsifMode.CANCEL, ptr, got, then)


def _make_method(name):
    c = CALLS[name]

    def method(self, *args, then=None, **replies):
        self._call(name, args, replies, then)
    method.__name__ = name
    cmd = "(no command word)" if c.command is None else f"0x{int(c.command):03X}"
    method.__doc__ = (f"{c.command.name if c.command else 'THREAD_INIT'} {cmd}: arguments "
                      f"({', '.join(c.args)}), replies ({', '.join(c.replies)}).")
    return method


for _name in CALLS:
    if _name != "ros_take_interruptable_cancel":
        setattr(OsifCalls, _name, _make_method(_name))


def memif_command_layout(arch):
    w = get_arch(arch).word_bits
    return data.StructLayout({"addr": w, "length": w})


class MemifEngine(wiring.Component):
    """MEM_READ/MEM_WRITE as streams: splits accesses into ReconOS requests (at most 256 B,
    never crossing a 256-B boundary, docs/reconos.md) and moves data at one word per cycle.

    Addresses and lengths are in bytes and must be multiples of W (their low bits are
    ignored, as in ReconOS' VHDL library). A read and a write may run at the same time (a
    streaming copy); their requests share the hwt2mem FIFO without deadlock because

    * read requests are issued only while the mem2hwt FIFO has room for all their data, and
    * a write request is issued only when its whole chunk is buffered (a 2-chunk buffer
      decouples the user's stream from the FIFO).

    Parameters
    ----------
    arch : str
    fence : bool
        After the last chunk of a write, read back one word of it and pulse ``write_done``
        only when that word arrives. The memory controller orders reads after completed
        writes, so ``write_done`` then means "in memory" and an OS call made after it (a
        publish) cannot overtake the data. Default ``True``.

    Members
    -------
    memif_hwt2mem, memif_mem2hwt :
        As in :func:`ThreadSignature`.
    read_cmd : In(stream.Signature(memif_command_layout))
        ``addr`` (virtual) and ``length`` of a read; started when the previous read's data
        has all been delivered. Commands of both kinds pass a
        :class:`~hdl.stream.PayloadRegisterSlice`: the issuing state machine's choice of
        address and length (often arithmetic on its registers) does not reach the engine's
        address and length registers and their tests in the same cycle. That costs a cycle
        per command; one command of each kind may wait in its slice.
    read_data : Out(stream.Signature(StructLayout{data, last}))
        ``length/W`` words; ``last`` on the final one. Through a
        :class:`~hdl.stream.ReadyRegisterSlice`: the reader's ready does not reach the
        mem2hwt FIFO and the request bookkeeping in the same cycle (no cycle of latency; a
        word offered while the reader is not ready is popped and held).
    write_cmd : In(stream.Signature(memif_command_layout))
    write_data : In(stream.Signature(W*8))
        ``length/W`` words to write.
    write_done : Out(1)
        One-cycle pulse when a write command has completed (see ``fence``), the cycle after
        the engine sees it.
    """

    def __init__(self, arch, *, fence=True, mem2hwt_depth=MEMIF_FIFO_DEPTH):
        self._arch = a = get_arch(arch)
        self._fence = bool(fence)
        self._credits = check_int("mem2hwt_depth", mem2hwt_depth, a.chunk_words)
        w = a.word_bits
        super().__init__({
            "memif_hwt2mem": Out(FifoWriteSignature(w)),
            "memif_mem2hwt": Out(FifoReadSignature(w)),
            "read_cmd": In(stream.Signature(memif_command_layout(a))),
            "read_data": Out(stream.Signature(data.StructLayout({"data": w, "last": 1}))),
            "write_cmd": In(stream.Signature(memif_command_layout(a))),
            "write_data": In(stream.Signature(w)),
            "write_done": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        a = self._arch
        w, wb, lb = a.word_bits, a.word_bytes, a.length_bits
        sh = wb.bit_length() - 1
        cw = a.chunk_words
        out, inp = self.memif_hwt2mem, self.memif_mem2hwt
        read_layout = self.read_data.payload.shape()
        m.submodules.read_slice = read_slice = ReadyRegisterSlice(read_layout)
        wiring.connect(m, read_slice.o, wiring.flipped(self.read_data))
        read_data = read_slice.i
        m.submodules.read_cmd_slice = read_cmd_slice = PayloadRegisterSlice(
            memif_command_layout(a))
        m.submodules.write_cmd_slice = write_cmd_slice = PayloadRegisterSlice(
            memif_command_layout(a))
        wiring.connect(m, wiring.flipped(self.read_cmd), read_cmd_slice.i)
        wiring.connect(m, wiring.flipped(self.write_cmd), write_cmd_slice.i)
        read_cmd, write_cmd = read_cmd_slice.o, write_cmd_slice.o

        def chunk_len(addr, remaining):
            # ``room`` is at most MEMIF_CHUNK: compare only the bits it can have (a full
            # word-wide comparison is a carry chain through the whole word)
            bits = MEMIF_CHUNK.bit_length()
            room = Signal(bits)
            m.d.comb += room.eq(MEMIF_CHUNK - addr[:bits - 1])
            less = (remaining[bits:] == 0) & (remaining[:bits] < room)
            return Mux(less, remaining, room)

        # ``write_done`` is registered: the thread's next step waits on it, and a zero-length
        # command would otherwise answer in the cycle it is given
        done_now = Signal()
        m.d.sync += self.write_done.eq(done_now)

        # ---- credits: words requested but not yet popped from mem2hwt ----
        outstanding = Signal(range(self._credits + 1))
        add = Signal(range(self._credits + 1))
        pop = Signal()
        # a pop is known late (the FIFO's level, the reader's ready): both successors are
        # computed beforehand and the pop only chooses between them
        after = kept(m, outstanding + add, "outstanding_after")
        after_pop = kept(m, outstanding + add - 1, "outstanding_after_pop")
        m.d.sync += outstanding.eq(Mux(pop, after_pop, after))

        # per read request: is its data for the user (0) or a fence word (1), and how many;
        # its head comes from flip-flops (the data routing below decides on it in the cycle a
        # word is taken), the extra cycle is hidden behind the memory's latency
        m.submodules.kinds = kinds = SyncFIFOBuffered(width=1 + 8, depth=8)

        # ---- hwt2mem owner: read issuer (0) or write issuer (1) ----
        r_words = [Signal(w, name="r_cmd"), Signal(w, name="r_addr")]
        w_cmd = Signal(w)
        w_addr = Signal(w)

        # ---- read issuer ----
        r_addr = Signal(w)
        r_rem = Signal(w)
        r_total = Signal(w)      # words of the user read not yet delivered
        # the next chunk's length is registered (it is a subtraction and a comparison, and
        # the sequencer's choice depends on it): valid one cycle after the address and the
        # remaining length change, which costs a cycle only after a new command
        r_len = Signal(w)
        r_len_valid = Signal()
        # and in words, in the credit counter's width: a chunk is at most MEMIF_CHUNK bytes,
        # so the credit check is not a word-wide addition in front of the sequencer
        r_len_words = Signal(range(self._credits + 1))
        next_len = Signal(w)
        m.d.comb += next_len.eq(chunk_len(r_addr, r_rem))
        # and r_rem != 0 and "the next chunk is the last" in flip-flops (as for writes below)
        r_more = Signal()
        r_last = Signal()
        m.d.sync += [r_len.eq(next_len), r_len_words.eq(next_len >> sh),
                     r_last.eq(next_len == r_rem), r_len_valid.eq(1)]
        r_want = Signal()
        fence_want = Signal()
        fence_addr = Signal(w)
        m.d.comb += r_want.eq(r_more & r_len_valid)

        # command addresses and lengths with their low bits ignored (W-aligned)
        r_cmd_addr, r_cmd_len, w_cmd_addr, w_cmd_len = (Signal(w) for _ in range(4))
        m.d.comb += [
            r_cmd_addr.eq(read_cmd.payload.addr >> sh << sh),
            r_cmd_len.eq(read_cmd.payload.length >> sh << sh),
            w_cmd_addr.eq(write_cmd.payload.addr >> sh << sh),
            w_cmd_len.eq(write_cmd.payload.length >> sh << sh),
        ]
        with m.If((r_total == 0) & ~r_more):
            m.d.comb += read_cmd.ready.eq(1)
            with m.If(read_cmd.valid):
                m.d.sync += [r_addr.eq(r_cmd_addr), r_rem.eq(r_cmd_len),
                             r_more.eq(r_cmd_len != 0),
                             r_total.eq(r_cmd_len >> sh), r_len_valid.eq(0)]

        # ---- write buffer and issuer ----
        m.submodules.wbuf = wbuf = SyncFIFO(width=w, depth=2 * cw)
        # words the user still has to supply for the command ("none" from a flip-flop: the
        # data path's ready does not wait for a word-wide zero test)
        w_rem_in = Countdown(w, "w_in")
        w_open = ~w_rem_in.none
        w_addr_cur = Signal(w)
        w_rem = Signal(w)        # bytes not yet issued
        # w_rem != 0 and "the next chunk is the last" from flip-flops: the sequencer's
        # priority between a write and a read does not wait for word-wide comparisons
        w_more = Signal()
        w_last = Signal()
        w_len = Signal(w)
        w_len_words = Signal(range(cw + 1))
        w_len_valid = Signal()
        w_next_len = Signal(w)
        m.d.comb += w_next_len.eq(chunk_len(w_addr_cur, w_rem))
        m.d.sync += [w_len.eq(w_next_len), w_len_words.eq(w_next_len >> sh),
                     w_last.eq(w_next_len == w_rem), w_len_valid.eq(1)]
        # "the next chunk is buffered", "a fence read may go", "the next read chunk may go",
        # from flip-flops (set below): the sequencer's priority does not wait for the
        # buffer's level and the credits to be compared
        w_ready, f_ok, r_ok = Signal(), Signal(), Signal()
        w_busy = Signal()
        with m.If(~w_busy):
            m.d.comb += write_cmd.ready.eq(1)
            with m.If(write_cmd.valid):
                with m.If(w_cmd_len != 0):
                    m.d.sync += [w_busy.eq(1), w_addr_cur.eq(w_cmd_addr), w_rem.eq(w_cmd_len),
                                 w_more.eq(1),
                                 *w_rem_in.load(w_cmd_len >> sh),
                                 w_len_valid.eq(0)]
                with m.Else():
                    m.d.comb += done_now.eq(1)
        m.d.comb += [wbuf.w_data.eq(self.write_data.payload),
                     wbuf.w_en.eq(self.write_data.valid & w_open),
                     self.write_data.ready.eq(wbuf.w_rdy & w_open)]
        with m.If(self.write_data.valid & self.write_data.ready):
            m.d.sync += w_rem_in.step()

        # ---- the request sequencer (owns hwt2mem) ----
        seq_words = Signal(range(cw + 1))    # data words left of the current write chunk
        with m.FSM() as seq:
            with m.State("IDLE"):
                with m.If(w_ready):
                    m.d.sync += [w_cmd.eq((MemifOp.WRITE << lb) | w_len), w_addr.eq(w_addr_cur),
                                 seq_words.eq(w_len_words),
                                 w_addr_cur.eq(w_addr_cur + w_len), w_rem.eq(w_rem - w_len),
                                 w_more.eq(~w_last),
                                 w_len_valid.eq(0)]
                    if self._fence:
                        with m.If(w_last):
                            m.d.sync += [fence_want.eq(1), fence_addr.eq(w_addr_cur)]
                    m.next = "W_CMD"
                with m.Elif(f_ok):
                    m.d.comb += [add.eq(1), kinds.w_en.eq(1), kinds.w_data.eq(1 | (1 << 1))]
                    m.d.sync += [r_words[0].eq((MemifOp.READ << lb) | wb),
                                 r_words[1].eq(fence_addr), fence_want.eq(0)]
                    m.next = "R_CMD"
                with m.Elif(r_ok):
                    m.d.comb += [add.eq(r_len_words), kinds.w_en.eq(1),
                                 kinds.w_data.eq(0 | (r_len_words << 1))]
                    m.d.sync += [r_words[0].eq((MemifOp.READ << lb) | r_len),
                                 r_words[1].eq(r_addr),
                                 r_addr.eq(r_addr + r_len), r_rem.eq(r_rem - r_len),
                                 r_more.eq(~r_last),
                                 r_len_valid.eq(0)]
                    m.next = "R_CMD"
            with m.State("R_CMD"):
                m.d.comb += [out.we.eq(1), out.data.eq(r_words[0])]
                with m.If(~out.full):
                    m.next = "R_ADDR"
            with m.State("R_ADDR"):
                m.d.comb += [out.we.eq(1), out.data.eq(r_words[1])]
                with m.If(~out.full):
                    m.next = "IDLE"
            with m.State("W_CMD"):
                m.d.comb += [out.we.eq(1), out.data.eq(w_cmd)]
                with m.If(~out.full):
                    m.next = "W_ADDR"
            with m.State("W_ADDR"):
                m.d.comb += [out.we.eq(1), out.data.eq(w_addr)]
                with m.If(~out.full):
                    m.next = "W_DATA"
            with m.State("W_DATA"):
                m.d.comb += [out.we.eq(wbuf.r_rdy), out.data.eq(wbuf.r_data),
                             wbuf.r_en.eq(~out.full)]
                with m.If(wbuf.r_rdy & ~out.full):
                    m.d.sync += seq_words.eq(seq_words - 1)
                    with m.If(seq_words == 1):
                        if not self._fence:
                            with m.If(~w_more):
                                m.d.comb += done_now.eq(1)
                                m.d.sync += w_busy.eq(0)
                        m.next = "IDLE"

        # The sequencer's three conditions are flip-flops, computed a cycle ahead: between
        # two requests, the words buffered beyond the chunk being sent (``seq_words``, 0
        # outside W_*) only grow, and so do the free credits and the room in ``kinds``; the
        # next chunk's length changes only when a request issues or a command loads. So a
        # condition can be a cycle late but never early, as long as the cycle in which a
        # request issues clears them all (the sequencer then spends at least two cycles in
        # R_*/W_* states, in which they are computed again). Early would be wrong: a write
        # chunk holding hwt2mem for words not yet buffered deadlocks a streaming copy whose
        # read waits behind it, and a read without credits overflows mem2hwt. The write
        # condition is computed during the last data word of a chunk, so the chunks of a
        # long write follow without a gap.
        issue = seq.ongoing("IDLE") & (w_ready | f_ok | r_ok)
        m.d.sync += [
            w_ready.eq(w_more & w_len_valid & ~issue &
                       (wbuf.r_level >= seq_words + w_len_words)),
            f_ok.eq(fence_want & kinds.w_rdy & (outstanding != self._credits) & ~issue),
            r_ok.eq(r_want & kinds.w_rdy & (outstanding + r_len_words <= self._credits) &
                    ~issue),
        ]

        # ---- read data routing ----
        kind_fence = kinds.r_data[0]
        kind_words = kinds.r_data[1:]
        got = Signal(8)
        with m.If(kinds.r_rdy):
            with m.If(kind_fence):
                m.d.comb += [inp.re.eq(1), pop.eq(~inp.empty)]
                with m.If(~inp.empty):
                    m.d.comb += [kinds.r_en.eq(1), done_now.eq(1)]
                    m.d.sync += w_busy.eq(0)
            with m.Else():
                m.d.comb += [
                    read_data.valid.eq(~inp.empty),
                    read_data.payload.data.eq(inp.data),
                    read_data.payload.last.eq(r_total == 1),
                    inp.re.eq(read_data.ready),
                    pop.eq(~inp.empty & read_data.ready),
                ]
                with m.If(~inp.empty & read_data.ready):
                    m.d.sync += [got.eq(got + 1), r_total.eq(r_total - 1)]
                    with m.If(got + 1 == kind_words):
                        m.d.sync += got.eq(0)
                        m.d.comb += kinds.r_en.eq(1)
        return m


class MemCalls:
    """FSM helpers for memory access through a :class:`MemifEngine` (the MEM_READ/MEM_WRITE
    of ReconOS' HLS library). Use each inside ``with m.State(...)`` only; the FSM moves to
    ``then`` when the access is complete. Addresses and lengths are W-aligned bytes.

    For streaming access, drive :attr:`engine`'s ``read_cmd``/``read_data`` and
    ``write_cmd``/``write_data``/``write_done`` directly.
    """

    def __init__(self, m, engine):
        self._m = m
        self.engine = engine
        self._w = engine._arch.word_bits
        self._wb = engine._arch.word_bytes

    def _issue(self, cmd, addr, length, sent, *also):
        """Offer one command on ``cmd`` until it is taken; then set ``sent`` (and ``also``)."""
        m = self._m
        with m.If(~sent):
            m.d.comb += [cmd.valid.eq(1), cmd.payload.addr.eq(addr),
                         cmd.payload.length.eq(length)]
            with m.If(cmd.ready):
                m.d.sync += [sent.eq(1), *also]

    def read_words(self, addr, targets, *, then):
        """Read ``len(targets)`` words from ``addr`` into the signals ``targets``."""
        m, e = self._m, self.engine
        sent = Signal(name="rd_sent")
        k = Signal(range(len(targets) + 1), name="rd_k")
        self._issue(e.read_cmd, addr, len(targets) * self._wb, sent, k.eq(0))
        with m.If(sent):
            m.d.comb += e.read_data.ready.eq(1)
            with m.If(e.read_data.valid):
                for i, t in enumerate(targets):
                    with m.If(k == i):
                        m.d.sync += t.eq(e.read_data.payload.data)
                m.d.sync += k.eq(k + 1)
                with m.If(e.read_data.payload.last):
                    m.d.sync += sent.eq(0)
                    m.next = then

    def read_word(self, addr, into, *, then):
        self.read_words(addr, [into], then=then)

    def write_words(self, addr, values, *, then):
        """Write the values (ints or Amaranth values) to consecutive words from ``addr``."""
        m, e = self._m, self.engine
        sent = Signal(name="wr_sent")
        k = Signal(range(len(values) + 1), name="wr_k")
        self._issue(e.write_cmd, addr, len(values) * self._wb, sent, k.eq(0))
        with m.If(sent):
            m.d.comb += e.write_data.valid.eq(k != len(values))
            for i, v in enumerate(values):
                with m.If(k == i):
                    m.d.comb += e.write_data.payload.eq(v)
            with m.If(e.write_data.valid & e.write_data.ready):
                m.d.sync += k.eq(k + 1)
            with m.If(e.write_done):
                m.d.sync += sent.eq(0)
                m.next = then

    def write_word(self, addr, value, *, then):
        self.write_words(addr, [value], then=then)

    def copy(self, src, dst, length, *, then):
        """Copy ``length`` bytes (a multiple of W) from ``src`` to ``dst`` at full rate: the
        read and the write run at the same time, the data streams through the thread."""
        m, e = self._m, self.engine
        r_sent = Signal(name="cp_r_sent")
        w_sent = Signal(name="cp_w_sent")
        self._issue(e.read_cmd, src, length, r_sent)
        self._issue(e.write_cmd, dst, length, w_sent)
        m.d.comb += [e.write_data.valid.eq(e.read_data.valid),
                     e.write_data.payload.eq(e.read_data.payload.data),
                     e.read_data.ready.eq(e.write_data.ready)]
        # (a zero-length write is done in the cycle its command is taken)
        with m.If(e.write_done):
            m.d.sync += [r_sent.eq(0), w_sent.eq(0)]
            m.next = then


    @staticmethod
    def _elements(length, stream):
        """Elements of ``stream``'s ``tdata`` width in ``length`` bytes."""
        return length >> ((len(stream.tdata) // 8).bit_length() - 1)

    def _unpack(self, sink, count, tag):
        """Drive ``sink`` (a stream of ``tvalid``/``tready``/``tdata``/``tlast`` with
        elements of W/k bits) from the read data, low element of a word first; elements
        past ``count`` (sampled when the read starts) are dropped. Returns the statements
        that start it."""
        m, e = self._m, self.engine
        ew = len(sink.tdata)
        per = self._w // ew
        lane = Signal(range(max(2, per)), name=f"{tag}_lane")
        # counted down from ``count``: it is arithmetic on the caller's registers, and a
        # comparison with it would be a carry chain in the sink's handshake
        left = Countdown(32, tag)
        data = e.read_data.payload.data
        last_lane = lane == per - 1
        m.d.comb += [
            sink.tdata.eq(data.word_select(lane[:max(1, (per - 1).bit_length())], ew)
                          if per > 1 else data),
            sink.tlast.eq(left.last),
            sink.tvalid.eq(e.read_data.valid & ~left.none),
            # a word moves on after its last element, or at once past the count-th element
            e.read_data.ready.eq(Mux(left.none, 1, sink.tready & last_lane)),
        ]
        with m.If(sink.tvalid & sink.tready):
            m.d.sync += [*left.step(), lane.eq(Mux(last_lane, 0, lane + 1))]
        return [*left.load(count), lane.eq(0)]

    def _pack(self, source, tag, count=None):
        """Drive the write data from ``source`` (elements of W/k bits, low element first),
        taking at most ``count`` elements (sampled when the write starts). Returns the
        statements that start it."""
        m, e = self._m, self.engine
        ew = len(source.tdata)
        per = self._w // ew
        restart = []
        full = None
        if count is not None:
            # counted down, as in _unpack: no comparison with ``count`` in the source's ready
            left = Countdown(32, tag)
            restart += left.load(count)
            full = left.none
            with m.If(source.tvalid & source.tready):
                m.d.sync += left.step()
        if per == 1:
            m.d.comb += [e.write_data.valid.eq(source.tvalid),
                         e.write_data.payload.eq(source.tdata),
                         source.tready.eq(e.write_data.ready)]
            if full is not None:
                with m.If(full):
                    m.d.comb += [e.write_data.valid.eq(0), source.tready.eq(0)]
            return restart
        lane = Signal(range(per), name=f"{tag}_lane")
        low = [Signal(ew, name=f"{tag}_low{k}") for k in range(per - 1)]
        with m.If(lane == per - 1):
            m.d.comb += [e.write_data.valid.eq(source.tvalid),
                         e.write_data.payload.eq(Cat(*low, source.tdata)),
                         source.tready.eq(e.write_data.ready)]
        with m.Else():
            m.d.comb += source.tready.eq(1)
            with m.If(source.tvalid):
                for k in range(per - 1):
                    with m.If(lane == k):
                        m.d.sync += low[k].eq(source.tdata)
        if full is not None:
            with m.If(full):
                m.d.comb += [e.write_data.valid.eq(0), source.tready.eq(0)]
        with m.If(source.tvalid & source.tready):
            m.d.sync += lane.eq(Mux(lane == per - 1, 0, lane + 1))
        return restart + [lane.eq(0)]

    def read_stream(self, addr, length, sink, *, count, then):
        """Read ``length`` bytes from ``addr`` and deliver the first ``count`` elements to
        ``sink`` (an AXI-Stream-like interface with elements of W/k bits, ``tlast`` on the
        ``count``-th); the rest of the last word is dropped."""
        m, e = self._m, self.engine
        sent = Signal(name="rs_sent")
        restart = self._unpack(sink, count, "rs")
        self._issue(e.read_cmd, addr, length, sent, *restart)
        with m.If(~sent):
            m.d.comb += [sink.tvalid.eq(0), e.read_data.ready.eq(0)]
        with m.If(sent & e.read_data.valid & e.read_data.ready & e.read_data.payload.last):
            m.d.sync += sent.eq(0)
            m.next = then

    def write_stream(self, addr, length, source, *, then):
        """Write ``length`` bytes (a multiple of W) to ``addr`` from the elements of
        ``source`` (W/k bits each, low element first; no more are taken than fit);
        ``then`` once they are in memory."""
        m, e = self._m, self.engine
        sent = Signal(name="ws_sent")
        restart = self._pack(source, "ws", count=self._elements(length, source))
        self._issue(e.write_cmd, addr, length, sent, *restart)
        with m.If(~sent):
            m.d.comb += [source.tready.eq(0), e.write_data.valid.eq(0)]
        with m.If(e.write_done):
            m.d.sync += sent.eq(0)
            m.next = then

    def transform(self, src, dst, length, sink, source, *, then, out_length=None):
        """Stream ``length`` bytes (a multiple of W) from ``src`` into ``sink`` and, at the
        same time, ``out_length`` bytes (a multiple of W; default ``length``) from ``source``
        to ``dst``: a streaming kernel between the two sees one element per cycle. ``then``
        once the written data is in memory."""
        m, e = self._m, self.engine
        out_length = length if out_length is None else out_length
        r_sent, w_sent = Signal(name="tf_r_sent"), Signal(name="tf_w_sent")
        restart = self._unpack(sink, self._elements(length, sink), "tf")
        self._issue(e.read_cmd, src, length, r_sent, *restart)
        self._issue(e.write_cmd, dst, out_length, w_sent, *self._pack(source, "tf"))
        with m.If(~r_sent):
            m.d.comb += [sink.tvalid.eq(0), e.read_data.ready.eq(0)]
        with m.If(~w_sent):
            m.d.comb += [source.tready.eq(0), e.write_data.valid.eq(0)]
        with m.If(e.write_done):
            m.d.sync += [r_sent.eq(0), w_sent.eq(0)]
            m.next = then

    def transform_bytes_states(self, name, src, dst, size, sink, source, *, then):
        """Emit the states ``name`` and ``name_TAIL_*``: stream ``size`` bytes (any count;
        ``src`` and ``dst`` W-aligned) from ``src`` through a kernel into ``dst``.

        ``sink`` (``tdata`` of W bytes, ``tkeep``, ``tlast``) gets the ``ceil(size / W)`` words
        from ``src``, the last one with ``tlast`` and ``tkeep`` marking its ``size mod W``
        bytes (all when W divides ``size``). From ``source`` (same shape) the first
        ``floor(size / W)`` beats are written to ``dst`` at full rate; the beat after them,
        when ``size`` is not a multiple of W, is merged into the destination word by
        read-modify-write, so no byte past ``dst + size`` changes. Call at FSM level."""
        m, e = self._m, self.engine
        w, wb = self._w, self._wb
        sh = wb.bit_length() - 1
        tag = name.lower()
        main = Signal(w, name=f"{tag}_main")
        tail = Signal(range(wb), name=f"{tag}_tail")
        words_in = Signal(w, name=f"{tag}_words_in")
        # words still to read and to write, with their flags in flip-flops: the stream
        # handshakes do not wait for word-wide comparisons
        read_left = Countdown(w, f"{tag}_read")
        write_left = Countdown(w, f"{tag}_write")
        r_sent, w_sent = Signal(name=f"{tag}_r_sent"), Signal(name=f"{tag}_w_sent")
        written, tail_in = Signal(name=f"{tag}_written"), Signal(name=f"{tag}_tail_in")
        t_word = Signal(w, name=f"{tag}_t_word")
        d_word = Signal(w, name=f"{tag}_d_word")
        merged = Signal(w, name=f"{tag}_merged")
        m.d.comb += [main.eq(size >> sh << sh), tail.eq(size[:sh]),
                     words_in.eq((size + wb - 1) >> sh)]
        for b in range(wb):
            keep = d_word.word_select(b, 8)
            m.d.comb += merged.word_select(b, 8).eq(
                Mux(tail > b, t_word.word_select(b, 8), keep) if b < wb - 1 else keep)
        with m.State(name):
            self._issue(e.read_cmd, src, words_in << sh, r_sent, *read_left.load(words_in))
            self._issue(e.write_cmd, dst, main, w_sent, *write_left.load(main >> sh),
                        written.eq(0), tail_in.eq(tail == 0))
            final = read_left.last
            m.d.comb += [
                sink.tdata.eq(e.read_data.payload.data),
                sink.tlast.eq(final),
                # a partial last word keeps its ``tail`` (< W) low bytes: never the top one
                sink.tkeep.eq(Mux(final & (tail != 0),
                                  Cat(*(tail > b for b in range(wb - 1)), Const(0, 1)),
                                  (1 << wb) - 1)),
                sink.tvalid.eq(r_sent & e.read_data.valid),
                e.read_data.ready.eq(r_sent & sink.tready),
            ]
            with m.If(sink.tvalid & sink.tready):
                m.d.sync += read_left.step()
            to_memory = w_sent & ~write_left.none
            m.d.comb += [
                e.write_data.valid.eq(to_memory & source.tvalid),
                e.write_data.payload.eq(source.tdata),
                source.tready.eq(Mux(to_memory, e.write_data.ready, w_sent & ~tail_in)),
            ]
            with m.If(e.write_data.valid & e.write_data.ready):
                m.d.sync += write_left.step()
            with m.If(w_sent & write_left.none & ~tail_in & source.tvalid):
                m.d.sync += [t_word.eq(source.tdata), tail_in.eq(1)]
            with m.If(e.write_done):
                m.d.sync += written.eq(1)
            # both flags are cleared on the way out: the next run starts from its own
            with m.If(w_sent & written & tail_in):
                m.d.sync += [r_sent.eq(0), w_sent.eq(0), written.eq(0), tail_in.eq(0)]
                m.next = f"{name}_TAIL"
        with m.State(f"{name}_TAIL"):
            with m.If(tail == 0):
                m.next = then
            with m.Else():
                m.next = f"{name}_TAIL_DST"
        with m.State(f"{name}_TAIL_DST"):
            self.read_word(dst + main, d_word, then=f"{name}_TAIL_WRITE")
        with m.State(f"{name}_TAIL_WRITE"):
            self.write_word(dst + main, merged, then=then)

    def copy_bytes_states(self, name, src, dst, size, *, then):
        """Emit the states ``name`` and ``name_TAIL_*`` of a copy of ``size`` bytes (any
        count; ``src`` and ``dst`` W-aligned): whole words stream at full rate, a tail of
        fewer than W bytes is merged into the destination word by read-modify-write, so no
        byte past ``dst + size`` changes. Call at FSM level (not inside a state)."""
        m = self._m
        w, wb = self._w, self._wb
        sh = wb.bit_length() - 1
        main = Signal(w, name=f"{name.lower()}_main")
        tail = Signal(range(wb), name=f"{name.lower()}_tail")
        s_word = Signal(w, name=f"{name.lower()}_s_word")
        d_word = Signal(w, name=f"{name.lower()}_d_word")
        merged = Signal(w, name=f"{name.lower()}_merged")
        m.d.comb += [main.eq(size >> sh << sh), tail.eq(size[:sh])]
        for b in range(wb):
            # byte b comes from the source when b < tail (tail < W, so never the top byte)
            keep = d_word.word_select(b, 8)
            m.d.comb += merged.word_select(b, 8).eq(
                Mux(tail > b, s_word.word_select(b, 8), keep) if b < wb - 1 else keep)
        with m.State(name):
            self.copy(src, dst, main, then=f"{name}_TAIL")
        with m.State(f"{name}_TAIL"):
            with m.If(tail == 0):
                m.next = then
            with m.Else():
                m.next = f"{name}_TAIL_SRC"
        with m.State(f"{name}_TAIL_SRC"):
            self.read_word(src + main, s_word, then=f"{name}_TAIL_DST")
        with m.State(f"{name}_TAIL_DST"):
            self.read_word(dst + main, d_word, then=f"{name}_TAIL_WRITE")
        with m.State(f"{name}_TAIL_WRITE"):
            self.write_word(dst + main, merged, then=then)


class HardwareThread(wiring.Component):
    """Base class of a hardware thread: a component with the slot ports of
    :func:`ThreadSignature` plus ``members``.

    Parameters
    ----------
    arch : str
        ``"r32"`` or ``"r64"``.
    members : dict
        Additional members (for example hardware-topic streams).
    """

    def __init__(self, arch, members=None):
        self.arch = get_arch(arch)
        super().__init__({**ThreadSignature(self.arch).members, **(members or {})})

    def os_and_memory(self, m, *, fence=True):
        """Add an :class:`OsifEngine` and a :class:`MemifEngine` to ``m``, connected to the slot
        ports; return ``(OsifCalls, MemCalls)``."""
        m.submodules.osif = osif = OsifEngine(self.arch)
        m.submodules.memif = mem = MemifEngine(self.arch, fence=fence)
        for name in ("osif_sw2hw", "osif_hw2sw"):
            wiring.connect(m, wiring.flipped(getattr(self, name)), getattr(osif, name))
        m.d.comb += osif.hwt_signal.eq(self.hwt_signal)
        for name in ("memif_hwt2mem", "memif_mem2hwt"):
            wiring.connect(m, wiring.flipped(getattr(self, name)), getattr(mem, name))
        return OsifCalls(m, osif), MemCalls(m, mem)
