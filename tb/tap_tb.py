"""Helpers of the tests that run ``rosgate tap`` as a user does (tb/test_tap_cli.py,
tb/test_board_sim.py): the command started until its design is up, commands in its network
namespace, and the engine's RBCP and TCP echo probe."""

import os
import subprocess
import sys
import time

from .harness import ROOT

__all__ = ["ROSGATE", "ENGINE_PROBE", "in_namespace", "start_tap"]

ROSGATE = [sys.executable, "-m", "host.cli"]
#: run in the namespace: RBCP (sitcpy) writes and reads back 16 registers, a TCP session
#: echoes 5 KiB
ENGINE_PROBE = ("import socket, sitcpy.rbcp as r\n"
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


def in_namespace(ns, *cmd, timeout=120):
    return subprocess.run(["ip", "netns", "exec", ns, *cmd], capture_output=True, text=True,
                          timeout=timeout)


def start_tap(*args, timeout=900):
    """``rosgate tap <args>`` started; its output up to the "Ctrl-C" line (the design is up)."""
    proc = subprocess.Popen([*ROSGATE, "tap", *map(str, args)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))
    lines = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            proc.kill()
            raise AssertionError(f"rosgate tap {args[0]} ended early:\n" + "".join(lines))
        lines.append(line)
        if line.startswith("Ctrl-C"):
            return proc, lines
    proc.kill()
    raise AssertionError(f"rosgate tap {args[0]} not up in {timeout} s:\n" + "".join(lines))
