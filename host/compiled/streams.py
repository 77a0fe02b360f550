"""A design's AXI4-Stream ports on packet FIFOs compiled into the simulator.

cocotbext-axi's ``AxiStreamSource`` and ``AxiStreamSink`` run a Python coroutine at every clock
edge while a packet is on its way: a camera frame of 76,800 beats is 76,800 trips into Python.
:func:`stream_harness` wraps an exported top for :func:`host.simulator.run_top` (Verilator)
so that the ports it names are driven by ``rosgate_axis_source`` and drained by
``rosgate_axis_sink`` (``axis_stream.sv``), whose FIFOs live in C++ (``axis_stream.cpp``).
Python puts whole packets in and takes whole packets out (:class:`CompiledStreamSource`,
:class:`CompiledStreamSink`) and wakes only when a packet has been taken or completed. Random
idle cycles and backpressure are drawn in C++ too, from a seed (:func:`pause_randomly`).

:func:`stream_source` and :func:`stream_sink` give a test the compiled port where the harness
took it and cocotbext-axi's otherwise (Icarus, which has no DPI-C), with the same methods, so
one bench runs on both simulators. With no pauses both take their beats at the same cycles.
"""

import ctypes
import logging
from pathlib import Path

from . import verilog_ports, wrapper_head

__all__ = ["STREAM_SOURCES", "STREAM_LINK_ARGS", "CompiledStreamSource", "CompiledStreamSink",
           "StreamPacket", "pause_randomly", "pause_runs", "stream_harness", "stream_sink",
           "stream_source", "stream_wrapper"]

HERE = Path(__file__).resolve().parent
#: the files a Verilator build with compiled stream ports adds to the exported Verilog
STREAM_SOURCES = (HERE / "axis_stream.sv", HERE / "axis_stream.cpp")
#: Verilator options that let Python find the FIFOs' functions in the simulator
STREAM_LINK_ARGS = ("-LDFLAGS", "-Wl,--export-dynamic-symbol=rosgate_axis_*")
#: widest ``tdata`` and ``tuser`` the compiled ports take (axis_stream.sv)
MAX_DATA_W, MAX_USER_W = 1024, 64
#: the counters of ``rosgate_axis_counter``, in its order
_COUNTERS = ("cycles", "beats", "packets", "stalls")
#: the wrapper's output that counts a port's packets, by the port's direction
_EVENT = {"source": "sent", "sink": "received"}


def _port_shape(ports, prefix, direction, top):
    """``(data_w, user_w, has_keep, has_user)`` of stream port ``prefix`` of ``top``, checked:
    a ``source`` drives the design's input."""
    needed = ("tdata", "tvalid", "tready", "tlast")
    for sig in needed:
        if f"{prefix}_{sig}" not in ports:
            raise ValueError(f"module {top!r} has no port {prefix}_{sig}: not an AXI4-Stream "
                             f"port {prefix!r}")
    into = "input" if direction == "source" else "output"
    if ports[f"{prefix}_tdata"][0] != into:
        other = "sink" if direction == "source" else "source"
        raise ValueError(f"stream port {prefix!r} of {top!r} is an {ports[f'{prefix}_tdata'][0]}"
                         f" of the design: it needs a {other}, not a {direction}")
    data_w = ports[f"{prefix}_tdata"][1]
    if data_w % 8 or data_w > MAX_DATA_W:
        raise ValueError(f"stream port {prefix!r} of {top!r}: tdata of {data_w} bits; the "
                         f"compiled ports take whole bytes up to {MAX_DATA_W} bits")
    has_keep = f"{prefix}_tkeep" in ports
    if has_keep and ports[f"{prefix}_tkeep"][1] != data_w // 8:
        raise ValueError(f"stream port {prefix!r} of {top!r}: tkeep of "
                         f"{ports[f'{prefix}_tkeep'][1]} bits for {data_w // 8} byte lanes")
    has_user = f"{prefix}_tuser" in ports
    user_w = ports[f"{prefix}_tuser"][1] if has_user else 1
    if user_w > MAX_USER_W:
        raise ValueError(f"stream port {prefix!r} of {top!r}: tuser of {user_w} bits; the "
                         f"compiled ports take up to {MAX_USER_W}")
    return data_w, user_w, has_keep, has_user


