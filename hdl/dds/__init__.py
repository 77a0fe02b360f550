"""Hardware-mapped topics (fpgaDDS): AXI4-Stream fabrics that carry ROS topics between nodes.

Spec: docs/topics.md.
"""

from .arbiter import TopicArbiter
from .broadcast import TopicBroadcast
from .topic import HW_TOPIC_STREAM, Topic, TopicMonitorSignature, QOS_POLICIES, MAX_ENDPOINTS

__all__ = ["TopicArbiter", "TopicBroadcast", "Topic", "TopicMonitorSignature", "QOS_POLICIES",
           "MAX_ENDPOINTS", "HW_TOPIC_STREAM"]
