"""A hardware-mapped topic: N publishers, M subscribers (docs/topics.md)."""

from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out, flipped

from ..params import ParameterError, check_choice, check_int
from ..stream import (AXIStreamSignature, MessageFIFO, RegisterSlice, StreamFIFO,
                      StreamMonitor, StreamMonitorSignature)
from .arbiter import TopicArbiter
from .broadcast import TopicBroadcast

__all__ = ["Topic", "TopicMonitorSignature", "QOS_POLICIES", "MAX_ENDPOINTS", "MAX_FIFO_DEPTH",
           "HW_TOPIC_STREAM"]

#: a project's hardware topic stream: 64-bit beats with TKEEP and a 1-bit TUSER, as ReconROS'
#: hardware topics (docs/topics.md)
HW_TOPIC_STREAM = AXIStreamSignature(64, user_width=1)

#: Subscriber QoS: DDS history/reliability combinations a topic implements.
QOS_POLICIES = ("keep_all", "keep_last", "best_effort")
MAX_ENDPOINTS = 16
MAX_FIFO_DEPTH = 1 << 16

DEFAULT_HISTORY = 4


class TopicMonitorSignature(wiring.Signature):
    """Per-port counters of a :class:`Topic`, seen from the topic (``Out``).

    Members
    -------
    pub : Out(StreamMonitorSignature).array(pubs)
        Messages, beats and stall cycles at each publisher port.
    sub : Out(StreamMonitorSignature).array(subs)
        The same at each subscriber port (after its FIFO).
    drops : Out(counter_width).array(subs)
        Whole messages each subscriber's FIFO dropped under ``keep_last`` / ``best_effort``
        (always 0 under ``keep_all``).
    """

    def __init__(self, pubs, subs, counter_width=32):
        self._params = (pubs, subs, counter_width)
        super().__init__({
            "pub": Out(StreamMonitorSignature(counter_width)).array(pubs),
            "sub": Out(StreamMonitorSignature(counter_width)).array(subs),
            "drops": Out(counter_width).array(subs),
        })

    def __eq__(self, other):
        return type(other) is type(self) and other._params == self._params

    def __hash__(self):
        return hash((type(self), self._params))

    def __repr__(self):
        return "TopicMonitorSignature({}, {}, {})".format(*self._params)


