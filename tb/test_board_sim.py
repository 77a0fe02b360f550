"""Board tops in simulation (docs/boards.md "Simulating a board top"): the top of ``rosgate
board build`` with only the ECP5 primitives replaced by cycle-level models, an RGMII PHY model
(cocotbext-eth) on its first Ethernet port bridged to a TAP device in a network namespace.
From the Linux side: the engine answers ping (iputils), RBCP (sitcpy) and a TCP echo
(``rosgate tap board engine``, as a user runs it); the tcpros design relays a ROS 1 topic
between software peers that speak TCPROS through the kernel's TCP, the ROS master and the
hardware node's XML-RPC in software as docs/ros1.md describes; a line of two finemb boards is
driven by the FinEmbP master (``rosgate tap board finemb``). The synthesised netlist of the
engine answers ARP, ping and RBCP (``make test-full``)."""

import os
import re
import signal
import subprocess
import sys
import time

import pytest

from host.tap import namespace_unavailable

from .harness import ROOT, SIM_BUILD
from .tap_tb import ENGINE_PROBE, ROSGATE, in_namespace, start_tap

pytestmark = pytest.mark.skipif(namespace_unavailable() is not None,
                                reason=f"board tops on TAP need {namespace_unavailable()}")
#: the board the tests simulate: two RGMII ports, a differential oscillator
BOARD = "versa_ecp5"
ENGINE_IP, KERNEL_IP = "198.18.0.16", "198.18.0.1"


def test_tap_board_engine_answers_ping_rbcp_and_tcp_echo():
    proc, lines = start_tap("board", "engine", "--board", BOARD, "--build-dir",
                            SIM_BUILD / "tap-board-engine")
    try:
        text = "".join(lines)
        ns = re.search(r"in namespace (rg[0-9a-f]+)", text).group(1)
        ping = in_namespace(ns, "ping", "-c", "3", "-W", "10", ENGINE_IP)
        assert ping.returncode == 0 and " 0% packet loss" in ping.stdout, ping.stdout
        probe = in_namespace(ns, sys.executable, "-c", ENGINE_PROBE, timeout=300)
        assert probe.returncode == 0 and "rbcp and echo ok" in probe.stdout, \
            probe.stdout + probe.stderr
    finally:
        proc.send_signal(signal.SIGINT)
        rest, _ = proc.communicate(timeout=180)
    assert proc.returncode == 0, "".join(lines) + rest
    assert rest.strip().splitlines()[-1].startswith("rosgate tap board: stopped after")


