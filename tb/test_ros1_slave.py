"""The hardware node's Slave API (gen/ros1/node.py, docs/messages.md, docs/network.md) over
real XML-RPC on loopback, with the endpoints' register space modelled as memory (the register
map of hdl/ros1/registers.py and the stack's global block): ``requestTopic`` names the port the
hardware publisher really listens on, a publisher's port 0 is the engine's ``tcp_port``
register (what ``LOCAL_PORT`` 0 means to the engine), and a bad port is refused by name. The
co-simulation with the engine is tb/test_ros1_node.py."""

import re
import xmlrpc.client

import pytest

from hdl.net.stack import global_register
from hdl.ros1.registers import CTRL, ENDPOINT_STRIDE, REG
from host.ros1 import HardwareNode, RosMaster

ENGINE_IP = "192.168.10.16"
SPEC = dict(type="std_msgs/String", md5sum="992ce8a1687cec8c8bd883ec73ca41d1",
            definition="string data\n")


class RegisterSpace:
    """Byte-addressed register space: reads what was written, zeros elsewhere; the global
    block's ``tcp_port`` holds ``tcp_port``; endpoint k's MODE reads ``modes[k]``."""

    def __init__(self, modes, tcp_port):
        self.memory = {}
        for k, mode in enumerate(modes):
            self.write_int(k * ENDPOINT_STRIDE + REG["MODE"][0], 1, mode)
        self.write_int(*global_register("tcp_port"), tcp_port)

    def read(self, address, length):
        return bytes(self.memory.get(address + i, 0) for i in range(length))

    def write(self, address, data):
        for i, byte in enumerate(bytes(data)):
            self.memory[address + i] = byte

    def read_int(self, address, size):
        return int.from_bytes(self.read(address, size), "big")

    def write_int(self, address, size, value):
        self.write(address, int(value).to_bytes(size, "big"))

    def endpoint(self, k, name):
        offset, size, _ = REG[name]
        return self.read_int(k * ENDPOINT_STRIDE + offset, size)


@pytest.fixture
def master():
    m = RosMaster("127.0.0.1", 0).start()
    yield m
    m.stop()


def start_node(master, registers, endpoints):
    return HardwareNode("/fpga", master.uri, "127.0.0.1", ENGINE_IP, registers,
                        endpoints).start()


@pytest.mark.parametrize("port,tcp_port,advertised", [(None, 11411, 11411), (0, 24, 24),
                                                      (5000, 11411, 5000)])
def test_request_topic_names_the_listening_port(master, port, tcp_port, advertised):
    registers = RegisterSpace([1, 0, 0], tcp_port)
    extra = {} if port is None else {"port": port}
    node = start_node(master, registers, [dict(SPEC, topic="/in"),
                                          dict(SPEC, topic="/out", **extra),
                                          dict(SPEC, topic="/other", port=6000)])
    try:
        slave = xmlrpc.client.ServerProxy(node.uri)
        code, _, params = slave.requestTopic("/sub", "/out", [["TCPROS"]])
        assert (code, params) == (1, ["TCPROS", ENGINE_IP, advertised])
        assert slave.requestTopic("/sub", "/other", [["TCPROS"]])[2] == ["TCPROS", ENGINE_IP,
                                                                        6000]
        # the endpoint was told to listen on the written port (0: the engine's port)
        assert registers.endpoint(1, "LOCAL_PORT") == (port or 0)
        assert registers.endpoint(1, "CTRL") & CTRL["START"]
        assert slave.requestTopic("/sub", "/in", [["TCPROS"]])[0] == -1
        assert slave.requestTopic("/sub", "/out", [["UDPROS"]])[0] == 0
        assert master.getSystemState("/t")[2][0] == [["/out", ["/fpga"]],
                                                      ["/other", ["/fpga"]]]
    finally:
        node.stop()


@pytest.mark.parametrize("port", [-1, 65536, "24", 24.0, True])
def test_bad_port_is_refused_by_name(master, port):
    with pytest.raises(ValueError, match=rf"endpoint 1 \('/out'\) port must be an integer "
                                         rf"in 0\.\.65535, not {re.escape(repr(port))}"):
        HardwareNode("/fpga", master.uri, "127.0.0.1", ENGINE_IP, RegisterSpace([1, 0], 24),
                     [dict(SPEC, topic="/in"), dict(SPEC, topic="/out", port=port)])
