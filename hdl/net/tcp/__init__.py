"""One TCP session as components (docs/network.md "TCP session"): the receive ring, the
transmit buffer with its segmenter and descriptor ring, the sequence engine, the timer, the
request scheduler, congestion control and the connection state machine, wired together
by :class:`TcpSession`."""

from .codes import (
    FIN_WAIT_2_SCALE, INITIAL_WINDOW, MAX_BACKOFF, TCP_COUNTERS, TcpError, TcpRequest, TcpState,
)
from .congestion import TcpCongestionControl
from .connection import TcpConnection
from .receive_ring import TcpReceiveRing
from .scheduler import TcpRequestScheduler
from .sequence_engine import TcpSequenceEngine
from .session import TcpSession
from .timer import TcpTimer, TimerMode
from .transmit_buffer import TcpTransmitBuffer

__all__ = ["TcpState", "TcpError", "TcpRequest", "TCP_COUNTERS", "INITIAL_WINDOW",
           "MAX_BACKOFF", "FIN_WAIT_2_SCALE", "TcpSession", "TcpReceiveRing",
           "TcpTransmitBuffer", "TcpSequenceEngine", "TcpRequestScheduler", "TcpTimer",
           "TimerMode", "TcpCongestionControl", "TcpConnection"]
