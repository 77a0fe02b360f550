"""ROS messages in hardware: (de)serializers generated from a stream plan (``gen.msg.plan``).

Specs: docs/messages.md (ROS 1, CDR), docs/topics.md (ReconROS).
"""

from .bytes import BytePacker, ByteUnpacker, ChunkSignature
from .serializer import ErrorSignature, Serializer, SerializerError, payload_port
from .deserializer import Deserializer, DeserializerError
from .reconros import ReconrosDeserializer, ReconrosSerializer
from .codec import MessageCodec

__all__ = ["BytePacker", "ByteUnpacker", "ChunkSignature", "ErrorSignature", "Serializer",
           "SerializerError", "payload_port", "Deserializer", "DeserializerError",
           "ReconrosSerializer", "ReconrosDeserializer", "MessageCodec"]