def stream_wrapper(text, top, *, sources=(), sinks=(), clock="aclk", reset="aresetn"):
    """Verilog of module ``<top>_streams``: ``top`` (in Verilog ``text``) with each of its
    AXI4-Stream ports named in ``sources`` (the design's inputs) driven by
    ``rosgate_axis_source`` and each in ``sinks`` (its outputs) drained by
    ``rosgate_axis_sink``, both on ``clock`` and ``reset`` (active low). Every other port of
    ``top`` is a port of the wrapper with the same name; each stream port adds an output
    ``<prefix>_sent`` (source) or ``<prefix>_received`` (sink), its packets so far. Return
    ``(name, verilog)``."""
    ports = verilog_ports(text, top)
    for name in (clock, reset):
        if name not in ports or ports[name][0] != "input":
            raise ValueError(f"module {top!r} has no input {name!r}")
    taken = {prefix: "source" for prefix in sources}
    for prefix in sinks:
        if prefix in taken:
            raise ValueError(f"stream port {prefix!r} named as a source and a sink")
        taken[prefix] = "sink"
    shapes = {prefix: _port_shape(ports, prefix, d, top) for prefix, d in taken.items()}
    inner = [p for p in ports for prefix in taken if p.startswith(prefix + "_t")]
    name = f"{top}_streams"
    lines = wrapper_head(name, ports, inner, f"{top} with its stream ports on compiled FIFOs")
    # the counters are outputs of the wrapper: visible to Python, which waits on them
    header = lines[1]
    events = [f"{prefix}_{_EVENT[d]}" for prefix, d in taken.items()]
    lines[1] = header[:-2] + "".join(f", {e}" for e in events) + ");"
    lines += [f"    output [31:0] {e};" for e in events]
    lines += [f"    {top} dut ("]
    lines.append(",\n".join(f"        .{p}({p})" for p in ports))
    lines.append("    );")
    # a source's tkeep or tuser the design does not take stays unconnected
    lines.append("    /* verilator lint_off PINMISSING */")
    for k, (prefix, direction) in enumerate(taken.items()):
        data_w, user_w, has_keep, has_user = shapes[prefix]
        pins = {"aclk": clock, "aresetn": reset, "tdata": f"{prefix}_tdata",
                "tkeep": f"{prefix}_tkeep" if has_keep else None,
                "tuser": f"{prefix}_tuser" if has_user else None,
                "tlast": f"{prefix}_tlast", "tvalid": f"{prefix}_tvalid",
                "tready": f"{prefix}_tready", _EVENT[direction]: f"{prefix}_{_EVENT[direction]}"}
        if direction == "sink":
            # a sink's inputs the design does not have: every lane kept, tuser 0
            pins["tkeep"] = pins["tkeep"] or f"{{{data_w // 8}{{1'b1}}}}"
            pins["tuser"] = pins["tuser"] or "1'b0"
        lines.append(f"    rosgate_axis_{direction} #(.NAME(\"{prefix}\"), .DATA_W({data_w}), "
                     f".USER_W({user_w}), .HAS_KEEP({int(has_keep)})) stream{k} (")
        lines.append(",\n".join(f"        .{pin}({wire})" for pin, wire in pins.items() if wire)
                     + ");")
    lines.append("endmodule")
    return name, "\n".join(lines) + "\n"


def stream_harness(*, sources=(), sinks=(), clock="aclk", reset="aresetn"):
    """A ``harness`` for :func:`host.simulator.run_top`: the exported top inside
    :func:`stream_wrapper`; the cocotb side sees the wrapper's ports and the stream ports'
    wires (to read, as a monitor would)."""
    from gen.export.verilog import write_if_changed

    def make(vfile, build_dir):
        vfile = Path(vfile)
        text = vfile.read_text()
        name, verilog = stream_wrapper(text, vfile.stem, sources=sources, sinks=sinks,
                                       clock=clock, reset=reset)
        wrapper = Path(build_dir) / f"{name}.v"
        write_if_changed(wrapper, verilog)
        inner = [p for p in verilog_ports(text, vfile.stem)
                 for prefix in (*sources, *sinks) if p.startswith(prefix + "_t")]
        return (name, [wrapper, STREAM_SOURCES[0]], [str(STREAM_SOURCES[1]), *STREAM_LINK_ARGS],
                list(verilog_ports(verilog, name)) + inner)
    return make


