"""DDS types of ROS 2 messages, built at run time from the project's message library, as
``cyclonedds`` ``IdlStruct`` classes named as ROS 2 names them on DDS
(``pkg::msg::dds_::T_``): final structs, ROS 2 primitives as their IDL types, ``T[N]`` as
arrays, ``T[]``/``T[<=N]`` as (bounded) sequences, ``string<=N`` as bounded strings, an empty
message as rosidl's one ``uint8`` placeholder member.

A service's request and reply carry rmw_cyclonedds_cpp's request header before the message's
fields (``uint64 guid``, ``int64 seq``: the client's writer and the call's number, copied into
the reply). The header is 16 bytes, so it moves no field's alignment."""

import struct

from gen.msg.model import Array, Named, Primitive, Sequence

from .graph import dds_type_name

__all__ = ["DdsTypes", "REQUEST_HEADER", "REQUEST_HEADER_SIZE", "pack_request_header",
           "unpack_request_header"]

#: rmw_cyclonedds_cpp's ``cdds_request_header_t`` (serdata.hpp): member name -> ROS type
REQUEST_HEADER = (("guid", "uint64"), ("seq", "int64"))
REQUEST_HEADER_SIZE = 16
_HEADER = struct.Struct("<Qq")


def pack_request_header(guid, seq):
    return _HEADER.pack(guid, seq)


def unpack_request_header(body):
    """(guid, seq) from the first 16 bytes after the encapsulation header."""
    if len(body) < REQUEST_HEADER_SIZE:
        raise ValueError(f"a service sample of {len(body)} bytes has no 16-byte request header")
    return _HEADER.unpack_from(body)


class DdsTypes:
    """``IdlStruct`` classes for the types of a :class:`gen.msg.MessageLibrary`, made once
    per type and shared by nested uses."""

    def __init__(self, library):
        from cyclonedds.idl import types as t
        self.library = library
        self._t = t
        self._made = {}
        self._primitives = {
            "bool": bool, "byte": t.byte, "char": t.uint8, "int8": t.int8, "uint8": t.uint8,
            "int16": t.int16, "uint16": t.uint16, "int32": t.int32, "uint32": t.uint32,
            "int64": t.int64, "uint64": t.uint64, "float32": t.float32, "float64": t.float64}

    def message(self, typename):
        """The class of message ``typename`` (``pkg/msg/T``)."""
        name = self.library[typename].name
        if name not in self._made:
            self._made[name] = self._struct(name, dds_type_name(name), ())
        return self._made[name]

    def service_part(self, typename):
        """The class of a service request or response (``pkg/srv/S_Request``) with the
        request header first."""
        key = ("service", self.library[typename].name)
        if key not in self._made:
            self._made[key] = self._struct(key[1], dds_type_name(key[1]), REQUEST_HEADER)
        return self._made[key]

    def _struct(self, name, dds_name, header):
        from cyclonedds.idl import make_idl_struct
        fields = {member: self._primitives[kind] for member, kind in header}
        definition = self.library[name]
        for f in definition.fields:
            fields[f.name] = self._type(f.type, name, f.name)
        if not definition.fields:
            fields["structure_needs_at_least_one_member"] = self._t.uint8
        class_name = dds_name.replace("::", "_")
        return make_idl_struct(class_name, dds_name, fields)

    def _type(self, type_, owner, member):
        t = self._t
        if isinstance(type_, Primitive):
            if type_.name == "wstring":
                raise ValueError(f"{owner}.{member}: wstring is not supported on the bridge")
            if type_.is_string:
                return t.bounded_str[type_.bound] if type_.bound else str
            return self._primitives[type_.name]
        if isinstance(type_, Named):
            return self.message(type_.typename)
        element = self._type(type_.element, owner, member)
        if isinstance(type_, Array):
            return t.array[element, type_.length]
        if isinstance(type_, Sequence):
            return t.sequence[element, type_.bound] if type_.bound else t.sequence[element]
        raise TypeError(f"{owner}.{member}: unknown field type {type_!r}")
