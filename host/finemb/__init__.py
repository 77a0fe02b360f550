"""FinEmbP on the host (docs/finemb.md): the master over UDP sockets, and a simulated line of
nodes on a TAP device to run it against."""

from .master import FinembError, FinembMaster, NodeRecord

__all__ = ["FinembError", "FinembMaster", "NodeRecord"]
