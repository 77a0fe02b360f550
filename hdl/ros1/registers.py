"""RBCP register map of a TCPROS endpoint (docs/network.md), shared by the hardware and the
software that drives it. Endpoint ``k`` sits at ``k * ENDPOINT_STRIDE``; multi-byte values
are big-endian."""

__all__ = ["ENDPOINT_STRIDE", "REG", "PHASES", "ERRORS", "CTRL", "CHECK", "COUNTERS",
           "EXPECTED", "EXPECTED_AREA", "COUNTERS_OFFSET", "HDR_TX", "HDR_ERR", "HDR_RX", "ENDPOINT_ID", "CHECK_DEFAULT"]

ENDPOINT_STRIDE = 0x1_0000

#: name -> (offset, bytes, access)
REG = {
    "ID": (0x00, 4, "R"),
    "MODE": (0x04, 1, "R"),           # 0 publisher (server), 1 subscriber (client); fixed
    "CTRL": (0x05, 1, "RW"),
    "LOCAL_PORT": (0x06, 2, "RW"),
    "REMOTE_IP": (0x08, 4, "RW"),     # subscriber: publisher to connect to; publisher: peer
    "REMOTE_PORT": (0x0C, 2, "RW"),
    "TCP_STATE": (0x10, 1, "R"),
    "PHASE": (0x11, 1, "R"),
    "ERROR": (0x12, 1, "RW1C"),
    "HDR_TX_LEN": (0x14, 2, "RW"),
    "HDR_ERR_LEN": (0x16, 2, "RW"),
    "HDR_RX_LEN": (0x18, 2, "R"),     # bit 15: the received header was truncated
    "CHECK": (0x1A, 1, "RW"),
    "MAX_MSG": (0x1C, 4, "RW"),
}

#: CTRL bits: START is a level (publisher: listen; subscriber: connect on its rise), STOP
#: and ABORT close with FIN or RST and clear START, CLR_CNT clears the counters, BLOCK holds
#: the publisher's input while no subscriber streams (else whole messages are dropped).
CTRL = {"START": 0x01, "STOP": 0x02, "ABORT": 0x04, "CLR_CNT": 0x08, "BLOCK": 0x20}

#: CHECK bits: compare topic, type, md5sum; accept md5sum "*"; fail on an ``error=`` field
CHECK = {"TOPIC": 0x01, "TYPE": 0x02, "MD5": 0x04, "STAR": 0x08, "ERROR": 0x10}
CHECK_DEFAULT = 0x1F

PHASES = ("idle", "connecting", "hdr_tx", "hdr_rx", "validating", "streaming", "closing",
          "error")

#: ERROR register bits
ERRORS = {"refused": 0x01, "timeout": 0x02, "arp": 0x04, "header_rejected": 0x08,
          "peer_error": 0x10, "reset": 0x20, "length_mismatch": 0x80}

#: counters from offset 0x20, 4 bytes each
COUNTERS = ("bytes_tx", "bytes_rx", "messages_tx", "messages_rx", "rto", "fast_retransmit",
            "dup_acks", "rst_rx", "header_rejects", "messages_dropped")
COUNTERS_OFFSET = 0x20

#: the memory holding the expected values below: (offset, bytes)
EXPECTED_AREA = (0x100, 256)
#: expected connection-header values: name -> (offset of the length byte, capacity). The
#: spec's 32-byte md5sum slot at 0x180 cannot hold a length byte and 32 hex digits, so
#: CALLERID moves from 0x1A0 to 0x1C0.
EXPECTED = {"topic": (0x100, 63), "type": (0x140, 63), "md5sum": (0x180, 32),
            "callerid": (0x1C0, 63)}

HDR_TX = (0x1000, 4096)       # our connection header, with its 4-byte length prefix
HDR_ERR = (0x2000, 256)       # the publisher's ``error=`` header, with its prefix
HDR_RX = (0x3000, 4096)       # the peer's header as received (after the prefix)

ENDPOINT_ID = b"RG\x01"       # then the endpoint count in byte 3