def _library():
    try:
        program = ctypes.CDLL(None)
        program.rosgate_axis_open
    except (OSError, AttributeError) as exc:
        raise RuntimeError("the simulator was not built with compiled stream ports "
                           "(host.compiled.streams.stream_harness)") from exc
    u64, i32 = ctypes.c_uint64, ctypes.c_int
    signatures = {
        "open": (i32, [ctypes.c_char_p, i32, i32, i32, i32]),
        "shape": (i32, [i32, i32]),
        "send": (i32, [i32, ctypes.c_char_p, u64, u64]),
        "waiting": (u64, [i32]),
        "queued": (u64, [i32]),
        "clear": (None, [i32]),
        "restart": (None, [i32]),
        "pause": (None, [i32, i32, i32, ctypes.c_uint32, ctypes.c_uint32, u64]),
        "force_pause": (None, [i32, i32]),
        "counter": (u64, [i32, i32]),
        "reset_counters": (None, [i32]),
        "record": (None, [i32, i32]),
        "transfers": (u64, [i32, ctypes.c_void_p, u64]),
        "next": (ctypes.c_int64, [i32, ctypes.POINTER(u64)]),
        "take": (i32, [i32, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]),
        "complete": (u64, [i32]),
    }
    functions = {}
    for name, (restype, argtypes) in signatures.items():
        f = getattr(program, f"rosgate_axis_{name}")
        f.restype, f.argtypes = restype, argtypes
        functions[name] = f
    return functions


class StreamPacket:
    """A packet a compiled sink received: ``tdata`` (the bytes of every lane of every beat),
    ``tkeep`` (a flag per lane), ``tuser`` (a value per beat), and :attr:`data`, the bytes
    whose ``tkeep`` is set. Its attributes are those of cocotbext-axi's ``AxiStreamFrame``
    that the benches read."""

    __slots__ = ("tdata", "tkeep", "tuser")

    def __init__(self, tdata, tkeep, tuser):
        self.tdata, self.tkeep, self.tuser = tdata, tkeep, tuser

    @property
    def data(self):
        return bytes(d for d, k in zip(self.tdata, self.tkeep) if k)

    def __len__(self):
        return len(self.tdata)

    def __repr__(self):
        return f"StreamPacket({bytes(self.tdata)!r}, {len(self.tuser)} beats)"


class _CompiledPort:
    direction = None

    def __init__(self, dut, prefix):
        self._f = _library()
        event = f"{prefix}_{_EVENT[self.direction]}"
        if not hasattr(dut, event):
            raise ValueError(f"{prefix!r} is not a compiled stream {self.direction} of this "
                             f"simulation (no {event}: see stream_harness)")
        self.prefix = prefix
        self.event = getattr(dut, event)
        self.port = self._f["open"](prefix.encode(), 0, -1, 0, 0)
        self._f["restart"](self.port)
        self._forced = False
        self.log = logging.getLogger(f"cocotb.{prefix}")

    @property
    def pause(self):
        """Pause every cycle (a source presents no beat, a sink takes none) while true."""
        return self._forced

    @pause.setter
    def pause(self, value):
        self._forced = bool(value)
        self._f["force_pause"](self.port, int(self._forced))

    def set_random_pause(self, probability, seed, max_run=1):
        """Pause in runs of 1..``max_run`` cycles, each pausing with ``probability``, drawn
        from ``seed`` in the simulator (``probability`` 0: no random pauses)."""
        if not 0 <= probability <= 1:
            raise ValueError(f"pause probability {probability!r}: expected 0..1")
        if not isinstance(max_run, int) or max_run < 1:
            raise ValueError(f"max_run {max_run!r}: expected a positive integer")
        threshold = min(int(probability * 2**32), 2**32 - 1)
        self._f["pause"](self.port, int(self._forced), int(probability > 0), threshold, max_run,
                         seed & (2**64 - 1))

    def counter(self, name):
        """``cycles`` (clock edges), ``beats``, ``packets`` or ``stalls`` (tvalid without
        tready) since the port opened or :meth:`clear_counters`."""
        return int(self._f["counter"](self.port, _COUNTERS.index(name)))

    def clear_counters(self):
        self._f["reset_counters"](self.port)

    def record_transfers(self, on=True):
        """Record the cycle (``counter("cycles")``) of every beat from now on."""
        self._f["record"](self.port, int(on))

    @property
    def transfers(self):
        n = self._f["transfers"](self.port, None, 0)
        out = (ctypes.c_uint64 * n)()
        self._f["transfers"](self.port, out, n)
        return list(out)


