"""Golden model of services and actions over hardware topics, written from docs/services.md:
the frame (one 8-byte header beat, then the body in CDR), the kinds and status codes, and
the Fibonacci sequence the action server computes. Bodies come from rosbags."""

import struct

__all__ = ["KIND", "REPLY_OK", "BAD_REQUEST", "GOAL_STATUS", "CANCEL_STATUS", "MAX_ORDER",
           "frame", "parse_header", "fibonacci"]

KIND = {"REQUEST": 1, "REPLY": 2, "GOAL": 3, "GOAL_RESPONSE": 4, "CANCEL": 5,
        "CANCEL_RESPONSE": 6, "FEEDBACK": 7, "RESULT": 8}
REPLY_OK, BAD_REQUEST = 0, 1
GOAL_STATUS = {"SUCCEEDED": 4, "CANCELED": 5, "ABORTED": 6}
CANCEL_STATUS = {"ERROR_NONE": 0, "ERROR_REJECTED": 1, "ERROR_UNKNOWN_GOAL_ID": 2,
                 "ERROR_GOAL_TERMINATED": 3}
#: the largest Fibonacci order whose values fit int32
MAX_ORDER = 46


def header(kind, client, sequence, status=0):
    """The 8-byte header beat: sequence (32 bits), client (16), kind (8), status (8), little
    endian."""
    return struct.pack("<IHBB", sequence & 0xFFFFFFFF, client, KIND[kind] if isinstance(kind, str)
                       else kind, status)


def frame(kind, client, sequence, body=b"", status=0):
    """A whole frame's bytes."""
    return header(kind, client, sequence, status) + body


def parse_header(data):
    """``(kind, client, sequence, status)`` of a frame's first 8 bytes."""
    sequence, client, kind, status = struct.unpack("<IHBB", data[:8])
    return kind, client, sequence, status


def fibonacci(n):
    """F(0..n)."""
    values = [0, 1][:n + 1]
    while len(values) < n + 1:
        values.append(values[-1] + values[-2])
    return values

