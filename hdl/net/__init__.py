"""Network engine building blocks (docs/network.md)."""

from .checksum import InternetChecksum
from .crc import CRC32_RESIDUE, Crc32
from .mac import GmiiRx, GmiiTx
from .rbcp import RbcpBusSignature, RbcpServer
from .rgmii import RgmiiPhy
from .rx import FrameParser
from .stack import NetStack
from .tcp import TcpSession, TcpState
from .tx import FrameBuilder

__all__ = ["CRC32_RESIDUE", "Crc32", "InternetChecksum", "GmiiRx", "GmiiTx", "FrameParser",
           "FrameBuilder", "RbcpBusSignature", "RbcpServer", "TcpSession", "TcpState",
           "NetStack", "RgmiiPhy"]
