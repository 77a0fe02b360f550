"""A hardware thread that moves ROS messages between the software path (ReconOS topics, the
message as a rosidl C struct in memory) and a hardware-mapped topic (the message as a stream in
ReconROS' framing): ReconROS' ROS gateway, and the halves of it that a node publishing or
subscribing a hardware topic needs."""

from types import SimpleNamespace

from amaranth import Cat, Const, Module, Mux, ResetInserter, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..dds.topic import HW_TOPIC_STREAM
from ..msg import ReconrosDeserializer, ReconrosSerializer
from ..msg.serializer import payload_port
from ..stream import RegisterSlice
from .hwt import HardwareThread

__all__ = ["TopicGatewayThread", "MemoryLayout"]

WORD = 8


class MemoryLayout:
    """Where a message's parts are in its rosidl C struct (computed by the generator from the
    target's C layout, ``gen.msg.layout``).

    Parameters
    ----------
    size : int
        The struct's size in bytes.
    leaves : dict
        Path of each fixed leaf of the stream plan (``"header.stamp.sec"``) -> byte offset.
    variables : dict
        Path of each variable-length field (``"data"``, ``"header.frame_id"``) -> byte offset
        of its ``{data, size, capacity}`` struct.
    """

    def __init__(self, size, leaves, variables):
        if size % WORD:
            raise ValueError(f"struct size {size}: expected a multiple of {WORD} bytes (r64)")
        self.size = size
        self.leaves = dict(leaves)
        self.variables = dict(variables)


