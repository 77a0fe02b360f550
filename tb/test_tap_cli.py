"""``rosgate tap`` as a user runs it (host/tap_cli.py, host/tapsim.py): the command creates a
network namespace with a TAP device, prints how to reach the simulated design, serves it until
SIGINT, then removes the namespace. The engine answers ping (iputils), RBCP (sitcpy) and TCP
echo (a socket) from inside the namespace; the FinEmbP line is found and cycled by the master.
"""

import os
import re
import select
import signal
import subprocess
import sys

import pytest

from host.tap import namespace_unavailable

from .harness import ROOT, SIM_BUILD
from .tap_tb import ENGINE_PROBE, ROSGATE, in_namespace, start_tap

pytestmark = pytest.mark.skipif(namespace_unavailable() is not None,
                                reason=f"rosgate tap needs {namespace_unavailable()}")


def test_tap_engine_serves_ping_rbcp_and_tcp_until_sigint():
    proc, lines = start_tap("engine", "--sessions", "1", "--build-dir",
                            SIM_BUILD / "tap-engine")
    try:
        text = "".join(lines)
        ns = re.search(r"in namespace (rg[0-9a-f]+)", text).group(1)
        assert f"ip netns exec {ns} ping 198.18.0.16" in text
        assert ns in subprocess.run(["ip", "netns", "list"], capture_output=True,
                                    text=True).stdout
        ping = in_namespace(ns, "ping", "-c", "2", "-W", "10", "198.18.0.16")
        assert ping.returncode == 0, ping.stdout + ping.stderr
        probe = in_namespace(ns, sys.executable, "-c", ENGINE_PROBE, timeout=300)
        assert probe.returncode == 0 and "rbcp and echo ok" in probe.stdout, \
            probe.stdout + probe.stderr
        # the printed hints, run as printed (a user pastes them into a shell)
        hints = {m["what"]: m["command"] for m in re.finditer(
            r"^  (?P<what>RBCP|TCP echo)\s+(?P<command>ip netns exec .*?)(?:  \(.*)?$", text,
            re.MULTILINE)}
        rbcp = subprocess.run(hints["RBCP"], shell=True, capture_output=True, text=True,
                              timeout=120)
        # the hint reads 16 bytes at 0, which nothing wrote (the registers start cleared)
        assert rbcp.returncode == 0 and rbcp.stdout.strip() == repr(bytearray(16)), \
            rbcp.stdout + rbcp.stderr
        # nc stays connected after its input ends: the line back is all the test waits for
        echo = subprocess.Popen(hints["TCP echo"], shell=True, stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
        try:
            echo.stdin.write("hello rosgate\n")
            echo.stdin.flush()
            ready, _, _ = select.select([echo.stdout], [], [], 20)
            line = echo.stdout.readline() if ready else ""
        finally:
            os.killpg(echo.pid, signal.SIGTERM)
            echo.wait(timeout=10)
        assert line == "hello rosgate\n", (line, echo.stderr.read())
    finally:
        proc.send_signal(signal.SIGINT)
        rest, _ = proc.communicate(timeout=180)
    assert proc.returncode == 0, "".join(lines) + rest
    last = rest.strip().splitlines()[-1]
    assert last.startswith("rosgate tap engine: stopped after") and f"{ns} removed" in last
    assert ns not in subprocess.run(["ip", "netns", "list"], capture_output=True,
                                    text=True).stdout


def test_tap_finemb_runs_the_master_for_some_cycles():
    result = subprocess.run([*ROSGATE, "tap", "finemb", "--nodes", "2", "--cycles", "12",
                             "--build-dir", str(SIM_BUILD / "tap-finemb-n2")], cwd=ROOT,
                            capture_output=True, text=True, timeout=900,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert result.returncode == 0, result.stdout + result.stderr
    assert "node 1: 02:00:00:00:46:01 at 198.18.0.17" in result.stdout
    last = result.stdout.strip().splitlines()[-1]
    assert re.match(r"rosgate tap finemb: 12 cycles at [0-9.]+ cycles/s, 0 late answers, "
                    r"nodes 1 OP, 2 OP; namespace rg[0-9a-f]+ removed", last), last


#: a FinEmbP master written from docs/finemb.md alone, over the standard socket module: it
#: finds and addresses the nodes, runs cycles, falls silent until the watchdog fires, sends
#: a REINIT (reason 1) to one node, and checks the state each answer reports
SOCKET_MASTER = r"""
import socket, struct, sys, time
TAP, KERNEL, MACS = sys.argv[1], sys.argv[2], [bytes.fromhex(m.replace(":", ""))
                                              for m in sys.argv[3:]]
PORT, GROUP, BCAST = 61920, "239.255.70.69", "255.255.255.255"
HDR = struct.Struct("<HBBHHIHH")     # magic, version, type, node_id, flags, cycle, length, seq
SOC, ISEND_REQ, ISEND_RES, ID_REQ, ID_RES, ADDR_REQ, ADDR_RES, REINIT = \
    0x01, 0x02, 0x03, 0x10, 0x11, 0x12, 0x13, 0x16
STATES = {0: "INIT", 1: "PREOP", 2: "OP", 3: "REINIT"}
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
s.setsockopt(socket.SOL_SOCKET, socket.SO_BINDTODEVICE, TAP.encode())
s.setsockopt(socket.IPPROTO_IP, socket.IP_TTL, 1)
s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(KERNEL))
s.bind(("", PORT))
s.settimeout(20)
seq = 0

def send(type_, node, body, to, cycle=0):
    global seq
    seq += 1
    s.sendto(HDR.pack(0x4546, 1, type_, node, 0, cycle, len(body), seq) + body, (to, PORT))

def receive(type_, count):
    got = []
    while len(got) < count:
        data, _ = s.recvfrom(2048)
        magic, version, t, node, flags, cycle, length, _ = HDR.unpack_from(data)
        if magic == 0x4546 and t == type_:
            assert length == len(data) - HDR.size, (length, len(data))
            got.append((node, flags, cycle, data[HDR.size:]))
    return got

send(ID_REQ, 0xFFFF, struct.pack("<H", 1), BCAST)
ids = receive(ID_RES, len(MACS))
assert sorted(r[3][:6] for r in ids) == sorted(MACS), ids
assert all(r[0] == 0xFFFF for r in ids), "ID_RES carries node id 0xFFFF"
pages = {r[3][:6]: struct.unpack_from("<HH", r[3], 14) for r in ids}   # in, out bytes
net = KERNEL.rsplit(".", 1)[0]
ips = {}
for k, mac in enumerate(MACS, 1):
    ips[k] = f"{net}.{16 + k}"
    send(ADDR_REQ, 0xFFFF, mac + socket.inet_aton(ips[k]) + socket.inet_aton("255.255.255.0")
         + struct.pack("<H", k), BCAST)
    (node, flags, _, body), = receive(ADDR_RES, 1)
    assert node == k and body[:6] == mac and STATES[flags >> 8 & 3] == "PREOP", (node, flags)
cycle = 0

def run_cycle(period_ns=10_000_000):
    global cycle
    cycle += 1
    send(SOC, 0xFFFF, struct.pack("<IQHH", period_ns, time.monotonic_ns(), len(MACS), 0),
         GROUP, cycle)
    for k, mac in enumerate(MACS, 1):
        send(ISEND_REQ, k, bytes(pages[mac][1]), ips[k], cycle)
    answers = {node: (flags, c, body) for node, flags, c, body in receive(ISEND_RES, len(MACS))}
    for k, mac in enumerate(MACS, 1):
        flags, c, body = answers[k]
        assert c == cycle and len(body) == pages[mac][0] and not flags & 2, answers
    return {k: STATES[answers[k][0] >> 8 & 3] for k in answers}

for _ in range(3):                  # 10 ms periods: the watchdog (3 periods) stays quiet
    assert set(run_cycle().values()) == {"OP"}
assert set(run_cycle(40_000).values()) == {"OP"}
time.sleep(2)                       # silence: three 40 us periods pass many times over
assert set(run_cycle().values()) == {"REINIT"}, "the first answer after the watchdog"
assert set(run_cycle().values()) == {"OP"}
send(REINIT, 1, bytes([1]), ips[1], cycle)
assert run_cycle() == {1: "REINIT", 2: "OP"}, "the first answer after a REINIT"
assert run_cycle() == {1: "OP", 2: "OP"}
print("socket master ok")
"""


def test_tap_finemb_no_master_serves_a_socket_master():
    """``rosgate tap finemb --no-master``: the line comes up and waits; a master written in
    the test from docs/finemb.md runs it from the namespace, including the REINIT answers."""
    proc, lines = start_tap("finemb", "--nodes", "2", "--no-master", "--build-dir",
                            SIM_BUILD / "tap-finemb-n2")
    try:
        text = "".join(lines)
        mo = re.search(r"up on (\S+) in namespace (rg[0-9a-f]+); the kernel is ([0-9.]+)/24",
                       text)
        assert mo, text
        tap, ns, kernel = mo.groups()
        macs = re.findall(r"node \d: MAC ([0-9a-f:]{17}), serial \d", text)
        assert macs == ["02:00:00:00:46:01", "02:00:00:00:46:02"], text
        master = in_namespace(ns, sys.executable, "-c", SOCKET_MASTER, tap, kernel, *macs,
                              timeout=600)
        assert master.returncode == 0 and "socket master ok" in master.stdout, \
            master.stdout + master.stderr
    finally:
        proc.send_signal(signal.SIGINT)
        rest, _ = proc.communicate(timeout=180)
    assert proc.returncode == 0, "".join(lines) + rest
    # the states as they change (sampled: the simulation writes its status about once a
    # second, so short states may pass unseen)
    assert re.search(r"\] nodes: 0 (PREOP|OP|REINIT), 1 (PREOP|OP|REINIT)$", rest, re.M), rest
    last = rest.strip().splitlines()[-1]
    assert last.startswith("rosgate tap finemb: stopped after") and f"{ns} removed" in last


def test_tap_needs_a_known_design_and_sane_sizes():
    bad = subprocess.run([*ROSGATE, "tap", "finemb", "--nodes", "0"], cwd=ROOT,
                         capture_output=True, text=True, timeout=60,
                         env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert bad.returncode == 2 and "--nodes must be an integer in 1..32, not 0" in bad.stderr
