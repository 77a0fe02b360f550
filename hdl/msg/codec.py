"""A serializer and a deserializer of the same type, framing and width, side by side."""

from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import Out

from .deserializer import Deserializer
from .reconros import ReconrosDeserializer, ReconrosSerializer
from .serializer import Serializer

__all__ = ["MessageCodec"]


class MessageCodec(wiring.Component):
    """:class:`Serializer` (members under ``ser``) and :class:`Deserializer` (under ``des``)
    for one plan: the exported ``msg_codec`` top, so that one build tests both directions.

    Parameters
    ----------
    plan : gen.msg.plan.StreamPlan
    data_width : int
    max_count : int
        Passed to the deserializer.
    beats : bool
        The ReconROS framing's beat-at-a-time pair (:class:`ReconrosSerializer`,
        :class:`ReconrosDeserializer`) instead of the byte-granular one.
    """

    def __init__(self, plan, data_width=64, *, max_count=1 << 24, beats=False):
        ser, des = ((ReconrosSerializer, ReconrosDeserializer) if beats
                    else (Serializer, Deserializer))
        self._ser = ser(plan, data_width)
        self._des = des(plan, data_width, max_count=max_count)
        self.plan = plan
        super().__init__({"ser": Out(self._ser.signature), "des": Out(self._des.signature)})

    @property
    def parameters(self):
        return {**self._des.parameters}

    def elaborate(self, platform):
        m = Module()
        m.submodules.ser = self._ser
        m.submodules.des = self._des
        wiring.connect(m, wiring.flipped(self.ser), self._ser)
        wiring.connect(m, wiring.flipped(self.des), self._des)
        return m