class CompiledStreamSource(_CompiledPort):
    """The compiled source on the design's stream input ``prefix`` (see
    :func:`stream_harness`), with cocotbext-axi ``AxiStreamSource``'s methods."""

    direction = "source"

    def send_nowait(self, frame, user=0):
        """Queue a packet: bytes, or an object with ``tdata`` (and an integer ``tuser``)."""
        data = getattr(frame, "tdata", frame)
        user = getattr(frame, "tuser", user)
        if isinstance(user, (list, tuple)):
            if len(set(user)) > 1:
                raise ValueError(f"{self.prefix}: a compiled source sends one tuser per packet, "
                                 f"not {sorted(set(user))}")
            user = user[0] if user else 0
        data = bytes(data)
        if not data:
            raise ValueError(f"{self.prefix}: a packet needs at least one byte")
        self._f["send"](self.port, data, len(data), int(user or 0))

    async def send(self, frame, user=0):
        self.send_nowait(frame, user)

    write = send
    write_nowait = send_nowait

    def count(self):
        """Packets queued and not begun."""
        return int(self._f["queued"](self.port))

    def empty(self):
        return self.count() == 0

    def idle(self):
        """Nothing queued, nothing on its way, the last beat taken."""
        return self._f["waiting"](self.port) == 0

    def clear(self):
        self._f["clear"](self.port)

    async def wait(self):
        """Until every queued packet's last beat was taken."""
        from cocotb.triggers import ValueChange
        while not self.idle():
            await ValueChange(self.event)


class CompiledStreamSink(_CompiledPort):
    """The compiled sink on the design's stream output ``prefix`` (see :func:`stream_harness`),
    with cocotbext-axi ``AxiStreamSink``'s methods; packets are :class:`StreamPacket`."""

    direction = "sink"

    def count(self):
        return int(self._f["complete"](self.port))

    def empty(self):
        return self.count() == 0

    def clear(self):
        self._f["clear"](self.port)

    def recv_nowait(self, compact=True):
        beats = ctypes.c_uint64()
        n = self._f["next"](self.port, ctypes.byref(beats))
        if n < 0:
            raise IndexError(f"{self.prefix}: no packet")
        data, keep = ctypes.create_string_buffer(n), ctypes.create_string_buffer(n)
        user = (ctypes.c_uint64 * beats.value)()
        self._f["take"](self.port, data, keep, user)
        packet = StreamPacket(data.raw, list(keep.raw), list(user))
        if compact:
            packet = StreamPacket(packet.data, [1] * sum(packet.tkeep), packet.tuser)
        return packet

    async def recv(self, compact=True):
        from cocotb.triggers import ValueChange
        while self.empty():
            await ValueChange(self.event)
        return self.recv_nowait(compact)

    read = recv
    read_nowait = recv_nowait


def _quiet(port):
    port.log.setLevel(logging.WARNING)
    return port


def stream_source(dut, prefix, clock=None, reset=None):
    """The source on ``dut``'s stream input ``prefix``: the compiled one where
    :func:`stream_harness` took the port, else cocotbext-axi's ``AxiStreamSource`` on
    ``clock`` and ``reset`` (active low; default ``dut.aclk`` and ``dut.aresetn``)."""
    if hasattr(dut, f"{prefix}_{_EVENT['source']}"):
        return CompiledStreamSource(dut, prefix)
    from cocotbext.axi import AxiStreamBus, AxiStreamSource
    return _quiet(AxiStreamSource(AxiStreamBus.from_prefix(dut, prefix), clock or dut.aclk,
                                  reset or dut.aresetn, reset_active_level=False))


def stream_sink(dut, prefix, clock=None, reset=None):
    """The sink on ``dut``'s stream output ``prefix``, as :func:`stream_source` chooses."""
    if hasattr(dut, f"{prefix}_{_EVENT['sink']}"):
        return CompiledStreamSink(dut, prefix)
    from cocotbext.axi import AxiStreamBus, AxiStreamSink
    return _quiet(AxiStreamSink(AxiStreamBus.from_prefix(dut, prefix), clock or dut.aclk,
                                reset or dut.aresetn, reset_active_level=False))


def pause_runs(rng, probability, max_run=1):
    """Pause generator (one value per cycle) of runs of 1..``max_run`` cycles, each run
    pausing with ``probability``, drawn from ``rng``: what the compiled ports draw in C++,
    for cocotbext-axi's and the benches' own Python drivers."""
    while True:
        value = rng.random() < probability
        for _ in range(rng.randint(1, max_run) if max_run > 1 else 1):
            yield value


def pause_randomly(port, rng, probability, max_run=1):
    """Random idle cycles (source) or backpressure (sink) on ``port`` (from
    :func:`stream_source` or :func:`stream_sink`): runs of 1..``max_run`` cycles, each pausing
    with ``probability``, drawn from ``rng`` (a ``random.Random``); 0 stops them."""
    if isinstance(port, _CompiledPort):
        port.set_random_pause(probability, rng.getrandbits(64), max_run)
        return
    import random
    port.set_pause_generator(pause_runs(random.Random(rng.getrandbits(64)), probability, max_run)
                             if probability else None)
    if not probability:
        port.pause = False   # the generator may have stopped on a pause
