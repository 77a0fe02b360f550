"""ROS message knowledge, defined once: definitions, C layouts, encodings.

Specs: docs/messages.md, docs/reconos.md.
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
