"""Packet captures of simulated links: pcap files Wireshark and tcpdump open, stamped with
simulated time."""

from pathlib import Path

__all__ = ["SimCapture"]


class SimCapture:
    """The first ``limit`` frames each way of a simulated link, written to ``path`` as a
    nanosecond pcap (Ethernet), each stamped with the simulated time of its clock cycle.

    Parameters
    ----------
    path : str or Path or None
        The file; ``None`` records nothing.
    limit : int
        Frames per direction (``"in"``, ``"out"``).
    clock_ns : int
        The clock period the cycle numbers count.
    """

    def __init__(self, path, limit=400, clock_ns=8):
        from scapy.utils import PcapWriter
        self.writer = None
        self.clock_ns = clock_ns
        self.left = {"in": limit, "out": limit}
        if path:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            # write_packet() does not write the file header; sync: a run that ends before
            # the limit still leaves a complete file
            self.writer = PcapWriter(str(path), linktype=1, nano=True, sync=True)
            self.writer.write_header(None)

    def record(self, direction, frame, cycle):
        """Record ``frame`` (bytes, no FCS) going ``direction`` at clock cycle ``cycle``."""
        if self.writer is None or not self.left[direction]:
            return
        self.left[direction] -= 1
        ns = cycle * self.clock_ns
        self.writer.write_packet(bytes(frame), sec=ns // 10**9, usec=ns % 10**9)
        if not any(self.left.values()):
            self.close()

    def close(self):
        if self.writer is not None:
            self.writer.close()
            self.writer = None
