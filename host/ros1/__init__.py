"""The software half of a ROS 1 hardware node (docs/network.md, docs/messages.md):
RBCP register access, an XML-RPC ROS master, and the node-side Slave API that hands TCPROS
data connections to the hardware endpoints."""

from .endpoint import EndpointClient, connection_header_fields
from .master import RosMaster
from .node import HardwareNode
from .rbcp import RbcpBusError, RbcpClient, RbcpTimeout

__all__ = ["EndpointClient", "HardwareNode", "RbcpBusError", "RbcpClient", "RbcpTimeout",
           "RosMaster", "connection_header_fields"]
