"""Example hardware threads: the ReconROS ping-pong nodes and an OS-call sequencer used by the
compatibility tests. They are written with the thread API only (no word counting)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal

from .hwt import HardwareThread
from .protocol import CALLS

__all__ = ["EchoThread", "CopyThread", "CallSequenceThread", "REPORT_MBOX"]


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
            m.d.comb += merged.word_select(b, 8).eq(
                Mux(b < tail, s_word.word_select(b, 8), d_word.word_select(b, 8)))

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
        ``ros_take_interruptable_check``) and their constant arguments.
    """

    def __init__(self, arch, *, program):
        self.program = [(name, tuple(args)) for name, args in program]
        for name, args in self.program:
            if name in ("ros_take_interruptable_check",):
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
                os.mbox_put(REPORT_MBOX, regs[0], then="CALL0")
            for i, (name, args) in enumerate(self.program):
                nxt = f"CALL{i + 1}" if i + 1 < len(self.program) else "EXIT"
                with m.State(f"CALL{i}"):
                    if name in ("ros_take_interruptable_check", "ros_take_interruptable_cancel"):
                        getattr(os, name)(ptr=regs[0], got=got, then=f"REPORT{i}_0")
                        replies = [regs[0], got]
                    else:
                        c = CALLS[name]
                        getattr(os, name)(*args, then=f"REPORT{i}_0" if c.replies else nxt,
                                          **{r: regs[k] for k, r in enumerate(c.replies)})
                        replies = regs[:len(c.replies)]
                for k, reg in enumerate(replies):
                    after = f"REPORT{i}_{k + 1}" if k + 1 < len(replies) else nxt
                    with m.State(f"REPORT{i}_{k}"):
                        os.mbox_put(REPORT_MBOX, reg, then=after)
            with m.State("EXIT"):
                os.thread_exit()
        return m
