"""host.pcap.SimCapture: the captures the network bench writes (bench/results/*.pcap)."""

import pytest
from scapy.layers.inet import IP, TCP
from scapy.layers.l2 import Ether
from scapy.utils import rdpcap

from host.pcap import SimCapture


def test_capture_is_a_pcap_scapy_reads(tmp_path):
    """A pcap file header first, every frame a record stamped with its simulated time, the
    limit per direction kept, and a complete file also when the run ends before the limit."""
    frame = bytes(Ether(src="02:00:00:00:00:01", dst="02:00:00:00:00:02") / IP() / TCP())
    capture = SimCapture(tmp_path / "a.pcap", limit=3)
    for k, direction in enumerate(("in", "out", "in", "out", "in", "out", "in")):
        capture.record(direction, frame, 125 * k)
    short = SimCapture(tmp_path / "b.pcap", limit=100)
    short.record("in", frame, 7)
    got = rdpcap(str(tmp_path / "a.pcap"))
    assert len(got) == 6 and TCP in got[0]
    assert float(got[5].time) == pytest.approx(5 * 125 * 8e-9)
    assert len(rdpcap(str(tmp_path / "b.pcap"))) == 1
