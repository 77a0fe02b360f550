"""The bench top of a FinEmbP line (``finemb_line`` benches): the product's
:class:`hdl.finemb.FinembLine` with a lossy cable on every link, the master's included, and
the signals the benches measure hop latency and loss with."""

from amaranth.hdl import ClockDomain, DomainRenamer, Module, ResetSignal, Signal
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from gen.finemb import load_io_description
from hdl.finemb import FinembLine
from hdl.net.mac import GmiiSignature
from hdl.finemb.protocol import NodeState
from hdl.params import check_int

__all__ = ["LossyLink", "FinembLineBench", "build_finemb_line_bench_top", "loss_threshold"]


def loss_threshold(fraction):
    """The ``loss_threshold`` of a loss probability."""
    return round(fraction * 65536)


class LossyLink(wiring.Component):
    """A :class:`hdl.finemb.line.Wire` that spoils frames at random, in both directions:
    at each frame's first cycle a 16-bit LFSR (one per direction, stepped every cycle) is
    drawn, and a draw below ``loss_threshold`` raises RX_ER on the frame's 21st byte, so its
    receiver drops it as a frame with a receive error, as it would a frame hit by noise.

    Members
    -------
    west, east : In(GmiiSignature())
    loss_threshold : In(16)
        Frames lost per 65536.
    lost : Out(16)
        Frames spoiled so far (both directions, wrapping).
    """

    def __init__(self, seed):
        self._seed = check_int("seed", seed, 1, 0xFFFF)
        super().__init__({"west": In(GmiiSignature()), "east": In(GmiiSignature()),
                          "loss_threshold": In(16), "lost": Out(16)})

    def elaborate(self, platform):
        m = Module()
        spoiled = []
        for d, (a, b) in enumerate(((self.west, self.east), (self.east, self.west))):
            lfsr = Signal(16, init=self._seed ^ (0x5A5A * d) or 1)
            # x^16 + x^14 + x^13 + x^11 + 1, Galois form
            m.d.sync += lfsr.eq((lfsr >> 1) ^ (0xB400 * lfsr[0]))
            was = Signal()
            spoil = Signal()
            count = Signal(6)
            m.d.sync += was.eq(a.tx_en)
            start = a.tx_en & ~was
            with m.If(start):
                m.d.sync += [spoil.eq(lfsr < self.loss_threshold), count.eq(0)]
            with m.Elif(a.tx_en & (count != 63)):
                m.d.sync += count.eq(count + 1)
            hit = spoil & a.tx_en & (count == 20)
            m.d.comb += [b.rxd.eq(a.txd), b.rx_dv.eq(a.tx_en), b.rx_er.eq(a.tx_er | hit)]
            spoiled.append(hit)
        with m.If(spoiled[0] | spoiled[1]):
            m.d.sync += self.lost.eq(self.lost + spoiled[0] + spoiled[1])
        return m


class FinembLineBench(wiring.Component):
    """A line of ``nodes`` PID nodes behind a lossy master link, every inner link lossy too.

    Members
    -------
    gmii_clk : In(1)
        The line's GMII clock (its links and the master's link run on it).
    port0 : Out(GmiiSignature())
        The master's link (through a :class:`LossyLink`).
    loss_threshold : In(16)
        Every link's (see :class:`LossyLink`).
    lost : Out(32)
        Frames spoiled on all links.
    state, node_id, updates, soc : arrays, as :class:`hdl.finemb.FinembLine`
    hop_in, hop_out : Out(1)
        Node 0's port 0 receive data valid and port 1 transmit enable: a forwarded frame's
        first byte in and out.
    """

    def __init__(self, descriptor, nodes, seed=1):
        self._links = []

        def link(k):
            self._links.append(LossyLink(seed=(seed * 977 + k * 131) % 65535 + 1))
            return self._links[-1]
        self._line = FinembLine(descriptor, nodes, link=link)
        self._master_link = LossyLink(seed=seed % 65535 + 1)
        super().__init__({
            "gmii_clk": In(1), "port0": Out(GmiiSignature()), "loss_threshold": In(16),
            "lost": Out(32),
            "state": Out(NodeState).array(nodes), "node_id": Out(16).array(nodes),
            "updates": Out(32).array(nodes), "soc": Out(1).array(nodes),
            "hop_in": Out(1), "hop_out": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.line = line = self._line
        # the master's link on the GMII clock (a domain name of its own: the line's and its
        # nodes' domains are local to them)
        m.domains += (cd := ClockDomain("master_link", local=True))
        m.d.comb += [cd.clk.eq(self.gmii_clk), line.gmii_clk.eq(self.gmii_clk)]
        m.submodules.link_reset = FFSynchronizer(ResetSignal("sync"), cd.rst,
                                                 o_domain="master_link", init=1)
        ml = self._master_link
        m.submodules.master_link = DomainRenamer("master_link")(ml)
        p = self.port0
        m.d.comb += [ml.west.txd.eq(p.rxd), ml.west.tx_en.eq(p.rx_dv), ml.west.tx_er.eq(p.rx_er),
                     p.txd.eq(ml.west.rxd), p.tx_en.eq(ml.west.rx_dv), p.tx_er.eq(ml.west.rx_er)]
        wiring.connect(m, line.port0, ml.east)
        far = line.port1
        m.d.comb += [far.rxd.eq(0), far.rx_dv.eq(0), far.rx_er.eq(0)]
        links = [ml] + self._links
        for link in links:
            m.d.comb += link.loss_threshold.eq(self.loss_threshold)
        m.d.comb += self.lost.eq(sum(link.lost for link in links))
        for name in ("state", "node_id", "updates", "soc"):
            for ours, theirs in zip(getattr(self, name), getattr(line, name)):
                m.d.comb += ours.eq(theirs)
        m.d.comb += [self.hop_in.eq(ml.east.rx_dv),
                     self.hop_out.eq(self._links[0].west.tx_en if self._links else far.tx_en)]
        return m


def build_finemb_line_bench_top(io, nodes, seed=1):
    """The bench top for ``run_bench(build=...)``: a line of ``nodes`` nodes described by
    the IO description file ``io``."""
    return FinembLineBench(load_io_description(io), nodes, seed)
