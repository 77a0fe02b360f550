"""The engine against the Linux kernel's own network stack (docs/network.md "Real peer"):
the bench runs the simulator inside a private network namespace whose TAP device carries the
simulated GMII, and the kernel's ARP, ICMP, UDP and TCP answer through ordinary sockets,
``ping`` and sitcpy's RBCP client. Kernel timers run on wall time while the simulation is
thousands of times slower, so the engine sees retransmitted SYNs and duplicate segments.

Verilator only (megabytes at one byte per cycle); the same top runs on both simulators in
tb/test_net_stack.py. Skipped with the reason where the machine cannot create namespaces.
"""

import errno
import os
import random
import socket
import subprocess
from pathlib import Path

import cocotb
import pytest

from hdl.net.tcp import TcpState
from tb.harness import run_bench
from tb.linux_tb import KERNEL_IP, TAP_NAME, LinuxTB, namespace_unavailable, network_namespace
from tb.net_tb import NET_CONFIGS, WIDE_USER_CONFIGS, SessionPort

#: bytes per direction, set by the pytest case
TRANSFER = int(os.environ.get("ROSGATE_NET_TRANSFER", 65536))

#: (id, impairment probability, bytes per direction, engine configuration); make test runs
#: the first
CASES = [("clean", 0.0, 64 * 1024, "stack"), ("megabytes", 0.0, 2 * 1024 * 1024, "stack"),
         ("impaired", 0.02, 1024 * 1024, "stack"), ("options_off", 0.0, 256 * 1024, "stack"),
         ("wide_user", 0.02, 256 * 1024, "stack_w32")]
CONFIGS = dict(NET_CONFIGS, **WIDE_USER_CONFIGS)
#: case -> the namespace's sysctls (docs/network.md: the kernel without timestamps, SACK and
#: window scaling; the other cases offer all three, which the engine ignores)
SYSCTLS = {"options_off": {"net.ipv4.tcp_timestamps": 0, "net.ipv4.tcp_sack": 0,
                           "net.ipv4.tcp_window_scaling": 0}}


@pytest.mark.parametrize("case,impairment,transfer,config", [
    pytest.param(name, p, n, config, id=name,
                 marks=() if name == "clean" else (pytest.mark.full,))
    for name, p, n, config in CASES])
def test_net_linux(case, impairment, transfer, config):
    why = namespace_unavailable()
    if why:
        pytest.skip(f"Linux peer bench skipped: {why}")
    params = CONFIGS[config]
    env = {"ROSGATE_NET_IMPAIRMENT": str(impairment), "ROSGATE_NET_TRANSFER": str(transfer)}
    with network_namespace():
        for key, value in SYSCTLS.get(case, {}).items():
            path = Path("/proc/sys") / key.replace(".", "/")
            path.write_text(f"{value}\n")
            assert path.read_text().strip() == str(value), (key, path.read_text())
        run_bench(__name__, "net", config, params, "verilator", extra_env=env, run_name=case)


def start_connect(sock, addr):
    sock.setblocking(False)
    err = sock.connect_ex(addr)
    assert err in (0, errno.EINPROGRESS), os.strerror(err)


async def wait_connected(tb, sock, addr):
    def connected():
        return sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR) == 0 and _peer(sock)
    await tb.poll(f"connect to {addr}", connected, 2_000_000)


async def connect(tb, sock, addr):
    start_connect(sock, addr)
    await wait_connected(tb, sock, addr)


def _peer(sock):
    try:
        sock.getpeername()
        return True
    except OSError:
        return False


