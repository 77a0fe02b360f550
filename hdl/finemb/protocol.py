"""FinEmbP on the wire, defined once (docs/finemb.md): UDP port, multicast group, the common
header, message types and their payload fields, node states, IO descriptor encoding.

Every FinEmbP message is a UDP datagram whose payload starts with the 16-byte common header;
all FinEmbP fields are little-endian. The hardware node, the Python master and the tests'
frame models import these tables.
"""

import enum
import struct

from hdl.net.frames import int_to_mac, ip_to_int

__all__ = [
    "FINEMB_PORT", "GROUP_IP", "GROUP_MAC", "BROADCAST_IP", "BROADCAST_MAC", "MAGIC", "VERSION",
    "HEADER", "HEADER_FORMAT", "NODE_MASTER", "NODE_ALL", "MsgType", "Flag", "NodeState",
    "ReinitReason", "PortType", "PORT_TYPE_BYTES", "Direction", "PAYLOAD_FORMATS",
    "STATE_SHIFT", "group_mac_for", "IP_TTL_FINEMB", "encode_header", "decode_header",
    "VENDOR_ROSGATE",
]

#: UDP port of FinEmbP, both directions (0xF1E0)
FINEMB_PORT = 61920
#: the multicast group of SoC, SoA and EoA (organisation-local scope)
GROUP_IP = "239.255.70.69"
BROADCAST_IP = "255.255.255.255"
BROADCAST_MAC = "ff:ff:ff:ff:ff:ff"
#: FinEmbP frames stay in the layer-2 domain
IP_TTL_FINEMB = 1

MAGIC = 0x4546                 # bytes 46 45, "FE"
VERSION = 1
HEADER = 16
#: magic, version, type, node_id, flags, cycle, length, seq
HEADER_FORMAT = "<HBBHHIHH"
assert struct.calcsize(HEADER_FORMAT) == HEADER

#: node ids: the master, and every node
NODE_MASTER = 0
NODE_ALL = 0xFFFF
#: rosgate's vendor id in ID_RES
VENDOR_ROSGATE = 0x0DE5


def group_mac_for(ip):
    """The Ethernet multicast address of IPv4 group ``ip`` (RFC 1112: 01:00:5e + the low
    23 bits)."""
    return int_to_mac(0x01005E000000 | (ip_to_int(ip) & 0x7FFFFF))


GROUP_MAC = group_mac_for(GROUP_IP)


class MsgType(enum.IntEnum):
    """The ``type`` byte of the common header."""

    SOC = 0x01           # master -> all: start of cycle
    ISEND_REQ = 0x02     # master -> node: the node's output page
    ISEND_RES = 0x03     # node -> master: the node's input page
    SOA = 0x04           # master -> all: start of the asynchronous phase
    ASND = 0x05          # generic asynchronous data
    EOA = 0x06           # master -> all: end of the asynchronous phase
    ID_REQ = 0x10        # master -> broadcast: nodes without an address, identify
    ID_RES = 0x11        # node -> broadcast: identity
    ADDR_REQ = 0x12      # master -> broadcast: address for the node with this MAC
    ADDR_RES = 0x13      # node -> master
    IODESC_REQ = 0x14    # master -> node: read the IO descriptor
    IODESC_RES = 0x15    # node -> master: part of the IO descriptor
    REINIT = 0x16        # master -> node (or all): re-initialise


class Flag(enum.IntFlag):
    """Bits of the header's ``flags``; bits 8-9 carry the sender's :class:`NodeState` in a
    node's responses (a rosgate choice: the master sees every node's state each cycle).

    rosgate's nodes set only ERROR and the state, and ignore the other bits in requests. The
    protocol's FORWARDED bit (bit 4, a forwarding node marking a frame) is not used: a node
    forwards frames cut-through, unchanged, so their checksums and FCS stay the sender's."""

    PAGE_PARITY = 1 << 0
    ERROR = 1 << 1
    MORE_FRAGMENTS = 1 << 2
    ACK_REQUIRED = 1 << 3


STATE_SHIFT = 8


class NodeState(enum.IntEnum):
    INIT = 0       # no address: answers ID_REQ, waits for ADDR_REQ
    PREOP = 1      # addressed: the master reads the IO descriptor
    OP = 2         # cyclic exchange
    REINIT = 3     # re-initialising: address and IO descriptor exchanged again


class ReinitReason(enum.IntEnum):
    APPLICATION = 1     # the node (or its application) asks to be initialised again
    MASTER_RESTART = 2  # a master starting up: every node forgets its address


#: payload after the header, by type (struct formats; ``s`` fields are raw bytes)
PAYLOAD_FORMATS = {
    MsgType.SOC: "<IQHH",           # cycle_period_ns, master_time_ns, n_nodes, reserved
    MsgType.SOA: "<HBB",            # async_owner, request, reserved
    MsgType.EOA: "<I",              # idle_ns until the next SoC
    MsgType.ID_REQ: "<H",           # first_unassigned_hint
    MsgType.ID_RES: "<6sHIBBHH",    # mac, vendor, serial, n_eth_ports, caps, page_in, page_out
    MsgType.ADDR_REQ: "<6s4s4sH",   # target mac, ipv4, netmask, node_id
    MsgType.ADDR_RES: "<6s4sHB",    # mac, ipv4, node_id, status
    MsgType.IODESC_REQ: "<HH",      # offset, max_len
    MsgType.IODESC_RES: "<HH",      # offset, total_len, then the descriptor bytes
    MsgType.REINIT: "<B",           # reason
}


class Direction(enum.IntEnum):
    """An IO port's direction: 0 = master -> node (the output page), 1 = node -> master."""

    OUT = 0
    IN = 1


class PortType(enum.IntEnum):
    BOOL = 1
    U8 = 2
    I8 = 3
    U16 = 4
    I16 = 5
    U32 = 6
    I32 = 7
    F32 = 8
    F64 = 9
    BLOB = 10


#: bytes of a port of each type (a blob gives its own size)
PORT_TYPE_BYTES = {PortType.BOOL: 1, PortType.U8: 1, PortType.I8: 1, PortType.U16: 2,
                   PortType.I16: 2, PortType.U32: 4, PortType.I32: 4, PortType.F32: 4,
                   PortType.F64: 8}


def encode_header(type_, node_id, *, flags=0, cycle=0, length=0, seq=0):
    """The 16-byte common header."""
    return struct.pack(HEADER_FORMAT, MAGIC, VERSION, int(type_), node_id, int(flags),
                       cycle & 0xFFFFFFFF, length, seq)


def decode_header(payload):
    """``(type, node_id, flags, cycle, length, seq)`` of a FinEmbP payload; ``ValueError``
    naming what is wrong for a short payload, a bad magic or version, or a length that
    disagrees with the payload."""
    if len(payload) < HEADER:
        raise ValueError(f"FinEmbP payload of {len(payload)} bytes, shorter than the "
                         f"{HEADER}-byte header")
    magic, version, type_, node_id, flags, cycle, length, seq = struct.unpack_from(
        HEADER_FORMAT, payload)
    if magic != MAGIC:
        raise ValueError(f"FinEmbP magic 0x{magic:04x}, expected 0x{MAGIC:04x}")
    if version != VERSION:
        raise ValueError(f"FinEmbP version {version}, expected {VERSION}")
    if length != len(payload) - HEADER:
        raise ValueError(f"FinEmbP length field {length}, but {len(payload) - HEADER} bytes "
                         f"follow the header")
    return type_, node_id, flags, cycle, length, seq
