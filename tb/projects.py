"""The example projects the tests and ``make lint`` use."""

import pytest

from .harness import ROOT

__all__ = ["EXAMPLES", "EXPORTED_EXAMPLES", "EXPORT_PARAMS", "example_cfg",
           "external_threads_project"]

#: every folder of examples/ with a build.cfg
EXAMPLES = sorted(p.parent.name for p in (ROOT / "examples").glob("*/build.cfg"))
#: the examples the export tests take, as pytest parameters: the lane-following chain (seven
#: threads, 28 s to export even at a fifth of its size) and the six service threads of
#: hw_services (25 s) in make test-full only; every part of the export they use is exercised
#: by the other examples in make test (sort_service and sort_action export services)
EXPORTED_EXAMPLES = [pytest.param(n, marks=pytest.mark.full)
                     if n in ("av_chain", "hw_services") else n for n in EXAMPLES]
#: ``--param`` settings the export tests use: the lane-following chain at a fifth of its
#: frame size and 1 px/clk (the full-size export at 4 px/clk takes two and a half minutes)
EXPORT_PARAMS = {"av_chain": ["*.scale=0.2", "*.pixels_per_beat=1"]}


def example_cfg(name):
    """The build.cfg of example project ``name``."""
    return ROOT / "examples" / name / "build.cfg"


#: the demo's gateway section, and a thread with the same endpoints that rosgate leaves external
GATEWAY_SECTION = """[ROSGateway@Gateway1]
Slot = Gateways(0)
HWTopic = "nicehwtopic"
SWTopic = "/topic/gateway"
MsgType = sensor_msgs/Image
"""
EXTERNAL_GATEWAY = """[ResourceGroup@RGateway]
node_1 = rosnode, "gateway"
HwSub = rossub, node_1, sensor_msgs/Image, "nicehwtopic", hw
HwPub = rospub, node_1, sensor_msgs/Image, "nicehwtopic", hw

[ReconosThread@Gateway1]
Slot = Gateways(0)
HwSource = hls
ResourceGroup = RGateway
"""


def external_threads_project(folder):
    """The demo's build.cfg in ``folder`` (without the demo's thread sources), its gateway as
    an external thread."""
    text = example_cfg("hwtopic_gateway").read_text()
    assert GATEWAY_SECTION in text
    (folder / "build.cfg").write_text(text.replace(GATEWAY_SECTION, EXTERNAL_GATEWAY))
    return folder / "build.cfg"
