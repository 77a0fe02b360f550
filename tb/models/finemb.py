"""FinEmbP frames as a master or a peer builds and reads them, written from the protocol's
definition (docs/finemb.md) with scapy for the Ethernet, IPv4 and UDP layers."""

import struct

from scapy.layers.inet import IP, UDP
from scapy.layers.l2 import Ether
from scapy.packet import Raw

from hdl.finemb.protocol import (
    FINEMB_PORT, GROUP_IP, GROUP_MAC, HEADER, HEADER_FORMAT, IP_TTL_FINEMB, MAGIC, PAYLOAD_FORMATS,
    STATE_SHIFT, VERSION, MsgType,
)

__all__ = ["finemb_frame", "parse_finemb", "MASTER_MAC", "MASTER_IP", "MASTER_PORT",
           "body_of"]

MASTER_MAC = "02:00:00:00:00:01"
MASTER_IP = "198.18.0.1"
MASTER_PORT = 50123


def finemb_frame(type_, node_id, body=b"", *, dst_mac=GROUP_MAC, dst_ip=GROUP_IP,
                 src_mac=MASTER_MAC, src_ip=MASTER_IP, sport=MASTER_PORT, dport=FINEMB_PORT,
                 flags=0, cycle=0, seq=0, length=None, magic=MAGIC, version=VERSION):
    """A FinEmbP frame (scapy ``Ether``) with the common header and ``body``; ``length``,
    ``magic`` and ``version`` may be given wrong on purpose."""
    header = struct.pack(HEADER_FORMAT, magic, version, int(type_), node_id, flags,
                         cycle & 0xFFFFFFFF, len(body) if length is None else length, seq)
    return (Ether(src=src_mac, dst=dst_mac) /
            IP(src=src_ip, dst=dst_ip, flags="DF", ttl=IP_TTL_FINEMB) /
            UDP(sport=sport, dport=dport) / Raw(header + bytes(body)))


def body_of(type_, *values):
    """The payload of a message type from its fields (struct formats of the protocol)."""
    return struct.pack(PAYLOAD_FORMATS[type_], *values)


def parse_finemb(frame):
    """The FinEmbP message of a scapy frame: a dict of the header's fields, ``state`` (flags
    bits 8-9), ``body`` (bytes) and the addresses; ``None`` when the frame is not FinEmbP."""
    if UDP not in frame or frame[UDP].dport not in (FINEMB_PORT,) and \
            frame[UDP].sport != FINEMB_PORT:
        return None
    payload = bytes(frame[UDP].payload)
    if len(payload) < HEADER:
        return None
    magic, version, type_, node_id, flags, cycle, length, seq = struct.unpack_from(
        HEADER_FORMAT, payload)
    return {"magic": magic, "version": version, "type": MsgType(type_), "node_id": node_id,
            "flags": flags, "state": flags >> STATE_SHIFT & 3, "cycle": cycle,
            "length": length, "seq": seq, "body": payload[HEADER:],
            "src_mac": frame[Ether].src, "dst_mac": frame[Ether].dst,
            "src_ip": frame[IP].src, "dst_ip": frame[IP].dst, "ttl": frame[IP].ttl,
            "sport": frame[UDP].sport,
            "dport": frame[UDP].dport}
