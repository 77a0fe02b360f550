"""Boards: rosgate's network designs as bitstreams for ECP5 boards with Gigabit RGMII PHYs
(``rosgate board``, docs/boards.md).

Pins come from amaranth-boards' platform definitions, never from this file. What the
definitions do not say is board data kept here: the PHY chips and the RGMII delays the FPGA
adds (those of LiteEth's targets for the same boards). The board layer adapts the
definitions where rosgate needs more than they allow: the Colorlight 5A-75B's two RGMII ports
share one PHY reset, MDC and MDIO, which amaranth-boards defines on both ports, so the second
port is requested without the subsignals whose pins the first already has.
"""

import importlib
from dataclasses import dataclass, field

from amaranth import ClockDomain, ClockSignal, Elaboratable, Module, Mux, Signal
from amaranth.build import DiffPairs, Resource
from amaranth.hdl import Instance
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer, ResetSynchronizer

__all__ = ["Board", "BOARDS", "BoardError", "board", "board_platform", "rgmii_ports",
           "ehxplll", "NetBoardTop", "EngineBoardTop", "TcprosBoardTop", "FinembBoardTop",
           "RGMII_RAW"]

#: the RGMII subsignals the PHY adapter drives itself (raw ports, no Amaranth buffer)
RGMII_RAW = ("tx_clk", "tx_ctl", "tx_data", "rx_clk", "rx_ctl", "rx_data")
#: amaranth-boards' other spellings of them
_ALIASES = {"tx_ctrl": "tx_ctl", "rx_ctrl": "rx_ctl"}
#: the PHY's reset: held this long after the clocks are up (the PHYs ask for 10 ms or less)
PHY_RESET_US = 10_000


class BoardError(ValueError):
    """A board or design rosgate cannot build; the message says which and why."""


@dataclass(frozen=True)
class Board:
    """A board rosgate builds for.

    Attributes
    ----------
    name : str
        Its name on the command line.
    platform : str
        ``module:Class`` of its amaranth-boards platform.
    title : str
    phys : tuple of str
        The PHY chip on each RGMII port.
    rx_delay_ns, tx_delay_ns : float
        The receive and transmit clock-to-data delays the FPGA adds (DELAYG taps of 25 ps):
        what a PHY does not add itself.
    """
    name: str
    platform: str
    title: str
    phys: tuple
    rx_delay_ns: float
    tx_delay_ns: float
    #: a TCP session's receive and transmit buffer each, in bytes (a DP16KD holds 2 KiB): 16
    #: KiB keeps two sessions within the smallest device's 56 DP16KD and the buffers close
    #: together on the larger ones (64 KiB spread them so far that the engine's clock missed
    #: 62.5 MHz on the ButterStick)
    buffer_bytes: int = 16384
    notes: tuple = field(default_factory=tuple)

    def platform_class(self):
        module, cls = self.platform.split(":")
        return getattr(importlib.import_module(module), cls)

    @property
    def rx_delay_taps(self):
        return round(self.rx_delay_ns * 1000 / 25)

    @property
    def tx_delay_taps(self):
        return round(self.tx_delay_ns * 1000 / 25)

    def fpga(self):
        """``LFE5U-25F-6BG256``: device, speed grade and package of the platform."""
        p = self.platform_class()
        return f"{p.device}-{p.speed}{p.package}"


BOARDS = {b.name: b for b in (
    Board("colorlight_5a75b_r7_0",
          "amaranth_boards.colorlight_5a75b_r7_0:Colorlight_5A75B_R70Platform",
          "Colorlight 5A-75B v7.0", ("Broadcom B50612D", "Broadcom B50612D"),
          rx_delay_ns=2.0, tx_delay_ns=0.0,
          notes=("both ports share the PHYs' reset, MDC and MDIO",)),
    Board("butterstick", "amaranth_boards.butterstick:ButterStickPlatform",
          "ButterStick r1.0", ("Microchip KSZ9031RNX",), rx_delay_ns=0.0, tx_delay_ns=2.0,
          notes=("the KSZ9031RNX adds about 1.2 ns to the receive clock itself",)),
    Board("versa_ecp5", "amaranth_boards.versa_ecp5:VersaECP5Platform",
          "Lattice ECP5 Versa (LFE5UM-45F)", ("Marvell 88E1512", "Marvell 88E1512"),
          rx_delay_ns=0.0, tx_delay_ns=0.0,
          notes=("the PHYs are strapped to delay both RGMII clocks themselves",)),
    Board("ecpix5_85", "amaranth_boards.ecpix5:ECPIX585Platform", "LambdaConcept ECPIX-5 85F",
          ("RGMII PHY",), rx_delay_ns=0.0, tx_delay_ns=2.0),
    Board("logicbone_85", "amaranth_boards.logicbone:Logicbone85FPlatform",
          "Logicbone ECP5 85F", ("RGMII PHY",), rx_delay_ns=2.0, tx_delay_ns=2.0,
          notes=("LiteEth's target adds both RGMII delays in the FPGA",)),
)}


