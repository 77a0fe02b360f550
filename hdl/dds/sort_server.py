"""The sort service as a node on hardware topics (docs/services.md)."""

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..logic import Countdown
from ..kernels.sort import MergeSorter
from ..msg import Deserializer, Serializer
from ..msg.serializer import payload_port
from ..params import ParameterError, check_power_of_two
from ..stream import AXIStreamSignature, RegisterSlice, StreamRepacker
from .service import ReplyStatus, ServiceServer
from .topic import HW_TOPIC_STREAM

__all__ = ["SortServer", "WordFeeder"]


def _single_uint32_sequence(plan, what):
    streams = plan.streams
    if (len(streams) != 1 or len(plan.layout.members) != 1 or streams[0].element_bytes != 4
            or streams[0].elements):
        raise ParameterError(what, plan.typename, "a type whose only field is a uint32[]")
    return streams[0]


class WordFeeder(wiring.Component):
    """Feeds exactly ``count`` 32-bit words from a message field's byte stream.

    The field's packet may end early (a message cut or failed inside it): the rest of the
    ``count`` words are all ones. Bytes beyond the ``count`` words are dropped up to ``tlast``.
    So whatever arrives, the consumer gets one packet of ``count`` words, ``tlast`` on the last.

    Members
    -------
    count : In(32)
        Words of the next packet; sampled with ``start``.
    start : In(1)
        Begins a packet of ``count`` words (0: only the input packet is read, to its end).
    s_axis : In(AXIStreamSignature(64, user_width=1))
        The field's bytes (``tkeep`` contiguous; a beat carries ``popcount(tkeep) // 4`` words).
    m_axis : Out(AXIStreamSignature(32, keep=False))
        The words.
    busy : Out(1)
        From ``start`` until the last word has left and the input packet has ended.
    """

    def __init__(self):
        super().__init__({"count": In(32), "start": In(1),
                          "s_axis": In(AXIStreamSignature(64, user_width=1)),
                          "m_axis": Out(AXIStreamSignature(32, keep=False)),
                          "busy": Out(1)})

    def elaborate(self, platform):
        m = Module()
        s, out = self.s_axis, self.m_axis
        # words still to send; the handshakes test its flags, not 32 bits
        left = Countdown(32, "words")
        some, one = ~left.none, left.last
        ended = Signal(init=1)       # the input packet's tlast was taken
        high = Signal()              # the low word of the held beat has been sent
        words = Mux(s.tkeep[7], 2, Mux(s.tkeep[3], 1, 0))
        from_input = ~ended & s.tvalid
        sent = out.tvalid & out.tready
        m.d.comb += [
            self.busy.eq(some | ~ended),
            out.tdata.eq(Mux(ended, 0xFFFF_FFFF, Mux(high, s.tdata[32:], s.tdata[:32]))),
            out.tlast.eq(one),
            out.tvalid.eq(some & (ended | (s.tvalid & (words > high)))),
            # a beat is taken once its words are sent, or at once when it carries none to send
            s.tready.eq(~ended & (~some | (words <= high) |
                                  (out.tready & ((words == high + 1) | one)))),
        ]
        taken = s.tvalid & s.tready
        with m.If(self.start):
            m.d.sync += [*left.load(self.count), ended.eq(0), high.eq(0)]
        with m.Else():
            with m.If(sent):
                m.d.sync += left.step()
            with m.If(taken):
                m.d.sync += [high.eq(0), ended.eq(s.tlast)]
            with m.Elif(sent & from_input):
                m.d.sync += high.eq(1)
        return m


