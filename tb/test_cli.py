# amaranth: UnusedElaboratable=no
"""The rosgate command line: export topic, its manifest, lint, and bad parameters."""

import json
import re
import subprocess
import sys

import pytest

from hdl.dds import Topic
from hdl.params import ParameterError
from host.cli import main
from host.lint import lint_verilog
from host.project_sim import TOP, WAVES

from .fst_names import fst_signal_names
from .harness import run_rosgate


def verilog_ports(text, module):
    """(direction, width, name) of every port declared in ``module``."""
    body = text[text.index(f"module {module}("):]
    body = body[:body.index("endmodule")]
    ports = {}
    for direction, width, name in re.findall(r"^\s*(input|output)\s+(?:\[(\d+):0\]\s+)?(\w+);",
                                             body, re.MULTILINE):
        ports[name] = (direction, int(width) + 1 if width else 1)
    return ports


@pytest.mark.parametrize("args", [
    ["--pubs", "4", "--subs", "4", "--width", "64"],
    ["--pubs", "1", "--subs", "1", "--width", "8"],
    ["--pubs", "3", "--subs", "2", "--width", "512", "--fifo-depth", "64", "--qos",
     "best_effort"],
    ["--pubs", "2", "--subs", "3", "--width", "32", "--fifo-depth", "256", "--qos", "keep_last",
     "--history", "8", "--user-width", "1", "--id-width", "2", "--dest-width", "1"],
])
def test_export_topic_writes_lint_clean_verilog_and_manifest(tmp_path, args, capsys):
    assert main(["export", "topic", *args, "-o", str(tmp_path)]) == 0
    assert "wrote" in capsys.readouterr().out
    text = (tmp_path / "topic.v").read_text()
    manifest = json.loads((tmp_path / "topic.json").read_text())
    assert manifest["module"] == "topic"
    ports = verilog_ports(text, "topic")
    declared = {p["name"]: (p["direction"], p["width"]) for p in manifest["ports"]}
    assert ports == declared
    pubs, subs = manifest["parameters"]["pubs"], manifest["parameters"]["subs"]
    width = manifest["parameters"]["data_width"]
    assert ports["aclk"] == ("input", 1) and ports["aresetn"] == ("input", 1)
    for i in range(pubs):
        assert ports[f"s{i}_axis_tdata"] == ("input", width)
        assert ports[f"s{i}_axis_tkeep"] == ("input", width // 8)
        assert ports[f"s{i}_axis_tready"] == ("output", 1)
    for j in range(subs):
        assert ports[f"m{j}_axis_tvalid"] == ("output", 1)
        assert ports[f"m{j}_axis_tready"] == ("input", 1)
    assert "/work/" not in text and "/home/" not in text, "host path in the Verilog"
    assert lint_verilog(tmp_path / "topic.v", "topic") == ""


def test_export_is_deterministic(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        assert main(["export", "topic", "--pubs", "2", "--subs", "2", "--width", "16",
                     "-o", str(out)]) == 0
    assert (a / "topic.v").read_text() == (b / "topic.v").read_text()


@pytest.mark.parametrize("args,message", [
    (["--pubs", "0", "--subs", "1", "--width", "8"], "--pubs must be an integer in 1..16, not 0"),
    (["--pubs", "1", "--subs", "17", "--width", "8"],
     "--subs must be an integer in 1..16, not 17"),
    (["--pubs", "1", "--subs", "1", "--width", "12"],
     "--width must be an integer in 8..1024 and a multiple of 8, not 12"),
    (["--pubs", "1", "--subs", "1", "--width", "2048"], "--width must be an integer in 8..1024"),
    (["--pubs", "1", "--subs", "1", "--width", "8", "--fifo-depth", "100"],
     "--fifo-depth must be 0 (no FIFO) or a power of two in 2..65536, not 100"),
    (["--pubs", "1", "--subs", "1", "--width", "8", "--qos", "reliable"],
     "--qos must be one of 'keep_all', 'keep_last', 'best_effort', not 'reliable'"),
    (["--pubs", "1", "--subs", "1", "--width", "8", "--qos", "best_effort"],
     "--fifo-depth must be a power of two in 2..65536 with qos='best_effort'"),
    (["--pubs", "1", "--subs", "1", "--width", "8", "--fifo-depth", "16", "--qos",
      "keep_last", "--history", "3"], "--history must be a power of two in 2..16"),
    (["--pubs", "x", "--subs", "1", "--width", "8"], "argument --pubs: invalid int value: 'x'"),
])
def test_export_topic_rejects_bad_parameters(tmp_path, args, message):
    result = run_rosgate("export", "topic", *args, "-o", tmp_path / "out")
    assert result.returncode == 2
    assert message in result.stderr, result.stderr
    assert not (tmp_path / "out").exists(), "nothing may be written on a bad parameter"


def test_topic_parameter_errors_name_the_parameter():
    with pytest.raises(ParameterError) as info:
        Topic(2, 2, 64, fifo_depth=3)
    assert info.value.name == "fifo_depth" and info.value.value == 3
    with pytest.raises(ParameterError, match="history must be None unless qos='keep_last'"):
        Topic(2, 2, 64, fifo_depth=8, history=4)


def test_help_documents_every_option():
    result = run_rosgate("export", "topic", "--help")
    assert result.returncode == 0
    for option in ("--pubs", "--subs", "--width", "--fifo-depth", "--qos", "--history",
                   "--no-monitor", "-o"):
        assert option in result.stdout


def test_msg_layout_prints_spec_offsets():
    result = run_rosgate("msg", "layout", "sensor_msgs/Image", "--arch", "arm32")
    assert result.returncode == 0, result.stderr
    assert "sizeof 60" in result.stdout
    assert re.search(r"^\s+48\s+4\s+pointer\s+data\.data$", result.stdout, re.MULTILINE)


def test_msg_show_project_action_type():
    result = run_rosgate("msg", "show", "sorter_msgs/action/Sort_GetResult_Response",
                     "--msg-dir", "examples/messages")
    assert result.returncode == 0, result.stderr
    assert "int8 status" in result.stdout and "sorter_msgs/action/Sort_Result result" in \
        result.stdout


def test_msg_export_c_writes_header(tmp_path):
    out = tmp_path / "image.h"
    result = run_rosgate("msg", "export-c", "sensor_msgs/Image", "-o", str(out))
    assert result.returncode == 0, result.stderr
    text = out.read_text()
    assert "typedef struct sensor_msgs__msg__Image {" in text
    assert "#define ROSGATE_OFFSET__sensor_msgs__msg__Image__data__data 72" in text


def test_msg_errors_exit_2_with_location(tmp_path):
    result = run_rosgate("msg", "show", "nope/Type")
    assert result.returncode == 2 and "unknown message type 'nope/Type'" in result.stderr
    bad = tmp_path / "bad_msgs" / "msg"
    bad.mkdir(parents=True)
    (bad / "Bad.msg").write_text("uint8 ok\nuint8[0] broken\n")
    result = run_rosgate("msg", "show", "bad_msgs/Bad", "--msg-dir", str(tmp_path))
    assert result.returncode == 2
    assert "Bad.msg:2: bad array bound: fixed arrays need N >= 1 ('uint8[0]')" in result.stderr


def test_msg_plan_per_framing():
    result = run_rosgate("msg", "plan", "sensor_msgs/Image")
    assert result.returncode == 0, result.stderr
    assert "framing cdr: 10 steps" in result.stdout
    assert "run 16 B: const 00 01 00 00 | field header.stamp.sec int32 4 B" in result.stdout
    result = run_rosgate("msg", "plan", "sensor_msgs/Image", "--framing", "ros1")
    assert result.returncode == 0, result.stderr
    assert "field header.seq uint32 4 B" in result.stdout
    assert "md5sum 060021388200f6f0f447d0fcd9c64743" in result.stdout
    assert "MSG: std_msgs/Header" in result.stdout
    result = run_rosgate("msg", "plan", "sensor_msgs/Image", "--framing", "reconros")
    assert result.returncode == 0, result.stderr
    assert "publisher 8 B beat 0 | publisher 8 B beat 1 | extend height uint32 8 B" in \
        result.stdout


def test_msg_plan_streams_sequences_of_messages_packed():
    result = run_rosgate("msg", "plan", "sensor_msgs/PointCloud2")
    assert result.returncode == 0, result.stderr
    assert "stream fields: sequence<sensor_msgs/msg/PointField> packed" in result.stdout
    assert "loop over the elements of fields" in result.stdout


def test_msg_plan_rejects_unstreamable_type():
    result = run_rosgate("msg", "plan", "sensor_msgs/PointCloud2", "--framing", "reconros")
    assert result.returncode == 2
    assert "no encoding for fields, sensor_msgs/msg/PointField[]" in result.stderr


@pytest.mark.parametrize("app", ["page", "pid"])
def test_export_finemb_writes_node_manifest_and_vivado_tcl(tmp_path, app, capsys):
    from gen.finemb import load_io_description
    from tb.finemb_tb import PID_IO
    out = tmp_path / app
    assert main(["export", "finemb", "--io", PID_IO, "--app", app, "--serial", "9",
                 "-o", str(out)]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith(f"wrote {out / 'hdl' / 'finemb_node.v'} (module finemb_node")
    verilog = out / "hdl" / "finemb_node.v"
    assert lint_verilog(verilog, "finemb_node") == ""
    ports = verilog_ports(verilog.read_text(), "finemb_node")
    assert {"port0_rxd", "port0_txd", "port1_rx_dv", "port1_tx_en"} <= set(ports)
    assert ("app_out_claim" in ports) == (app == "page")
    manifest = json.loads((out / "finemb_node.json").read_text())
    io = load_io_description(PID_IO)
    assert manifest["io_descriptor_hex"] == io.encode().hex()
    assert (manifest["page_out_bytes"], manifest["page_in_bytes"], manifest["serial"]) == \
        (10, 8, 9)
    assert [p["offset"] for p in manifest["io_ports"]] == [p.offset for p in io.ports]
    tcl = (out / "ip" / "package_finemb_node.tcl").read_text()
    assert "ipx::package_project" in tcl and "finemb_node.v" in tcl
    # two clocks, on ports of the Verilog, asynchronous to each other
    assert manifest["clocks_mhz"] == {"aclk": 62.5, "gmii_clk": 125.0}
    xdc = (out / "constraints" / "finemb_node_clocks.xdc").read_text().splitlines()
    assert "create_clock -name aclk -period 16.000 [get_ports aclk]" in xdc
    assert "create_clock -name gmii_clk -period 8.000 [get_ports gmii_clk]" in xdc
    assert "set_clock_groups -asynchronous -group [get_clocks aclk] " \
        "-group [get_clocks gmii_clk]" in xdc
    assert {"aclk", "gmii_clk"} <= set(ports)


def test_export_finemb_names_a_bad_io_file(tmp_path, capsys):
    bad = tmp_path / "node.toml"
    bad.write_text('name = "x"\n[[port]]\nname = "a"\ndirection = "out"\ntype = "i17"\n')
    assert main(["export", "finemb", "--io", str(bad), "-o", str(tmp_path / "o")]) == 2
    assert f"{bad}:5: port 1" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_export_av_chain_writes_lint_clean_verilog_and_manifest(tmp_path, capsys):
    """``rosgate export av_chain`` (docs/av_chain.md): the fpgaDDS chain as one module whose
    ports are the manifest's, camera and bird's-eye sizes as asked."""
    assert main(["export", "av_chain", "--scale", "0.2", "--pixels-per-beat", "2",
                 "-o", str(tmp_path)]) == 0
    assert "camera 128x96, bird's-eye view 200x120, 2 px/beat" in capsys.readouterr().out
    text = (tmp_path / "av_chain.v").read_text()
    manifest = json.loads((tmp_path / "av_chain.json").read_text())
    ports = verilog_ports(text, "av_chain")
    assert ports == {p["name"]: (p["direction"], p["width"]) for p in manifest["ports"]}
    assert manifest["camera"] == [128, 96] and manifest["bev"] == [200, 120]
    # 2 px/beat of bgr8: 48-bit camera beats in, the 64-bit drive command out
    assert ports["camera_tdata"] == ("input", 48) and ports["command_tdata"] == ("output", 64)
    assert lint_verilog(tmp_path / "av_chain.v", "av_chain") == ""


def test_export_av_chain_refuses_a_bad_scale(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["export", "av_chain", "--scale", "1.5", "-o", str(tmp_path)])
    assert exc.value.code == 2 and "--scale must be in (0, 1], not 1.5" in capsys.readouterr().err


def test_output_into_a_closed_pipe_ends_quietly():
    """``rosgate ... | head``: no traceback, the status of a SIGPIPE."""
    # the reader is gone before rosgate writes (Python starts in a tenth of a second, `true`
    # ends at once), so the first write meets the closed pipe
    result = subprocess.run(
        f"set -o pipefail; {sys.executable} -m host.cli info examples/av_chain/build.cfg | "
        f"true", shell=True, executable="/bin/bash", capture_output=True, text=True)
    assert result.returncode == 141 and result.stderr == "", result.stderr


def test_waves_are_written_into_the_output_folder(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["sim", "examples/inverse_kinematics/build.cfg", "--sim", "icarus", "--waves",
                 "--arg", "requests=2", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    fst = out / "rosgate_system.fst"
    assert f"waveform (every signal of the system, FST): {fst}" in printed
    assert fst.stat().st_size > 10_000


def _design_signals(fst, prefix):
    """The signal names below ``prefix`` in ``fst``, without widths, escapes and the ``$n``
    suffixes a conversion numbers differently per simulator flavour, nor yosys' temporaries."""
    names = set()
    for name in fst_signal_names(fst):
        name = re.sub(r" \[.*\]$", "", name)
        if name.startswith(prefix):
            parts = [re.sub(r"\$\d+$", "", p.lstrip("\\")) for p in name[len(prefix):].split(".")]
            if not re.fullmatch(r"_\d+_|\$.*", parts[-1]):
                names.add(".".join(parts))
    return names


@pytest.mark.full
def test_verilator_waves_hold_every_signal_icarus_records(tmp_path):
    """--waves under Verilator (a model that shows only its ports to cocotb) records the
    design's inner signals all the same: every signal Icarus' waveform of the same run has,
    down to the threads' own registers."""
    fst = {}
    for sim in ("icarus", "verilator"):
        out = tmp_path / sim
        assert main(["sim", "examples/inverse_kinematics/build.cfg", "--sim", sim, "--waves",
                     "--arg", "requests=2", "-o", str(out)]) == 0
        fst[sim] = out / WAVES
    # under Verilator the system is instance ``dut`` of its compiled-memory wrapper
    icarus = _design_signals(fst["icarus"], f"{TOP}.")
    verilator = _design_signals(fst["verilator"], f"{TOP}_cosim.dut.")
    assert len([n for n in icarus if n.startswith("core.reconos.slot0.kernel.")]) > 100
    missing = sorted(icarus - verilator)
    assert not missing, f"{len(missing)} signals missing under Verilator: {missing[:20]}"
