"""Shared cocotb harness of the network-engine benches (docs/network.md): GMII models from
cocotbext-eth, scapy frames, an RBCP register-bus model and counter decoding."""

import logging

import cocotb
from cocotb.triggers import ClockCycles, First, RisingEdge, Timer
from cocotbext.eth import GmiiFrame, GmiiSink, GmiiSource
from scapy.layers.inet import ICMP, IP, TCP, UDP
from scapy.layers.l2 import Ether
from scapy.packet import Raw

from hdl.net.frames import DEFAULT_RBCP_PORT, int_to_ip, int_to_mac
from hdl.net.stack import STACK_COUNTERS
from hdl.net.tcp import TCP_COUNTERS
from host.simulator import CORE_NS, GMII_NS, clock_cycles, start_gmii_clocks
from tb.harness import bench_params
from tb.streams import StreamPort, reset_aresetn

__all__ = ["NET_CONFIGS", "WIDE_USER_CONFIGS", "NODE_CONFIG", "NetTB", "read_counter_bank",
           "PEER_MAC", "PEER_IP", "ENGINE_IP", "CLOCK_NS", "GMII_NS", "RegisterBusModel",
           "SessionPort", "checksums_ok", "eth", "rbcp", "start_gmii_clocks"]

#: the engine's core clock (62.5 MHz: two bytes per cycle) and the GMII clock (125 MHz)
CLOCK_NS = CORE_NS
#: The network benches' configuration: one build per simulator, shared by the scripted and
#: the Linux benches (the address is the TAP namespace's; docs/network.md).
#: the engine's and the peer's addresses (RFC 2544 block; on the TAP inside the namespace)
ENGINE_IP = "198.18.0.16"
PEER_IP = "198.18.0.1"
#: The ISS clock starts 12,000 below 2**32 at reset, so a connection opened soon after a
#: reset sends across 2**32 within its first 12 KB (docs/network.md: tests wrap 2**32).
NET_CONFIGS = {"stack": dict(ip=ENGINE_IP, sessions=2, tx_depth=4096, rx_depth=4096,
                             rto_us=200, msl_us=20, arp_retry_us=40, iss_seed=2**32 - 12_000,
                             user_width=16)}
#: The same engine with 32-bit user streams (``user_width``), for the benches of the user side.
WIDE_USER_CONFIGS = {"stack_w32": dict(NET_CONFIGS["stack"], user_width=32)}
#: The ROS 1 node benches' configuration (the seed paper's component: a subscriber looped
#: back to a publisher), shared by tb/test_ros1_node.py and tb/test_ros1_registers.py.
NODE_CONFIG = dict(endpoints=["subscriber", "publisher"], loopback=[[0, 1]], ip=ENGINE_IP,
                   tx_depth=4096, rx_depth=4096, rto_us=500, msl_us=20)
PEER_MAC = "02:00:00:00:00:01"


async def read_counter_bank(clock, index, value, names, *, registered=False):
    """Counters read through an :class:`~hdl.net.counters.EventCounters` index/value port,
    once every event so far has reached them (a bank shows an event within ``len(names) + 1``
    cycles, one more in block RAM). ``registered``: the value follows the index a clock
    later (a bank in block RAM)."""
    await ClockCycles(clock, len(names) + 3)
    values = {}
    for k, name in enumerate(names):
        index.value = k
        if registered:
            await ClockCycles(clock, 1)
        await Timer(1, "ns")
        values[name] = int(value.value)
    return values


class RegisterBusModel:
    """User registers on the RBCP bus: a byte store for addresses below ``size``, acked
    ``latency`` cycles after each strobe (SiTCP's sample acks after 3); addresses at or above
    ``size`` are never acked (the stack's decoder rejects them first)."""

    def __init__(self, dut, size=0x10000, latency=3):
        self.dut = dut
        self.size = size
        self.latency = latency
        self.mem = bytearray(size)
        self.writes = 0
        dut.rbcp_ack.value = 0
        dut.rbcp_rd.value = 0
        cocotb.start_soon(self._run())

    async def _run(self):
        dut = self.dut
        while True:
            await First(RisingEdge(dut.rbcp_we), RisingEdge(dut.rbcp_re))
            await Timer(1, "ns")
            addr = int(dut.rbcp_addr.value)
            write = int(dut.rbcp_we.value)
            data = int(dut.rbcp_wd.value)
            await clock_cycles(dut.aclk, self.latency)
            if addr >= self.size:
                continue
            if write:
                self.mem[addr] = data
                self.writes += 1
            else:
                dut.rbcp_rd.value = self.mem[addr]
            dut.rbcp_ack.value = 1
            await RisingEdge(dut.aclk)
            dut.rbcp_ack.value = 0


