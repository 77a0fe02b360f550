"""ROS message knowledge, defined once: definitions, C layouts, encodings.

Specs: shared/spec/ros_wire.md, shared/spec/reconos.md §6.
"""

from .library import MessageLibrary, normalize_name
from .model import (
                    PRIMITIVES,
                    Array,
                    Constant,
                    Field,
                    MessageDef,
                    MessageDefinitionError,
                    Named,
                    Primitive,
                    Sequence,
)
from .parser import parse_action, parse_file, parse_msg, parse_srv, parse_type

__all__ = ["PRIMITIVES", "Array", "Constant", "Field", "MessageDef", "MessageDefinitionError",
           "Named", "Primitive", "Sequence", "parse_action", "parse_file", "parse_msg",
           "parse_srv", "parse_type", "MessageLibrary", "normalize_name"]
