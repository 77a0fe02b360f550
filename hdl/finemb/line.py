"""A line of FinEmbP nodes, port 1 of each wired to port 0 of the next: what a simulation of
a fieldbus segment runs (docs/finemb.md)."""

from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import Out

from hdl.net.frames import int_to_mac

from ..params import check_int
from .node import PortSignature
from .pid_app import FinembPidNode
from .protocol import NodeState

__all__ = ["FinembLine", "line_mac"]


def line_mac(k):
    """The MAC address of node ``k`` of a line (locally administered)."""
    return int_to_mac(0x020000004600 + k + 1)


class FinembLine(wiring.Component):
    """``nodes`` :class:`~hdl.finemb.FinembPidNode` in a line: node 0's port 0 faces the
    master, node k's port 1 is wired to node k+1's port 0 (GMII transmit to receive, both
    ways, no PHY in between), the last node's port 1 is left open (its receive side idle).

    Parameters
    ----------
    descriptor : IoDescriptor
        Every node's application (the PID benchmark).
    nodes : int
        1..32.

    Members
    -------
    port0 : Out(PortSignature())
        Node 0's port 0: the master's link.
    state : Out(NodeState).array(nodes)
    node_id : Out(16).array(nodes)
    updates : Out(32).array(nodes)
        Each node's PID updates so far.
    """

    def __init__(self, descriptor, nodes):
        self._n = check_int("nodes", nodes, 1, 32)
        self._nodes = [FinembPidNode(descriptor, mac=line_mac(k), serial=k + 1)
                       for k in range(nodes)]
        super().__init__({
            "port0": Out(PortSignature()),
            "state": Out(NodeState).array(nodes), "node_id": Out(16).array(nodes),
            "updates": Out(32).array(nodes),
        })

    nodes = property(lambda self: list(self._nodes))

    def elaborate(self, platform):
        m = Module()
        nodes = self._nodes
        for k, node in enumerate(nodes):
            m.submodules[f"node{k}"] = node
            m.d.comb += [self.state[k].eq(node.state), self.node_id[k].eq(node.node_id),
                         self.updates[k].eq(node.updates), node.counter_index.eq(0)]
        wiring.connect(m, wiring.flipped(self.port0), nodes[0].port0)
        for a, b in zip(nodes, nodes[1:]):
            m.d.comb += [b.port0.rxd.eq(a.port1.txd), b.port0.rx_dv.eq(a.port1.tx_en),
                         b.port0.rx_er.eq(a.port1.tx_er),
                         a.port1.rxd.eq(b.port0.txd), a.port1.rx_dv.eq(b.port0.tx_en),
                         a.port1.rx_er.eq(b.port0.tx_er)]
        last = nodes[-1].port1
        m.d.comb += [last.rxd.eq(0), last.rx_dv.eq(0), last.rx_er.eq(0)]
        return m