class NetTB:
    """Clocks, reset, GMII source and sink, frame helpers for a ``net`` top."""

    def __init__(self, dut):
        self.dut = dut
        self.params = bench_params()
        rx_clk, tx_clk = start_gmii_clocks(dut)
        self.source = GmiiSource(dut.gmii_rxd, dut.gmii_rx_er, dut.gmii_rx_dv, rx_clk,
                                 dut.aresetn, reset_active_level=False)
        self.sink = GmiiSink(dut.gmii_txd, dut.gmii_tx_er, dut.gmii_tx_en, tx_clk,
                             dut.aresetn, reset_active_level=False)
        for model in (self.source, self.sink):
            model.log.setLevel(logging.WARNING)
        self.sessions = self.params.get("sessions", 0) if hasattr(dut, "tcp0_state") else 0
        for k in range(self.sessions):
            for name in ("open_req", "active", "local_port", "remote_ip", "remote_port",
                         "close_ack", "abort", "tx_tvalid", "tx_tdata", "tx_tlast",
                         "rx_tready", "counter_index", "counters_clear", "tx_tkeep"):
                if hasattr(dut, f"tcp{k}_{name}"):
                    getattr(dut, f"tcp{k}_{name}").value = 0
        self.bus = RegisterBusModel(dut) if hasattr(dut, "rbcp_ack") else None
        self.cycle = 0          # the peer model's clock (see run_peer)
        if hasattr(dut, "counter_index"):
            dut.counter_index.value = 0

    async def reset(self):
        await reset_aresetn(self.dut)

    @property
    def mac(self):
        return int_to_mac(int(self.dut.local_mac.value))

    @property
    def ip(self):
        return int_to_ip(int(self.dut.local_ip.value))

    async def counters(self):
        """The stack's counters (:data:`~hdl.net.stack.STACK_COUNTERS`)."""
        return await read_counter_bank(self.dut.aclk, self.dut.counter_index,
                                       self.dut.counter_value, STACK_COUNTERS)

    async def session_counters(self, k=0):
        """Session ``k``'s counters (:data:`~hdl.net.tcp.TCP_COUNTERS`)."""
        return await read_counter_bank(self.dut.aclk, getattr(self.dut, f"tcp{k}_counter_index"),
                                       getattr(self.dut, f"tcp{k}_counter_value"), TCP_COUNTERS)

    async def send(self, frame, *, fcs=True, error=False):
        """Send ``frame`` (scapy packet or bytes, without FCS) into the engine."""
        raw = bytes(frame)
        gf = GmiiFrame.from_payload(raw) if fcs else GmiiFrame.from_raw_payload(raw)
        if error:
            gf.error = [0] * len(gf.data)
            gf.error[len(gf.data) // 2] = 1
        await self.source.send(gf)

    async def recv(self, timeout_cycles=5000):
        """The next frame the engine sends, as a scapy ``Ether`` (FCS checked and removed),
        or ``None`` after ``timeout_cycles``."""
        for _ in range(timeout_cycles // 16):
            if not self.sink.empty():
                gf = self.sink.recv_nowait()
                assert gf.check_fcs(), "frame from the engine with a bad FCS"
                assert not any(gf.error or []), "frame from the engine with TX_ER"
                payload = bytes(gf.get_payload())            # without the FCS
                assert len(payload) >= 60, f"frame of {len(payload)} bytes is not padded"
                frame = Ether(payload)
                if IP in frame:             # drop the Ethernet padding
                    frame = Ether(payload[:14 + frame[IP].len])
                return frame
            await ClockCycles(self.dut.aclk, 16)
        return None

    async def expect_silence(self, cycles=2000):
        await self.source.wait()
        frame = await self.recv(cycles)
        assert frame is None, f"unexpected frame {frame!r}"

    async def idle(self, cycles):
        await clock_cycles(self.dut.aclk, cycles)

    async def put(self, frame, *, fcs=True, error=False):
        """Send a frame of a peer model (:meth:`send`; benches count or learn here)."""
        await self.send(frame, fcs=fcs, error=error)

    def check_frame(self, payload):
        """A frame from the engine to a peer model, FCS checked and removed (benches add
        their oracles here)."""

    async def run_peer(self, peer):
        """Frames between the engine and a :class:`~tb.models.tcp_peer.TcpPeerModel` until
        cancelled: the engine's frames to the peer, the peer's answers and timed frames
        (:meth:`~tb.models.tcp_peer.TcpPeerModel.poll`, every 64 cycles) to the engine."""
        while True:
            while not self.sink.empty():
                gf = self.sink.recv_nowait()
                assert gf.check_fcs(), "engine frame with a bad FCS"
                payload = bytes(gf.get_payload())
                self.check_frame(payload)
                for f in peer.on_frame(payload, self.cycle):
                    await self.put(f)
            for f in peer.poll(self.cycle):
                await self.put(f)
            await ClockCycles(self.dut.aclk, 64)
            self.cycle += 64


class SessionPort(StreamPort):
    """Session ``k``'s user streams: a cocotbext-axi source on ``tcp<k>_tx`` (one ``tlast``
    per written chunk) and a :class:`PacketSink` on ``tcp<k>_rx``, with optional random idle
    and backpressure, and its control signals. The streams may be wider than a byte
    (``user_width``): bytes are counted by ``tkeep``, and ``received`` joins the packets that
    ``tlast`` cut."""

    def __init__(self, dut, k, rng):
        super().__init__(dut, f"tcp{k}", rng, out="rx", into="tx")
        self.dut = dut
        self.k = k

    def signal(self, name):
        return getattr(self.dut, f"tcp{self.k}_{name}")

    def set(self, **values):
        for name, value in values.items():
            self.signal(name).value = value

    def get(self, name):
        return int(self.signal(name).value)

    @property
    def received(self):
        packets = self.sink.packets + [self.sink.current]
        return b"".join(bytes(p.data) for p in packets)

    async def write(self, data):
        from cocotbext.axi import AxiStreamFrame
        await self.source.send(AxiStreamFrame(data))

    async def wait_received(self, count, timeout_cycles):
        for _ in range(timeout_cycles // 64):
            if len(self.received) >= count:
                return self.received
            await ClockCycles(self.dut.aclk, 64)
        raise AssertionError(f"session {self.k}: {len(self.received)} of {count} "
                             f"bytes received in {timeout_cycles} cycles")

    async def wait_state(self, state, timeout_cycles=100000):
        for _ in range(timeout_cycles // 16):
            if self.get("state") == state.value:
                return
            await ClockCycles(self.dut.aclk, 16)
        raise AssertionError(f"session {self.k}: state {self.get('state')}, not {state!r}")


def checksums_ok(pkt):
    """Whether scapy computes the same IP and L4 checksums as the packet carries."""
    rebuilt = Ether(bytes(pkt))
    for layer in (IP, ICMP, UDP, TCP):
        if layer in rebuilt:
            del rebuilt[layer].chksum
    rebuilt = Ether(bytes(rebuilt))
    for layer in (IP, ICMP, UDP, TCP):
        if layer in pkt and pkt[layer].chksum != rebuilt[layer].chksum:
            return False
    return True


def eth(tb, dst=None):
    return Ether(src=PEER_MAC, dst=dst or tb.mac)


async def rbcp(tb, payload, sport=50000):
    """Send one RBCP request from the peer; return the reply's UDP payload (``None`` when no
    reply comes), after checking its checksums and addresses."""
    await tb.send(eth(tb) / IP(src=PEER_IP, dst=tb.ip) /
                  UDP(sport=sport, dport=DEFAULT_RBCP_PORT) / Raw(payload))
    reply = await tb.recv(20000)
    if reply is None:
        return None
    assert checksums_ok(reply), reply.show(dump=True)
    assert (reply[IP].dst, reply[UDP].dport, reply[UDP].sport) == (PEER_IP, sport,
                                                                    DEFAULT_RBCP_PORT)
    return bytes(reply[UDP].payload)
