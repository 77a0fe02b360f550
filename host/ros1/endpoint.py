"""Drive one hardware TCPROS endpoint through its RBCP registers (docs/network.md)."""

from gen.msg.ros1 import decode_connection_header, encode_connection_header
from hdl.net.frames import ip_to_int
from hdl.ros1.registers import (
    CHECK_DEFAULT,
    COUNTERS,
    COUNTERS_OFFSET,
    CTRL,
    ENDPOINT_STRIDE,
    ERRORS,
    EXPECTED,
    HDR_ERR,
    HDR_RX,
    HDR_TX,
    PHASES,
    REG,
)

__all__ = ["EndpointClient", "connection_header_fields"]


def connection_header_fields(role, *, callerid, topic, typename, md5sum, definition):
    """The fields a hardware endpoint sends (docs/messages.md "hardware publisher minimum"):
    a publisher answers with callerid, md5sum, type, topic, latching=0 and
    message_definition; a subscriber sends callerid, topic, md5sum, type, tcp_nodelay=1 and
    message_definition."""
    if role == "publisher":
        return [("callerid", callerid), ("md5sum", md5sum), ("type", typename),
                ("topic", topic), ("latching", "0"), ("message_definition", definition)]
    if role == "subscriber":
        return [("callerid", callerid), ("topic", topic), ("md5sum", md5sum),
                ("type", typename), ("tcp_nodelay", "1"), ("message_definition", definition)]
    raise ValueError(f"role must be 'publisher' or 'subscriber', not {role!r}")


class EndpointClient:
    """Registers of endpoint ``index`` of a :class:`~hdl.ros1.TcprosNode`."""

    def __init__(self, rbcp, index):
        self.rbcp = rbcp
        self.index = index
        self.base = index * ENDPOINT_STRIDE

    def read(self, name):
        offset, size, _ = REG[name]
        return self.rbcp.read_int(self.base + offset, size)

    def write(self, name, value):
        offset, size, access = REG[name]
        if "W" not in access:
            raise ValueError(f"register {name} is read-only")
        self.rbcp.write_int(self.base + offset, size, value)

    @property
    def role(self):
        return ("publisher", "subscriber")[self.read("MODE")]

    def _write_string(self, name, text):
        offset, capacity = EXPECTED[name]
        raw = text.encode()
        if len(raw) > capacity:
            raise ValueError(f"{name} {text!r} is longer than the {capacity} bytes the "
                             f"endpoint compares")
        self.rbcp.write(self.base + offset, bytes([len(raw)]) + raw)

    def configure(self, *, callerid, topic, typename, md5sum, definition,
                  check=CHECK_DEFAULT, max_msg=None, error_text=None):
        """Write the expected values, the pre-encoded local connection header and (for a
        publisher) the ``error=`` header sent to a mismatching subscriber."""
        role = self.role
        for name, value in (("topic", topic), ("type", typename), ("md5sum", md5sum),
                            ("callerid", callerid)):
            self._write_string(name, value)
        header = encode_connection_header(connection_header_fields(
            role, callerid=callerid, topic=topic, typename=typename, md5sum=md5sum,
            definition=definition))
        if len(header) > HDR_TX[1]:
            raise ValueError(f"connection header of {len(header)} bytes does not fit the "
                             f"{HDR_TX[1]}-byte HDR_TX memory")
        self.rbcp.write(self.base + HDR_TX[0], header)
        self.write("HDR_TX_LEN", len(header))
        if role == "publisher":
            text = error_text or (f"client wants topic or type other than [{topic}] "
                                  f"[{typename}] md5 [{md5sum}]")
            err = encode_connection_header([("error", text)])[:HDR_ERR[1]]
            self.rbcp.write(self.base + HDR_ERR[0], err)
            self.write("HDR_ERR_LEN", len(err))
        self.write("CHECK", check)
        if max_msg is not None:
            self.write("MAX_MSG", max_msg)

    def listen(self, port, *, block=False):
        self.write("LOCAL_PORT", port)
        self.write("CTRL", CTRL["START"] | (CTRL["BLOCK"] if block else 0))

    def connect(self, ip, port):
        self.write("CTRL", 0)             # re-arm: START must rise
        self.write("REMOTE_IP", ip_to_int(ip))
        self.write("REMOTE_PORT", port)
        self.write("CTRL", CTRL["START"])

    def stop(self):
        self.write("CTRL", CTRL["STOP"])

    @property
    def phase(self):
        return PHASES[self.read("PHASE")]

    @property
    def errors(self):
        value = self.read("ERROR")
        return {name for name, bit in ERRORS.items() if value & bit}

    def clear_errors(self):
        self.write("ERROR", 0xFF)

    @property
    def local_port(self):
        return self.read("LOCAL_PORT")

    def counters(self):
        raw = self.rbcp.read(self.base + COUNTERS_OFFSET, 4 * len(COUNTERS))
        return {name: int.from_bytes(raw[4 * k:4 * k + 4], "big")
                for k, name in enumerate(COUNTERS)}

    def clear_counters(self):
        """Zero the endpoint's counters (``CTRL.CLR_CNT``), keeping START and BLOCK."""
        kept = self.read("CTRL") & (CTRL["START"] | CTRL["BLOCK"])
        self.write("CTRL", kept | CTRL["CLR_CNT"])

    def received_header(self):
        """The peer's connection header as the endpoint stored it, decoded."""
        length = self.read("HDR_RX_LEN")
        if length & 0x8000:
            raise ValueError("the received connection header was truncated")
        return decode_connection_header(self.rbcp.read(self.base + HDR_RX[0], length))
