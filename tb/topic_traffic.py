"""Traffic generator + checker around a real :class:`hdl.dds.Topic`, for cycle benchmarks.

Python cannot drive a beat per simulated cycle for megabyte messages quickly, so the bench top
generates messages in hardware and checks them in hardware: publisher ``i`` sends ``count[i]``
messages of ``beats[i]`` beats as fast as the topic accepts them; each beat carries
``{i, sequence number}``. Each subscriber checks that the sequence of every publisher continues
without gap, repeat or interleaving and that ``tlast`` falls on message boundaries, and records
the cycles of its first and last beat. Only the topic is measured; the generator and checker
are always ready.
"""

from amaranth.hdl import Array, Cat, Const, Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from hdl.dds import Topic

__all__ = ["TopicTrafficBench", "SEQ_BITS", "TOPOLOGIES", "WIDTHS", "build_topic_bench_top"]

#: the (publishers, subscribers) and data widths of the topics ``make bench`` measures
TOPOLOGIES = [(1, 1), (1, 4), (4, 1), (4, 4)]
WIDTHS = (64, 512)

SEQ_BITS = 28


class TopicTrafficBench(wiring.Component):
    """``Topic(pubs, subs, data_width, **topic_params)`` between generators and checkers.

    Members
    -------
    start : In(1)
        Pulse: clear the records and start sending.
    beats, count : In(32).array(pubs)
        Beats per message and messages of each publisher (``count = 0``: silent).
    cycle : Out(32)
        Cycles since ``start``.
    pub_first : Out(32).array(pubs)
        Cycle of each publisher's first transfer.
    sub_first, sub_last, sub_beats, sub_messages, sub_errors : Out(32).array(subs)
        Per subscriber: cycles of the first and last received beat, beats and messages
        received, and beats that broke a publisher's sequence or a message boundary.
    done : Out(1)
        Every subscriber has received every message.
    """

    def __init__(self, pubs, subs, data_width, **topic_params):
        if data_width < 32:
            raise ValueError("the traffic bench needs data_width >= 32")
        self.topic = Topic(pubs, subs, data_width, monitor=False, **topic_params)
        self._pubs, self._subs, self._width = pubs, subs, data_width
        members = {"start": In(1), "cycle": Out(32), "done": Out(1),
                   "beats": In(32).array(pubs), "count": In(32).array(pubs),
                   "pub_first": Out(32).array(pubs)}
        for name in ("sub_first", "sub_last", "sub_beats", "sub_messages", "sub_errors"):
            members[name] = Out(32).array(subs)
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        m.submodules.topic = topic = self.topic
        pubs, subs, width = self._pubs, self._subs, self._width
        running = Signal()
        finished = Signal()
        with m.If(self.start):
            m.d.sync += [running.eq(1), self.cycle.eq(0)]
        with m.Elif(running):
            m.d.sync += self.cycle.eq(self.cycle + 1)
            with m.If(finished):
                m.d.sync += running.eq(0)  # inputs may change only after the case ends

        total = Signal(32)
        m.d.comb += total.eq(sum(self.count[i] for i in range(pubs)))

        for i in range(pubs):
            port = topic.s_axis[i]
            sent = Signal(32)
            pos = Signal(32)
            seq = Signal(SEQ_BITS)
            started = Signal()
            word = Cat(seq, Const(i, 32 - SEQ_BITS))
            m.d.comb += [
                port.tdata.eq(Cat(*([word] * (width // 32)))),
                port.tkeep.eq(-1),
                port.tlast.eq(pos + 1 == self.beats[i]),
                port.tvalid.eq(running & ~self.start & (sent != self.count[i])),
            ]
            with m.If(self.start):
                m.d.sync += [sent.eq(0), pos.eq(0), seq.eq(0), started.eq(0)]
            with m.Elif(port.tvalid & port.tready):
                m.d.sync += [seq.eq(seq + 1), started.eq(1)]
                with m.If(~started):
                    m.d.sync += self.pub_first[i].eq(self.cycle)
                with m.If(port.tlast):
                    m.d.sync += [pos.eq(0), sent.eq(sent + 1)]
                with m.Else():
                    m.d.sync += pos.eq(pos + 1)

        all_done = []
        for j in range(subs):
            port = topic.m_axis[j]
            m.d.comb += port.tready.eq(1)
            expect = Array(Signal(SEQ_BITS, name=f"expect{j}_{i}") for i in range(pubs))
            pos = Array(Signal(32, name=f"pos{j}_{i}") for i in range(pubs))
            index_bits = max(1, (pubs - 1).bit_length())
            current = Signal(index_bits)
            inside = Signal()
            word = port.tdata[:32]
            pub = word[SEQ_BITS:]
            seq = word[:SEQ_BITS]
            index = pub[:index_bits]
            beats = Array(self.beats)
            bad = Signal()
            lanes_differ = (port.tdata != Cat(*([word] * (width // 32)))) if width > 32 else 0
            m.d.comb += bad.eq((pub >= pubs) | (inside & (pub != current)) |
                               (seq != expect[index]) | lanes_differ |
                               (port.tlast != (pos[index] + 1 == beats[index])))
            done = Signal()
            all_done.append(done)
            m.d.comb += done.eq(self.sub_messages[j] == total)
            with m.If(self.start):
                m.d.sync += [self.sub_beats[j].eq(0), self.sub_messages[j].eq(0),
                             self.sub_errors[j].eq(0), inside.eq(0)]
                for i in range(pubs):
                    m.d.sync += [expect[i].eq(0), pos[i].eq(0)]
            with m.Elif(port.tvalid):
                m.d.sync += [self.sub_beats[j].eq(self.sub_beats[j] + 1),
                             self.sub_last[j].eq(self.cycle),
                             expect[index].eq(seq + 1), current.eq(index),
                             inside.eq(~port.tlast)]
                with m.If(self.sub_beats[j] == 0):
                    m.d.sync += self.sub_first[j].eq(self.cycle)
                with m.If(port.tlast):
                    m.d.sync += [self.sub_messages[j].eq(self.sub_messages[j] + 1),
                                 pos[index].eq(0)]
                with m.Else():
                    m.d.sync += pos[index].eq(pos[index] + 1)
                with m.If(bad):
                    m.d.sync += self.sub_errors[j].eq(self.sub_errors[j] + 1)
        m.d.comb += finished.eq(Cat(*all_done).all())
        done = Signal()
        with m.If(self.start):
            m.d.sync += done.eq(0)
        with m.Elif(running & finished):
            m.d.sync += done.eq(1)
        m.d.comb += self.done.eq(done)
        return m


def build_topic_bench_top(*, pubs, subs, data_width):
    """The topic traffic bench top (``topic_bench``), for :func:`tb.harness.run_bench`."""
    return TopicTrafficBench(pubs, subs, data_width)
