"""Network engine building blocks (spec net.md)."""

from .checksum import InternetChecksum
from .crc import CRC32_RESIDUE, Crc32

__all__ = ["CRC32_RESIDUE", "Crc32", "InternetChecksum"]
