"""Wire constants of the network engine, defined once (docs/network.md).

Offsets are byte offsets from the first byte of the destination MAC address (the byte after
the SFD). The hardware parser and builder and the Python models import them from here.
"""

from amaranth.lib import data

__all__ = [
    "ETH_HEADER_FIELDS", "ARP_HEADER_FIELDS", "IPV4_HEADER_FIELDS", "ICMP_HEADER_FIELDS",
    "UDP_HEADER_FIELDS", "TCP_HEADER_FIELDS",
    "ETH_HEADER", "ETH_SRC_OFFSET", "ARP_SHA_OFFSET", "ARP_SPA_OFFSET", "IP_PROTO_OFFSET",
    "IP_CSUM_OFFSET", "IP_SRC_OFFSET", "L4_OFFSET", "UDP_CSUM_OFFSET", "TCP_CSUM_OFFSET",
    "ETHERTYPE_IPV4", "ETHERTYPE_ARP", "ETHERTYPE_IPV6", "MIN_FRAME", "MAX_FRAME", "PREAMBLE",
    "PREAMBLE_BYTE",
    "SFD", "IFG", "ARP_OFFSET", "ARP_LENGTH", "ARP_REQUEST", "ARP_REPLY", "IP_OFFSET", "IP_VERSION",
    "MIN_HEADER_WORDS", "IP_PROTO_ICMP",
    "IP_PROTO_TCP", "IP_PROTO_UDP", "IP_TTL", "ICMP_ECHO_REQUEST", "ICMP_ECHO_REPLY",
    "TCP_FLAGS", "TCP_FIN", "TCP_SYN", "TCP_RST", "TCP_PSH", "TCP_ACK", "TCP_OPT_MSS",
    "TCP_OPT_MSS_LENGTH",
    "TCP_MSS", "TCP_MSS_DEFAULT", "TCP_MSS_MIN", "RBCP_VERSION", "RBCP_WRITE", "RBCP_READ",
    "RBCP_REPLY",
    "RBCP_BUS_ERROR", "RBCP_HEADER", "DEFAULT_IP", "DEFAULT_MAC", "DEFAULT_TCP_PORT",
    "DEFAULT_RBCP_PORT", "ip_to_int", "int_to_ip", "mac_to_int", "int_to_mac",
    "DROP_REASONS",
]

PREAMBLE = 7                  # PREAMBLE_BYTE bytes before the SFD
PREAMBLE_BYTE = 0x55
SFD = 0xD5
IFG = 12                      # byte times between frames at the transmitter
ETH_HEADER = 14
MIN_FRAME = 64                # dst MAC .. FCS
MAX_FRAME = 1518
ETHERTYPE_IPV4 = 0x0800
ETHERTYPE_ARP = 0x0806
#: not handled: counted as ``not_mine`` (docs/network.md, the kernel's neighbour discovery)
ETHERTYPE_IPV6 = 0x86DD

#: Header layouts: field -> (byte offset in its header, bytes), multi-byte fields big-endian.
#: The frame parser captures its fields from these tables.
ETH_HEADER_FIELDS = {"dst": (0, 6), "src": (6, 6), "ethertype": (12, 2)}
#: ARP for IPv4 over Ethernet (RFC 826)
ARP_HEADER_FIELDS = {"htype": (0, 2), "ptype": (2, 2), "hlen": (4, 1), "plen": (5, 1),
                     "oper": (6, 2), "sha": (8, 6), "spa": (14, 4), "tha": (18, 6),
                     "tpa": (24, 4)}
#: IPv4 (RFC 791)
IPV4_HEADER_FIELDS = {"version_ihl": (0, 1), "tos": (1, 1), "total_length": (2, 2),
                      "identification": (4, 2), "flags_fragment": (6, 2), "ttl": (8, 1),
                      "protocol": (9, 1), "checksum": (10, 2), "src": (12, 4), "dst": (16, 4)}
#: ICMP (RFC 792)
ICMP_HEADER_FIELDS = {"type": (0, 1), "code": (1, 1), "checksum": (2, 2)}
#: UDP (RFC 768)
UDP_HEADER_FIELDS = {"src_port": (0, 2), "dst_port": (2, 2), "length": (4, 2),
                     "checksum": (6, 2)}
#: TCP (RFC 9293 §3.1); ``data_offset`` is the byte whose high nibble holds it
TCP_HEADER_FIELDS = {"src_port": (0, 2), "dst_port": (2, 2), "seq": (4, 4), "ack": (8, 4),
                     "data_offset": (12, 1), "flags": (13, 1), "window": (14, 2),
                     "checksum": (16, 2), "urgent": (18, 2)}

ETH_SRC_OFFSET = ETH_HEADER_FIELDS["src"][0]
ARP_OFFSET = ETH_HEADER
ARP_SHA_OFFSET = ARP_OFFSET + ARP_HEADER_FIELDS["sha"][0]
ARP_SPA_OFFSET = ARP_OFFSET + ARP_HEADER_FIELDS["spa"][0]
#: an ARP packet for IPv4 over Ethernet, after the Ethernet header
ARP_LENGTH = sum(ARP_HEADER_FIELDS["tpa"])
ARP_REQUEST = 1
ARP_REPLY = 2

