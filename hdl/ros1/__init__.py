"""ROS 1 (TCPROS) data connections in hardware (docs/network.md)."""

from .node import TcprosNode
from .tcpros import ROLES, TcprosEndpoint, message_stream_signature

__all__ = ["ROLES", "TcprosEndpoint", "TcprosNode", "message_stream_signature"]
