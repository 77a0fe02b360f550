"""Event counters kept in distributed RAM (docs/network.md "counters")."""

from amaranth.hdl import Array, Module, Mux, Signal
from amaranth.lib import data, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int

__all__ = ["EventCounters"]


class EventCounters(wiring.Component):
    """Wrapping counters in one small RAM, with read ports for registers and status.

    Each counter has an accumulator that adds its event input every cycle; a service pointer
    visits one counter per cycle, round robin, and adds that counter's accumulator to its
    RAM word. A counter therefore shows an event at most ``len(names)`` cycles late; an
    accumulator is sized for the events one round can bring, so it never overflows. After
    reset, and after ``clear``, one round writes the accumulators instead of adding them,
    which clears the RAM.

    Parameters
    ----------
    names : sequence of str
        The counters, in the order of their read addresses.
    width : int
        Bits of each counter (they wrap).
    amounts : dict of str to int
        Bits of a counter's event input (1, a plain event, unless given here).
    readers : int
        Read ports.
    spacing : int
        Fewest cycles between two events of one counter (1: every cycle), which sizes the
        accumulators.

    Members
    -------
    events : In(StructLayout)
        One field per counter: the amount to add this cycle.
    rd_addr : In(ArrayLayout(range(len(names)), readers))
        Counter to read on each port ...
    rd_data : Out(ArrayLayout(width, readers))
        ... and its value, in the same cycle.
    clear : In(1)
        Set every counter to zero: the events of this cycle and later are counted, earlier
        ones are not. A counter shows the clear within ``len(names)`` cycles.
    """

    def __init__(self, names, *, width=32, amounts=None, readers=1, spacing=1):
        self._names = tuple(names)
        if not self._names or len(set(self._names)) != len(self._names):
            raise ParameterError("names", names, "distinct counter names")
        self._width = check_int("width", width, 1, 64)
        amounts = dict(amounts or {})
        for name in amounts:
            if name not in self._names:
                raise ParameterError("amounts", name, f"one of the counters {self._names}")
        self._amounts = {name: check_int(f"amounts[{name!r}]", amounts.get(name, 1), 1, width)
                         for name in self._names}
        self._readers = check_int("readers", readers, 1, 3)
        n = len(self._names)
        self._spacing = check_int("spacing", spacing, 1)
        super().__init__({
            "events": In(data.StructLayout(self._amounts)),
            "rd_addr": In(data.ArrayLayout(range(n), self._readers)),
            "rd_data": Out(data.ArrayLayout(self._width, self._readers)),
            "clear": In(1),
        })

    def elaborate(self, platform):
        m = Module()
        n = len(self._names)
        m.submodules.mem = mem = Memory(shape=self._width, depth=n, init=[])
        write = mem.write_port()
        current = mem.read_port(domain="comb")
        for k in range(self._readers):
            port = mem.read_port(domain="comb")
            m.d.comb += [port.addr.eq(self.rd_addr[k]), self.rd_data[k].eq(port.data)]

        # a clearing round starts at the service position of the reset or the clear and
        # ends when the pointer comes back to it
        service = Signal(range(n))
        next_service = Mux(service == n - 1, 0, service + 1)
        clearing = Signal(init=1)
        clear_at = Signal(range(n))
        m.d.sync += service.eq(next_service)
        with m.If(self.clear):
            m.d.sync += [clearing.eq(1), clear_at.eq(service)]
        with m.Elif(next_service == clear_at):
            m.d.sync += clearing.eq(0)
        per_round = -(-n // self._spacing)
        accumulators = [Signal((per_round * (2**self._amounts[name] - 1)).bit_length(),
                               name=f"acc_{name}") for name in self._names]
        for k, (name, acc) in enumerate(zip(self._names, accumulators)):
            event = self.events[name]
            with m.If((service == k) | self.clear):
                m.d.sync += acc.eq(event)
            with m.Else():
                m.d.sync += acc.eq(acc + event)
        m.d.comb += [current.addr.eq(service), write.addr.eq(service), write.en.eq(1),
                     write.data.eq(Mux(clearing | self.clear, 0, current.data) +
                                   Mux(self.clear, 0, Array(accumulators)[service]))]
        return m