class TopicGatewayThread(HardwareThread):
    """Moves messages of one type between ReconOS topics and a hardware topic (r64).

    Two state machines run side by side and share the OSIF through a lock; the transmitter
    reads memory, the receiver only writes it, so they share the MEMIF without waiting for
    each other. The receiver therefore always drains the hardware topic, and a gateway that
    publishes and subscribes the same topic cannot block it: its own messages come back on
    ``<in_port>`` while it sends them.

    To the hardware topic (``to_hw``): take a message from the software subscription (blocking
    ``ROS_TAKE``, or ``ROS_TRYTAKE`` polled every ``poll_cycles`` when the thread also moves
    messages the other way), read its struct and every string and sequence over MEMIF, and
    stream it in ReconROS' framing with this thread's publisher id on ``<out_port>``.

    From the hardware topic (``from_hw``): messages with this thread's own publisher id (its
    own publications coming back) are dropped as they arrive, as ReconROS' gateway does; each
    other message is deserialized. For each string or sequence, as its bytes begin,
    ``ROS_MESSAGE_SET_SIZE`` gives the outgoing message a buffer (capacity rounded up to whole
    words, with room for a string's NUL) and the bytes are written into it; then the whole
    struct (fixed fields, buffer pointers, sizes and capacities) is written, and the message is
    published with ``ROS_PUBLISH``. A bad message (the deserializer's error: a count above
    ``max_count``, an early or late end) is dropped and counted in ``rx_errors``; its buffers
    are completed with zeros, nothing is published, the next message is read normally.

    Parameters
    ----------
    arch : str
        ``"r64"`` (the hardware topic's 64-bit beats are memory words).
    plan : gen.msg.plan.StreamPlan
        The message type in the ``reconros`` framing.
    layout : MemoryLayout
    publisher_id : int
        This thread's id (beat 0 carries it + 1000).
    to_hw : (h_sub, h_msg) or None
    from_hw : (h_pub, h_msg) or None
    out_port, in_port : str
        Names of the hardware-topic ports.
    max_count : int
        Largest element count of a string or sequence taken from the hardware topic.
    poll_cycles : int
        Cycles between two ``ROS_TRYTAKE`` that found nothing (both directions only).

    Members
    -------
    <out_port> : Out(HW_TOPIC_STREAM)
        Present with ``to_hw``.
    <in_port> : In(HW_TOPIC_STREAM)
        Present with ``from_hw``.

    The count of bad messages is the register ``rx_errors`` (in waveforms; a thread core has
    only its slot and topic ports).
    """

    def __init__(self, arch, *, plan, layout, publisher_id, to_hw=None, from_hw=None,
                 out_port="topic_out", in_port="topic_in", max_count=1 << 20,
                 poll_cycles=256):
        if plan.framing != "reconros":
            raise ValueError(f"plan framing {plan.framing!r}: the gateway speaks 'reconros'")
        if to_hw is None and from_hw is None:
            raise ValueError("a gateway needs to_hw, from_hw or both")
        missing = [leaf.path for leaf in plan.leaves
                   if leaf.type not in ("count", "publisher") and leaf.path not in layout.leaves]
        missing += [v.path for v in plan.variables if v.path not in layout.variables]
        if missing:
            raise ValueError(f"layout of {plan.typename} has no offset for {missing}")
        members = {}
        if to_hw is not None:
            members[out_port] = Out(HW_TOPIC_STREAM)
        if from_hw is not None:
            members[in_port] = In(HW_TOPIC_STREAM)
        super().__init__(arch, members)
        if self.arch.word_bits != 64:
            raise ValueError(f"arch {arch!r}: the gateway runs on r64 (64-bit memory words)")
        self.plan, self.layout = plan, layout
        self.publisher_id = publisher_id
        self.to_hw, self.from_hw = to_hw, from_hw
        self.out_port, self.in_port = out_port, in_port
        self.max_count = max_count
        self.poll_cycles = poll_cycles
        #: the variable-length fields in the order they are on the stream
        self.order = [s.var for s in plan.steps if s.kind == "payload"]

    def elaborate(self, platform):
        m = Module()
        os, mem = self.os_and_memory(m)
        started = Signal()          # THREAD_INIT (and the message's address) done
        lock = _OsifLock(m)
        rx = tx = None
        if self.from_hw:
            m.submodules.deserializer = des = ReconrosDeserializer(
                self.plan, max_count=self.max_count)
            _EchoFilter(m, getattr(self, self.in_port), des.s_axis,
                        des.signature.members["s_axis"].signature.flip(), self.publisher_id,
                        self.plan.publisher_offset)
            rx = _Receiver(self, m, os, mem, lock, started, des, self.from_hw[1])
        if self.to_hw:
            m.submodules.serializer = ser = ReconrosSerializer(self.plan)
            out = getattr(self, self.out_port)
            m.d.comb += [out.tdata.eq(ser.m_axis.tdata), out.tkeep.eq(ser.m_axis.tkeep),
                         out.tlast.eq(ser.m_axis.tlast), out.tuser.eq(ser.m_axis.tuser),
                         out.tvalid.eq(ser.m_axis.tvalid), ser.m_axis.tready.eq(out.tready)]
            tx = _Transmitter(self, m, os, mem, lock, started, ser)
        with m.FSM(name="start"):
            with m.State("INIT"):
                os.thread_init(then="ADDR" if rx else "RUN")
            if rx:
                with m.State("ADDR"):
                    os.memory_getobjaddr(self.from_hw[1], ptr=rx.msg, then="RUN")
            with m.State("RUN"):
                m.d.comb += started.eq(1)
        if rx:
            h_pub, h_msg = self.from_hw
            rx.build(lambda then: os.ros_publish(h_pub, h_msg, then=then))
        if tx:
            tx.build(self._take_states(m, os, tx, lock, both=rx is not None))
        return m

    def _take_states(self, m, os, tx, lock, both):
        """The transmitter's TX_TAKE states: a blocking take, or with messages moving both
        ways a ROS_TRYTAKE polled every ``poll_cycles``."""
        h_sub, h_msg = self.to_hw

        def states():
            if both:
                lock.call(_OsifLock.TX, "TX_TAKE", lambda then: os.ros_trytake(
                    h_sub, h_msg, ptr=tx.ptr, ret=tx.ret, then=then), "TX_TRIED")
                with m.State("TX_TRIED"):
                    with m.If(tx.ret == 0):
                        m.next = "TX_READ"
                    with m.Else():
                        m.d.sync += tx.wait.eq(self.poll_cycles)
                        m.next = "TX_IDLE"
            else:
                lock.call(_OsifLock.TX, "TX_TAKE", lambda then: os.ros_take(
                    h_sub, h_msg, ptr=tx.ptr, then=then), "TX_READ")
        return states


