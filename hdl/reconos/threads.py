"""Example hardware threads: the ReconROS ping-pong nodes and an OS-call sequencer used by the
compatibility tests. They are written with the thread API only (no word counting)."""

from amaranth.hdl import Module, Mux, Signal

from .hwt import HardwareThread
from .protocol import CALLS

__all__ = ["EchoThread", "CopyThread", "CallSequenceThread", "MemoryTestThread", "REPORT_MBOX"]


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
        w, wb = self.arch.word_bits, self.arch.word_bytes
        sh = wb.bit_length() - 1
        in_ptr, src, size, dst = (Signal(w, name=n) for n in ("in_ptr", "src", "size", "dst"))
        main = Signal(w)
        tail = Signal(range(wb))
        s_word, d_word = Signal(w), Signal(w)
        m.d.comb += [main.eq(size >> sh << sh), tail.eq(size[:sh])]
        merged = Signal(w)
        for b in range(wb):
            # byte b comes from the source when b < tail (tail < W, so never the top byte)
            src_byte = s_word.word_select(b, 8) if b < wb - 1 else d_word.word_select(b, 8)
            m.d.comb += merged.word_select(b, 8).eq(
                Mux(tail > b, src_byte, d_word.word_select(b, 8)) if b < wb - 1 else src_byte)

        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="TAKE")
            with m.State("TAKE"):
                os.ros_take(h_sub, h_in, ptr=in_ptr, then="HEADER")
            with m.State("HEADER"):
                mem.read_words(in_ptr + self.data_offset, [src, size], then="SET_SIZE")
            with m.State("SET_SIZE"):
                os.ros_message_set_size(h_out, self.data_offset, 1, size, ptr=dst, then="COPY")
            with m.State("COPY"):
                mem.copy(src, dst, main, then="TAIL")
            with m.State("TAIL"):
                with m.If(tail == 0):
                    m.next = "PUBLISH"
                with m.Else():
                    m.next = "TAIL_SRC"
            with m.State("TAIL_SRC"):
                mem.read_word(src + main, s_word, then="TAIL_DST")
            with m.State("TAIL_DST"):
                mem.read_word(dst + main, d_word, then="TAIL_WRITE")
            with m.State("TAIL_WRITE"):
                mem.write_word(dst + main, merged, then="PUBLISH")
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
