"""The compiled TAP port (``host.compiled.gmii_tap``: ``rosgate_gmii_tap`` and its C++ side)
on a real TAP device in a network namespace the test creates, behind ``gmii_loopback.sv``
(a design that sends back what it receives).

Frames of 14, 15, 59, 60, 61 and 1514 bytes and of random length (random contents) are written into the kernel with
an ``AF_PACKET`` socket at random gaps, in bursts and one by one; each must come back through
the design as it was sent, padded to Ethernet's 60 bytes, in order, none lost or doubled. A
monitor of a copy of the receive pins checks the bytes the pump puts on the wire against the
standard independently of the pump's code: preamble and SFD, the
kernel's frame padded to 60 bytes, an FCS that ``zlib.crc32`` agrees with, at least 12 idle
cycles between frames. Frames the design spoils (TX_ER raised, or bits flipped after the SFD
so the FCS fails) are counted and never reach the kernel, and the next good frame passes
(IPv6 is off on the test's TAP device, so that the kernel sends no frames of its own)."""

import json
import random
import socket
import zlib

import cocotb
import pytest
from cocotb.triggers import RisingEdge

from host.compiled.gmii_tap import CompiledTapPort, gmii_tap_harness
from host.simulator import QUICK_CXX_OPT, clock_cycles, run_top, start_clock, top_params
from host.tap import TAP_NAME, TapBridge, namespace_unavailable, network_namespace

from .harness import ROOT, SIM_BUILD, amount

LOOPBACK = ROOT / "tb" / "gmii_loopback.sv"
#: a local experimental EtherType (IEEE 802): the kernel's own frames carry others
ETHERTYPE = 0x88B5
ETH_P_ALL = 0x0003
PACKET_OUTGOING = 4
CLOCK_NS = 8