def board(name):
    """The :class:`Board` called ``name``, or a :class:`BoardError` listing the boards (and,
    for a board amaranth-boards defines, why rosgate does not build for it)."""
    try:
        return BOARDS[name]
    except KeyError:
        known = f"rosgate knows {', '.join(sorted(BOARDS))} (rosgate board list)"
        why = _unsupported(name)
        raise BoardError(f"--board {name!r}: {why + '; ' if why else ''}{known}") from None


def _unsupported(name):
    """Why an amaranth-boards board called ``name`` is not one rosgate builds for, or
    ``None`` when amaranth-boards has no such board."""
    try:
        module = importlib.import_module(f"amaranth_boards.{name}")
    except ImportError:
        return None
    from amaranth.vendor import LatticeECP5Platform
    platforms = [p for p in vars(module).values() if isinstance(p, type)
                 and hasattr(p, "resources") and isinstance(getattr(p, "device", None), str)]
    if not platforms:
        return None
    ethernet = sorted({r.name for p in platforms for r in p.resources
                       if r.name.startswith("eth") and "clk" not in r.name})
    if not any(issubclass(p, LatticeECP5Platform) for p in platforms):
        return f"{name} is not an ECP5 board ({platforms[0].device})"
    ours = [b.name for b in BOARDS.values() if b.platform.startswith(f"amaranth_boards.{name}:")]
    if ours:
        return f"amaranth-boards' {name} module is built for as {', '.join(ours)}"
    if "eth_rgmii" not in ethernet:
        return (f"{name}'s Ethernet is {', '.join(ethernet) or 'absent'}: rosgate's PHY "
                f"adapter speaks RGMII only")
    return f"{name} has an RGMII port, but rosgate has no board data (PHYs, delays) for it"


def rgmii_ports(platform):
    """The numbers of the platform's ``eth_rgmii`` resources."""
    return sorted(number for name, number in platform.resources if name == "eth_rgmii")


def board_platform(b):
    """An instance of ``b``'s platform for building: no programming tool required, every
    RGMII port requestable (``request_rgmii``)."""
    base = b.platform_class()

    class BoardPlatform(base):
        @property
        def required_tools(self):
            return ["yosys", "nextpnr-ecp5", "ecppack"]

        def request_rgmii(self, number):
            """RGMII port ``number`` with raw data and clock pins (:data:`RGMII_RAW`) and
            buffered ``rst``; a subsignal whose pins an earlier port already has (a shared
            PHY reset, MDC, MDIO) is left out, so the port has no ``rst`` then."""
            resource = self.resources["eth_rgmii", number]
            taken = set()
            for other in rgmii_ports(self):
                if other < number:
                    for sub in self.resources["eth_rgmii", other].ios:
                        taken.update(_pins(sub))
            kept = [sub for sub in resource.ios if not (set(_pins(sub)) & taken)]
            name = f"eth_rgmii_port{number}"
            if (name, number) not in self.resources:
                self.add_resources([Resource(name, number, *kept, resource.attrs)])
            present = {sub.name for sub in kept}
            want = {sub: "-" for sub in present if _ALIASES.get(sub, sub) in RGMII_RAW}
            port = self.request(name, number, dir=want)
            return _Rgmii(port, present)

    return BoardPlatform()


def _pins(subsignal):
    pins = subsignal.ios[0]
    return tuple(getattr(pins, "names", ()) or (getattr(pins, "p", None),))


class _Rgmii:
    """A requested RGMII port under rosgate's names (``tx_ctl``/``rx_ctl`` whatever the board
    calls them)."""

    def __init__(self, port, present):
        self._port = port
        for name in present:
            setattr(self, _ALIASES.get(name, name), getattr(port, name))
        self.shares_reset = "rst" not in present


