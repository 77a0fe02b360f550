"""rt_invert: take each sensor_msgs/Image from /image_in, invert its pixel bytes in place
(255 - value) through a byte kernel, publish the message on /image_inverted. A hardware
thread written as its own FSM (docs/howto.md, "A thread")."""

from amaranth import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from hdl.reconos import HardwareThread
from hdl.stream import AXIStreamSignature


class InvertBytes(wiring.Component):
    """255 - value of every byte, one register stage, one word per cycle.

    Members
    -------
    i : In(AXIStreamSignature(width))
        Words of a message's bytes; ``tkeep`` marks the bytes of the last one.
    o : Out(AXIStreamSignature(width))
        The same words inverted, ``tkeep`` and ``tlast`` as they came.
    """

    def __init__(self, width):
        super().__init__({"i": In(AXIStreamSignature(width)),
                          "o": Out(AXIStreamSignature(width))})

    def elaborate(self, platform):
        m = Module()
        i, o = self.i, self.o
        m.d.comb += i.tready.eq(o.tready | ~o.tvalid)       # the register is free
        with m.If(i.tready):
            m.d.sync += [o.tvalid.eq(i.tvalid), o.tdata.eq(~i.tdata), o.tkeep.eq(i.tkeep),
                         o.tlast.eq(i.tlast)]
        return m


class InvertThread(HardwareThread):
    """Take an image, invert its ``data`` in memory, publish the same message.

    Parameters
    ----------
    arch : str
        ``"r32"`` or ``"r64"``.
    h_sub, h_pub, h_msg : int
        Thread-local handles of the subscriber, the publisher and the message object.
    data_offset : int
        Byte offset of ``data`` (a ``uint8[]``: pointer, size, capacity) in the C struct.
    """

    def __init__(self, arch, *, h_sub, h_pub, h_msg, data_offset):
        self.handles = (h_sub, h_pub, h_msg)
        self.data_offset = data_offset
        super().__init__(arch)

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        h_sub, h_pub, h_msg = self.handles
        w = self.arch.word_bits
        m.submodules.kernel = kernel = InvertBytes(w)
        ptr, data, size = (Signal(w, name=n) for n in ("ptr", "data", "size"))
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="TAKE")
            with m.State("TAKE"):           # wait for a message on /image_in: its address
                os.ros_take(h_sub, h_msg, ptr=ptr, then="DATA")
            with m.State("DATA"):           # the data sequence: its bytes' address and count
                mem.read_words(ptr + self.data_offset, [data, size], then="EMPTY")
            with m.State("EMPTY"):          # an image without bytes goes out as it came
                m.next = "PUBLISH"
                with m.If(size != 0):
                    m.next = "INVERT"
            # memory -> kernel -> the same memory, the last word merged byte by byte
            mem.transform_bytes_states("INVERT", data, data, size, kernel.i, kernel.o,
                                       then="PUBLISH")
            with m.State("PUBLISH"):
                os.ros_publish(h_pub, h_msg, then="TAKE")
        return m


def build(ctx):
    return InvertThread(ctx.arch, h_sub=ctx.handle("sub"), h_pub=ctx.handle("pub"),
                        h_msg=ctx.handle("image_msg"),
                        data_offset=ctx.offsets("sensor_msgs/msg/Image")["data"])
