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

from amaranth import ClockDomain, ClockSignal, Elaboratable, Module, Signal
from amaranth.build import Resource
from amaranth.hdl import Instance
from amaranth.lib.cdc import ResetSynchronizer

__all__ = ["Board", "BOARDS", "BoardError", "board", "board_platform", "rgmii_ports",
           "ehxplll", "EngineBoardTop", "RGMII_RAW"]

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
    #: a TCP session's receive and transmit buffer each, in bytes: what the device's block
    #: RAM holds for two sessions (a DP16KD holds 2 KiB)
    buffer_bytes: int = 65536
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
          rx_delay_ns=2.0, tx_delay_ns=0.0, buffer_bytes=16384,
          notes=("both ports share the PHYs' reset, MDC and MDIO",
                 "56 DP16KD: 16 KiB per session buffer")),
    Board("butterstick", "amaranth_boards.butterstick:ButterStickPlatform",
          "ButterStick r1.0", ("Microchip KSZ9031RNX",), rx_delay_ns=0.0, tx_delay_ns=2.0,
          notes=("the KSZ9031RNX adds about 1.2 ns to the receive clock itself",)),
    Board("ecpix5_85", "amaranth_boards.ecpix5:ECPIX585Platform", "LambdaConcept ECPIX-5 85F",
          ("RGMII PHY",), rx_delay_ns=0.0, tx_delay_ns=2.0),
)}


def board(name):
    """The :class:`Board` called ``name``, or a :class:`BoardError` listing the boards."""
    try:
        return BOARDS[name]
    except KeyError:
        raise BoardError(f"--board {name!r}: rosgate knows {', '.join(sorted(BOARDS))} "
                         f"(rosgate board list)") from None


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


class EngineBoardTop(Elaboratable):
    """The TCP/IP engine (:class:`hdl.net.echo.EchoEngine`: ARP, ICMP echo, RBCP registers,
    TCP echo sessions) on a board's first RGMII port.

    Clocks: the board's oscillator into an EHXPLLL making 125 MHz (the RGMII transmit clock,
    ``gmii_tx``) and 62.5 MHz (the engine's ``sync``); the PHY's receive clock drives
    ``gmii_rx``. ``sync`` leaves reset once the PLL has locked (a reset synchroniser); the
    engine synchronises that reset into its GMII domains. The PHY's reset is held for
    :data:`PHY_RESET_US` after that; MDC is low and MDIO released (the PHYs' defaults serve
    1000 Mb/s RGMII)."""

    SYNC_MHZ = 62.5
    GMII_MHZ = 125.0

    def __init__(self, b, *, pll, mac, ip, sessions=2, registers=256, buffer_bytes=None):
        from hdl.net.echo import EchoEngine
        self.board = b
        #: the EHXPLLL's parameters for GMII_MHZ and SYNC_MHZ from the board's oscillator
        self.pll = pll
        self.engine = EchoEngine(mac=mac, ip=ip, sessions=sessions, registers=registers,
                                 buffer_bytes=buffer_bytes or b.buffer_bytes)
        self.pin_clocks = {}
        #: the last part of a clock net's name after synthesis -> what the clock is
        self.clock_names = {"clk": "sync (the engine)", "gmii_rx_clk": "gmii_rx (PHY's RXC)",
                            "gmii_tx_clk": "gmii_tx (125 MHz, TXC)"}

    def elaborate(self, platform):
        from hdl.net.rgmii import RgmiiPhy
        m = Module()
        b = self.board
        osc = platform.request(platform.default_clk)
        # nextpnr derives the PLL's output clocks from the oscillator's constraint
        clk125, clk62, locked = Signal(name="clk125"), Signal(name="clk62"), Signal()
        m.submodules.pll = ehxplll(self.pll, osc.i, clk125, clk62, locked)
        m.domains.sync = ClockDomain("sync")
        m.d.comb += ClockSignal("sync").eq(clk62)
        m.submodules.sync_reset = ResetSynchronizer(~locked, domain="sync")

        pins = platform.request_rgmii(rgmii_ports(platform)[0])
        m.submodules.phy = phy = RgmiiPhy(pins, rx_delay_taps=b.rx_delay_taps,
                                          tx_delay_taps=b.tx_delay_taps)
        #: input clocks the LPF constrains by their pin (``FREQUENCY PORT``): name -> MHz
        self.pin_clocks = {pins.rx_clk.io.name: self.GMII_MHZ}
        m.submodules.engine = engine = self.engine
        gmii = engine.gmii
        m.d.comb += [phy.tx_clk.eq(clk125), gmii.tx_clk.eq(clk125), gmii.rx_clk.eq(phy.rx_clk),
                     phy.gmii_txd.eq(gmii.txd), phy.gmii_tx_en.eq(gmii.tx_en),
                     phy.gmii_tx_er.eq(gmii.tx_er), gmii.rxd.eq(phy.gmii_rxd),
                     gmii.rx_dv.eq(phy.gmii_rx_dv), gmii.rx_er.eq(phy.gmii_rx_er)]
        if hasattr(pins, "rst"):
            hold = int(PHY_RESET_US * self.SYNC_MHZ)
            count = Signal(range(hold + 1))
            with m.If(count != hold):
                m.d.sync += count.eq(count + 1)
            m.d.comb += pins.rst.o.eq(count != hold)
        if hasattr(pins, "mdc"):
            m.d.comb += [pins.mdc.o.eq(0), pins.mdio.oe.eq(0)]
        return m