IP_OFFSET = ETH_HEADER
IP_VERSION = 4
#: the smallest IPv4 IHL and TCP data offset, in 32-bit words (20-byte headers)
MIN_HEADER_WORDS = 5
IP_PROTO_OFFSET = IP_OFFSET + IPV4_HEADER_FIELDS["protocol"][0]
IP_CSUM_OFFSET = IP_OFFSET + IPV4_HEADER_FIELDS["checksum"][0]
IP_SRC_OFFSET = IP_OFFSET + IPV4_HEADER_FIELDS["src"][0]
L4_OFFSET = IP_OFFSET + 20    # the L4 header of a frame without IP options (all we send)
UDP_CSUM_OFFSET = L4_OFFSET + UDP_HEADER_FIELDS["checksum"][0]
TCP_CSUM_OFFSET = L4_OFFSET + TCP_HEADER_FIELDS["checksum"][0]
IP_PROTO_ICMP = 1
IP_PROTO_TCP = 6
IP_PROTO_UDP = 17
IP_TTL = 64

ICMP_ECHO_REQUEST = 8
ICMP_ECHO_REPLY = 0

#: The TCP header's flag byte (RFC 9293 §3.1, RFC 3168 for ECE and CWR), bit 0 first.
TCP_FLAGS = data.StructLayout({"fin": 1, "syn": 1, "rst": 1, "psh": 1, "ack": 1, "urg": 1,
                               "ece": 1, "cwr": 1})
TCP_FIN, TCP_SYN, TCP_RST, TCP_PSH, TCP_ACK = (1 << TCP_FLAGS[name].offset
                                               for name in ("fin", "syn", "rst", "psh", "ack"))
TCP_OPT_MSS = 2
TCP_OPT_MSS_LENGTH = 4
TCP_MSS = 1460                # sent in SYN and SYN-ACK
TCP_MSS_DEFAULT = 536         # assumed when the peer's SYN has no MSS option (RFC 9293 §3.7.1)
#: The smallest peer MSS used: a smaller announced one is raised to it, as Linux does
#: (``net.ipv4.tcp_min_snd_mss``, CVE-2019-11479): an MSS of 1 would fill the descriptor
#: ring with one-byte segments.
TCP_MSS_MIN = 48

RBCP_VERSION = 0xFF
RBCP_WRITE = 0x80
RBCP_READ = 0xC0
RBCP_REPLY = 0x08             # set in the reply's CMD/flag byte
RBCP_BUS_ERROR = 0x01
RBCP_HEADER = 8

DEFAULT_IP = "192.168.10.16"
DEFAULT_MAC = "02:00:c0:a8:0a:10"   # locally administered; SiTCP reads its MAC from an EEPROM
DEFAULT_TCP_PORT = 24
DEFAULT_RBCP_PORT = 4660

#: Why a received frame was dropped, in the order of the stack's drop counters (docs/network.md
#: "drop counters per reason").
DROP_REASONS = (
    "fcs",          # bad FCS
    "rx_er",        # RX_ER inside the frame
    "size",         # shorter than 64 or longer than 1518 bytes
    "not_mine",     # destination MAC or IP not ours, unknown EtherType, ARP not for us
    "ip_header",    # bad IPv4 version, IHL, total length or header checksum
    "fragment",     # MF set or fragment offset not 0
    "protocol",     # IP protocol other than ICMP, UDP, TCP; ICMP other than echo request
    "l4_checksum",  # bad ICMP, UDP or TCP checksum or length
    "no_port",      # UDP to a closed port, TCP answered with RST
    "busy",         # reply buffer or reply slot in use
    "listen_no_syn",  # TCP to a listening port without SYN, ACK or RST (RFC 9293 §3.10.7.2)
)


def ip_to_int(text):
    """``"192.168.10.16"`` -> ``0xC0A80A10``; raise ``ValueError`` naming a bad address."""
    parts = str(text).split(".")
    if len(parts) != 4 or not all(p.isdigit() and int(p) < 256 for p in parts):
        raise ValueError(f"not an IPv4 address: {text!r}")
    return int.from_bytes(bytes(int(p) for p in parts), "big")


def int_to_ip(value):
    return ".".join(str(b) for b in value.to_bytes(4, "big"))


def mac_to_int(text):
    """``"02:00:c0:a8:0a:10"`` -> 48-bit integer; raise ``ValueError`` naming a bad address."""
    parts = str(text).split(":")
    if len(parts) != 6 or not all(len(p) == 2 for p in parts):
        raise ValueError(f"not a MAC address: {text!r}")
    try:
        return int.from_bytes(bytes(int(p, 16) for p in parts), "big")
    except ValueError:
        raise ValueError(f"not a MAC address: {text!r}") from None


def int_to_mac(value):
    return ":".join(f"{b:02x}" for b in value.to_bytes(6, "big"))