def ehxplll(params, clk_in, clk_op, clk_os, locked):
    """The ``EHXPLLL`` instance of ``params`` (:func:`host.board.pll_parameters`: the
    parameters by name, the attributes under ``"attrs"``), CLKOP fed back."""
    attrs = {f"a_{k}": v for k, v in params["attrs"].items()}
    values = {f"p_{k}": v for k, v in params.items() if k != "attrs"}
    return Instance("EHXPLLL", **attrs, **values,
                    i_RST=0, i_STDBY=0, i_CLKI=clk_in, o_CLKOP=clk_op, o_CLKOS=clk_os,
                    i_CLKFB=clk_op, i_PHASESEL0=0, i_PHASESEL1=0, i_PHASEDIR=1,
                    i_PHASESTEP=1, i_PHASELOADREG=1, i_PLLWAKESYNC=0, i_ENCLKOP=0,
                    o_LOCK=locked)


def _status_leds(platform):
    """The board's plain LEDs (``led``), else the green of its RGB LEDs (``rgb_led``): output
    signals, first first; none on a board with neither."""
    leds = []
    for name, number in sorted(platform.resources):
        if name == "led":
            leds.append(platform.request("led", number).o)
    if not leds:
        for name, number in sorted(platform.resources):
            if name == "rgb_led":
                leds.append(platform.request("rgb_led", number).g.o)
    return leds


