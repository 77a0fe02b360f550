"""The compiled stream ports (host/compiled/streams.py, axis_stream.sv/.cpp) against
cocotbext-axi's ``AxiStreamSource`` and ``AxiStreamSink``: on the ``topic`` top with every port
ready, the beats of every port are taken at the same cycles by the compiled ports under
Verilator as by cocotbext-axi's under Icarus; the wrapper refuses what is not a stream port
of the right direction.

The scoreboards under random idle and backpressure are tb/test_topic.py's, which runs the
compiled ports on Verilator and cocotbext-axi's on Icarus."""

import json
import os

import cocotb
import pytest
from cocotb.triggers import RisingEdge, gather
from cocotbext.axi import AxiStreamFrame

from host.compiled.streams import stream_wrapper
from host.simulator import start_clock
from tb.harness import run_bench
from tb.models.topic import TopicScoreboard, tagged_message

from .topic_tb import CONFIGS, TopicTB, topic_harness

#: tb/test_topic.py's 3x3_w8 configuration: its Icarus build and its compiled-port Verilator
#: build are shared with that bench
CONFIG, PARAMS = "3x3_w8", CONFIGS["3x3_w8"]


@cocotb.test()
async def record_transfer_cycles(dut):
    """Messages queued on every publisher while paused, released together, then more sent one
    at a time from Python as the previous arrives: every port's beat cycles and the messages,
    to ``ROSGATE_BENCH_OUT``."""
    tb = TopicTB(dut, seed=7)
    await tb.reset()
    for watch in tb.pub_watch + tb.sub_watch:
        watch.keep_cycles = True
    scoreboard = TopicScoreboard(tb.pubs, tb.subs)
    lengths = [1, 4, 5, 17, 64, 3]
    for source in tb.sources:
        source.pause = True
    for pub, source in enumerate(tb.sources):
        for seq, n in enumerate(lengths):
            message = tagged_message(pub, seq, n + pub, tb.rng)
            scoreboard.publish(pub, message)
            await source.send(tb.frame(message))
    receivers = [cocotb.start_soon(tb.run_subscriber(scoreboard, j, tb.pubs * len(lengths)))
                 for j in range(tb.subs)]
    await RisingEdge(dut.aclk)
    for source in tb.sources:
        source.pause = False
    await gather(*receivers)
    for seq in range(4):
        message = tagged_message(0, len(lengths) + seq, 9 + seq, tb.rng)
        scoreboard.publish(0, message)
        await tb.sources[0].send(tb.frame(message))
        await tb.sources[0].wait()
        for j in range(tb.subs):
            await tb.run_subscriber(scoreboard, j, 1)
    scoreboard.check_complete()
    await tb.cycles(3)
    first = tb.pub_watch[0].transfer_cycles[0]
    record = {
        "pub": [[c - first for c in w.transfer_cycles] for w in tb.pub_watch],
        "sub": [[c - first for c in w.transfer_cycles] for w in tb.sub_watch],
        "stalls": [w.stalls for w in tb.pub_watch + tb.sub_watch],
        "received": scoreboard.received,
    }
    with open(os.environ["ROSGATE_BENCH_OUT"], "w") as f:
        json.dump(record, f)


@cocotb.test()
async def compiled_ports_refuse_bad_input(dut):
    """Bad input to a compiled port is refused with a message naming it."""
    from host.compiled.streams import CompiledStreamSink, CompiledStreamSource
    start_clock(dut.aclk, 10)
    source, sink = CompiledStreamSource(dut, "s0_axis"), CompiledStreamSink(dut, "m0_axis")
    refusals = [
        (lambda: source.send_nowait(b""), "s0_axis: a packet needs at least one byte"),
        (lambda: source.send_nowait(AxiStreamFrame(b"ab", tuser=[0, 1])),
         "s0_axis: a compiled source sends one tuser per packet, not [0, 1]"),
        (lambda: source.set_random_pause(1.5, 1), "pause probability 1.5: expected 0..1"),
        (lambda: sink.set_random_pause(0.5, 1, max_run=0),
         "max_run 0: expected a positive integer"),
        (lambda: sink.recv_nowait(), "m0_axis: no packet"),
        (lambda: CompiledStreamSource(dut, "m0_axis"),
         "'m0_axis' is not a compiled stream source of this simulation (no m0_axis_sent: see "
         "stream_harness)"),
    ]
    for call, message in refusals:
        try:
            call()
        except (ValueError, IndexError) as exc:
            assert str(exc) == message, str(exc)
        else:
            raise AssertionError(f"not refused: {message}")
    assert source.idle() and sink.empty()


