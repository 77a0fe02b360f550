"""ReconOS hardware threads around image kernels, with their topics through memory and the
software broker (ReconROS' way; docs/av_chain.md): the nodes of the lane-following chain as
ReconROS builds them.

An :class:`ImageNodeThread` takes ``bgr8`` ``sensor_msgs/Image`` messages, streams each
frame's pixels from memory through its kernel (MEMIF, at most one W-byte word per cycle) and
publishes the kernel's answer: an image, or one 64-bit word per frame in a message whose
first member holds it (``std_msgs/UInt64``). :class:`LaneControlThread` is the one node that
takes words, on three subscriptions.
"""

from amaranth.hdl import Cat, Const, Module, Signal
from amaranth.lib import wiring

from ..params import ParameterError, check_int
from ..stream import RegisterSlice, StreamRepacker
from .hwt import HardwareThread
from .threads import _image_offsets

__all__ = ["ImageNodeThread", "LaneControlThread", "ENCODING_BGR8"]

#: the only encoding the nodes take, as the first four bytes of the string, little-endian
ENCODING_BGR8 = int.from_bytes(b"bgr8", "little")


def _image_fields(offsets, arch):
    """The Image members a node reads, checked (:func:`~hdl.reconos.threads._image_offsets`)
    with ``header``, whose stamp an image node copies."""
    if "header" not in offsets:
        raise ParameterError("image_offsets", offsets, "the offset of header")
    return {**_image_offsets(offsets, arch), "header": int(offsets["header"])}