def check_gateway_side(name, plan, layout, what):
    """Refuse a plan (of a service's or action's ``cdr`` bodies) that a gateway cannot move
    between memory and the hardware topic: not ``cdr``, no offset for a part, or a sequence
    of messages."""
    if plan.framing != "cdr":
        raise ValueError(f"{name} framing {plan.framing!r}: {what} over hardware topics carry "
                         f"'cdr' bodies")
    if not isinstance(layout, MemoryLayout):
        raise TypeError(f"{name}: its layout must be a MemoryLayout, not {layout!r}")
    missing = [leaf.path for leaf in plan.leaves
               if leaf.type != "count" and leaf.path not in layout.leaves]
    missing += [v.path for v in plan.variables if v.path not in layout.variables]
    if missing:
        raise ValueError(f"layout of {plan.typename} has no offset for {missing}")
    packed = [v.path for v in plan.variables if v.elements]
    if packed:
        raise ValueError(f"{plan.typename}: the gateway moves strings and sequences of "
                         f"primitives, not {packed[0]} (a sequence of messages)")


def gateway_side(plan, layout):
    """What a gateway's transmitter or receiver reads of one message type (the attributes a
    :class:`TopicGatewayThread` has for its own)."""
    return SimpleNamespace(plan=plan, layout=layout, poll_cycles=1, publisher_id=0,
                           order=[s.var for s in plan.steps if s.kind == "payload"])


class _OsifLock:
    """The OSIF for one of the state machines at a time: the receivers first (``RX``, then
    ``RX2`` when ``second_receiver``), then the transmitter."""

    RX, TX, RX2 = 1, 2, 3

    def __init__(self, m, second_receiver=False):
        self.m = m
        self.owner = Signal(2, name="osif_owner")
        self.want = {self.RX: Signal(name="osif_rx_wants"),
                     self.TX: Signal(name="osif_tx_wants")}
        order = [self.RX, self.TX]
        if second_receiver:
            self.want[self.RX2] = Signal(name="osif_rx2_wants")
            order = [self.RX, self.RX2, self.TX]
        with m.If(self.owner == 0):
            with m.If(self.want[order[0]]):
                m.d.sync += self.owner.eq(order[0])
            for who in order[1:]:
                with m.Elif(self.want[who]):
                    m.d.sync += self.owner.eq(who)

    def call(self, who, name, call, then):
        """States ``name`` (wait for the lock), ``name``_CALL (``call(then=...)``) and
        ``name``_FREE (release, go to ``then``)."""
        m = self.m
        with m.State(name):
            m.d.comb += self.want[who].eq(self.owner != who)
            with m.If(self.owner == who):
                m.next = f"{name}_CALL"
        with m.State(f"{name}_CALL"):
            call(then=f"{name}_FREE")
        with m.State(f"{name}_FREE"):
            m.d.sync += self.owner.eq(0)
            m.next = then