def test_tap_board_finemb_line_of_two_boards_runs_the_master():
    """Two boards of the finemb design, board 0's port 1 wired to board 1's port 0, their
    oscillators 250 ppm apart (the receive crossings at work), found, initialised and cycled
    by rosgate's FinEmbP master over UDP sockets."""
    result = subprocess.run([*ROSGATE, "tap", "board", "finemb", "--board", BOARD, "--cycles",
                             "12", "--build-dir", str(SIM_BUILD / "tap-board-finemb")],
                            cwd=ROOT, capture_output=True, text=True, timeout=900,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert result.returncode == 0, result.stdout + result.stderr
    assert "the oscillators are 0, 250 ppm off 125 MHz" in result.stdout
    assert "node 2: 02:00:00:00:46:02 at 198.18.0.18, serial 2" in result.stdout
    last = result.stdout.strip().splitlines()[-1]
    assert re.match(r"rosgate tap board finemb: 12 cycles at [0-9.]+ cycles/s, 0 late answers, "
                    r"nodes 1 OP, 2 OP; namespace rg[0-9a-f]+ removed", last), last


def wait_for(what, condition, timeout_s=120):
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"no {what} within {timeout_s} s"
        time.sleep(0.1)


def test_board_tcpros_relays_a_topic_between_software_peers():
    from gen.msg import MessageLibrary
    from gen.msg.ros1 import md5sum, message_definition
    from hdl.net.stack import global_register
    from host.board_sim import TOP, board_sim_verilog
    from host.ros1 import HardwareNode, RbcpClient, RosMaster
    from host.tapsim import TapSimulation

    from .models.ros1_peers import SoftwarePublisher, SoftwareSubscriber
    lib = MessageLibrary(store="ros1_noetic")
    kind = "std_msgs/String"
    md5, definition = md5sum(lib, kind), message_definition(lib, kind)
    folder = SIM_BUILD / "tap-board-tcpros"
    verilog, pins = board_sim_verilog("tcpros", BOARD, folder, {"ip": ENGINE_IP})
    with TapSimulation(None, TOP, folder, exported=verilog, module="host.tap_board_serve",
                       params={"pins": pins}, kernel_ip=KERNEL_IP):
        master = RosMaster(KERNEL_IP, 0).start()
        rbcp = RbcpClient(ENGINE_IP, timeout=2.0, retries=5)
        spec = dict(type=kind, md5sum=md5, definition=definition)
        node = HardwareNode("/fpga", master.uri, KERNEL_IP, ENGINE_IP, rbcp,
                            [dict(spec, topic="/chatter"), dict(spec, topic="/chatter_fpga")])
        talker = SoftwarePublisher("/talker", master.uri, KERNEL_IP, "/chatter", kind, md5,
                                   definition)
        listener = SoftwareSubscriber("/listener", master.uri, KERNEL_IP, "/chatter_fpga", kind,
                                      md5, definition)
        try:
            rbcp.write_int(*global_register("tcp_port"), 11411)
            node.start()
            talker.register()
            wait_for("hardware subscriber at /talker", lambda: talker.connections)
            listener.register()
            wait_for("/listener connected to the hardware publisher",
                     lambda: listener.headers)
            sent = [len(text).to_bytes(4, "little") + text for text in (
                b"hello from the talker", b"", "ROS 1 on an ECP5 board".encode(), b"x" * 1000)]
            for body in sent:
                talker.publish(body)
            wait_for("messages at /listener", lambda: len(listener.messages) >= len(sent))
            assert listener.messages == sent
            header = listener.headers[0]
            assert (header["type"], header["md5sum"], header["callerid"]) == (kind, md5, "/fpga")
            assert not talker.errors and not listener.errors and not node.errors
        finally:
            for closer in (node.stop, talker.close, listener.close, master.stop, rbcp.close):
                try:
                    closer()
                except OSError:
                    pass


@pytest.mark.full
def test_engine_netlist_answers_arp_ping_and_rbcp():
    """The netlist Yosys synthesised for the engine's bitstream (with Yosys' ECP5 cell models
    and rosgate's DP16KD and primitive models) answers the kernel's ARP, a ping and an RBCP
    write and read (``make test-full``: synthesis and the netlist's build take minutes)."""
    from host.board import synthesise_board
    from host.board_sim import netlist_sim_verilog
    from host.tapsim import TapSimulation
    build = SIM_BUILD / "board-netlist-engine"
    synthesise_board("engine", BOARD, build, options={"ip": ENGINE_IP})
    verilog, pins = netlist_sim_verilog(build, build / "sim")
    with TapSimulation(None, "top", build / "sim", exported=verilog,
                       module="host.tap_board_serve", params={"pins": pins},
                       kernel_ip=KERNEL_IP, ready_timeout_s=1800) as sim:
        ping = in_namespace(sim.namespace, "ping", "-c", "3", "-W", "30", ENGINE_IP,
                            timeout=300)
        replies = re.findall(r"bytes from " + re.escape(ENGINE_IP), ping.stdout)
        assert replies, ping.stdout + ping.stderr
        script = ("import sitcpy.rbcp as r\n"
                  f"b = r.Rbcp('{ENGINE_IP}', 4660)\n"
                  "b.write(0x20, bytes(range(40, 56)))\n"
                  "assert bytes(b.read(0x20, 16)) == bytes(range(40, 56))\n"
                  "print('rbcp ok')\n")
        probe = in_namespace(sim.namespace, sys.executable, "-c", script, timeout=300)
        assert probe.returncode == 0 and "rbcp ok" in probe.stdout, probe.stdout + probe.stderr