class _BoardTop(Elaboratable):
    """What every board design has: the board's oscillator into an EHXPLLL making 125 MHz
    (``clk125``: the RGMII transmit clock) and 62.5 MHz (``sync``: the design's core clock),
    ``sync`` out of reset once the PLL has locked (a reset synchroniser), each used RGMII
    port's PHY held in reset for :data:`PHY_RESET_US` after that with MDC low and MDIO
    released (the PHYs' defaults serve 1000 Mb/s RGMII), and the status LEDs (docs/boards.md
    "LEDs"): the first blinks once a second while ``sync`` runs, the next ones light for
    about 50 ms on each frame received on port 0, 1, ..."""

    SYNC_MHZ = 62.5
    GMII_MHZ = 125.0

    def __init__(self, b, *, pll):
        self.board = b
        #: the EHXPLLL's parameters for GMII_MHZ and SYNC_MHZ from the board's oscillator
        self.pll = pll
        #: input clocks the LPF constrains by their pin (``FREQUENCY PORT``): name -> MHz
        self.pin_clocks = {}
        #: a clock net's name after synthesis (without ``$glbnet$``), or its last part -> what
        #: the clock is
        self.clock_names = {"clk": "sync (62.5 MHz, the core)",
                            "clk125": "gmii_tx (125 MHz, TXC)"}
        #: the top's port names (after elaboration): ``oscillator`` and, per used RGMII port,
        #: its raw pins by :data:`RGMII_RAW` name (what a simulation drives and watches)
        self.sim_pins = {"oscillator": None, "ports": []}

    def _clocks(self, m, platform):
        osc = platform.request(platform.default_clk)
        # a differential oscillator is one port, its positive pin
        pair = isinstance(platform.resources[platform.default_clk, 0].ios[0], DiffPairs)
        self.sim_pins["oscillator"] = f"{platform.default_clk}_0__{'p' if pair else 'io'}"
        # nextpnr derives the PLL's output clocks from the oscillator's constraint
        clk125, clk62, locked = Signal(name="clk125"), Signal(name="clk62"), Signal()
        m.submodules.pll = ehxplll(self.pll, osc.i, clk125, clk62, locked)
        m.domains.sync = ClockDomain("sync")
        m.d.comb += ClockSignal("sync").eq(clk62)
        m.submodules.sync_reset = ResetSynchronizer(~locked, domain="sync")
        return clk125, locked

    def _port(self, m, platform, k, number, locked):
        """RGMII port ``number`` as the design's port ``k``: its PHY adapter, PHY reset and
        receive clock domain ``port<k>_rx`` (reset until the PLL has locked)."""
        from hdl.net.rgmii import RgmiiPhy
        pins = platform.request_rgmii(number)
        m.submodules[f"phy{k}"] = phy = RgmiiPhy(pins, rx_delay_taps=self.board.rx_delay_taps,
                                                 tx_delay_taps=self.board.tx_delay_taps)
        self.pin_clocks[pins.rx_clk.io.name] = self.GMII_MHZ
        self.sim_pins["ports"].append({sub: getattr(pins, sub).io.name for sub in RGMII_RAW})
        self.clock_names[f"phy{k}.rx_clk"] = f"port{k} rx (125 MHz, the PHY's RXC)"
        domain = ClockDomain(f"port{k}_rx", local=True)
        m.domains += domain
        m.d.comb += domain.clk.eq(phy.rx_clk)
        m.submodules[f"port{k}_rx_reset"] = ResetSynchronizer(~locked, domain=domain.name)
        if hasattr(pins, "rst"):
            hold = int(PHY_RESET_US * self.SYNC_MHZ)
            count = Signal(range(hold + 1), name=f"phy{k}_reset_count")
            with m.If(count != hold):
                m.d.sync += count.eq(count + 1)
            m.d.comb += pins.rst.o.eq(count != hold)
        if hasattr(pins, "mdc"):
            m.d.comb += [pins.mdc.o.eq(0), pins.mdio.oe.eq(0)]
        return phy

    def _leds(self, m, platform, frames):
        """The status LEDs: heartbeat, then one per entry of ``frames`` (levels that toggle
        on each frame received, in their port's receive domain)."""
        leds = _status_leds(platform)
        if not leds:
            return
        second = int(self.SYNC_MHZ * 1e6)
        beat = Signal(range(second))
        blink = Signal()
        m.d.sync += beat.eq(Mux(beat == second - 1, 0, beat + 1))
        with m.If(beat == second - 1):
            m.d.sync += blink.eq(~blink)
        m.d.comb += leds[0].eq(blink)
        for led, toggle in zip(leds[1:], frames):
            synced, last = Signal(), Signal()
            flash = Signal(range(second // 20 + 1))
            m.submodules += FFSynchronizer(toggle, synced)
            m.d.sync += last.eq(synced)
            with m.If(synced != last):
                m.d.sync += flash.eq(second // 20)
            with m.Elif(flash != 0):
                m.d.sync += flash.eq(flash - 1)
            m.d.comb += led.eq(flash != 0)


def _toggle_on(m, domain, event):
    """A level that toggles on each rising edge of ``event`` in ``domain`` (to cross it)."""
    level, last = Signal(), Signal()
    m.d[domain] += last.eq(event)
    with m.If(event & ~last):
        m.d[domain] += level.eq(~level)
    return level


class NetBoardTop(_BoardTop):
    """A design on the network engine (``core``: an :class:`hdl.net.echo.EchoEngine` or an
    :class:`hdl.ros1.TcprosNode`, two lanes) on the board's first RGMII port: the PHY's
    receive clock drives the engine's ``gmii_rx`` domain, 125 MHz its ``gmii_tx``; the
    engine synchronises its reset into both."""

    def __init__(self, b, core, *, pll):
        super().__init__(b, pll=pll)
        self.core = core
        self.clock_names.update({"gmii_rx_clk": "port0 rx (125 MHz, the PHY's RXC)",
                                 "gmii_tx_clk": "gmii_tx (125 MHz, TXC)"})

    def _gmii(self):
        core = self.core
        if hasattr(core, "gmii"):
            g = core.gmii
            return {name: getattr(g, name) for name in g.signature.members}
        return {name.removeprefix("gmii_"): getattr(core, name)
                for name in core.signature.members if name.startswith("gmii_")}

    def elaborate(self, platform):
        m = Module()
        clk125, locked = self._clocks(m, platform)
        phy = self._port(m, platform, 0, rgmii_ports(platform)[0], locked)
        m.submodules.core = self.core
        gmii = self._gmii()
        m.d.comb += [phy.tx_clk.eq(clk125), gmii["tx_clk"].eq(clk125),
                     gmii["rx_clk"].eq(phy.rx_clk),
                     phy.gmii_txd.eq(gmii["txd"]), phy.gmii_tx_en.eq(gmii["tx_en"]),
                     phy.gmii_tx_er.eq(gmii["tx_er"]), gmii["rxd"].eq(phy.gmii_rxd),
                     gmii["rx_dv"].eq(phy.gmii_rx_dv), gmii["rx_er"].eq(phy.gmii_rx_er)]
        self._leds(m, platform, [_toggle_on(m, "port0_rx", phy.gmii_rx_dv)])
        return m


class EngineBoardTop(NetBoardTop):
    """The TCP/IP engine (:class:`hdl.net.echo.EchoEngine`: ARP, ICMP echo, RBCP registers,
    TCP echo sessions) on a board's first RGMII port (:class:`NetBoardTop`)."""

    def __init__(self, b, *, pll, mac, ip, sessions=2, registers=256, buffer_bytes=None):
        from hdl.net.echo import EchoEngine
        engine = EchoEngine(mac=mac, ip=ip, sessions=sessions, registers=registers,
                            buffer_bytes=buffer_bytes or b.buffer_bytes)
        super().__init__(b, engine, pll=pll)


class TcprosBoardTop(NetBoardTop):
    """The SiTCP ROS component's design (:class:`hdl.ros1.TcprosNode`): a subscriber endpoint
    whose messages a publisher endpoint sends on unchanged, any message type (the ROS master
    side in software writes the endpoints' registers over RBCP, docs/ros1.md), on a board's
    first RGMII port (:class:`NetBoardTop`). The messages pass from one endpoint to the other
    through a register slice, so that no path runs from the subscriber's receive ring through
    both endpoints."""

    def __init__(self, b, *, pll, mac, ip, buffer_bytes=None):
        from hdl.ros1 import TcprosNode
        depth = buffer_bytes or b.buffer_bytes
        node = TcprosNode(["subscriber", "publisher"], mac=mac, ip=ip, tx_depth=depth,
                          rx_depth=depth)
        super().__init__(b, node, pll=pll)

    def elaborate(self, platform):
        from hdl.ros1.tcpros import message_stream_signature
        from hdl.stream import RegisterSlice
        m = super().elaborate(platform)
        m.submodules.relay = relay = RegisterSlice(message_stream_signature(2))
        wiring.connect(m, self.core.sub0, relay.s_axis)
        wiring.connect(m, relay.m_axis, self.core.pub1)
        return m


class FinembBoardTop(_BoardTop):
    """A FinEmbP PID node (:class:`hdl.finemb.FinembPidNode`) on the board's RGMII ports: port
    0 and port 1 of the node on the board's first two (the line of the paper: frames for
    other nodes pass through); on a board with one port, the node ends the line (its port 1
    is idle). Each port's receive side crosses from its PHY's clock onto the node's 125 MHz
    (:class:`hdl.net.gmii_crossing.GmiiRxCrossing`); both transmit on it."""

    def __init__(self, b, *, pll, descriptor, mac, serial=1):
        from hdl.finemb import FinembPidNode
        super().__init__(b, pll=pll)
        # the queues' block RAM outputs end at flip-flops: 125 MHz with the board's pins
        self.node = FinembPidNode(descriptor, mac=mac, serial=serial, registered_queues=True)

    def elaborate(self, platform):
        from hdl.net.gmii_crossing import GmiiRxCrossing
        m = Module()
        clk125, locked = self._clocks(m, platform)
        self.clock_names["line_clk"] = "line (125 MHz, the node's GMII and TXC)"
        # the node's transmit clock, onto which each port's receive side crosses
        m.domains.line = ClockDomain("line", local=True)
        m.d.comb += ClockSignal("line").eq(clk125)
        m.submodules.line_reset = ResetSynchronizer(~locked, domain="line")
        m.submodules.node = node = self.node
        m.d.comb += node.gmii_clk.eq(clk125)
        frames = []
        for k, number in enumerate(rgmii_ports(platform)[:2]):
            phy = self._port(m, platform, k, number, locked)
            port = getattr(node, f"port{k}")
            m.submodules[f"crossing{k}"] = cross = GmiiRxCrossing(i_domain=f"port{k}_rx",
                                                                  o_domain="line")
            m.d.comb += [phy.tx_clk.eq(clk125), cross.rxd.eq(phy.gmii_rxd),
                         cross.rx_dv.eq(phy.gmii_rx_dv), cross.rx_er.eq(phy.gmii_rx_er),
                         port.rxd.eq(cross.out_rxd), port.rx_dv.eq(cross.out_rx_dv),
                         port.rx_er.eq(cross.out_rx_er), phy.gmii_txd.eq(port.txd),
                         phy.gmii_tx_en.eq(port.tx_en), phy.gmii_tx_er.eq(port.tx_er)]
            frames.append(_toggle_on(m, f"port{k}_rx", phy.gmii_rx_dv))
        self._leds(m, platform, frames)
        return m