class SortServer(wiring.Component):
    """A service server on hardware topics that sorts: requests and replies are messages whose
    only field is a ``uint32[]`` (ReconROS' ``Sort.srv``: ``uint32[] unsorted --- uint32[]
    sorted``).

    One request at a time: the request is deserialized, its values merge-sorted
    (:class:`~hdl.kernels.MergeSorter`) and the reply serialized with the request's id. A request
    the deserializer rejects (bad CDR, a count above ``block_size``, cut short, too long) gets a
    reply with status :attr:`~hdl.dds.service.ReplyStatus.BAD_REQUEST` and no body.

    Parameters
    ----------
    request_plan, reply_plan : gen.msg.plan.StreamPlan
        ``cdr`` plans of the request and reply types.
    block_size : int
        Most values per request, a power of two in 2..4096.

    Members
    -------
    request_in : In(HW_TOPIC_STREAM)
    reply_out : Out(HW_TOPIC_STREAM)
        The service's topics (:class:`~hdl.dds.service.ServiceServer`).
    served : Out(32)
        Replies with status OK.
    bad_requests : Out(32)
        Replies with status BAD_REQUEST.
    bad_frames : Out(32)
        Frames on the request topic that were not requests.
    """

    def __init__(self, request_plan, reply_plan, *, block_size=2048):
        for name, plan in (("request_plan", request_plan), ("reply_plan", reply_plan)):
            if plan.framing != "cdr":
                raise ParameterError(name, plan.framing, "the 'cdr' framing")
        self._in_field = _single_uint32_sequence(request_plan, "request_plan")
        self._out_field = _single_uint32_sequence(reply_plan, "reply_plan")
        self._block_size = check_power_of_two("block_size", block_size, 2, 4096)
        self.request_plan, self.reply_plan = request_plan, reply_plan
        super().__init__({"request_in": In(HW_TOPIC_STREAM),
                          "reply_out": Out(HW_TOPIC_STREAM),
                          "served": Out(32),
                          "bad_requests": Out(32),
                          "bad_frames": Out(32)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.server = server = ServiceServer()
        m.submodules.deserializer = des = Deserializer(self.request_plan, 64,
                                                       max_count=self._block_size)
        m.submodules.serializer = ser = Serializer(self.reply_plan, 64)
        m.submodules.feeder = feeder = WordFeeder()
        m.submodules.sorter = sorter = MergeSorter(self._block_size)
        m.submodules.packer = packer = StreamRepacker(4, 8)
        wiring.connect(m, wiring.flipped(self.request_in), server.request_in)
        wiring.connect(m, server.reply_out, wiring.flipped(self.reply_out))
        # the next request is read only once this one's reply is out: the deserializer's
        # verdict pulses then always come while the node waits for them
        reading = Signal()
        req = server.request
        m.d.comb += [des.s_axis.tdata.eq(req.tdata), des.s_axis.tkeep.eq(req.tkeep),
                     des.s_axis.tlast.eq(req.tlast), des.s_axis.tvalid.eq(req.tvalid & reading),
                     req.tready.eq(des.s_axis.tready & reading)]
        wiring.connect(m, ser.m_axis, server.reply)
        m.d.comb += self.bad_frames.eq(server.bad_frames)

        # a register slice between the deserializer and the feeder: the feeder's ready does
        # not reach into the deserializer's byte window
        values_port = payload_port(self._in_field, "m")
        m.submodules.values_slice = values_slice = RegisterSlice(
            des.signature.members[values_port].signature)
        wiring.connect(m, getattr(des, values_port), values_slice.s_axis)
        wiring.connect(m, values_slice.m_axis, feeder.s_axis)
        wiring.connect(m, feeder.m_axis, sorter.i)
        sorted_in = getattr(ser, payload_port(self._out_field, "s"))
        in_count = des.fields.payload[self._in_field.path]

        count = Signal(32)
        ok, failed = Signal(), Signal()          # the request's verdict
        verdict = ok | failed
        m.d.comb += sorter.length.eq(count)
        m.d.comb += [packer.s_axis.tdata.eq(sorter.o.tdata), packer.s_axis.tkeep.eq(0xF),
                     packer.s_axis.tlast.eq(sorter.o.tlast)]
        ser_fields = ser.fields.payload
        m.d.comb += ser_fields[self._out_field.path].eq(count)
        with m.FSM() as fsm:
            m.d.comb += reading.eq(fsm.ongoing("IDLE") | fsm.ongoing("LOAD") |
                                   fsm.ongoing("VERDICT"))
            with m.State("IDLE"):
                m.d.comb += des.fields.ready.eq(1)
                m.d.sync += [ok.eq(0), failed.eq(0)]
                with m.If(des.fields.valid):
                    # an empty request may end in the cycle its count is read
                    m.d.sync += [count.eq(in_count), ok.eq(des.done),
                                 failed.eq(des.error.valid)]
                    with m.If(in_count > self._block_size):
                        m.next = "VERDICT"       # a LENGTH error follows; no values come
                    with m.Else():
                        m.d.comb += [feeder.count.eq(in_count), feeder.start.eq(1)]
                        m.next = "LOAD"
                with m.Elif(des.error.valid):
                    m.next = "REJECT"
            with m.State("LOAD"):
                with m.If(des.done):
                    m.d.sync += ok.eq(1)
                with m.If(des.error.valid):
                    m.d.sync += failed.eq(1)
                with m.If(verdict & ~feeder.busy & failed):
                    m.next = "DRAIN"
                with m.Elif(verdict & ~feeder.busy):
                    m.next = "REPLY"
            with m.State("VERDICT"):
                with m.If(verdict | des.done | des.error.valid):
                    m.next = "REJECT"
            with m.State("REPLY"):
                # an empty sequence is one beat with tlast (Serializer); otherwise the sorter
                wiring.connect(m, packer.m_axis, sorted_in)
                m.d.comb += [ser.fields.valid.eq(1),
                             packer.s_axis.tvalid.eq(sorter.o.tvalid),
                             sorter.o.tready.eq(packer.s_axis.tready)]
                with m.If(count == 0):
                    m.d.comb += [sorted_in.tvalid.eq(1), sorted_in.tlast.eq(1),
                                 sorted_in.tkeep.eq(0), packer.m_axis.tready.eq(0)]
                with m.If(ser.fields.ready):
                    m.d.sync += self.served.eq(self.served + 1)
                    m.next = "IDLE"
            with m.State("DRAIN"):
                m.d.comb += sorter.o.tready.eq(1)
                with m.If((count == 0) | (sorter.o.tvalid & sorter.o.tlast)):
                    m.next = "REJECT"
            with m.State("REJECT"):
                m.d.comb += [server.reply_error.valid.eq(1),
                             server.reply_error.payload.eq(ReplyStatus.BAD_REQUEST)]
                with m.If(server.reply_error.ready):
                    m.d.sync += self.bad_requests.eq(self.bad_requests + 1)
                    m.next = "IDLE"
        return m