def run_case(sim, compiled, out):
    name = f"cycles-{'compiled' if compiled else 'cocotbext'}"
    run_bench(__name__, "topic", CONFIG, PARAMS, sim,
              extra_env={"ROSGATE_BENCH_OUT": str(out)}, run_name=name,
              harness=topic_harness if compiled else None, testcase=["record_transfer_cycles"])
    return json.loads(out.read_text())


def test_compiled_ports_take_the_cycles_of_cocotbext(tmp_path):
    reference = run_case("icarus", False, tmp_path / "icarus.json")
    compiled = run_case("verilator", True, tmp_path / "compiled.json")
    # one byte per beat
    pubs, subs = PARAMS["pubs"], PARAMS["subs"]
    beats = sum(n + pub for pub in range(pubs) for n in (1, 4, 5, 17, 64, 3)) + \
        sum(9 + s for s in range(4))
    assert sum(len(cycles) for cycles in reference["pub"]) == beats
    assert all(len(reference["sub"][j]) == beats for j in range(subs))
    assert compiled == reference, "not the cycles of cocotbext-axi's ports on Icarus"


def test_compiled_ports_refuse_bad_input():
    run_bench(__name__, "topic", CONFIG, PARAMS, "verilator", run_name="refusals",
              harness=topic_harness, testcase=["compiled_ports_refuse_bad_input"])


TOP = """module dut(aclk, aresetn, a_tdata, a_tvalid, a_tready, a_tlast, b_tdata, b_tkeep,
  b_tvalid, b_tready, b_tlast, w_tdata, w_tvalid, w_tready, w_tlast);
  input aclk;
  input aresetn;
  input [31:0] a_tdata;
  input a_tvalid;
  output a_tready;
  input a_tlast;
  output [63:0] b_tdata;
  output [7:0] b_tkeep;
  output b_tvalid;
  input b_tready;
  output b_tlast;
  input [11:0] w_tdata;
  input w_tvalid;
  output w_tready;
  input w_tlast;
endmodule
"""


def test_wrapper_connects_sources_and_sinks():
    name, verilog = stream_wrapper(TOP, "dut", sources=["a"], sinks=["b"])
    assert name == "dut_streams"
    assert "rosgate_axis_source #(.NAME(\"a\"), .DATA_W(32), .USER_W(1), .HAS_KEEP(0))" in verilog
    assert "rosgate_axis_sink #(.NAME(\"b\"), .DATA_W(64), .USER_W(1), .HAS_KEEP(1))" in verilog
    assert "output [31:0] a_sent;" in verilog and "output [31:0] b_received;" in verilog


@pytest.mark.parametrize("kwargs,message", [
    (dict(sources=["c"]), "module 'dut' has no port c_tdata: not an AXI4-Stream port 'c'"),
    (dict(sources=["b"]), "stream port 'b' of 'dut' is an output of the design: it needs a "
                          "sink, not a source"),
    (dict(sinks=["a"]), "stream port 'a' of 'dut' is an input of the design: it needs a "
                        "source, not a sink"),
    (dict(sources=["a"], sinks=["a"]), "stream port 'a' named as a source and a sink"),
    (dict(sources=["w"]), "stream port 'w' of 'dut': tdata of 12 bits; the compiled ports "
                          "take whole bytes up to 1024 bits"),
    (dict(sources=["a"], clock="clk"), "module 'dut' has no input 'clk'"),
])
def test_wrapper_names_what_it_refuses(kwargs, message):
    with pytest.raises(ValueError) as info:
        stream_wrapper(TOP, "dut", **kwargs)
    assert str(info.value) == message
