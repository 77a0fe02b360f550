"""A line of FinEmbP nodes, port 1 of each wired to port 0 of the next: the fieldbus segment a
simulation runs and a board carries (docs/finemb.md)."""

from amaranth.hdl import ClockDomain, DomainRenamer, Module, ResetSignal
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from hdl.net.frames import int_to_mac
from hdl.net.mac import GmiiSignature

from ..params import ParameterError, check_int
from .pid_app import FinembPidNode
from .protocol import NodeState

__all__ = ["Wire", "FinembLine", "line_mac"]


def line_mac(k):
    """The MAC address of node ``k`` of a line (locally administered)."""
    return int_to_mac(0x020000004600 + k + 1)


class Wire(wiring.Component):
    """The cable between two node ports: each side's transmit drives the other's receive.

    Members
    -------
    west, east : In(GmiiSignature())
        The two ports it joins (each side connects a node's ``Out(GmiiSignature())``).
    """

    def __init__(self):
        super().__init__({"west": In(GmiiSignature()), "east": In(GmiiSignature())})

    def elaborate(self, platform):
        m = Module()
        for a, b in ((self.west, self.east), (self.east, self.west)):
            m.d.comb += [b.rxd.eq(a.txd), b.rx_dv.eq(a.tx_en), b.rx_er.eq(a.tx_er)]
        return m


class FinembLine(wiring.Component):
    """``nodes`` :class:`~hdl.finemb.FinembPidNode` in a line: node k's port 1 is joined to
    node k+1's port 0 by a link (a :class:`Wire`, GMII transmit to receive both ways, unless
    ``link`` makes another, which runs on the line's GMII clock). Node 0's port 0 is the
    line's ``port0`` (the master's side), the last node's port 1 the line's ``port1`` (the far
    end: leave its receive side idle, or continue the line there).

    Parameters
    ----------
    descriptor : IoDescriptor
        Every node's application (the PID benchmark).
    nodes : int
        1..32.
    link : callable or None
        ``link(k)`` returns the component between node k and node k+1, with the members of
        :class:`Wire` (a fault-injecting cable in a bench).

    Members
    -------
    gmii_clk : In(1)
        Every node's GMII clock (a line's PHYs share one 125 MHz reference).
    port0, port1 : Out(GmiiSignature())
        The line's two ends.
    state : Out(NodeState).array(nodes)
    node_id : Out(16).array(nodes)
    updates : Out(32).array(nodes)
        Each node's PID updates so far.
    soc : Out(1).array(nodes)
        Each node's start-of-cycle pulse.
    """

    def __init__(self, descriptor, nodes, *, link=None):
        self._n = check_int("nodes", nodes, 1, 32)
        if link is not None and not callable(link):
            raise ParameterError("link", link, "a callable returning a link component, or None")
        self._nodes = [FinembPidNode(descriptor, mac=line_mac(k), serial=k + 1)
                       for k in range(nodes)]
        self._links = [(link or Wire)(*(() if link is None else (k,)))
                       for k in range(nodes - 1)]
        super().__init__({
            "gmii_clk": In(1), "port0": Out(GmiiSignature()), "port1": Out(GmiiSignature()),
            "state": Out(NodeState).array(nodes), "node_id": Out(16).array(nodes),
            "updates": Out(32).array(nodes), "soc": Out(1).array(nodes),
        })

    nodes = property(lambda self: list(self._nodes))
    links = property(lambda self: list(self._links))

    def elaborate(self, platform):
        m = Module()
        nodes = self._nodes
        for k, node in enumerate(nodes):
            m.submodules[f"node{k}"] = node
            m.d.comb += [self.state[k].eq(node.state), self.node_id[k].eq(node.node_id),
                         self.updates[k].eq(node.updates), self.soc[k].eq(node.soc),
                         node.counter_index.eq(0), node.gmii_clk.eq(self.gmii_clk)]
        # the links on the GMII clock, in a domain of their own name (each node has its own
        # local ``gmii`` domain, and a local domain is seen by the submodules)
        m.domains += (cd := ClockDomain("links", local=True))
        m.d.comb += cd.clk.eq(self.gmii_clk)
        m.submodules.links_reset = FFSynchronizer(ResetSignal("sync"), cd.rst,
                                                  o_domain="links", init=1)
        for k, link in enumerate(self._links):
            m.submodules[f"link{k}"] = DomainRenamer("links")(link)
            wiring.connect(m, nodes[k].port1, link.west)
            wiring.connect(m, nodes[k + 1].port0, link.east)
        wiring.connect(m, wiring.flipped(self.port0), nodes[0].port0)
        wiring.connect(m, wiring.flipped(self.port1), nodes[-1].port1)
        return m
