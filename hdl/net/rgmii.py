"""An RGMII PHY adapter for Lattice ECP5 (docs/boards.md): GMII bytes on one side, the four
data pins and the control pin of each direction on the other, moved on both clock edges by
the ECP5's DDR input and output registers."""

from amaranth import Module, Signal
from amaranth.hdl import Instance
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int

__all__ = ["RgmiiPhy", "MAX_DELAY_TAPS", "DELAY_TAP_PS"]

#: ECP5 DELAYG: 128 taps of about 25 ps (Lattice TN1265)
MAX_DELAY_TAPS = 127
DELAY_TAP_PS = 25


class RgmiiPhy(wiring.Component):
    """RGMII at 1000 Mb/s on ECP5 pins, GMII to the MAC.

    Receive: ``rx_ctl`` and ``rx_data[3:0]`` are each delayed by ``rx_delay_taps`` DELAYG taps
    (the skew a PHY without its own receive delay needs, RGMII 2.0: 1.5 to 2 ns) and sampled
    by an IDDRX1F on the PHY's receive clock: the rising edge gives data bits 3:0 and RX_DV,
    the falling edge bits 7:4 and RX_DV xor RX_ER. Transmit: an ODDRX1F per pin on the 125 MHz
    ``tx_clk``: bits 3:0 and TX_EN on the rising edge, bits 7:4 and TX_EN xor TX_ER on the
    falling; the PHY's TXC is forwarded through an ODDRX1F (1 then 0) delayed by
    ``tx_delay_taps`` (for a PHY that does not delay it itself).

    Only 1000 Mb/s: at 10 or 100 Mb/s a PHY sends each nibble twice at 2.5 or 25 MHz, which
    this adapter reads as bytes of doubled nibbles; the MAC then drops every such frame on its
    FCS check and counts it (``fcs_errors``).

    Parameters
    ----------
    pins : object
        The board's RGMII resource requested with raw ports (``dir="-"``) for ``tx_clk``,
        ``tx_ctl``, ``tx_data`` (4), ``rx_clk``, ``rx_ctl``, ``rx_data`` (4).
    rx_delay_taps, tx_delay_taps : int
        DELAYG taps, 0..127 (25 ps each).

    Members
    -------
    tx_clk : In(1)
        The 125 MHz transmit clock (from a PLL); ``gmii_tx*`` are sampled on its rising edge.
    gmii_txd, gmii_tx_en, gmii_tx_er : In
        The MAC's transmit byte, enable and error, on ``tx_clk``.
    rx_clk : Out(1)
        The PHY's receive clock from its pin (drive the MAC's receive domain with it).
    gmii_rxd, gmii_rx_dv, gmii_rx_er : Out
        The received byte, data valid and error, on ``rx_clk``.
    """

    def __init__(self, pins, *, rx_delay_taps=0, tx_delay_taps=0):
        self._pins = pins
        self._rx_delay = check_int("rx_delay_taps", rx_delay_taps, 0, MAX_DELAY_TAPS)
        self._tx_delay = check_int("tx_delay_taps", tx_delay_taps, 0, MAX_DELAY_TAPS)
        for name, width in (("tx_clk", 1), ("tx_ctl", 1), ("tx_data", 4), ("rx_clk", 1),
                            ("rx_ctl", 1), ("rx_data", 4)):
            port = getattr(pins, name, None)
            if port is None or len(port) != width:
                raise ValueError(f"pins: expected a raw port {name} of {width} pin(s), found "
                                 f"{port!r}")
        super().__init__({"tx_clk": In(1), "gmii_txd": In(8), "gmii_tx_en": In(1),
                          "gmii_tx_er": In(1), "rx_clk": Out(1), "gmii_rxd": Out(8),
                          "gmii_rx_dv": Out(1), "gmii_rx_er": Out(1)})

    def elaborate(self, platform):
        m = Module()
        pins = self._pins
        m.submodules.rx_clk_buffer = Instance("IB", i_I=pins.rx_clk.io[0], o_O=self.rx_clk)

        def delayed_input(name, pad, taps):
            if taps == 0:
                return pad
            out = Signal(name=f"{name}_delayed")
            m.submodules[f"{name}_delay"] = Instance(
                "DELAYG", p_DEL_MODE="USER_DEFINED", p_DEL_VALUE=taps, i_A=pad, o_Z=out)
            return out

        def pad_in(name, port):
            signal = Signal(name=f"{name}_pad")
            m.submodules[f"{name}_ib"] = Instance("IB", i_I=port, o_O=signal)
            return signal

        def pad_out(name, port, signal):
            m.submodules[f"{name}_ob"] = Instance("OB", i_I=signal, o_O=port)

        ctl_rise, ctl_fall = Signal(), Signal()
        rx_inputs = [("rx_ctl", pins.rx_ctl.io[0], ctl_rise, ctl_fall)]
        for i in range(4):
            rx_inputs.append((f"rx_data{i}", pins.rx_data.io[i], self.gmii_rxd[i],
                              self.gmii_rxd[i + 4]))
        for name, port, rise, fall in rx_inputs:
            pad = delayed_input(name, pad_in(name, port), self._rx_delay)
            m.submodules[f"{name}_iddr"] = Instance(
                "IDDRX1F", i_D=pad, i_SCLK=self.rx_clk, i_RST=0, o_Q0=rise, o_Q1=fall)
        m.d.comb += [self.gmii_rx_dv.eq(ctl_rise), self.gmii_rx_er.eq(ctl_rise ^ ctl_fall)]

        tx_outputs = [("tx_ctl", pins.tx_ctl.io[0], self.gmii_tx_en,
                       self.gmii_tx_en ^ self.gmii_tx_er)]
        for i in range(4):
            tx_outputs.append((f"tx_data{i}", pins.tx_data.io[i], self.gmii_txd[i],
                               self.gmii_txd[i + 4]))
        for name, port, rise, fall in tx_outputs:
            q = Signal(name=f"{name}_q")
            m.submodules[f"{name}_oddr"] = Instance(
                "ODDRX1F", i_D0=rise, i_D1=fall, i_SCLK=self.tx_clk, i_RST=0, o_Q=q)
            pad_out(name, port, q)
        clock = Signal(name="tx_clk_q")
        m.submodules.tx_clk_oddr = Instance("ODDRX1F", i_D0=1, i_D1=0, i_SCLK=self.tx_clk,
                                            i_RST=0, o_Q=clock)
        if self._tx_delay:
            late = Signal(name="tx_clk_delayed")
            m.submodules.tx_clk_delay = Instance(
                "DELAYG", p_DEL_MODE="USER_DEFINED", p_DEL_VALUE=self._tx_delay, i_A=clock,
                o_Z=late)
            clock = late
        pad_out("tx_clk", pins.tx_clk.io[0], clock)
        return m
