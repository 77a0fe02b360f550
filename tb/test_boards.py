"""``rosgate board``: ECP5 boards with RGMII PHYs (gen/boards.py, hdl/net/rgmii.py,
host/board.py, docs/boards.md).

* The pins of every board design are amaranth-boards' definitions: the constraints file of
  the engine's board top holds each RGMII pin at the site the board's platform defines for it
  (read here from the platform class itself), the Colorlight's second port without the reset,
  MDC and MDIO it shares with the first.
* The PLL parameters (from Project Trellis' ecppll) make the clocks asked for, checked with
  the EHXPLLL's own frequency relations, the VCO within its range.
* `rosgate board list` names every board with its FPGA and PHYs; bad boards, designs and
  delays are refused with the reason.
* A whole build through nextpnr with the board's pins (minutes) is in make test-full.
"""

import contextlib
import gc
import re
import warnings

import pytest
from amaranth.hdl import UnusedElaboratable

from gen.boards import BOARDS, BoardError, board, board_platform, rgmii_ports
from hdl.params import ParameterError
from host.board import board_top, pll_parameters

from .harness import run_rosgate


def platform_pins(platform_class, name, number):
    """Subsignal -> pin sites of resource ``name`` ``number`` as the platform class defines
    it."""
    resource = next(r for r in platform_class.resources
                    if r.name == name and r.number == number)
    return {sub.name: list(sub.ios[0].names) for sub in resource.ios}


def lpf_sites(lpf, port_prefix):
    """Subsignal -> pin sites of the ports named ``<port_prefix>__<sub>__io[k]`` in an LPF."""
    found = {}
    for port, site in re.findall(r'LOCATE COMP "([^"]+)" SITE "([^"]+)";', lpf):
        if port.startswith(port_prefix + "__"):
            sub = port[len(port_prefix) + 2:].split("__")[0]
            index = re.search(r"\[(\d+)\]$", port)
            found.setdefault(sub, {})[int(index.group(1)) if index else 0] = site
    return {sub: [sites[k] for k in sorted(sites)] for sub, sites in found.items()}


@pytest.mark.parametrize("name", sorted(BOARDS))
def test_board_top_pins_are_the_board_definition(name):
    b = board(name)
    platform = board_platform(b)
    top = board_top("engine", b, platform, {"mac": "02:00:00:00:00:01", "ip": "10.0.0.2",
                                            "sessions": 1})
    plan = platform.prepare(top, name="top")
    lpf = plan.files["top.lpf"]
    first = rgmii_ports(platform)[0]
    want = platform_pins(b.platform_class(), "eth_rgmii", first)
    got = lpf_sites(lpf, f"eth_rgmii_port{first}_{first}")
    assert got == want, (got, want)
    assert top.pin_clocks == {f"eth_rgmii_port{first}_{first}__rx_clk__io": 125.0}


@pytest.mark.parametrize("name", ["versa_ecp5", "colorlight_5a75b_r7_0"])
def test_finemb_top_has_the_node_on_both_ports(name):
    b = board(name)
    platform = board_platform(b)
    top = board_top("finemb", b, platform, {})
    lpf = platform.prepare(top, name="top").files["top.lpf"]
    first = platform_pins(b.platform_class(), "eth_rgmii", 0)
    for number in (0, 1):
        want = platform_pins(b.platform_class(), "eth_rgmii", number)
        if number == 1:
            # pins the first port already has (the Colorlight's shared reset, MDC, MDIO)
            want = {sub: pins for sub, pins in want.items() if pins != first.get(sub)}
        assert lpf_sites(lpf, f"eth_rgmii_port{number}_{number}") == want
    assert sorted(top.pin_clocks) == [f"eth_rgmii_port{k}_{k}__rx_clk__io" for k in (0, 1)]
    assert len(top.sim_pins["ports"]) == 2


