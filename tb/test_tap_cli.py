"""``rosgate tap`` as a user runs it (host/tap_cli.py, host/tapsim.py): the command creates a
network namespace with a TAP device, prints how to reach the simulated design, serves it until
SIGINT, then removes the namespace. The engine answers ping (iputils), RBCP (sitcpy) and TCP
echo (a socket) from inside the namespace; the FinEmbP line is found and cycled by the master.
"""

import os
import re
import signal
import subprocess
import sys
import time

import pytest

from host.tap import namespace_unavailable

from .harness import ROOT, SIM_BUILD

pytestmark = pytest.mark.skipif(namespace_unavailable() is not None,
                                reason=f"rosgate tap needs {namespace_unavailable()}")
ROSGATE = [sys.executable, "-m", "host.cli"]


def in_namespace(ns, *cmd, timeout=120):
    return subprocess.run(["ip", "netns", "exec", ns, *cmd], capture_output=True, text=True,
                          timeout=timeout)


def test_tap_engine_serves_ping_rbcp_and_tcp_until_sigint():
    proc = subprocess.Popen([*ROSGATE, "tap", "engine", "--sessions", "1", "--build-dir",
                             str(SIM_BUILD / "tap-engine")], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))
    lines = []
    try:
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            assert line, "rosgate tap engine ended early:\n" + "".join(lines)
            lines.append(line)
            if line.startswith("Ctrl-C"):
                break
        text = "".join(lines)
        ns = re.search(r"in namespace (rg[0-9a-f]+)", text).group(1)
        assert f"ip netns exec {ns} ping 198.18.0.16" in text
        assert ns in subprocess.run(["ip", "netns", "list"], capture_output=True,
                                    text=True).stdout
        ping = in_namespace(ns, "ping", "-c", "2", "-W", "10", "198.18.0.16")
        assert ping.returncode == 0, ping.stdout + ping.stderr
        script = ("import socket, sitcpy.rbcp as r\n"
                  "b = r.Rbcp('198.18.0.16', 4660)\n"
                  "b.write(0x20, bytes(range(40, 56)))\n"
                  "assert bytes(b.read(0x20, 16)) == bytes(range(40, 56))\n"
                  "s = socket.create_connection(('198.18.0.16', 24), timeout=60)\n"
                  "data = bytes(range(256)) * 20\n"
                  "s.sendall(data)\n"
                  "got = b''\n"
                  "while len(got) < len(data):\n"
                  "    got += s.recv(65536)\n"
                  "assert got == data\n"
                  "s.close()\n"
                  "print('rbcp and echo ok')\n")
        probe = in_namespace(ns, sys.executable, "-c", script, timeout=300)
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
        echo = subprocess.run(f"(printf 'hello rosgate\\n'; sleep 3) | timeout 20 "
                              f"{hints['TCP echo']}", shell=True, capture_output=True, text=True,
                              timeout=60)
        assert "hello rosgate" in echo.stdout, (echo.returncode, echo.stdout, echo.stderr)
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


def test_tap_needs_a_known_design_and_sane_sizes():
    bad = subprocess.run([*ROSGATE, "tap", "finemb", "--nodes", "0"], cwd=ROOT,
                         capture_output=True, text=True, timeout=60,
                         env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert bad.returncode == 2 and "--nodes must be an integer in 1..32, not 0" in bad.stderr
