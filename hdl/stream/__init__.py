"""AXI4-Stream library: signature, register slice, FIFOs, width converters."""

from .signature import AXIStreamSignature, PAYLOAD_MEMBERS, check_stream_signature
from .skid import PayloadRegisterSlice, ReadyRegisterSlice, RegisterSlice, skid_buffer
from .fifo import StreamFIFO, AsyncStreamFIFO, OVERFLOW_POLICIES
from .message_fifo import MessageFIFO

__all__ = ["AXIStreamSignature", "PAYLOAD_MEMBERS", "check_stream_signature", "RegisterSlice",
           "PayloadRegisterSlice", "ReadyRegisterSlice", "StreamFIFO", "AsyncStreamFIFO",
           "OVERFLOW_POLICIES", "MessageFIFO", "skid_buffer"]

from .monitor import StreamMonitorSignature, StreamMonitor

__all__ += ["StreamMonitorSignature", "StreamMonitor"]

from .width import (ByteWindow, StreamDownsizer, StreamRepacker, StreamUpsizer, keep_count,
                    keep_count_shallow)

__all__ += ["StreamDownsizer", "StreamUpsizer", "StreamRepacker", "ByteWindow", "keep_count",
            "keep_count_shallow"]