@contextlib.contextmanager
def requests_left_unbuilt():
    """Resources requested and never elaborated: their buffers' warnings are expected."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        yield
        gc.collect()


def test_colorlight_second_port_leaves_out_the_shared_pins():
    b = board("colorlight_5a75b_r7_0")
    with requests_left_unbuilt():
        platform = board_platform(b)
        assert rgmii_ports(platform) == [0, 1]
        first, second = platform.request_rgmii(0), platform.request_rgmii(1)
        assert hasattr(first, "rst") and not first.shares_reset
        assert second.shares_reset and not hasattr(second, "mdio")
        assert len(second.rx_data) == 4 and len(second.tx_data) == 4
        del platform, first, second
    defined = platform_pins(b.platform_class(), "eth_rgmii", 1)
    shared = {k for k, v in defined.items() if v == platform_pins(b.platform_class(),
                                                                  "eth_rgmii", 0)[k]}
    assert shared == {"rst", "mdc", "mdio"}


@pytest.mark.parametrize("f_in,f_op,f_os", [(25, 125, 62.5), (30, 125, 62.5),
                                            (100, 125, 62.5)])
def test_pll_parameters_make_the_clocks(f_in, f_op, f_os):
    p = pll_parameters(f_in, f_op, f_os)
    assert p["FEEDBK_PATH"] == "CLKOP"
    # EHXPLLL with CLKOP feedback: CLKOP = CLKI * CLKFB_DIV / CLKI_DIV, VCO = CLKOP * CLKOP_DIV
    op = f_in * p["CLKFB_DIV"] / p["CLKI_DIV"]
    vco = op * p["CLKOP_DIV"]
    assert op == pytest.approx(f_op) and vco / p["CLKOS_DIV"] == pytest.approx(f_os)
    assert 400 <= vco <= 800 and 3.125 <= f_in / p["CLKI_DIV"] <= 400   # ECP5 data sheet


def test_board_list_and_refusals(tmp_path):
    result = run_rosgate("board", "list")
    assert result.returncode == 0, result.stderr
    for b in BOARDS.values():
        line = next(line for line in result.stdout.splitlines() if line.startswith(b.name))
        assert b.fpga() in line and b.phys[0] in line, line
    assert "LFE5U-25F-6BG256" in result.stdout and "1: Broadcom B50612D" in result.stdout
    result = run_rosgate("board", "build", "engine", "--board", "colorlight")
    assert result.returncode == 2 and "--board 'colorlight': rosgate knows" in result.stderr
    result = run_rosgate("board", "build", "gateway", "--board", "butterstick")
    assert result.returncode == 2 and "invalid choice: 'gateway'" in result.stderr
    for options, message in ((["--sessions", "9"], "--sessions must be an integer in 1..8, "
                                                   "not 9"),
                             (["--ip", "300.1.1.1"], "--ip must be an IPv4 address"),
                             (["--seeds", "0"], "--seeds 0: expected 1 or more")):
        result = run_rosgate("board", "build", "engine", "--board", "butterstick", *options,
                             "-o", str(tmp_path / "out"))
        assert result.returncode == 2 and message in result.stderr, result.stderr
        assert not (tmp_path / "out").exists(), "refused before anything was written"
    bad_io = tmp_path / "bad.toml"
    bad_io.write_text("name = 'pid'\n[[port]]\nname = 'x'\n")
    for options, message in ((["--mac", "03:00:00:00:46:01"], "--mac must be a unicast MAC"),
                             (["--io", str(bad_io)], "bad.toml"),
                             (["--io", str(tmp_path / "none.toml")], "none.toml")):
        result = run_rosgate("board", "build", "finemb", "--board", "versa_ecp5", *options,
                             "-o", str(tmp_path / "out"))
        assert result.returncode == 2 and message in result.stderr, result.stderr
        assert not (tmp_path / "out").exists(), "refused before anything was written"
    with pytest.raises(BoardError, match="rosgate knows butterstick"):
        board("nope")
    # boards amaranth-boards defines that rosgate does not build for say why
    with pytest.raises(BoardError, match="arty_a7 is not an ECP5 board"):
        board("arty_a7")
    with pytest.raises(BoardError, match="ulx3s's Ethernet is absent: rosgate's PHY adapter "
                                         "speaks RGMII only"):
        board("ulx3s")
    with pytest.raises(BoardError, match="versa_ecp5_5g has an RGMII port, but rosgate has no "
                                         "board data"):
        board("versa_ecp5_5g")
    with pytest.raises(BoardError, match="module is built for as logicbone_85"):
        board("logicbone")


def test_rgmii_phy_refuses_delays_beyond_the_delay_line():
    from hdl.net.rgmii import RgmiiPhy
    with requests_left_unbuilt():
        platform = board_platform(board("butterstick"))
        pins = platform.request_rgmii(0)
        with pytest.raises(ParameterError, match="rx_delay_taps"):
            RgmiiPhy(pins, rx_delay_taps=128)
        with pytest.raises(ValueError, match="raw port rx_data of 4 pin"):
            RgmiiPhy(type("Pins", (), {"tx_clk": pins.tx_clk, "tx_ctl": pins.tx_ctl,
                                       "tx_data": pins.tx_data, "rx_clk": pins.rx_clk,
                                       "rx_ctl": pins.rx_ctl, "rx_data": pins.rx_data[:2]})())
        del platform, pins


@pytest.mark.full
def test_engine_bitstream_for_the_butterstick(tmp_path):
    """The whole flow with the board's pins: a bitstream and nextpnr's report per seed; the
    result records every clock's worst Fmax against its target times 1.05."""
    from host.board import build_board
    result = build_board("engine", "butterstick", tmp_path, seeds=(1,))
    assert (tmp_path / "top.bit").stat().st_size > 100_000
    assert (tmp_path / "top.svf").is_file()
    assert set(result["clocks"]) and all("worst_mhz" in c for c in result["clocks"].values())


NEXTPNR_UTILISATION = """Info: Device utilisation:
Info: \t          TRELLIS_IO:      17/    197     8%
Info: \t              DP16KD:     131/     56   233%
Info: \t          TRELLIS_FF:   11285/  24288    46%
Info: \t        TRELLIS_COMB:   40198/  24288   165%
"""


def test_a_design_too_large_for_the_device_is_named_by_resource(tmp_path):
    """What nextpnr's log says about a design larger than the device (the engine with 8
    sessions on the Colorlight's 25F, as the full test below builds) becomes the resources
    and how many too many."""
    from host.board import _over_capacity
    log = tmp_path / "top_seed1.tim"
    log.write_text(NEXTPNR_UTILISATION)
    assert _over_capacity(log) == [("DP16KD", 131, 56), ("TRELLIS_COMB", 40198, 24288)]


@pytest.mark.full
def test_engine_with_eight_sessions_does_not_fit_the_colorlight(tmp_path):
    result = run_rosgate("board", "build", "engine", "--board", "colorlight_5a75b_r7_0",
                         "--sessions", "8", "--seeds", "1", "-o", str(tmp_path / "out"))
    assert result.returncode == 2, result.stderr
    assert "engine does not fit colorlight_5a75b_r7_0's LFE5U-25F-6BG256: DP16KD" in \
        result.stderr and "too many" in result.stderr
    assert not (tmp_path / "out" / "top.bit").exists()
    assert not (tmp_path / "out" / "board.json").exists()
