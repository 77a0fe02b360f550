"""The software side of a ReconROS system, for co-simulation with its hardware threads: the
process memory with its page tables, ROS messages in it, an in-process ROS graph, the ReconOS
runtime with one delegate per slot, and :class:`ReconosCosim`, which connects them to a
simulated system top."""

from .broker import ActionGoal, Broker, Queue
from .cosim import RAM_SIZE, ReconosCosim
from .memory import PAGE, ProcessMemory
from .messages import MessageMemory
from .runtime import ProtocolError, ReconosRuntime, Resource

__all__ = ["ActionGoal", "Broker", "Queue", "PAGE", "ProcessMemory", "MessageMemory",
           "ProtocolError", "ReconosRuntime", "Resource", "RAM_SIZE", "ReconosCosim"]
