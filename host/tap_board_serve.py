"""The cocotb side of ``rosgate tap board``: drives a board top's oscillator pin (at CLKOP's
frequency, as the PLL model asks; each board's of a line of boards) and port 0's receive
clock, puts a cocotbext-eth RGMII PHY model on port 0's pins, bridges it to the TAP device and
writes the status file until the stop file appears
(:func:`host.tap_serve.serve_until_stopped`)."""

import logging

import cocotb
from cocotbext.eth import RgmiiSink, RgmiiSource

from host.simulator import GMII_NS, start_clock, top_params
from host.tap import TapBridge
from host.tap_serve import serve_until_stopped


@cocotb.test()
async def serve(dut):
    """Run the board top on the TAP device until the stop file appears."""
    params = top_params()
    pins = params["pins"]
    # a line of boards has one oscillator each, ``ppm`` apart from the nominal
    names = pins.get("oscillators") or [pins["oscillator"]]
    ppm = pins.get("ppm") or [0] * len(names)
    for name, offset in zip(names, ppm):
        start_clock(getattr(dut, name), round(GMII_NS * (1 + offset * 1e-6) * 1000) / 1000)
    osc = getattr(dut, names[0])
    bridges = []
    for k, port in enumerate(pins["ports"][:1]):
        def pin(name):
            return getattr(dut, port[name])
        start_clock(pin("rx_clk"), GMII_NS)
        source = RgmiiSource(pin("rx_data"), pin("rx_ctl"), pin("rx_clk"))
        sink = RgmiiSink(pin("tx_data"), pin("tx_ctl"), pin("tx_clk"))
        for model in (source, sink):
            model.log.setLevel(logging.WARNING)
        bridges.append(TapBridge(source, sink, osc, tap=params["tap"], strict=False,
                                 poll_cycles=params.get("poll_cycles", 64)))
    await serve_until_stopped(dut, osc, bridges, params)
