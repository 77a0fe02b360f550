"""ROS 1 (TCPROS) data connections in hardware (spec net.md §7)."""

from .node import TcprosNode
from .tcpros import ROLES, TcprosEndpoint, message_stream_signature

__all__ = ["ROLES", "TcprosEndpoint", "TcprosNode", "message_stream_signature"]
