"""ROS messages in hardware: (de)serializers generated from a stream plan (``gen.msg.plan``).

Specs: shared/spec/ros_wire.md §1.2 and §2 (ROS 1, CDR), shared/spec/hmt.md §5 (ReconROS).
"""

from .bytes import BytePacker, ByteUnpacker, ChunkSignature
from .serializer import ErrorSignature, Serializer, SerializerError, payload_port
from .deserializer import Deserializer, DeserializerError
from .codec import MessageCodec

__all__ = ["BytePacker", "ByteUnpacker", "ChunkSignature", "ErrorSignature", "Serializer",
           "SerializerError", "payload_port", "Deserializer", "DeserializerError", "MessageCodec"]
