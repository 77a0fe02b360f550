"""Verilog export helpers: port naming, the Icarus t=0 rewrite, stable output."""

from gen.export.verilog import export_verilog, fix_icarus_t0, port_name
from hdl.dds import Topic


def test_port_names_follow_xilinx_axis_convention():
    assert port_name(("s_axis", 0, "tdata")) == "s0_axis_tdata"
    assert port_name(("m_axis", 15, "tready")) == "m15_axis_tready"
    assert port_name(("monitor", "pub", 2, "beats")) == "monitor_pub2_beats"
    assert port_name(("monitor", "drops", 1)) == "monitor_drops1"


def test_icarus_t0_rewrite():
    text = "module m;\n  reg \\$auto$verilog_backend.cc:2355:dump_module$1  = 0;\nendmodule\n"
    fixed = fix_icarus_t0(text)
    assert "reg \\$auto$verilog_backend.cc:2355:dump_module$1 ;" in fixed
    assert "initial \\$auto$verilog_backend.cc:2355:dump_module$1 = 0;" in fixed
    assert "= 0;\n  initial" not in fixed.split("reg")[1].split("\n")[0]


def test_exported_topic_has_no_declaration_initialised_trigger():
    text, _ = export_verilog(Topic(3, 2, 8, fifo_depth=4), "topic")
    assert "initial \\$auto$" in text
    for line in text.splitlines():
        if line.strip().startswith("reg \\$auto$"):
            assert "=" not in line, line
    assert "src = " not in text, "source locations leak host paths"
