"""The Internet checksum's sum (RFC 1071), from scapy's own checksum."""

from scapy.utils import checksum as scapy_checksum

__all__ = ["ones_sum"]


def ones_sum(data):
    """The one's complement sum of ``data`` as big-endian 16-bit words, an odd last byte
    padded with zero (RFC 1071, not inverted: 0 for no data)."""
    return (~scapy_checksum(bytes(data))) & 0xFFFF
