"""The AXI4-Stream interface as an Amaranth signature (AMBA 4 AXI4-Stream, ARM IHI 0051A)."""

from amaranth.hdl import Cat, Shape
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int

__all__ = ["AXIStreamSignature", "PAYLOAD_MEMBERS", "check_stream_signature"]


#: Members that travel with a beat, in the order they are packed into a storage word.
PAYLOAD_MEMBERS = ("tdata", "tkeep", "tlast", "tuser", "tid", "tdest")


class AXIStreamSignature(wiring.Signature):
    """AXI4-Stream, seen from the transmitter (``Out``); flip it for the receiver.

    Parameters
    ----------
    data_width : int
        Width of ``tdata`` in bits, a multiple of 8 in 8..1024.
    keep : bool
        Whether ``tkeep`` (one bit per byte of ``tdata``) is present. Default ``True``.
    user_width, id_width, dest_width : int
        Widths of ``tuser`` (0..1024), ``tid`` (0..8) and ``tdest`` (0..8); 0 omits the member.

    Members
    -------
    tdata : Out(data_width)
        Payload; byte ``i`` is ``tdata[8*i+7:8*i]``.
    tkeep : Out(data_width // 8)
        Byte qualifiers: bit ``i`` set means byte ``i`` is part of the stream. rosgate blocks
        only clear ``tkeep`` bits at the high end of the last beat of a message.
    tlast : Out(1)
        Marks the last beat of a message (a ROS message, a frame, a packet).
    tuser, tid, tdest : Out
        Sideband, carried unchanged with the beat.
    tvalid : Out(1)
        The transmitter offers a beat. Once asserted it stays asserted, with the payload
        unchanged, until a cycle in which ``tready`` is also asserted (the transfer).
        ``tvalid`` never depends combinationally on ``tready``.
    tready : In(1)
        The receiver accepts a beat in this cycle. It may depend on ``tvalid``.
    """

    def __init__(self, data_width, *, keep=True, user_width=0, id_width=0, dest_width=0):
        check_int("data_width", data_width, 8, 1024, multiple_of=8)
        check_int("user_width", user_width, 0, 1024)
        check_int("id_width", id_width, 0, 8)
        check_int("dest_width", dest_width, 0, 8)
        self._data_width = data_width
        self._keep = bool(keep)
        self._user_width = user_width
        self._id_width = id_width
        self._dest_width = dest_width
        members = {"tdata": Out(data_width)}
        if keep:
            members["tkeep"] = Out(data_width // 8)
        members["tlast"] = Out(1)
        if user_width:
            members["tuser"] = Out(user_width)
        if id_width:
            members["tid"] = Out(id_width)
        if dest_width:
            members["tdest"] = Out(dest_width)
        members["tvalid"] = Out(1)
        members["tready"] = In(1)
        super().__init__(members)

    data_width = property(lambda self: self._data_width)
    keep = property(lambda self: self._keep)
    user_width = property(lambda self: self._user_width)
    id_width = property(lambda self: self._id_width)
    dest_width = property(lambda self: self._dest_width)

    @property
    def bytes_per_beat(self):
        return self._data_width // 8

    @property
    def payload_width(self):
        """Bits needed to store one beat (every payload member, packed)."""
        return sum(Shape.cast(self.members[name].shape).width for name in self.payload_members)

    @property
    def payload_members(self):
        """Names of the payload members present, in packing order."""
        return tuple(name for name in PAYLOAD_MEMBERS if name in self.members)

    def pack(self, interface):
        """Return the payload members of ``interface`` concatenated (``tdata`` lowest)."""
        return Cat(*(getattr(interface, name) for name in self.payload_members))

    def unpack(self, interface, word):
        """Return assignments that drive the payload members of ``interface`` from ``word``."""
        stmts = []
        offset = 0
        for name in self.payload_members:
            width = Shape.cast(self.members[name].shape).width
            stmts.append(getattr(interface, name).eq(word[offset:offset + width]))
            offset += width
        return stmts

    def copy_payload(self, dst, src):
        """Return assignments driving every payload member of ``dst`` from ``src``."""
        return [getattr(dst, name).eq(getattr(src, name)) for name in self.payload_members]

    def _params(self):
        return (self._data_width, self._keep, self._user_width, self._id_width, self._dest_width)

    def __eq__(self, other):
        return type(other) is type(self) and other._params() == self._params()

    def __hash__(self):
        return hash((type(self), self._params()))

    def __repr__(self):
        args = [f"{self._data_width}"]
        if not self._keep:
            args.append("keep=False")
        for name in ("user_width", "id_width", "dest_width"):
            if getattr(self, name):
                args.append(f"{name}={getattr(self, name)}")
        return f"AXIStreamSignature({', '.join(args)})"


def check_stream_signature(signature):
    """Return ``signature`` if it is an :class:`AXIStreamSignature`, else raise ``TypeError``."""
    if not isinstance(signature, AXIStreamSignature):
        raise TypeError(f"signature must be an AXIStreamSignature, not {signature!r}")
    return signature