class _Transmitter:
    """A taken message's struct and buffers over MEMIF (reads only) -> ``ser``, a serializer
    of ``thread.plan``. ``thread`` has ``plan``, ``layout``, ``order``, ``poll_cycles`` and
    ``publisher_id`` (for a ``reconros`` plan)."""

    def __init__(self, thread, m, os, mem, lock, started, ser, early_ready=False):
        self.t, self.m, self.os, self.mem, self.lock = thread, m, os, mem, lock
        self.started = started
        self.ser = ser
        #: ``early_ready``: the serializer may take the fields with the last payload beat
        #: (a CDR message that ends with its payload), before the read has ended; then the
        #: fields are offered no more and TX_DONE only moves on
        self.taken = Signal(name="tx_fields_taken") if early_ready else None
        self.words = [Signal(64, name=f"tx_word{i}") for i in range(thread.layout.size // WORD)]
        self.struct = Cat(*self.words)
        self.ptr = Signal(64, name="tx_ptr")
        self.ret = Signal(64, name="tx_ret")
        self.wait = Signal(range(thread.poll_cycles + 1), name="tx_wait")
        with m.If(self.wait != 0):
            m.d.sync += self.wait.eq(self.wait - 1)

    def _fields(self):
        """The serializer's fixed part from the struct words."""
        t, plan = self.t, self.t.plan
        payload = Signal(plan.layout.size, name="tx_fields")
        for leaf in plan.leaves:
            if leaf.type == "publisher":
                value = Const(t.publisher_id, leaf.width)
            elif leaf.type == "count":
                at = t.layout.variables[leaf.path] + WORD        # the size_t after data
                value = self.struct[at * 8:at * 8 + leaf.width]
            else:
                at = t.layout.leaves[leaf.path]
                value = self.struct[at * 8:at * 8 + leaf.width]
            self.m.d.comb += payload[leaf.offset:leaf.offset + len(value)].eq(value)
        return payload

    def build(self, take_states, sent="TX_IDLE", extra_states=None):
        """The ``tx`` FSM: TX_IDLE, the states ``take_states()`` emits (TX_TAKE, ending in
        TX_READ with the message's address in ``ptr``, or back in TX_IDLE), the reads and
        the stream; once the message's last byte has left, ``sent``, a state that
        ``extra_states()`` emits unless it is TX_IDLE."""
        m, mem, t, ser = self.m, self.mem, self.t, self.ser
        payload = self._fields()
        with m.FSM(name="tx"):
            with m.State("TX_IDLE"):
                with m.If(self.started & (self.wait == 0)):
                    m.next = "TX_TAKE"
            take_states()
            if extra_states is not None:
                extra_states()
            with m.State("TX_READ"):
                mem.read_words(self.ptr, self.words,
                               then=f"TX_VAR{t.order[0]}" if t.order else "TX_DONE")
            taken = self.taken

            def offer():
                valid = 1 if taken is None else ~taken
                m.d.comb += [ser.fields.valid.eq(valid), ser.fields.payload.eq(payload)]
                if taken is not None:
                    with m.If(ser.fields.valid & ser.fields.ready):
                        m.d.sync += taken.eq(1)
            for k, var in enumerate(t.order):
                v = t.plan.variables[var]
                at = t.layout.variables[v.path]
                data_ptr = self.struct[at * 8:at * 8 + 64]
                count = self.struct[(at + WORD) * 8:(at + WORD) * 8 + 32]
                nbytes = Signal(40, name=f"tx_bytes{var}")
                m.d.comb += nbytes.eq(count * v.element_bytes)
                # the stream's lengths from flip-flops (the struct is still from TX_VAR on):
                # its handshakes do not wait for the multiplication and the rounding
                nbytes_held = Signal(40, name=f"tx_bytes_held{var}")
                words = Signal(37, name=f"tx_words{var}")
                m.d.sync += [nbytes_held.eq(nbytes), words.eq((nbytes + WORD - 1) >> 3)]
                port = getattr(ser, payload_port(v, "s"))
                after = "TX_DONE" if k == len(t.order) - 1 else f"TX_VAR{t.order[k + 1]}"
                # the serializer holds the fields until the message's last byte: payloads
                # are fed while it has them
                with m.State(f"TX_VAR{var}"):
                    offer()
                    with m.If(nbytes == 0):
                        m.d.comb += [port.tvalid.eq(1), port.tlast.eq(1), port.tkeep.eq(0)]
                        with m.If(port.tready):
                            m.next = after
                    with m.Else():
                        m.next = f"TX_STREAM{var}"
                with m.State(f"TX_STREAM{var}"):
                    offer()
                    sink = _WordSink(port, nbytes_held)
                    m.d.comb += sink.connect()
                    mem.read_stream(data_ptr, words << 3, sink, count=words, then=after)
            with m.State("TX_DONE"):
                offer()
                with m.If(ser.fields.ready if taken is None else taken | ser.fields.ready):
                    if taken is not None:
                        m.d.sync += taken.eq(0)
                    m.next = sent


class _WordSink:
    """What :meth:`MemCalls.read_stream` drives (64-bit elements) in front of a serializer
    payload port: ``tkeep`` from the byte count on the last word."""

    def __init__(self, port, nbytes):
        self.port, self.nbytes = port, nbytes
        self.tdata = Signal(64, name="sink_tdata")
        self.tvalid = Signal(name="sink_tvalid")
        self.tlast = Signal(name="sink_tlast")
        self.tready = Signal(name="sink_tready")

    def connect(self):
        tail = self.nbytes[:3]
        # a partial last word keeps its first `tail` bytes (never all 8)
        keep = Mux(self.tlast & (tail != 0), Cat(*(tail > j for j in range(WORD - 1)), 0), 0xFF)
        return [self.port.tdata.eq(self.tdata), self.port.tvalid.eq(self.tvalid),
                self.port.tlast.eq(self.tlast), self.port.tkeep.eq(keep),
                self.tready.eq(self.port.tready)]


class _EchoFilter:
    """Drops whole messages whose beat 0 carries ``publisher_id`` + ``offset`` (this
    thread's own publications) between the topic port and the deserializer.

    The beats it passes go through a ready-only :class:`~hdl.stream.RegisterSlice`: the
    deserializer's ready (its decision to take bytes) reaches the slice's flip-flops, not the
    filter's state and the topic port's ready, and no cycle is added."""

    def __init__(self, m, inp, out, signature, publisher_id, offset):
        m.submodules.echo_slice = passed = RegisterSlice(signature, ready_only=True)
        wiring.connect(m, passed.m_axis, out)
        first = Signal(init=1, name="echo_first")
        dropping = Signal(name="echo_dropping")
        own = first & (inp.tdata[:32] == publisher_id + offset)
        drop = dropping | own
        m.d.comb += [*signature.copy_payload(passed.s_axis, inp),
                     passed.s_axis.tvalid.eq(inp.tvalid & ~drop),
                     inp.tready.eq(Mux(drop, 1, passed.s_axis.tready))]
        with m.If(inp.tvalid & inp.tready):
            m.d.sync += first.eq(inp.tlast)
            with m.If(own & ~inp.tlast):
                m.d.sync += dropping.eq(1)
            with m.If(inp.tlast):
                m.d.sync += dropping.eq(0)


class _Receiver:
    """``des``, a deserializer of ``thread.plan`` -> buffers of message ``h_msg``
    (SET_SIZE, MEMIF writes) and its struct -> an OS call that sends it (ROS_PUBLISH).
    ``thread`` has ``plan``, ``layout`` and ``order``."""

    def __init__(self, thread, m, os, mem, lock, started, des, h_msg, *, prefix="rx",
                 who=None, fixed=None):
        self.t, self.m, self.os, self.mem, self.lock = thread, m, os, mem, lock
        self.started = started
        self.des = des
        self.h_msg = h_msg
        #: names of its signals, submodules and FSM; its party on the OSIF lock
        self.prefix = prefix
        self.who = _OsifLock.RX if who is None else who
        #: byte offset in the struct -> a value written there with every message
        self.fixed = dict(fixed or {})
        plan = thread.plan
        self.msg = Signal(64, name=f"{prefix}_msg")
        self.words = [Signal(64, name=f"{prefix}_word{i}")
                      for i in range(thread.layout.size // WORD)]
        self.ptrs = {v.index: Signal(64, name=f"{prefix}_ptr{v.index}")
                     for v in plan.variables}
        self.counts = {v.index: Signal(32, name=f"{prefix}_count{v.index}")
                       for v in plan.variables}
        # each payload port through a ready-only slice: the MEMIF write's decision to take a
        # word reaches the slice's flip-flops, not the deserializer's decision to take bytes.
        # An error empties the slices: what they hold belongs to the failed message, whose
        # buffers are completed with zeros and which is not published.
        self.sources = {}
        for v in plan.variables:
            name = payload_port(v, "m")
            passed = m.submodules[f"{prefix}_slice{v.index}"] = ResetInserter(des.error.valid)(
                RegisterSlice(des.signature.members[name].signature, ready_only=True))
            wiring.connect(m, getattr(des, name), passed.s_axis)
            self.sources[v.index] = _WordSource(passed.m_axis)
        errors = Signal(16, name=f"{prefix}_errors")
        #: between taking a message's first part and going back to waiting
        self.active = Signal(name=f"{prefix}_active")
        #: the deserializer's verdict on the message being taken (the first after it began:
        #: the next message's cannot come before it): it failed (complete its buffers,
        #: publish nothing) or it was read to its end
        self.failed = Signal(name=f"{prefix}_failed")
        self.good = Signal(name=f"{prefix}_good")
        #: a failed message left its fields offered: they are taken here, whatever state the
        #: receiver is in. They can only be the failed message's own, as the deserializer
        #: reads no further before they are taken; the receiver must not take fields at the
        #: end of a failed message itself, as those may already be the next message's.
        self.drain = drain = Signal(name=f"{prefix}_drain")
        #: the next message's good verdict, when it came while this one was being published
        #: (possible only for a type without strings or sequences)
        self.next_good = Signal(name=f"{prefix}_next_good")
        #: the receiver takes a message this cycle: a verdict in this cycle is that message's
        self.taking = Signal(name=f"{prefix}_taking")
        decided = self.good | self.failed
        with m.If(des.error.valid):
            m.d.sync += errors.eq(errors + 1)
            with m.If(self.active & ~decided):
                m.d.sync += self.failed.eq(1)
            with m.If(des.fields.valid & ~des.fields.ready):
                m.d.sync += drain.eq(1)
        with m.If(des.done):
            with m.If(self.active & ~decided):
                m.d.sync += self.good.eq(1)
            with m.Elif(~self.taking):
                m.d.sync += self.next_good.eq(1)
        # ready from registers only (not from the offer): the deserializer's decision to take
        # bytes follows its ready, and its offer is the end of a long chain of its own checks
        with m.If(drain):
            m.d.comb += des.fields.ready.eq(1)
            with m.If(des.fields.valid):
                m.d.sync += drain.eq(0)
        if thread.order:
            self.arriving = self.sources[thread.order[0]].port.tvalid & ~drain
        else:
            self.arriving = des.fields.valid & ~drain

    def _capacity(self, v):
        """Elements to allocate for ``v``: whole words, and room for a string's NUL."""
        es = v.element_bytes
        return ((self.counts[v.index] + int(v.string)) * es + WORD - 1) // WORD * WORD // es

    def _struct(self):
        """The outgoing struct's words: fixed fields, and each string or sequence as its
        buffer, size and capacity; zeros elsewhere."""
        t, m, prefix = self.t, self.m, self.prefix
        payload = self.des.fields.payload.as_value()
        struct = Signal(t.layout.size * 8, name=f"{prefix}_struct")
        for leaf in t.plan.leaves:
            if leaf.type in ("publisher", "count"):
                continue
            at = t.layout.leaves[leaf.path] * 8
            m.d.comb += struct[at:at + leaf.width].eq(
                payload[leaf.offset:leaf.offset + leaf.width])
        for v in t.plan.variables:
            at = t.layout.variables[v.path] * 8
            m.d.comb += struct[at:at + 3 * 64].eq(Cat(self.ptrs[v.index],
                                                      self.counts[v.index].as_unsigned(),
                                                      Const(0, 32), self._capacity(v)))
        for at, value in self.fixed.items():
            m.d.comb += struct[at * 8:at * 8 + len(value)].eq(value)
        return struct

    def _empty_struct(self):
        """The struct of an empty message: zeros, and the fixed values."""
        empty = Signal(self.t.layout.size * 8, name=f"{self.prefix}_empty")
        self.m.d.comb += empty.eq(0)
        for at, value in self.fixed.items():
            self.m.d.comb += empty[at * 8:at * 8 + len(value)].eq(value)
        return empty

    def build(self, send, empty=None, failed="RX_IDLE"):
        """The ``rx`` FSM. ``send(then)`` is the OS call that sends the written message
        (RX_PUBLISH). ``empty``, a signal: in RX_IDLE, when no message arrives, write the
        struct all zeros (every string and sequence empty) and send that (it is cleared
        there). ``failed``: the state after a failed message (RX_EMPTY sends the zero struct
        in its place)."""
        m, os, mem, t, des, lock = self.m, self.os, self.mem, self.t, self.des, self.lock
        h_msg, prefix = self.h_msg, self.prefix
        payload = des.fields.payload.as_value()
        struct = self._struct()
        first = f"RX_VAR{t.order[0]}" if t.order else "RX_FIELDS"
        with m.FSM(name=self.prefix) as fsm:
            with m.State("RX_IDLE"):
                with m.If(self.started & self.arriving):
                    m.d.comb += self.taking.eq(1)
                    m.d.sync += [self.active.eq(1), self.failed.eq(des.error.valid),
                                 self.good.eq(self.next_good | des.done),
                                 self.next_good.eq(0)]
                    m.next = first
                if empty is not None:
                    with m.Elif(self.started & empty):
                        m.d.sync += empty.eq(0)
                        m.next = "RX_EMPTY"
            if empty is not None or failed == "RX_EMPTY":
                with m.State("RX_EMPTY"):
                    empty = self._empty_struct()
                    m.d.sync += [w.eq(empty[64 * i:64 * i + 64])
                                 for i, w in enumerate(self.words)]
                    m.d.sync += [self.active.eq(0), self.good.eq(1), self.failed.eq(0)]
                    m.next = "RX_WRITE"
            for k, var in enumerate(t.order):
                v = t.plan.variables[var]
                source, count = self.sources[var], self.counts[var]
                port = source.port
                after = "RX_FIELDS" if k == len(t.order) - 1 else f"RX_VAR{t.order[k + 1]}"
                capacity = Signal(40, name=f"{prefix}_capacity{var}")
                m.d.comb += capacity.eq(self._capacity(v))
                with m.State(f"RX_VAR{var}"):
                    # the field's count has been read when its first byte is offered
                    with m.If(self.failed):
                        m.next = "RX_END"
                    with m.Elif(port.tvalid):
                        m.d.sync += [count.eq(payload[v.count.offset:v.count.offset + 32]),
                                     source.ended.eq(0)]
                        m.next = f"RX_SIZE{var}"
                lock.call(self.who, f"RX_SIZE{var}", lambda then, v=v, var=var, c=capacity:
                          os.ros_message_set_size(h_msg, t.layout.variables[v.path],
                                                  v.element_bytes, c, ptr=self.ptrs[var],
                                                  then=then), f"RX_WRITE{var}")
                with m.State(f"RX_WRITE{var}"):
                    m.d.comb += source.connect(m, self.failed)
                    mem.write_stream(self.ptrs[var], capacity * v.element_bytes, source,
                                     then=f"RX_REST{var}")
                with m.State(f"RX_REST{var}"):
                    # an empty sequence's one beat (its buffer took no word)
                    with m.If(port.tvalid & ~source.ended & ~self.failed):
                        m.d.comb += port.tready.eq(1)
                        with m.If(port.tlast):
                            m.d.sync += source.ended.eq(1)
                    with m.Elif(self.failed):
                        m.next = "RX_END"
                    with m.Else():
                        m.next = after
            with m.State("RX_FIELDS"):
                with m.If(self.failed):
                    m.next = "RX_END"
                with m.Else():
                    m.d.comb += des.fields.ready.eq(1)
                    with m.If(des.fields.valid):
                        m.d.sync += [w.eq(struct[64 * i:64 * i + 64])
                                     for i, w in enumerate(self.words)]
                        m.next = "RX_WRITE"
            with m.State("RX_WRITE"):
                mem.write_words(self.msg, self.words, then="RX_CHECK")
            with m.State("RX_CHECK"):
                # published only once read to its end: an error after its fields (a message
                # that goes on past its end) still stops it
                with m.If(self.failed | self.good):
                    m.d.sync += self.active.eq(0)
                    m.next = failed
                    with m.If(self.good):
                        m.next = "RX_PUBLISH"
            lock.call(self.who, "RX_PUBLISH", send, "RX_IDLE")
            with m.State("RX_END"):
                m.d.sync += self.active.eq(0)
                m.next = failed
        return fsm


class _WordSource:
    """A deserializer payload port as :meth:`MemCalls.write_stream`'s source (64-bit words);
    once the packet has ended (its ``tlast``, or the message failed), zeros complete the
    buffer so that the MEMIF write always finishes. (An empty string's one beat has ``tkeep``
    0 and zero data: it becomes the word holding the NUL.)"""

    def __init__(self, port):
        self.port = port
        self.tdata = Signal(64, name="src_tdata")
        self.tvalid = Signal(name="src_tvalid")
        self.tready = Signal(name="src_tready")
        self.ended = Signal(name="src_ended")

    def connect(self, m, failed):
        port = self.port
        done = self.ended | failed
        with m.If(port.tvalid & port.tready & port.tlast):
            m.d.sync += self.ended.eq(1)
        return [self.tdata.eq(Mux(done, 0, port.tdata)),
                self.tvalid.eq(done | port.tvalid),
                port.tready.eq(~done & self.tready)]
