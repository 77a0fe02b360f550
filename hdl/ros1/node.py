"""A ROS 1 hardware node: one network engine and a TCPROS endpoint per TCP session, with
the endpoints' registers on RBCP (docs/network.md; seed paper Fig. 8)."""

from amaranth.hdl import Array, Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..net.stack import STACK_COUNTERS, NetStack
from ..params import ParameterError, check_int
from .registers import ENDPOINT_STRIDE, PHASES
from .tcpros import ROLES, TcprosEndpoint, message_stream_signature

__all__ = ["TcprosNode"]


class TcprosNode(wiring.Component):
    """Network engine plus TCPROS endpoints, as the seed paper's FPGA component: software
    keeps XML-RPC and writes each endpoint's registers over RBCP; the hardware carries the
    data connections.

    Parameters
    ----------
    endpoints : sequence of str
        Role of each endpoint (``"publisher"`` or ``"subscriber"``); endpoint ``k`` uses TCP
        session ``k`` and registers at ``k * 0x10000``.
    loopback : sequence of (int, int)
        ``(subscriber, publisher)`` pairs whose received messages are published again
        unchanged (the paper's receive-and-send-back component); those endpoints have no
        user port.
    **stack
        :class:`~hdl.net.NetStack` parameters (``mac``, ``ip``, ``tx_depth``, ``lanes``, ...;
        the sessions' user streams are as wide as the engine, ``8 * lanes`` bits).

    Members
    -------
    gmii_* : GMII to the PHY; with an engine of two lanes (the default) also its receive
        and transmit clocks ``gmii_rx_clk``, ``gmii_tx_clk``, the node on ``sync`` at half
        their rate (:class:`~hdl.net.stack.NetStack`).
    pub<k> : In(message_stream_signature(lanes))
        Messages for publisher endpoint ``k``.
    sub<k> : Out(message_stream_signature(lanes))
        Messages from subscriber endpoint ``k``.
    phase<k> : Out
        Endpoint ``k``'s phase (:data:`~hdl.ros1.registers.PHASES`).
    counter_index, counter_value : In, Out
        One of the engine's :data:`~hdl.net.stack.STACK_COUNTERS` (see
        :class:`~hdl.net.stack.NetStack`).
    """

    def __init__(self, endpoints, *, loopback=(), **stack):
        endpoints = list(endpoints)
        if not 1 <= len(endpoints) <= 8:
            raise ParameterError("endpoints", endpoints, "a list of 1..8 roles")
        for k, role in enumerate(endpoints):
            if role not in ROLES:
                raise ParameterError(f"endpoints[{k}]", role, "'publisher' or 'subscriber'")
        self._roles = endpoints
        self._loopback = []
        for pair in loopback:
            sub, pub = pair
            check_int("loopback subscriber", sub, 0, len(endpoints) - 1)
            check_int("loopback publisher", pub, 0, len(endpoints) - 1)
            if endpoints[sub] != "subscriber" or endpoints[pub] != "publisher":
                raise ParameterError("loopback", pair,
                                     "(subscriber index, publisher index) pairs")
            self._loopback.append((sub, pub))
        lanes = stack.get("lanes", 2)
        self._stack_params = dict(stack, sessions=len(endpoints), user_width=8 * lanes,
                                  user_window=len(endpoints) * ENDPOINT_STRIDE)
        self._stack = NetStack(**self._stack_params)
        self._lanes = self._stack.lanes
        looped = {i for pair in self._loopback for i in pair}
        members = {"gmii_txd": Out(8), "gmii_tx_en": Out(1), "gmii_tx_er": Out(1),
                   "gmii_rxd": In(8), "gmii_rx_dv": In(1), "gmii_rx_er": In(1)}
        if self._stack.lanes == 2:
            members.update({"gmii_rx_clk": In(1), "gmii_tx_clk": In(1)})
        for k, role in enumerate(endpoints):
            if k not in looped:
                if role == "publisher":
                    members[f"pub{k}"] = In(message_stream_signature(self._lanes))
                else:
                    members[f"sub{k}"] = Out(message_stream_signature(self._lanes))
            members[f"phase{k}"] = Out(range(len(PHASES)))
        members["local_mac"] = Out(48)
        members["local_ip"] = Out(32)
        members["counter_index"] = In(range(len(STACK_COUNTERS)))
        members["counter_value"] = Out(32)
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        m.submodules.stack = stack = self._stack
        inputs = ("gmii_rxd", "gmii_rx_dv", "gmii_rx_er")
        if stack.lanes == 2:
            inputs += ("gmii_rx_clk", "gmii_tx_clk")
        for name in inputs:
            m.d.comb += getattr(stack, name).eq(getattr(self, name))
        for name in ("gmii_txd", "gmii_tx_en", "gmii_tx_er", "local_mac", "local_ip",
                     "counter_value"):
            m.d.comb += getattr(self, name).eq(getattr(stack, name))
        m.d.comb += stack.counter_index.eq(self.counter_index)

        endpoints = []
        for k, role in enumerate(self._roles):
            ep = TcprosEndpoint(role, endpoints=len(self._roles), lanes=self._lanes)
            m.submodules[f"endpoint{k}"] = ep
            endpoints.append(ep)
            wiring.connect(m, getattr(stack, f"tcp{k}"), ep.tcp)
            m.d.comb += getattr(self, f"phase{k}").eq(ep.phase)
            if f"pub{k}" in self.signature.members:
                wiring.connect(m, wiring.flipped(getattr(self, f"pub{k}")), ep.s_axis)
            if f"sub{k}" in self.signature.members:
                wiring.connect(m, ep.m_axis, wiring.flipped(getattr(self, f"sub{k}")))
        for sub, pub in self._loopback:
            wiring.connect(m, endpoints[sub].m_axis, endpoints[pub].s_axis)

        # RBCP: endpoint k at k * 0x10000
        bus = stack.rbcp
        low = ENDPOINT_STRIDE.bit_length() - 1
        sel = bus.addr[low:low + 3]
        for k, ep in enumerate(endpoints):
            hit = sel == k
            m.d.comb += [ep.regs.addr.eq(bus.addr), ep.regs.wd.eq(bus.wd),
                         ep.regs.we.eq(bus.we & hit), ep.regs.re.eq(bus.re & hit),
                         ep.regs.act.eq(bus.act)]
        owner = Signal(range(max(len(endpoints), 2)))
        with m.If(bus.we | bus.re):
            m.d.sync += owner.eq(sel)
        m.d.comb += [bus.ack.eq(Array(ep.regs.ack for ep in endpoints)[owner]),
                     bus.rd.eq(Array(ep.regs.rd for ep in endpoints)[owner])]
        return m