class TapPortTB:
    """The loopback design on the TAP device, the kernel's side through a packet socket."""

    def __init__(self, dut, tap, seed):
        self.dut = dut
        self.rng = random.Random(seed)
        start_clock(dut.aclk, CLOCK_NS)
        dut.spoil_er.value = 0
        dut.flip.value = 0
        with open(f"/proc/sys/net/ipv6/conf/{tap}/disable_ipv6", "w") as f:
            f.write("1")
        self.port = CompiledTapPort(TapBridge.open_tap(tap), poll_cycles=16)
        self.wire = []
        cocotb.start_soon(self._watch_wire())
        self.sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
        self.sock.bind((tap, 0))
        self.sock.setblocking(False)
        self.mac = self.sock.getsockname()[4]

    def frame(self, length=None):
        """A frame to our own address: ``length`` bytes of body (random: 0 to 1500)."""
        length = self.rng.randrange(0, 1501) if length is None else length
        body = self.rng.randbytes(length)
        return self.mac + bytes.fromhex("020000000001") + ETHERTYPE.to_bytes(2, "big") + body

    async def send(self, frames, gaps):
        for frame in frames:
            self.sock.send(frame)
            await clock_cycles(self.dut.aclk, self.rng.choice(gaps))

    async def collect(self, count, within_cycles):
        """Frames of our EtherType the kernel received, until ``count`` or the time is up."""
        got = []
        for _ in range(within_cycles // 64):
            while True:
                try:
                    data, address = self.sock.recvfrom(4096)
                except BlockingIOError:
                    break
                if address[2] != PACKET_OUTGOING and data[12:14] == ETHERTYPE.to_bytes(2, "big"):
                    got.append(data)
            if len(got) >= count:
                break
            await clock_cycles(self.dut.aclk, 64)
        return got

    async def _watch_wire(self):
        """Every frame on the receive pins, byte for byte with its first and last cycle."""
        frame, cycle = None, 0
        while True:
            await RisingEdge(self.dut.aclk)
            cycle += 1
            if int(self.dut.mon_rx_dv.value):
                if frame is None:
                    frame = {"data": bytearray(), "first": cycle, "error": False}
                frame["data"].append(int(self.dut.mon_rxd.value))
                frame["error"] |= bool(int(self.dut.mon_rx_er.value))
            elif frame is not None:
                frame["last"] = cycle - 1
                self.wire.append(frame)
                frame = None

    def wire_frames(self):
        """The pump's frames on the receive pins, checked against the standard: (the frame
        without preamble and FCS, first cycle, last cycle)."""
        frames = []
        for f in self.wire:
            data = bytes(f["data"])
            assert data[:8] == bytes([0x55] * 7 + [0xD5]), f"preamble/SFD {data[:8].hex()}"
            payload, fcs = data[8:-4], data[-4:]
            assert zlib.crc32(payload).to_bytes(4, "little") == fcs, "FCS"
            assert len(payload) >= 60 and not f["error"]
            frames.append((payload, f["first"], f["last"]))
        self.wire.clear()
        return frames


def padded(frame):
    return frame + bytes(max(0, 60 - len(frame)))


@cocotb.test()
async def frames_through_the_pump(dut):
    p = top_params()
    tb = TapPortTB(dut, p["tap"], p["seed"])
    await clock_cycles(dut.aclk, 100)
    results = {}

    # the edges of padding (a 60-byte minimum) and the largest frame, then random lengths
    edges = [0, 1, 45, 46, 47, 1500]
    sent = [tb.frame(n) for n in edges] + [tb.frame() for _ in range(p["frames"] - len(edges))]
    tb.rng.shuffle(sent)
    half = len(sent) // 2
    await tb.send(sent[:half], gaps=[1])                  # a burst: the kernel queues them
    await tb.send(sent[half:], gaps=[1, 20, 200, 2000])
    got = await tb.collect(len(sent), 4000 * len(sent))
    assert len(got) == len(sent), f"{len(got)} of {len(sent)} frames came back"
    for k, (g, s) in enumerate(zip(got, sent)):
        assert g == padded(s), f"frame {k} ({len(s)} bytes) came back changed"
    wire = [w for w in tb.wire_frames() if w[0][12:14] == ETHERTYPE.to_bytes(2, "big")]
    assert [w[0] for w in wire] == [padded(s) for s in sent]
    gaps = [b[1] - a[2] - 1 for a, b in zip(wire, wire[1:])]
    assert min(gaps) >= 12, f"an inter-frame gap of {min(gaps)} cycles"
    results["echoed"] = len(got)
    results["min_gap_cycles"] = min(gaps)

    before = tb.port.stats["bad_fcs"]
    for signal, count in ((dut.spoil_er, 3), (dut.flip, 4)):
        signal.value = 1
        await tb.send([tb.frame() for _ in range(count)], gaps=[500])
        assert await tb.collect(1, 20_000) == [], f"a frame spoilt with {signal._name} passed"
        signal.value = 0
        good = tb.frame()
        await tb.send([good], gaps=[10])
        assert await tb.collect(1, 20_000) == [padded(good)], "the next good frame"
    results["bad_fcs"] = tb.port.stats["bad_fcs"] - before
    results["stats"] = tb.port.stats
    with open(p["out"], "w") as f:
        json.dump(results, f)


def test_compiled_tap_port_moves_frames_and_drops_spoilt_ones(tmp_path):
    why = namespace_unavailable()
    if why:
        pytest.skip(f"no network namespace or TAP device here: {why}")
    out = tmp_path / "result.json"
    frames = amount(40, 400)
    with network_namespace():
        run_top(__name__, LOOPBACK.stem, None, "verilator", SIM_BUILD / "compiled_gmii_tap",
                params={"tap": TAP_NAME, "frames": frames, "seed": random.randrange(1 << 32),
                        "out": str(out)},
                extra_env={"PYTHONPATH": str(ROOT)}, lint=False, cxx_opt=QUICK_CXX_OPT,
                exported=LOOPBACK, harness=gmii_tap_harness("gmii"))
    result = json.loads(out.read_text())
    assert result["echoed"] == frames
    assert result["bad_fcs"] == 7
    assert result["stats"]["from_design"] >= frames + 2
