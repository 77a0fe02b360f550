"""ReconOS/ReconROS-compatible hardware-thread infrastructure (docs/reconos.md).

:mod:`.protocol` holds the command codes, word sequences and register maps; the components
are the OSIF/MEMIF FIFOs (:mod:`.fifo`), the AXI4-Lite control blocks (:mod:`.control`), the
MEMIF arbiter (:mod:`.memif`), the MMU (:mod:`.mmu`), the AXI4 memory controller
(:mod:`.memctrl`), the hardware-thread API (:mod:`.hwt`) and the system around a set of
threads (:mod:`.system`).
"""

from .protocol import ARCHS, CALLS, Command, MemifOp, MemStatus, ProcControlRegister, OsifRegister
from .fifo import FifoReadSignature, FifoWriteSignature, ReconosFifo
from .control import OsifIntc, ProcControl, ReconosOsif
from .memif import MemifArbiter
from .mmu import MMU, TLB
from .memctrl import MemoryController
from .hwt import HardwareThread, MemCalls, MemifEngine, OsifCalls, OsifEngine, ThreadSignature
from .system import ReconosSystem
from .threads import CallSequenceThread, CopyThread, EchoThread
from .gateway import TopicGatewayThread
from .service_gateway import ServiceGatewayThread
from .action_gateway import ActionGatewayThread

__all__ = [
    "ARCHS", "CALLS", "Command", "MemifOp", "MemStatus", "ProcControlRegister", "OsifRegister",
    "FifoReadSignature", "FifoWriteSignature", "ReconosFifo", "OsifIntc", "ProcControl",
    "ReconosOsif", "MemifArbiter", "MMU", "TLB", "MemoryController", "HardwareThread",
    "MemCalls", "MemifEngine", "OsifCalls", "OsifEngine", "ThreadSignature", "ReconosSystem",
    "CallSequenceThread", "CopyThread", "EchoThread", "TopicGatewayThread",
    "ServiceGatewayThread", "ActionGatewayThread",
]
