"""Event counters kept in one RAM, distributed or block (docs/network.md, "Trimming the shared
blocks for a design")."""

from amaranth.hdl import Array, Module, Mux, Signal
from amaranth.lib import data, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_int

__all__ = ["EventCounters"]


class EventCounters(wiring.Component):
    """Wrapping counters in one RAM, with read ports for registers and status.

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
    block_ram : bool
        Keep the counters in a RAM with registered reads (block RAM): ``rd_data`` then
        shows the counter ``rd_addr`` named in the cycle before, and a counter shows an
        event or a clear at most ``len(names) + 1`` cycles late. Otherwise (the default) the
        RAM is read without a register (distributed RAM) and ``rd_data`` follows ``rd_addr``
        in the same cycle.
    spacing : int or dict of str to int
        Fewest cycles between two events of one counter (1: every cycle), which sizes the
        accumulators: one number for every counter, or a number per counter (1 for a counter
        the dict does not name). A counter whose events come no closer than a round
        (``len(names)`` cycles) needs a one-bit accumulator.

    Members
    -------
    events : In(StructLayout)
        One field per counter: the amount to add this cycle.
    rd_addr : In(ArrayLayout(range(len(names)), readers))
        Counter to read on each port ...
    rd_data : Out(ArrayLayout(width, readers))
        ... and its value, in the same cycle (with ``block_ram``, in the next).
    clear : In(1)
        Set every counter to zero: the events of this cycle and later are counted, earlier
        ones are not. A counter shows the clear within ``len(names)`` cycles.
    """

    def __init__(self, names, *, width=32, amounts=None, readers=1, spacing=1,
                 block_ram=False):
        self._block_ram = bool(block_ram)
        self._names = tuple(names)
        if not self._names or len(set(self._names)) != len(self._names):
            raise ParameterError("names", names, "distinct counter names")
        self._width = check_int("width", width, 1, 64)
        self._amounts = self._per_counter("amounts", amounts or {}, 1, width)
        self._readers = check_int("readers", readers, 1, 3)
        n = len(self._names)
        if not isinstance(spacing, dict):
            spacing = dict.fromkeys(self._names, check_int("spacing", spacing, 1))
        self._spacing = self._per_counter("spacing", spacing, 1)
        super().__init__({
            "events": In(data.StructLayout(self._amounts)),
            "rd_addr": In(data.ArrayLayout(range(n), self._readers)),
            "rd_data": Out(data.ArrayLayout(self._width, self._readers)),
            "clear": In(1),
        })

    def _per_counter(self, param, values, minimum, maximum=None):
        """``values`` (a dict by counter name) for every counter, 1 where it names none."""
        for name in values:
            if name not in self._names:
                raise ParameterError(param, name, f"one of the counters {self._names}")
        return {name: check_int(f"{param}[{name!r}]", values.get(name, 1), minimum, maximum)
                for name in self._names}

    def elaborate(self, platform):
        m = Module()
        n = len(self._names)
        m.submodules.mem = mem = Memory(shape=self._width, depth=n, init=[], attrs=(
            {"ram_style": "block"} if self._block_ram else {}))
        write = mem.write_port()
        read_domain = "sync" if self._block_ram else "comb"
        # (a registered read of the only counter must see the write of the cycle before)
        current = mem.read_port(domain=read_domain,
                                transparent_for=(write,) if self._block_ram and n == 1 else ())
        for k in range(self._readers):
            port = mem.read_port(domain=read_domain)
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
        accumulators = [Signal((-(-n // self._spacing[name]) *
                                (2**self._amounts[name] - 1)).bit_length(),
                               name=f"acc_{name}") for name in self._names]
        for k, (name, acc) in enumerate(zip(self._names, accumulators)):
            event = self.events[name]
            with m.If((service == k) | self.clear):
                m.d.sync += acc.eq(event)
            with m.Else():
                m.d.sync += acc.eq(acc + event)
        zero = clearing | self.clear
        add = Mux(self.clear, 0, Array(accumulators)[service])
        m.d.comb += current.addr.eq(service)
        if self._block_ram:
            # the word read in the service cycle is written back in the next
            w_addr, w_zero, w_en = Signal.like(service), Signal(), Signal()
            w_add = Signal(max(len(acc) for acc in accumulators))
            m.d.sync += [w_addr.eq(service), w_zero.eq(zero), w_add.eq(add), w_en.eq(1)]
            m.d.comb += [write.addr.eq(w_addr), write.en.eq(w_en),
                         write.data.eq(Mux(w_zero, 0, current.data) + w_add)]
        else:
            m.d.comb += [write.addr.eq(service), write.en.eq(1),
                         write.data.eq(Mux(zero, 0, current.data) + add)]
        return m
