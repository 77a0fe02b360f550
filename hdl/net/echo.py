"""The network engine as a peer to try out from a host: RBCP registers in block RAM and TCP
sessions that send back what they receive (``rosgate tap engine``, docs/network.md)."""

from amaranth.hdl import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import check_power_of_two
from ..stream import RegisterSlice
from .frames import DEFAULT_IP, DEFAULT_MAC, DEFAULT_RBCP_PORT, DEFAULT_TCP_PORT
from .mac import GmiiSignature
from .stack import STACK_COUNTERS, NetStack

__all__ = ["EchoEngine"]


class EchoEngine(wiring.Component):
    """A :class:`NetStack` with something behind it: ``registers`` bytes of RAM at RBCP
    address 0 (read and written with SiTCP's RBCP, e.g. sitcpy), and every TCP session
    listening on the TCP port (``tcp_port``; several sessions serve as many connections) and
    echoing each byte it receives (through a register slice: no path runs from a session's
    receive ring into its transmit buffer). When the peer closes, the session closes too and
    listens again.

    Parameters
    ----------
    mac, ip, rbcp_port, tcp_port, sessions :
        As :class:`NetStack`.
    registers : int
        Bytes of register RAM, a power of two in 16..65536.
    buffer_bytes : int
        Each session's receive and transmit buffer (:class:`NetStack`'s ``rx_depth`` and
        ``tx_depth``; default 65536).

    Members
    -------
    gmii : Out(GmiiSignature(clocks=True))
        The Ethernet port, with its receive and transmit clocks (the engine's core runs on the
        ``sync`` clock at half their rate, :class:`NetStack` with two lanes).
    counter_index, counter_value :
        The engine's counters (:data:`~hdl.net.stack.STACK_COUNTERS`).
    """

    def __init__(self, *, mac=DEFAULT_MAC, ip=DEFAULT_IP, rbcp_port=DEFAULT_RBCP_PORT,
                 tcp_port=DEFAULT_TCP_PORT, sessions=2, registers=256, buffer_bytes=65536):
        self._registers = check_power_of_two("registers", registers, 16, 65536)
        self._stack = NetStack(mac=mac, ip=ip, rbcp_port=rbcp_port, tcp_port=tcp_port,
                               sessions=sessions, user_window=registers, user_width=16,
                               tx_depth=buffer_bytes, rx_depth=buffer_bytes)
        self._sessions = sessions
        super().__init__({"gmii": Out(GmiiSignature(clocks=self._stack.lanes == 2)),
                          "counter_index": In(range(len(STACK_COUNTERS))),
                          "counter_value": Out(32)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.stack = stack = self._stack
        stack.connect_gmii(m, self.gmii)
        m.d.comb += [stack.counter_index.eq(self.counter_index),
                     self.counter_value.eq(stack.counter_value)]

        # RBCP: register RAM, every access acknowledged the next cycle
        m.submodules.registers = mem = Memory(shape=8, depth=self._registers, init=[])
        wr, rd = mem.write_port(), mem.read_port()
        bus = stack.rbcp
        aw = (self._registers - 1).bit_length()
        ack = Signal()
        m.d.comb += [wr.addr.eq(bus.addr[:aw]), wr.data.eq(bus.wd), wr.en.eq(bus.we),
                     rd.addr.eq(bus.addr[:aw]), bus.rd.eq(rd.data), bus.ack.eq(ack)]
        m.d.sync += ack.eq(bus.we | bus.re)

        # TCP: listen, echo, close when the peer closes
        for k in range(self._sessions):
            s = getattr(stack, f"tcp{k}")
            m.submodules[f"echo{k}"] = echo = RegisterSlice(s.rx.signature)
            wiring.connect(m, s.rx, echo.s_axis)
            wiring.connect(m, echo.m_axis, s.tx)
            m.d.comb += [s.open_req.eq(1), s.active.eq(0), s.local_port.eq(0),
                         s.close_ack.eq(s.close_req)]
        return m