class Topic(wiring.Component):
    """Hardware-mapped topic for ``pubs`` publishers and ``subs`` subscribers.

    Structure (docs/topics.md, topology by counts): 1:1 is a wire (or a FIFO); with several
    publishers a :class:`TopicArbiter` merges whole messages round robin; with several
    subscribers a :class:`TopicBroadcast` gives each one every message; a
    :class:`~hdl.stream.RegisterSlice` between them breaks the ``tready`` path, so the topic
    has one cycle of latency and moves one beat per cycle with no idle cycle between
    messages. Each subscriber may have a FIFO.

    Parameters
    ----------
    pubs, subs : int
        Publishers and subscribers, 1..16 each.
    data_width : int
        ``tdata`` bits, a multiple of 8 in 8..1024.
    fifo_depth : int
        Beats of FIFO per subscriber: 0 (none) or a power of two in 2..65536.
    qos : str
        ``"keep_all"`` (default, DDS KEEP_ALL + RELIABLE as in fpgaDDS): nothing is dropped, a
        full subscriber back-pressures the topic (:class:`~hdl.stream.StreamFIFO`).
        ``"keep_last"`` (KEEP_LAST + BEST_EFFORT): each subscriber keeps its newest ``history``
        messages of at most ``fifo_depth // history`` beats; a new message displaces the oldest
        one not yet begun (:class:`~hdl.stream.MessageFIFO`). ``"best_effort"``: a subscriber
        whose FIFO cannot take a message loses that (newest) message and nobody waits
        (:class:`~hdl.stream.StreamFIFO` with ``overflow="drop_new"``). The last two need a
        FIFO, never block the topic, and deliver a message only once it is complete in the
        subscriber's FIFO; drops are whole messages, counted in ``monitor.drops``.
    history : int or None
        ``keep_last`` only: message slots per subscriber (the ROS history depth), a power of
        two in 2..64 and at most ``fifo_depth``; default 4.
    user_width, id_width, dest_width : int
        Sideband widths carried unchanged (0 = absent).
    keep : bool
        Whether the streams have ``tkeep`` (default; image streams have none).
    register : bool
        Insert the register slice (default). Without it the topic is purely combinational.
    monitor : bool
        Provide the ``monitor`` counters (default).
    counter_width : int
        Width of each monitor counter.

    Members
    -------
    s_axis : In(AXIStreamSignature).array(pubs)
        Publisher ``i`` sends messages on ``s_axis[i]``, ``tlast`` on the last beat.
        A publisher may pause (``tvalid`` low) inside a message: the topic waits for it and
        carries no other message meanwhile.
    m_axis : Out(AXIStreamSignature).array(subs)
        Subscriber ``j`` receives every message (all of them under ``keep_all``), whole, in
        the order the topic granted them, which keeps each publisher's own order.
    monitor : Out(TopicMonitorSignature)
        Counters, present when ``monitor=True``.
    """

    def __init__(self, pubs, subs, data_width, *, fifo_depth=0, qos="keep_all", history=None,
                 user_width=0, id_width=0, dest_width=0, keep=True, register=True,
                 monitor=True, counter_width=32):
        check_int("pubs", pubs, 1, MAX_ENDPOINTS)
        check_int("subs", subs, 1, MAX_ENDPOINTS)
        self._stream = AXIStreamSignature(data_width, keep=keep, user_width=user_width,
                                          id_width=id_width, dest_width=dest_width)
        if (not isinstance(fifo_depth, int) or isinstance(fifo_depth, bool) or
                (fifo_depth != 0 and (fifo_depth < 2 or fifo_depth > MAX_FIFO_DEPTH or
                                      fifo_depth & (fifo_depth - 1)))):
            raise ParameterError("fifo_depth", fifo_depth,
                                 f"0 (no FIFO) or a power of two in 2..{MAX_FIFO_DEPTH}")
        check_choice("qos", qos, QOS_POLICIES)
        if qos != "keep_all" and fifo_depth == 0:
            raise ParameterError("fifo_depth", fifo_depth,
                                 f"a power of two in 2..{MAX_FIFO_DEPTH} with qos={qos!r} "
                                 "(drops happen in the subscriber FIFOs)")
        if history is not None and qos != "keep_last":
            raise ParameterError("history", history, "None unless qos='keep_last'")
        if qos == "keep_last":
            if history is None:
                history = min(DEFAULT_HISTORY, fifo_depth)
            if (not isinstance(history, int) or isinstance(history, bool) or history < 2 or
                    history > min(64, fifo_depth) or history & (history - 1)):
                raise ParameterError("history", history,
                                     f"a power of two in 2..{min(64, fifo_depth)} "
                                     f"(at most fifo_depth={fifo_depth})")
        check_int("counter_width", counter_width, 1, 64)
        self._pubs, self._subs = pubs, subs
        self._fifo_depth = fifo_depth
        self._qos = qos
        self._history = history
        self._register = bool(register)
        self._monitor = bool(monitor)
        self._counter_width = counter_width
        members = {
            "s_axis": In(self._stream).array(pubs),
            "m_axis": Out(self._stream).array(subs),
        }
        if monitor:
            members["monitor"] = Out(TopicMonitorSignature(pubs, subs, counter_width))
        super().__init__(members)

    pubs = property(lambda self: self._pubs)
    subs = property(lambda self: self._subs)
    stream_signature = property(lambda self: self._stream)
    fifo_depth = property(lambda self: self._fifo_depth)
    qos = property(lambda self: self._qos)

    @property
    def parameters(self):
        """The generator parameters, as a JSON-friendly dict (for manifests)."""
        sig = self._stream
        return {
            "pubs": self._pubs, "subs": self._subs, "data_width": sig.data_width,
            "fifo_depth": self._fifo_depth, "qos": self._qos, "history": self._history,
            "user_width": sig.user_width, "id_width": sig.id_width, "dest_width": sig.dest_width,
            "register": self._register, "monitor": self._monitor,
            "counter_width": self._counter_width,
        }

    @property
    def latency(self):
        """Cycles from a publisher's beat to the same beat at a subscriber, all ready."""
        slice_ = int(self._register and (self._pubs > 1 or self._subs > 1))
        fifo = 2 if self._fifo_depth else 0
        if self._fifo_depth and self._qos != "keep_all":
            fifo = 3  # commit at tlast, then the read
        return slice_ + fifo

    def elaborate(self, platform):
        m = Module()
        sig = self._stream

        if self._pubs > 1:
            m.submodules.arbiter = arbiter = TopicArbiter(sig, self._pubs)
            for i in range(self._pubs):
                wiring.connect(m, flipped(self.s_axis[i]), arbiter.s_axis[i])
            merged = arbiter.m_axis
        else:
            merged = flipped(self.s_axis[0])

        if self._register and (self._pubs > 1 or self._subs > 1):
            m.submodules.slice = slice_ = RegisterSlice(sig)
            wiring.connect(m, merged, slice_.s_axis)
            merged = slice_.m_axis

        if self._subs > 1:
            m.submodules.broadcast = broadcast = TopicBroadcast(sig, self._subs)
            wiring.connect(m, merged, broadcast.s_axis)
            copies = list(broadcast.m_axis)
        else:
            copies = [merged]

        for j, copy in enumerate(copies):
            if self._qos == "keep_last":
                fifo = MessageFIFO(sig, self._history, self._fifo_depth // self._history,
                                   counter_width=self._counter_width)
            elif self._fifo_depth:
                best_effort = self._qos == "best_effort"
                fifo = StreamFIFO(sig, self._fifo_depth, packet=best_effort,
                                  overflow="drop_new" if best_effort else "block",
                                  counter_width=self._counter_width)
            if self._fifo_depth:
                m.submodules[f"fifo{j}"] = fifo
                wiring.connect(m, copy, fifo.s_axis)
                wiring.connect(m, fifo.m_axis, flipped(self.m_axis[j]))
                if self._monitor:
                    m.d.comb += self.monitor.drops[j].eq(fifo.drops)
            else:
                wiring.connect(m, copy, flipped(self.m_axis[j]))

        if self._monitor:
            ports = ([(f"pub{i}", p, self.monitor.pub[i]) for i, p in enumerate(self.s_axis)] +
                     [(f"sub{j}", p, self.monitor.sub[j]) for j, p in enumerate(self.m_axis)])
            for name, port, counters in ports:
                mon = m.submodules[f"monitor_{name}"] = StreamMonitor(self._counter_width)
                m.d.comb += [mon.tvalid.eq(port.tvalid), mon.tready.eq(port.tready),
                             mon.tlast.eq(port.tlast)]
                wiring.connect(m, mon.counters, flipped(counters))
        return m
