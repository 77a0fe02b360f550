"""Codes and constants of a TCP session (docs/network.md "TCP session")."""

from amaranth.lib import enum

__all__ = ["TcpState", "TcpError", "TcpRequest", "TCP_COUNTERS", "INITIAL_WINDOW",
           "MAX_BACKOFF", "FIN_WAIT_2_SCALE"]


class TcpState(enum.Enum, shape=4):
    """Connection states (RFC 9293 §3.3.2) plus ARP resolution before a client's SYN; the
    value is the TCP_STATE register code (docs/network.md)."""
    CLOSED = 0
    LISTEN = 1
    SYN_SENT = 2
    SYN_RECEIVED = 3
    ESTABLISHED = 4
    FIN_WAIT_1 = 5
    FIN_WAIT_2 = 6
    CLOSE_WAIT = 7
    CLOSING = 8
    LAST_ACK = 9
    TIME_WAIT = 10
    ARP = 11


class TcpError(enum.Enum, shape=4):
    """Sticky error codes (docs/network.md ERROR register)."""
    NONE = 0
    REFUSED = 1
    TIMEOUT = 2
    ARP = 3
    RESET = 6


class TcpRequest(enum.Enum, shape=3):
    """The frames a session asks the frame builder for, in the order it sends them when
    several are due (:class:`~hdl.net.tcp.scheduler.TcpRequestScheduler`)."""
    RST = 0
    ARP = 1
    SYN = 2
    DATA = 3
    FIN = 4
    PROBE = 5
    ACK = 6


#: Session counters, in the order of the ``counters`` output (docs/network.md "counters").
TCP_COUNTERS = ("bytes_tx", "bytes_rx", "segments_tx", "segments_rx", "rto", "fast_retransmit",
                "dup_acks", "rst_rx", "dropped_segments")

#: Initial congestion window in segments (docs/network.md: 3 x 1460 bytes)
INITIAL_WINDOW = 3
#: Back-offs of the retransmission timeout: it doubles per expiry up to 2**5 times the RTO
MAX_BACKOFF = 5
#: FIN-WAIT-2 ends after 2**6 MSL without a segment from the peer (64 s at the default MSL of
#: 1 s; docs/network.md proposes 60 s)
FIN_WAIT_2_SCALE = 6
