"""SiTCP's RBCP register protocol over UDP: the request in a buffer becomes byte accesses on
a local bus, the buffer becomes the reply (docs/network.md)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int
from .checksum import ones_complement_add
from .frames import RBCP_BUS_ERROR, RBCP_HEADER, RBCP_READ, RBCP_REPLY, RBCP_VERSION, RBCP_WRITE

__all__ = ["RbcpBusSignature", "RbcpServer", "RBCP_TIMEOUT"]

#: cycles without RBCP_ACK after a strobe before the access is a bus error
RBCP_TIMEOUT = 255


class RbcpBusSignature(wiring.Signature):
    """SiTCP's local register bus, from the RBCP server's side (``Out`` = server drives).

    Members
    -------
    act : Out(1)
        High while the server works through one request (RBCP_ACT).
    addr : Out(32)
        Byte address of the current access (RBCP_ADDR).
    wd : Out(8)
        Write data (RBCP_WD).
    we, re : Out(1)
        One-cycle write or read strobe, one per byte, at increasing addresses.
    ack : In(1)
        One-cycle acknowledge of the strobe (RBCP_ACK); a read returns ``rd`` with it.
    rd : In(8)
        Read data (RBCP_RD).
    """

    def __init__(self):
        super().__init__({"act": Out(1), "addr": Out(32), "wd": Out(8), "we": Out(1),
                          "re": Out(1), "ack": In(1), "rd": In(8)})


class RbcpServer(wiring.Component):
    """Execute the RBCP request held in a packet buffer and turn the buffer into the reply.

    A request with a version other than 0xFF, an unknown command or fewer than 8 bytes gets
    no reply. Length 0, write data shorter than Length, an address range that wraps or is not
    inside one of ``windows`` answer with the bus-error flag before any access; an access
    that is not acknowledged within :data:`RBCP_TIMEOUT` cycles sets the flag and ends the
    accesses. Read data that was not read is sent as zeros; a write reply echoes the data.

    Parameters
    ----------
    windows : sequence of (base, size)
        Address ranges the bus decodes.

    Members
    -------
    start : In(1)
        Pulse: a request of ``length`` bytes is in the buffer from address 0.
    length : In(11)
        UDP payload bytes.
    buf_addr : Out(11)
        Buffer address to read (data in ``buf_rdata`` the next cycle) or write.
    buf_rdata : In(8)
    buf_wdata : Out(8)
    buf_we : Out(1)
    bus : Out(RbcpBusSignature())
    done : Out(1)
        Pulse when finished; with ``reply`` the buffer holds ``reply_len`` reply bytes whose
        one's complement sum is ``reply_sum``.
    reply : Out(1)
    reply_len : Out(11)
    reply_sum : Out(16)
    """

    def __init__(self, windows):
        self._windows = []
        for k, (base, size) in enumerate(windows):
            check_int(f"windows[{k}] base", base, 0, 2**32 - 1)
            check_int(f"windows[{k}] size", size, 1, 2**32 - base)
            self._windows.append((base, size))
        super().__init__({
            "start": In(1), "length": In(11),
            "buf_addr": Out(11), "buf_rdata": In(8), "buf_wdata": Out(8), "buf_we": Out(1),
            "bus": Out(RbcpBusSignature()),
            "done": Out(1), "reply": Out(1), "reply_len": Out(11), "reply_sum": Out(16),
        })

    def elaborate(self, platform):
        m = Module()
        length = Signal(11)
        header = Signal(64)           # bytes 0..7, byte 0 in the top bits
        k = Signal(11)
        cmd = header[48:56]
        count = header[32:40]
        base = header[0:32]
        is_write = cmd == RBCP_WRITE
        bus_error = Signal()
        wait = Signal(8)
        acc = Signal(16)
        total = Signal(11)
        m.d.comb += [total.eq(RBCP_HEADER + count), self.reply_len.eq(total),
                     self.reply_sum.eq(acc)]
        end = Signal(33)
        m.d.comb += end.eq(base + count)
        inside = Const(0)
        for wbase, wsize in self._windows:
            inside = inside | ((base >= wbase) & (end <= wbase + wsize))
        m.d.sync += [self.done.eq(0), self.bus.we.eq(0), self.bus.re.eq(0)]

        with m.FSM():
            with m.State("IDLE"):
                with m.If(self.start):
                    m.d.sync += [length.eq(self.length), k.eq(0), bus_error.eq(0), acc.eq(0)]
                    m.d.comb += self.buf_addr.eq(0)
                    m.next = "HEADER"
            with m.State("HEADER"):
                # byte k's data is here; ask for byte k + 1
                m.d.comb += self.buf_addr.eq(k + 1)
                m.d.sync += [header.eq(Cat(self.buf_rdata, header[:56])), k.eq(k + 1)]
                with m.If(k == RBCP_HEADER - 1):
                    m.next = "CHECK"
            with m.State("CHECK"):
                version_ok = header[56:64] == RBCP_VERSION
                with m.If((length < RBCP_HEADER) | ~version_ok |
                          ((cmd != RBCP_WRITE) & (cmd != RBCP_READ))):
                    m.d.sync += [self.done.eq(1), self.reply.eq(0)]
                    m.next = "IDLE"
                with m.Else():
                    m.d.sync += k.eq(0)
                    with m.If((count == 0) | end[32] | ~inside |
                              (is_write & (length < total))):
                        m.d.sync += bus_error.eq(1)
                        m.next = "FILL"
                    with m.Else():
                        m.d.sync += self.bus.act.eq(1)
                        m.next = "FETCH"
            with m.State("FETCH"):
                m.d.comb += self.buf_addr.eq(RBCP_HEADER + k)
                with m.If(k == count):
                    m.d.sync += self.bus.act.eq(0)
                    m.next = "PATCH"
                with m.Else():
                    m.next = "STROBE"
            with m.State("STROBE"):
                m.d.sync += [self.bus.addr.eq(base + k), self.bus.wd.eq(self.buf_rdata),
                             self.bus.we.eq(is_write), self.bus.re.eq(~is_write), wait.eq(0)]
                m.next = "WAIT"
            with m.State("WAIT"):
                m.d.sync += wait.eq(wait + 1)
                with m.If(self.bus.ack):
                    with m.If(~is_write):
                        m.d.comb += [self.buf_addr.eq(RBCP_HEADER + k),
                                     self.buf_wdata.eq(self.bus.rd), self.buf_we.eq(1)]
                    m.d.sync += k.eq(k + 1)
                    m.next = "FETCH"
                with m.Elif(wait == RBCP_TIMEOUT - 1):
                    m.d.sync += [bus_error.eq(1), self.bus.act.eq(0)]
                    m.next = "FILL"
            with m.State("FILL"):
                # reads not done and write data not received are sent as zeros
                with m.If(k == count):
                    m.next = "PATCH"
                with m.Else():
                    m.d.comb += [self.buf_addr.eq(RBCP_HEADER + k), self.buf_wdata.eq(0),
                                 self.buf_we.eq(~is_write | (RBCP_HEADER + k >= length))]
                    m.d.sync += k.eq(k + 1)
            with m.State("PATCH"):
                m.d.comb += [self.buf_addr.eq(1), self.buf_we.eq(1),
                             self.buf_wdata.eq(cmd | RBCP_REPLY | Mux(bus_error, RBCP_BUS_ERROR, 0))]
                m.d.sync += k.eq(0)
                m.next = "SUM_ADDR"
            with m.State("SUM_ADDR"):
                m.d.comb += self.buf_addr.eq(0)
                m.d.sync += k.eq(0)
                m.next = "SUM"
            with m.State("SUM"):
                m.d.comb += self.buf_addr.eq(k + 1)
                word = Mux(k[0], Cat(self.buf_rdata, Const(0, 8)), Cat(Const(0, 8), self.buf_rdata))
                m.d.sync += [acc.eq(ones_complement_add(acc, word)), k.eq(k + 1)]
                with m.If(k + 1 == total):
                    m.d.sync += [self.done.eq(1), self.reply.eq(1)]
                    m.next = "IDLE"
        return m
