"""The one timer of a TCP session: retransmission, ARP retry, TIME-WAIT and FIN-WAIT-2
(docs/network.md "TCP session")."""

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import enum, wiring
from amaranth.lib.wiring import In, Out

from .codes import FIN_WAIT_2_SCALE, MAX_BACKOFF

__all__ = ["TimerMode", "TcpTimer"]


class TimerMode(enum.Enum, shape=2):
    """What the timer measures, which sets its limit and tick."""
    RETRANSMIT = 0      #: ``rto_cycles`` x 2**backoff
    ARP = 1             #: ``arp_retry_cycles``
    TIME_WAIT = 2       #: ``msl_cycles`` x 2 (2 MSL)
    FIN_WAIT_2 = 3      #: ``msl_cycles`` x 2**FIN_WAIT_2_SCALE


class TcpTimer(wiring.Component):
    """A 32-bit count of ticks, compared with a limit.

    A tick is 2**scale cycles, so the retransmission timeout doubles per back-off without a
    shifter, and TIME-WAIT lasts 2 MSL with the MSL register as its limit. The scale follows
    ``mode`` at once; the limit one cycle later (it is registered).

    Commands, at most one acting per cycle, in this priority: ``stop`` (zero, stopped),
    ``restart`` (zero, running), ``start`` (zero and running if stopped, else nothing),
    ``zero`` (zero, running or not); otherwise a running timer counts ticks.

    Members
    -------
    mode : In(TimerMode)
    rto_cycles, msl_cycles, arp_retry_cycles : In(32)
        The limits, in cycles (before the mode's scale).
    stop, restart, start, zero : In(1)
        Commands (above).
    back_off : In(1)
        Double the retransmission timeout (up to 2**MAX_BACKOFF times).
    backoff_reset : In(1)
        Back to one retransmission timeout (wins over ``back_off``).
    running : Out(1)
    done : Out(1)
        The count has reached the limit (running or not: TIME-WAIT ends on it).
    expired : Out(1)
        ``running`` and ``done``.
    """

    def __init__(self):
        super().__init__({
            "mode": In(TimerMode),
            "rto_cycles": In(32), "msl_cycles": In(32), "arp_retry_cycles": In(32),
            "stop": In(1), "restart": In(1), "start": In(1), "zero": In(1),
            "back_off": In(1), "backoff_reset": In(1),
            "running": Out(1), "done": Out(1), "expired": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        limit = Signal(32)
        backoff = Signal(range(MAX_BACKOFF + 1))
        prescaler = Signal(FIN_WAIT_2_SCALE)
        scale = Signal(range(FIN_WAIT_2_SCALE + 1))
        m.d.sync += prescaler.eq(prescaler + 1)
        with m.Switch(self.mode):
            with m.Case(TimerMode.RETRANSMIT):
                m.d.comb += scale.eq(backoff)
                m.d.sync += limit.eq(self.rto_cycles)
            with m.Case(TimerMode.ARP):
                m.d.comb += scale.eq(0)
                m.d.sync += limit.eq(self.arp_retry_cycles)
            with m.Case(TimerMode.TIME_WAIT):
                m.d.comb += scale.eq(1)
                m.d.sync += limit.eq(self.msl_cycles)
            with m.Case(TimerMode.FIN_WAIT_2):
                m.d.comb += scale.eq(FIN_WAIT_2_SCALE)
                m.d.sync += limit.eq(self.msl_cycles)
        tick = Cat(*(prescaler[b] | (scale <= b) for b in range(FIN_WAIT_2_SCALE))).all()
        # a command acts through three flip-flops: the count and the running flag this cycle
        # are what they would be had it acted on the registers at once, so the path from the
        # connection's decisions ends at those flip-flops, not at the count's 32 resets
        count_reg, running_reg = Signal(32), Signal()
        zero_pending, run_pending, run_set = Signal(), Signal(), Signal()
        count = Signal(32)
        m.d.comb += [count.eq(Mux(zero_pending, 0, count_reg)),
                     self.running.eq(Mux(run_set, run_pending, running_reg)),
                     self.done.eq(count >= limit), self.expired.eq(self.running & self.done)]
        m.d.sync += [count_reg.eq(count + (self.running & tick)), running_reg.eq(self.running),
                     zero_pending.eq(0), run_set.eq(0)]
        with m.If(self.stop):
            m.d.sync += [zero_pending.eq(1), run_set.eq(1), run_pending.eq(0)]
        with m.Elif(self.restart | (self.start & ~self.running)):
            m.d.sync += [zero_pending.eq(1), run_set.eq(1), run_pending.eq(1)]
        with m.Elif(self.zero):
            m.d.sync += zero_pending.eq(1)

        with m.If(self.backoff_reset):
            m.d.sync += backoff.eq(0)
        with m.Elif(self.back_off & (backoff != MAX_BACKOFF)):
            m.d.sync += backoff.eq(backoff + 1)
        return m