@cocotb.test()
async def run_linux_ping_and_rbcp(dut):
    tb = LinuxTB(dut)
    await tb.reset()
    ping = subprocess.Popen(["ping", "-c", "3", "-i", "0.2", "-W", "5", tb.ip],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    await tb.poll("ping", lambda: ping.poll() is not None, 3_000_000, step=1024)
    out = ping.stdout.read()
    assert ping.returncode == 0 and " 0% packet loss" in out, out    # only TCP is impaired
    from sitcpy.rbcp import Rbcp, RbcpBusError
    client = Rbcp(tb.ip, 4660, 20000)
    data = bytes(tb.rng.randrange(256) for _ in range(64))
    await tb.run_in_thread("rbcp write", client.write, 0x1200, data)
    assert bytes(tb.bus.mem[0x1200:0x1240]) == data
    got = await tb.run_in_thread("rbcp read", client.read, 0x1200, 64)
    assert bytes(got) == data

    def unmapped():
        try:
            client.write(0x00100000, b"\x01\x02")
        except RbcpBusError:
            return "bus error"
        return "no error"
    assert await tb.run_in_thread("rbcp bus error", unmapped) == "bus error"


@cocotb.test()
async def run_linux_client_engine_server(dut):
    """A kernel client connects to session 0 listening on port 24; both directions."""
    tb = LinuxTB(dut)
    await tb.reset()
    s = SessionPort(dut, 0, random.Random(tb.rng.random()))
    s.set_pauses(0.2, 0.2)
    s.set(active=0, local_port=24, open_req=1)
    await s.wait_state(TcpState.LISTEN)
    sock = socket.socket()
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    try:
        await connect(tb, sock, (tb.ip, 24))
        await s.wait_state(TcpState.ESTABLISHED)
        up = tb.rng.randbytes(TRANSFER)
        down = tb.rng.randbytes(TRANSFER)
        got_engine, got_kernel = await tb.transfer(sock, s, up, down, 40 * TRANSFER + 2_000_000)
        assert got_engine == up, "engine received other bytes than the kernel sent"
        assert got_kernel == down, "kernel received other bytes than the engine sent"
        # the kernel closes; the engine answers close_req with close_ack and its own FIN
        sock.shutdown(socket.SHUT_WR)
        await s.wait_state(TcpState.CLOSE_WAIT, 2_000_000)
        s.set(close_ack=1)

        def eof():
            try:
                return sock.recv(1) == b""
            except BlockingIOError:
                return False
        await tb.poll("FIN from the engine", eof, 2_000_000)
        s.set(close_ack=0)
        await s.wait_state(TcpState.LISTEN, 2_000_000)
    finally:
        sock.close()
    dut._log.info("pump %s, session %s", tb.pump.stats, await tb.session_counters(0))


@cocotb.test()
async def run_linux_two_clients_one_port(dut):
    """Two kernel clients connect at once to the engine's default TCP port (24), on which
    sessions 0 and 1 both listen with ``local_port`` 0: each connection lands on one
    session only (with both sessions taking the first SYN, the kernel never connects), also
    when the kernel resends a SYN while the simulation is slow. Then 8 KiB each way on both
    connections, byte-exact."""
    tb = LinuxTB(dut)
    await tb.reset()
    sessions = [SessionPort(dut, k, random.Random(tb.rng.random())) for k in range(2)]
    for s in sessions:
        s.set(active=0, local_port=0, open_req=1)
        await s.wait_state(TcpState.LISTEN)
    socks = [socket.socket() for _ in sessions]
    try:
        for sock in socks:
            start_connect(sock, (tb.ip, 24))
        for sock in socks:
            await wait_connected(tb, sock, (tb.ip, 24))
        for s in sessions:
            await s.wait_state(TcpState.ESTABLISHED, 2_000_000)
        by_port = {s.get("peer_port"): s for s in sessions}
        assert sorted(by_port) == sorted(sock.getsockname()[1] for sock in socks), by_port
        for sock in socks:
            s = by_port[sock.getsockname()[1]]
            up, down = tb.rng.randbytes(8192), tb.rng.randbytes(8192)
            got_engine, got_kernel = await tb.transfer(sock, s, up, down, 2_000_000)
            assert got_engine == up and got_kernel == down
    finally:
        for sock in socks:
            sock.close()
    dut._log.info("pump %s", tb.pump.stats)


@cocotb.test()
async def run_linux_server_engine_client(dut):
    """Session 1 connects as a client to a kernel listener; both directions; the engine
    closes first."""
    tb = LinuxTB(dut)
    await tb.reset()
    s = SessionPort(dut, 1, random.Random(tb.rng.random()))
    s.set_pauses(0.2, 0.2)
    listener = socket.socket()
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    listener.bind((KERNEL_IP, 5000))
    listener.listen(1)
    listener.setblocking(False)
    conn = None
    try:
        s.set(active=1, remote_ip=int.from_bytes(socket.inet_aton(KERNEL_IP), "big"),
              remote_port=5000, local_port=0, open_req=1)
        accepted = []

        def accept():
            try:
                accepted.append(listener.accept()[0])
            except BlockingIOError:
                return False
            return True
        await tb.poll("accept", accept, 3_000_000)
        conn = accepted[0]
        await s.wait_state(TcpState.ESTABLISHED, 2_000_000)
        assert conn.getpeername()[1] >= 49152, "client port not ephemeral"
        up = tb.rng.randbytes(TRANSFER)
        down = tb.rng.randbytes(TRANSFER)
        got_engine, got_kernel = await tb.transfer(conn, s, up, down, 40 * TRANSFER + 2_000_000)
        assert got_engine == up and got_kernel == down
        s.set(open_req=0)                       # engine closes: FIN after its data

        def eof():
            try:
                return conn.recv(1) == b""
            except BlockingIOError:
                return False
        await tb.poll("FIN from the engine", eof, 2_000_000)
        conn.close()
        conn = None
        await s.wait_state(TcpState.CLOSED, 3_000_000)
    finally:
        listener.close()
        if conn is not None:
            conn.close()
    dut._log.info("pump %s, session %s", tb.pump.stats, await tb.session_counters(1))


@cocotb.test()
async def run_linux_ipv6_dropped_and_counted(dut):
    """docs/network.md: IPv6 stays on in the namespace. A datagram to an unknown link-local
    neighbour makes the kernel send a neighbour solicitation (to a multicast MAC); the
    engine drops it and whatever else the kernel sends meanwhile, and counts every frame:
    ``frames_in`` grows by exactly the frames the pump delivered, ``not_mine`` by at least
    the IPv6 ones."""
    from scapy.layers.inet6 import ICMPv6ND_NS
    from scapy.layers.l2 import Ether
    tb = LinuxTB(dut)
    await tb.reset()
    before, pumped = await tb.quiet_counters()
    ipv6_before = tb.pump.stats["ipv6"]
    tb.pump.ipv6_frames = []

    def solicitation():
        return any(ICMPv6ND_NS in Ether(f) and Ether(f)[ICMPv6ND_NS].tgt == "fe80::1"
                   for f in tb.pump.ipv6_frames)
    sock = socket.socket(socket.AF_INET6, socket.SOCK_DGRAM)
    try:
        for _ in range(20):      # the link-local address may still be tentative (DAD)
            try:
                sock.sendto(b"neighbour?", (f"fe80::1%{TAP_NAME}", 9))
                break
            except OSError:
                await tb.idle(100_000)
        await tb.poll("the kernel's neighbour solicitation for fe80::1", solicitation,
                      3_000_000, step=1024)
    finally:
        sock.close()
    after, delivered = await tb.quiet_counters()
    ipv6 = tb.pump.stats["ipv6"] - ipv6_before
    assert after["frames_in"] - before["frames_in"] == delivered - pumped, (before, after)
    assert after["not_mine"] - before["not_mine"] >= ipv6 >= 1, (ipv6, before, after)
    dut._log.info("IPv6 frames dropped and counted: %d; pump %s", ipv6, tb.pump.stats)
