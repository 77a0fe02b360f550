"""The FinEmbP benchmark application: the AVR221 PID controller fed from the node's output
page and answering in its input page (docs/finemb.md)."""

from amaranth.hdl import Cat, Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import Out

from hdl.kernels.pid import PidController

from ..params import ParameterError
from .descriptor import IoDescriptor
from .node import FinembNode
from .page import PageAppSignature
from .protocol import Direction, PortType

__all__ = ["PID_PORTS", "PidApplication", "FinembPidNode"]

#: the ports the PID application needs: name -> (direction, type)
PID_PORTS = {
    "set_point": (Direction.OUT, PortType.I16),
    "measurement": (Direction.OUT, PortType.I16),
    "p_gain": (Direction.OUT, PortType.U16),
    "i_gain": (Direction.OUT, PortType.U16),
    "d_gain": (Direction.OUT, PortType.U16),
    "output": (Direction.IN, PortType.I16),
    "updates": (Direction.IN, PortType.U32),
}


def _check_descriptor(descriptor):
    if not isinstance(descriptor, IoDescriptor):
        raise ParameterError("descriptor", descriptor, "an IoDescriptor")
    for name, (direction, ptype) in PID_PORTS.items():
        try:
            port = descriptor.port(name)
        except KeyError:
            raise ParameterError("descriptor", descriptor,
                                 f"a port {name!r} ({direction.name.lower()}, "
                                 f"{ptype.name.lower()}) for the PID application") from None
        if (port.direction, port.type) != (direction, ptype):
            raise ParameterError(f"descriptor port {name!r}",
                                 f"{port.direction.name.lower()} {port.type.name.lower()}",
                                 f"{direction.name.lower()} {ptype.name.lower()}")


class PidApplication(wiring.Component):
    """Each new output page: read the set point, the measurement and the gains; reload the
    controller when the gains changed (AVR221 ``pid_Init``: about 32 cycles); run one PID
    update (:class:`~hdl.kernels.PidController`); write the output and the count of updates
    into the input page and commit it. About 20 cycles from the page's flip to the commit
    (50 after a gain change).

    Gains are in the AVR221 scaling (real gain x 128), 0..32767.

    Parameters
    ----------
    descriptor : IoDescriptor
        With the ports of :data:`PID_PORTS` (any others are left alone).

    Members
    -------
    pages : Out(PageAppSignature(...)), flipped
        To the node's ``app`` port.
    updates : Out(32)
        PID updates so far.
    """

    def __init__(self, descriptor):
        _check_descriptor(descriptor)
        self._desc = descriptor
        super().__init__({
            "pages": Out(PageAppSignature(descriptor.page_out_bytes,
                                          descriptor.page_in_bytes)).flip(),
            "updates": Out(32),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.pid = pid = PidController()
        d = self._desc
        pg = self.pages
        fields = {name: Signal(16, name=name) for name in
                  ("set_point", "measurement", "p_gain", "i_gain", "d_gain")}
        loaded = Signal(45)
        output = Signal(16)
        updates = self.updates
        # the bytes to read: (page offset, field, byte) in order
        reads = [(d.port(name).offset + b, name, b) for name in fields for b in range(2)]
        k = Signal(range(len(reads) + 2))
        gains = Cat(fields["p_gain"][:15], fields["i_gain"][:15], fields["d_gain"][:15])
        m.d.comb += [pid.p_gain.eq(fields["p_gain"][:15]), pid.i_gain.eq(fields["i_gain"][:15]),
                     pid.d_gain.eq(fields["d_gain"][:15]),
                     pid.i.tdata.eq(Cat(fields["set_point"], fields["measurement"])),
                     pid.i.tlast.eq(1), pid.o.tready.eq(1)]
        writes = ([(d.port("output").offset + b, output.word_select(b, 8)) for b in range(2)] +
                  [(d.port("updates").offset + b, updates.word_select(b, 8)) for b in range(4)])
        w = Signal(range(len(writes) + 1))
        with m.FSM():
            with m.State("WAIT"):
                with m.If(pg.out_pending):
                    m.d.comb += pg.out_claim.eq(1)
                    m.d.sync += k.eq(0)
                    m.next = "READ"
            with m.State("READ"):
                # one byte per cycle, one cycle behind its address
                for i, (offset, name, b) in enumerate(reads):
                    with m.If(k == i):
                        m.d.comb += pg.out_raddr.eq(offset)
                    with m.If(k == i + 1):
                        m.d.sync += fields[name].word_select(b, 8).eq(pg.out_rdata)
                m.d.sync += k.eq(k + 1)
                with m.If(k == len(reads)):
                    m.d.comb += pg.out_release.eq(1)
                    m.next = "GAINS"
            with m.State("GAINS"):
                with m.If(gains != loaded):
                    m.d.comb += pid.load.eq(1)
                    m.d.sync += loaded.eq(gains)
                m.next = "UPDATE"
            with m.State("UPDATE"):
                m.d.comb += pid.i.tvalid.eq(1)
                with m.If(pid.i.tready):
                    m.next = "RESULT"
            with m.State("RESULT"):
                with m.If(pid.o.tvalid):
                    m.d.sync += [output.eq(pid.o.tdata), updates.eq(updates + 1), w.eq(0)]
                    m.next = "WRITE"
            with m.State("WRITE"):
                with m.If(pg.in_ready):
                    for i, (offset, value) in enumerate(writes):
                        with m.If(w == i):
                            m.d.comb += [pg.in_we.eq(1), pg.in_waddr.eq(offset),
                                         pg.in_wdata.eq(value)]
                    m.d.sync += w.eq(w + 1)
                    with m.If(w == len(writes) - 1):
                        m.next = "COMMIT"
            with m.State("COMMIT"):
                with m.If(pg.in_ready):
                    m.d.comb += pg.in_commit.eq(1)
                    m.next = "WAIT"
        return m


class FinembPidNode(wiring.Component):
    """A :class:`~hdl.finemb.FinembNode` with the :class:`PidApplication` on its pages: the
    P-FIN benchmark node in gateware.

    Parameters
    ----------
    descriptor : IoDescriptor
        With the ports of :data:`PID_PORTS`.
    mac, serial, app_deadline, registered_queues : see :class:`~hdl.finemb.FinembNode`.

    Members
    -------
    gmii_clk, port0, port1, state, node_id, local_ip, soc, counter_index, counter_value :
        As :class:`~hdl.finemb.FinembNode`.
    updates : Out(32)
        PID updates so far.
    """

    def __init__(self, descriptor, *, mac="02:00:00:00:46:01", serial=0, app_deadline=256,
                 registered_queues=False):
        _check_descriptor(descriptor)
        self._node = FinembNode(descriptor, mac=mac, serial=serial, app_deadline=app_deadline,
                                registered_queues=registered_queues)
        members = {name: member for name, member in self._node.signature.members.items()
                   if name != "app"}
        members["updates"] = Out(32)
        super().__init__(members)

    node = property(lambda self: self._node)

    def elaborate(self, platform):
        m = Module()
        m.submodules.node = node = self._node
        m.submodules.app = app = PidApplication(node.descriptor)
        wiring.connect(m, node.app, app.pages)
        for name in self.signature.members:
            if name in ("updates",):
                continue
            ours, theirs = getattr(self, name), getattr(node, name)
            if name in ("port0", "port1"):
                wiring.connect(m, wiring.flipped(ours), theirs)
            elif name in ("counter_index", "gmii_clk"):
                m.d.comb += theirs.eq(ours)
            else:
                m.d.comb += ours.eq(theirs)
        m.d.comb += self.updates.eq(app.updates)
        return m
