"""FinEmbP, FINROC's fieldbus for embedded nodes, with the whole node in gateware
(docs/finemb.md): the protocol's tables, the IO descriptor, the page buffer, the client state
machine, the two-port node with layer-2 forwarding, and the PID benchmark application."""

from .descriptor import IoDescriptor, IoPort
from .line import FinembLine, line_mac
from .node import NODE_CLOCKS_HZ, NODE_COUNTERS, FinembNode
from .page import PageAppSignature, PageBuffer
from .pid_app import PID_PORTS, FinembPidNode, PidApplication

__all__ = ["IoDescriptor", "IoPort", "FinembLine", "line_mac", "NODE_CLOCKS_HZ", "NODE_COUNTERS",
           "FinembNode",
           "PageAppSignature", "PageBuffer", "PID_PORTS", "FinembPidNode",
           "PidApplication"]
