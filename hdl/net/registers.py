"""The network engine's own registers on the RBCP bus, the "global block" (docs/network.md
"The engine's own registers")."""

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import ParameterError
from .frames import DROP_REASONS
from .rbcp import RbcpBusSignature

__all__ = ["STACK_COUNTERS", "GLOBAL_BASE", "GLOBAL_REGS", "GLOBAL_OFFSETS", "global_register",
           "GlobalRegisters"]

#: Stack counters, in the order of their read addresses (``counter_index``, RBCP): every
#: received frame ends in exactly one of ``delivered`` and the drop reasons;
#: ``tcp_bad_options`` counts TCP segments that passed every check and had malformed
#: options (processed all the same, docs/network.md).
STACK_COUNTERS = ("frames_in", "delivered") + DROP_REASONS + ("frames_out", "tcp_bad_options")

#: RBCP base of the stack's own registers (docs/network.md "global block")
GLOBAL_BASE = 0xFFFF0000
#: offset -> (name, bytes, writable) of the global block; multi-byte values big-endian
GLOBAL_REGS = {
    0x00: ("mac", 6, True),
    0x08: ("ip", 4, True),
    0x0C: ("rto_cycles", 4, True),
    0x10: ("msl_cycles", 4, True),
    0x14: ("rbcp_port", 2, True),
    0x18: ("arp_retry_cycles", 4, True),
    0x1C: ("tcp_port", 2, True),
    0x40: ("counters", 4 * len(STACK_COUNTERS), False),
}
#: name -> offset of the global block's registers
GLOBAL_OFFSETS = {name: offset for offset, (name, _, _) in GLOBAL_REGS.items()}
#: the counter index is offset bits 2..5: the counters are 64-byte aligned, at most 16
assert GLOBAL_OFFSETS["counters"] % 64 == 0 and len(STACK_COUNTERS) <= 16


def global_register(name):
    """``(RBCP address, bytes)`` of the global block's register ``name``."""
    offset = GLOBAL_OFFSETS[name]
    return GLOBAL_BASE + offset, GLOBAL_REGS[offset][1]


class GlobalRegisters(wiring.Component):
    """The global block at :data:`GLOBAL_BASE`: the engine's settings and counters, and the
    user's window everywhere else on the bus.

    A byte access inside the 64 KiB block is answered the cycle after its strobe (reads of
    unused offsets return 0, writes to them and to the counters do nothing); any other
    address passes to ``user`` unchanged, and ``user``'s acknowledge and data come back.

    Parameters
    ----------
    init : dict of str to int
        Reset value of each writable register of :data:`GLOBAL_REGS`.

    Members
    -------
    bus : In(RbcpBusSignature())
        From the RBCP server.
    user : Out(RbcpBusSignature())
        To the user's registers (strobes only outside the block).
    mac, ip, rto_cycles, msl_cycles, rbcp_port, arp_retry_cycles, tcp_port : Out
        The registers' values.
    counter_index : Out(range(len(STACK_COUNTERS)))
        The counter a read of the counters addresses ...
    counter_value : In(32)
        ... returns (big-endian 32-bit words, the first counter first).
    """

    def __init__(self, init):
        widths = {name: 8 * size for name, size, writable in GLOBAL_REGS.values() if writable}
        missing = set(widths) - set(init)
        if missing:
            raise ParameterError("init", sorted(missing)[0], "a value for every register")
        for name, value in init.items():
            if name not in widths or not 0 <= value < 2 ** widths[name]:
                raise ParameterError(f"init[{name!r}]", value,
                                     f"one of {sorted(widths)} with {widths.get(name)} bits")
        members = {"bus": In(RbcpBusSignature()), "user": Out(RbcpBusSignature()),
                   "counter_index": Out(range(len(STACK_COUNTERS))), "counter_value": In(32)}
        members.update({name: Out(width, init=init[name]) for name, width in widths.items()})
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        bus, user = self.bus, self.user
        inside = bus.addr[16:] == (GLOBAL_BASE >> 16)
        m.d.comb += [user.act.eq(bus.act), user.addr.eq(bus.addr), user.wd.eq(bus.wd),
                     user.we.eq(bus.we & ~inside), user.re.eq(bus.re & ~inside)]
        ack = Signal()
        rd = Signal(8)
        m.d.sync += ack.eq((bus.we | bus.re) & inside)
        m.d.comb += [bus.ack.eq(Mux(inside, ack, user.ack)), bus.rd.eq(Mux(inside, rd, user.rd))]

        offset = bus.addr[:16]
        m.d.comb += self.counter_index.eq(offset[2:6])
        with m.Switch(offset):
            for base, (name, size, writable) in GLOBAL_REGS.items():
                if name == "counters":
                    with m.Case(*range(base, base + size)):
                        m.d.sync += rd.eq(self.counter_value.word_select(~offset[:2], 8))
                    continue
                value = getattr(self, name)
                for b in range(size):
                    with m.Case(base + b):
                        byte = value.word_select(size - 1 - b, 8)
                        m.d.sync += rd.eq(byte)
                        if writable:
                            with m.If(bus.we & inside):
                                m.d.sync += byte.eq(bus.wd)
            with m.Default():
                m.d.sync += rd.eq(0)
        return m