def _words(fields, start, count, wb):
    """The ``count`` W-byte words from byte ``start`` with ``fields`` (name -> (offset, bytes,
    value)) in place: constants for the geometry a node writes."""
    words = [0] * count
    for at, size, value in fields.values():
        for k, byte in enumerate(int(value).to_bytes(size, "little")):
            pos = at + k - start
            words[pos // wb] |= byte << (8 * (pos % wb))
    return words


def _pulse_per_message_states(m, os, name, h_sub, h_msg, port, ptr, got, *, then):
    """States ``name``, ``name?`` and ``name_PULSE``: take every message waiting on the
    subscription ``h_sub`` without blocking (ROS_TRYTAKE into ``h_msg``), one valid beat on
    ``port`` (a ``stream.Signature``) for each, then go to ``then``."""
    with m.State(name):
        os.ros_trytake(h_sub, h_msg, ptr=ptr, ret=got, then=f"{name}?")
    with m.State(f"{name}?"):
        m.next = then
        with m.If(got == 0):
            m.next = f"{name}_PULSE"
    with m.State(f"{name}_PULSE"):
        m.d.comb += port.valid.eq(1)
        with m.If(port.ready):
            m.next = name


class ImageNodeThread(HardwareThread):
    """A node that takes ``bgr8`` images and publishes what its kernel makes of them.

    Loop: ROS_TAKE an image; with ``h_arm``, take every message waiting on that subscription
    without blocking, one ``arm`` pulse to the kernel each; read the image's geometry, the
    encoding string and the payload's pointer and size; a frame that is not ``bgr8`` of
    ``in_size`` pixels with ``step = 3 width`` and a payload of ``height step`` bytes is
    dropped (its frame number goes into the ``h_err`` mailbox if there is one, without
    blocking) and the next one taken; otherwise stream the payload through the kernel and

    * image output (``out_size``): write the kernel's frame into the output image's payload
      (sized once, with the geometry and encoding, when the thread starts), copy the input's
      ``header.stamp`` and ROS_PUBLISH;
    * word output: write the kernel's beat for the frame into the output message's first
      64 bits and ROS_PUBLISH it, unless the kernel's ``o`` has ``tuser`` and it is clear.

    Parameters
    ----------
    arch : str
    kernel : wiring.Component
        ``i``: :func:`~hdl.kernels.image.image_stream_signature` ``(3, P)``; ``o`` the same
        (image output) or 64-bit beats, exactly one per frame (word output); ``width`` and
        ``height`` inputs, when it has them, are driven with ``in_size``; ``arm`` with
        ``h_arm``.
    h_sub, h_pub, h_in, h_out : int
        Handles of the image subscription, the publisher, the input image and the output
        message.
    image_offsets : dict
        ``sensor_msgs/Image`` member offsets for the target ABI.
    in_size, out_size : (int, int)
        Width and height of the frames taken and (image output) made. Their payloads must be
        whole W-byte words.
    h_arm, h_arm_msg : int or None
        A subscription whose messages arm the kernel, and its message.
    h_err : int or None
        A mailbox for the numbers of the dropped frames.
    """

    def __init__(self, arch, kernel, *, h_sub, h_pub, h_in, h_out, image_offsets, in_size,
                 out_size=None, h_arm=None, h_arm_msg=None, h_err=None):
        super().__init__(arch)
        wb = self.arch.word_bytes
        self.fields = _image_fields(image_offsets, self.arch)
        members = kernel.signature.members
        pixel_bits = len(kernel.i.tdata)
        if pixel_bits % 24:
            raise ParameterError("kernel", kernel, "an i stream of whole bgr8 pixels")
        self.pixels_per_beat = pixel_bits // 24
        self.in_size = tuple(check_int(n, v, 1, 1 << 14)
                             for n, v in zip(("in width", "in height"), in_size))
        if (3 * self.in_size[0] * self.in_size[1]) % wb:
            raise ParameterError("in_size", in_size, f"a payload of whole {wb}-byte words")
        self.out_size = None
        if out_size is not None:
            self.out_size = tuple(check_int(n, v, 1, 1 << 14)
                                  for n, v in zip(("out width", "out height"), out_size))
            if (3 * self.out_size[0] * self.out_size[1]) % wb:
                raise ParameterError("out_size", out_size,
                                     f"a payload of whole {wb}-byte words")
            if len(kernel.o.tdata) != pixel_bits:
                raise ParameterError("kernel", kernel, "an o stream of the i stream's pixels")
        elif len(kernel.o.tdata) != 64:
            raise ParameterError("kernel", kernel, "an o stream of 64-bit beats (no out_size)")
        if (h_arm is None) != (h_arm_msg is None) or (h_arm is not None and
                                                       "arm" not in members):
            raise ParameterError("h_arm", h_arm, "given with h_arm_msg, for a kernel with arm")
        self.kernel = kernel
        self.handles = (h_sub, h_pub, h_in, h_out, h_arm, h_arm_msg, h_err)

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        m.submodules.kernel = kernel = self.kernel
        h_sub, h_pub, h_in, h_out, h_arm, h_arm_msg, h_err = self.handles
        a, f = self.arch, self.fields
        w, wb = a.word_bits, a.word_bytes
        P = self.pixels_per_beat
        in_w, in_h = self.in_size
        in_bytes = 3 * in_w * in_h
        members = kernel.signature.members
        if "width" in members:
            m.d.comb += [kernel.width.eq(in_w), kernel.height.eq(in_h)]

        # the members from height to the payload's size, read as one block of words
        start = f["height"] - f["height"] % wb
        block = [Signal(w, name=f"geometry{k}") for k in range((f["data"] + 2 * wb - start)
                                                               // wb)]
        whole = Cat(*block)

        def member(at, size):
            return whole[8 * (at - start):8 * (at - start + size)]
        height, width = member(f["height"], 4), member(f["width"], 4)
        step = member(f["step"], 4)
        enc_ptr, enc_size = member(f["encoding"], wb), member(f["encoding"] + wb, wb)
        src, size = member(f["data"], wb), member(f["data"] + wb, wb)
        encoding = Signal(w)
        img, out, dst, ptr = (Signal(w, name=n) for n in ("img", "out", "dst", "ptr"))
        got = Signal(w)
        frame = Signal(32)
        good = Signal()
        m.d.sync += good.eq((height == in_h) & (width == in_w) & (step == 3 * in_w) &
                            (size == in_bytes) & (enc_size == 4) &
                            (encoding[:32] == ENCODING_BGR8))

        m.submodules.to_pixels = to_pixels = StreamRepacker(wb, 3 * P)
        # register slices on both sides of the kernel (as the Sobel service thread has): a
        # kernel's ready reaches from its output to its input and enables its whole
        # pipeline, and the memory copy's control drives both repackers
        m.submodules.pixel_slice = pixel_slice = RegisterSlice(
            to_pixels.signature.members["m_axis"].signature)
        wiring.connect(m, to_pixels.m_axis, pixel_slice.s_axis)
        pixels = pixel_slice.m_axis
        first = Signal()
        m.d.comb += [to_pixels.s_axis.tkeep.eq((1 << wb) - 1),
                     kernel.i.tdata.eq(pixels.tdata),
                     kernel.i.tlast.eq(pixels.tlast),
                     kernel.i.tuser.eq(first),
                     kernel.i.tvalid.eq(pixels.tvalid),
                     pixels.tready.eq(kernel.i.tready)]
        with m.If(kernel.i.tvalid & kernel.i.tready):
            m.d.sync += first.eq(0)
        if self.out_size is not None:
            m.submodules.to_words = to_words = StreamRepacker(3 * P, wb)
            m.submodules.result_slice = result_slice = RegisterSlice(
                to_words.signature.members["s_axis"].signature.flip())
            wiring.connect(m, result_slice.m_axis, to_words.s_axis)
            results = result_slice.s_axis
            m.d.comb += [results.tdata.eq(kernel.o.tdata),
                         results.tkeep.eq((1 << (3 * P)) - 1),
                         results.tlast.eq(kernel.o.tlast),
                         results.tvalid.eq(kernel.o.tvalid),
                         kernel.o.tready.eq(results.tready)]
            out_w, out_h = self.out_size
            out_bytes = 3 * out_w * out_h
        result = Signal(64)
        publish = Signal()
        has_user = "tuser" in members["o"].signature.members

        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="OUT_ADDR")
            with m.State("OUT_ADDR"):
                os.memory_getobjaddr(h_out, ptr=out,
                                     then="ENCODING" if self.out_size else "TAKE")
            if self.out_size is not None:
                with m.State("ENCODING"):
                    os.ros_message_set_size(h_out, f["encoding"], 1, 4, ptr=ptr,
                                            then="ENCODING_READ")
                with m.State("ENCODING_READ"):
                    mem.read_word(ptr, encoding, then="ENCODING_WRITE")
                with m.State("ENCODING_WRITE"):
                    # read-modify-write: the string has 4 bytes, the word W
                    mem.write_word(ptr, Cat(Const(ENCODING_BGR8, 32), encoding[32:])
                                   if w > 32 else Const(ENCODING_BGR8, 32),
                                   then="GEOMETRY_OUT")
                # height and width, then is_bigendian and step, as constant words
                lay = {"height": (f["height"], 4, out_h), "width": (f["width"], 4, out_w)}
                first_words = _words(lay, start, (f["width"] + 4 - start + wb - 1) // wb, wb)
                low = f["is_bigendian"] - f["is_bigendian"] % wb
                lay = {"is_bigendian": (f["is_bigendian"], 1, 0),
                       "step": (f["step"], 4, 3 * out_w)}
                step_words = _words(lay, low, (f["step"] + 4 - low + wb - 1) // wb, wb)
                with m.State("GEOMETRY_OUT"):
                    mem.write_words(out + start, first_words, then="STEP_OUT")
                with m.State("STEP_OUT"):
                    mem.write_words(out + low, step_words, then="DATA_OUT")
                with m.State("DATA_OUT"):
                    os.ros_message_set_size(h_out, f["data"], 1, out_bytes, ptr=dst,
                                            then="TAKE")
            with m.State("TAKE"):
                os.ros_take(h_sub, h_in, ptr=img, then="GEOMETRY" if h_arm is None else "ARM")
            if h_arm is not None:
                # after the take: the events of the frames before this one are published
                _pulse_per_message_states(m, os, "ARM", h_arm, h_arm_msg, kernel.arm, ptr, got,
                                          then="GEOMETRY")
            with m.State("GEOMETRY"):
                mem.read_words(img + start, block, then="ENCODING?")
            with m.State("ENCODING?"):
                m.d.sync += encoding.eq(0)
                m.next = "CHECK"
                with m.If(enc_size == 4):
                    m.next = "ENCODING_IN"
            with m.State("ENCODING_IN"):
                mem.read_word(enc_ptr, encoding, then="CHECK")
            with m.State("CHECK"):
                m.next = "CHECKED"
            with m.State("CHECKED"):
                m.d.sync += frame.eq(frame + 1)
                with m.If(good):
                    m.d.sync += first.eq(1)
                    m.next = "STAMP" if self.out_size else "STREAM"
                with m.Else():
                    m.next = "DROPPED" if h_err is not None else "TAKE"
            if h_err is not None:
                with m.State("DROPPED"):
                    os.mbox_tryput(h_err, frame - 1, then="TAKE")
            if self.out_size is not None:
                with m.State("STAMP"):
                    mem.copy(img + f["header"], out + f["header"], 8 if wb == 4 else wb,
                             then="STREAM")
                with m.State("STREAM"):
                    mem.transform(src, dst, in_bytes, to_pixels.s_axis, to_words.m_axis,
                                  out_length=out_bytes, then="PUBLISH")
            else:
                with m.State("STREAM"):
                    mem.read_stream(src, in_bytes, to_pixels.s_axis, count=in_bytes // wb,
                                    then="RESULT")
                with m.State("RESULT"):
                    m.d.comb += kernel.o.tready.eq(1)
                    with m.If(kernel.o.tvalid):
                        m.d.sync += [result.eq(kernel.o.tdata),
                                     publish.eq(kernel.o.tuser if has_user else 1)]
                        m.next = "WRITE"
                with m.State("WRITE"):
                    with m.If(publish):
                        mem.write_words(out, [result.word_select(k, w) for k in range(64 // w)],
                                        then="PUBLISH")
                    with m.Else():
                        m.next = "TAKE"
            with m.State("PUBLISH"):
                os.ros_publish(h_pub, h_out, then="TAKE")
        return m


class LaneControlThread(HardwareThread):
    """The lane-control node: a :class:`~hdl.kernels.LaneControl` on three subscriptions.

    Loop: ROS_TAKE a lane result (blocking); take every stop event waiting (ROS_TRYTAKE, a
    ``stop`` pulse each), then every start event (``start`` pulses): the events of a frame
    are published before its lane result, whose path is longer; give the result to the
    kernel and publish its command. Events and results are ``std_msgs/UInt64`` (their first
    64 bits: the frame number, :data:`~hdl.kernels.lane.LANE_RESULT`,
    :data:`~hdl.kernels.lane.DRIVE_COMMAND`).

    Parameters
    ----------
    arch : str
    kernel : LaneControl
    h_lane, h_lane_msg, h_stop, h_stop_msg, h_start, h_start_msg : int
        The three subscriptions and their messages.
    h_pub, h_out : int
        The command's publisher and message.
    """

    def __init__(self, arch, kernel, *, h_lane, h_lane_msg, h_stop, h_stop_msg, h_start,
                 h_start_msg, h_pub, h_out):
        super().__init__(arch)
        self.kernel = kernel
        self.handles = (h_lane, h_lane_msg, h_stop, h_stop_msg, h_start, h_start_msg, h_pub,
                        h_out)

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        m.submodules.kernel = kernel = self.kernel
        h_lane, h_lane_msg, h_stop, h_stop_msg, h_start, h_start_msg, h_pub, h_out = \
            self.handles
        w = self.arch.word_bits
        n = 64 // w
        out, ptr, got = (Signal(w, name=nm) for nm in ("out", "ptr", "got"))
        lane = [Signal(w, name=f"lane{k}") for k in range(n)]
        command = Signal(64)
        with m.FSM():
            with m.State("INIT"):
                os.thread_init(then="OUT_ADDR")
            with m.State("OUT_ADDR"):
                os.memory_getobjaddr(h_out, ptr=out, then="LANE")
            with m.State("LANE"):
                os.ros_take(h_lane, h_lane_msg, ptr=ptr, then="READ")
            with m.State("READ"):
                mem.read_words(ptr, lane, then="STOP")
            _pulse_per_message_states(m, os, "STOP", h_stop, h_stop_msg, kernel.stop, ptr, got,
                                      then="START")
            _pulse_per_message_states(m, os, "START", h_start, h_start_msg, kernel.start, ptr,
                                      got, then="FEED")
            with m.State("FEED"):
                m.d.comb += [kernel.lane.tvalid.eq(1), kernel.lane.tdata.eq(Cat(*lane)),
                             kernel.lane.tlast.eq(1)]
                with m.If(kernel.lane.tready):
                    m.next = "COMMAND"
            with m.State("COMMAND"):
                m.d.comb += kernel.o.tready.eq(1)
                with m.If(kernel.o.tvalid):
                    m.d.sync += command.eq(kernel.o.tdata)
                    m.next = "WRITE"
            with m.State("WRITE"):
                mem.write_words(out, [command.word_select(k, w) for k in range(n)],
                                then="PUBLISH")
            with m.State("PUBLISH"):
                os.ros_publish(h_pub, h_out, then="LANE")
        return m
