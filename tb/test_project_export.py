"""``rosgate export-hw`` of every example project: lint-clean Verilog, Vivado TCL checked by
content (every file it uses exists, every interface maps onto ports of the Verilog, the
block design's addresses and interrupts are ReconROS'), FuseSoC cores that FuseSoC itself
reads and lints, and a manifest that agrees with build.cfg."""

import json
import os
import re
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from gen.config import load_project
from gen.export.vivado import BOARDS
from hdl.reconos.protocol import ARCHS
from host.cli import main as rosgate
from host.lint import lint_verilog
from host.simulator import exclusive

from .harness import ROOT
from .projects import EXPORT_PARAMS, EXPORTED_EXAMPLES, example_cfg, external_threads_project


class _Exports:
    """Example projects exported on first use, once per test run: ``exported[name]`` is
    ``(project, output folder, manifest)``. The folders are shared by pytest-xdist's workers,
    a lock per project keeps two from exporting it at once; so each worker exports only what
    its tests need and nothing twice."""

    def __init__(self, root):
        self.root = root
        root.mkdir(parents=True, exist_ok=True)

    def __getitem__(self, name):
        cfg = example_cfg(name)
        folder = self.root / name
        with exclusive(self.root / f"{name}.lock"):
            if not (folder / "manifest.json").is_file():
                params = [a for p in EXPORT_PARAMS.get(name, ()) for a in ("--param", p)]
                assert rosgate(["export-hw", str(cfg), "-o", str(folder), *params]) == 0
        return load_project(cfg), folder, json.loads((folder / "manifest.json").read_text())


@pytest.fixture(scope="session")
def exported(tmp_path_factory):
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent                  # the run's folder, above each worker's own
    return _Exports(root / "exported")


def verilog_ports(path, module):
    """Port names of ``module`` in ``path``, from its declarations."""
    text = Path(path).read_text()
    body = text[text.index(f"module {module}("):]
    body = body[:body.index("endmodule")]
    return set(re.findall(r"^\s*(?:input|output|inout)\s+(?:wire\s+|reg\s+)?(?:\[[^\]]+\]\s*)?"
                          r"(\w+)\s*;", body, re.M))


def tcl_interfaces(text):
    """``{interface: {logical: physical}}`` declared by a packaging script."""
    out = {}
    current = None
    for line in text.splitlines():
        mo = re.match(r"set bif \[ipx::add_bus_interface (\S+) \$core\]", line)
        if mo:
            current = out.setdefault(mo.group(1), {})
        mo = re.match(r"set_property physical_name (\S+) \[ipx::add_port_map (\S+) \$bif\]", line)
        if mo:
            current[mo.group(2)] = mo.group(1)
    return out


@pytest.mark.parametrize("name", EXPORTED_EXAMPLES)
def test_verilog_lint_clean(exported, name):
    project, folder, manifest = exported[name]
    for core, info in manifest["cores"].items():
        report = lint_verilog(folder / info["verilog"], core)
        assert not report, f"{name}/{core}:\n{report}"


@pytest.mark.parametrize("name", EXPORTED_EXAMPLES)
def test_tcl_references_and_interfaces(exported, name):
    project, folder, manifest = exported[name]
    scripts = [folder / "build.tcl", folder / "bd" / "design_1.tcl",
               *(folder / "ip").glob("package_*.tcl")]
    for script in scripts:
        text = script.read_text()
        for ref in re.findall(r"(?:source|add_files -norecurse|ip_repo_paths \[list) "
                              r"\[file join \$here ([^\]]+)\]", text):
            target = script.parent.joinpath(*ref.split())
            assert target.exists(), f"{script.name} uses {ref}, which does not exist"
    for core, info in manifest["cores"].items():
        ports = verilog_ports(folder / info["verilog"], core)
        assert {p["name"] for p in info["ports"]} == ports
        declared = tcl_interfaces((folder / info["package_tcl"]).read_text())
        assert declared, core
        assert set(declared) == {i["name"] for i in info["interfaces"]}
        for bif, mapping in declared.items():
            for logical, physical in mapping.items():
                assert physical in ports, f"{core}: {bif}.{logical} -> {physical} is no port"
        used = {p for m in declared.values() for p in m.values()}
        plain = {p for p in ports - used if not p.endswith("hwt_signal")}
        assert plain == set(), f"{core}: ports in no interface: {plain}"
        for fifo in (i for i in info["interfaces"] if i["kind"] == "fifo"):
            bus = fifo["bus"].split(":")[2]
            tree = ET.parse(folder / "ip" / "busdefs" / f"{bus}_rtl.xml")
            logical = {e.text for e in tree.iter() if e.tag.endswith("logicalName")}
            assert set(fifo["ports"]) == logical, (core, fifo["name"])


@pytest.mark.parametrize("name", EXPORTED_EXAMPLES)
def test_block_design(exported, name):
    """ReconROS addresses (docs/reconos.md), interrupt positions, memory port and clocks."""
    project, folder, manifest = exported[name]
    text = (folder / "bd" / "design_1.tcl").read_text()
    board = BOARDS[project.board]
    arch = ARCHS[project.arch]
    assert manifest["address_map"] == {
        "s_axi_osif": {"base": f"0x{arch.osif_base:08X}", "range": "0x10000"},
        "s_axi_intc": {"base": f"0x{arch.intc_base:08X}", "range": "0x10000"},
        "s_axi_proc": {"base": f"0x{arch.proc_control_base:08X}", "range": "0x10000"}}
    for slave, entry in manifest["address_map"].items():
        assert (f"-offset {entry['base']} -range 64K [get_bd_addr_segs "
                f"rosgate_system/{slave}/reg0]") in text
    irq = (6, 7) if project.arch == "r64" else (14, 15)
    assert (board["irq_osif"], board["irq_pgf"]) == irq
    assert f"rosgate_system/irq_osif] [get_bd_pins irq_concat/In{irq[0]}]" in text
    assert f"rosgate_system/irq_pgf] [get_bd_pins irq_concat/In{irq[1]}]" in text
    memory = "S_AXI_HPC0_FPD" if project.arch == "r64" else "S_AXI_ACP"
    assert f"[get_bd_intf_pins ps/{memory}]" in text
    declared = tcl_interfaces((folder / "ip" / "package_rosgate_system.tcl").read_text())
    ports = verilog_ports(folder / "hdl" / "rosgate_system.v", "rosgate_system")
    for pin in re.findall(r"get_bd_intf_pins rosgate_system/(\w+)", text):
        assert pin in declared, f"block design uses interface {pin}, not packaged"
    for pin in re.findall(r"get_bd_pins rosgate_system/(\w+)", text):
        assert pin in ports, f"block design uses pin {pin}, not a port"
    for slot in project.slots:
        if slot.clock is not project.system_clock:
            assert f"rosgate_system/slot{slot.id}_clk]" in text
            assert f"REQUESTED_OUT_FREQ {{{slot.clock.freq / 1e6:g}}}" in text
    build = (folder / "build.tcl").read_text()
    assert f"-part {project.part}" in build and "write_bitstream" in build
    assert "BIN_FILE true" in build


@pytest.mark.parametrize("name", EXPORTED_EXAMPLES)
def test_manifest_agrees_with_build_cfg(exported, name):
    project, folder, manifest = exported[name]
    assert manifest["arch"] == project.arch and manifest["top"] == "rosgate_system"
    for t, entry in zip(project.threads, manifest["threads"]):
        assert entry["handles"] == {r.c_name: h for h, r in enumerate(t.resources)}
        assert [s["id"] for s in manifest["slots"] if s["thread"] == t.name] == \
            [s.id for s in t.slots]
    assert set(manifest["topics"]) == set(project.topics)
    for topic, entry in manifest["topics"].items():
        assert entry["topology"] == project.topics[topic].topology


def test_external_slots_and_topic_ports(tmp_path):
    """The gateway demo without its thread sources and with its gateway as a plain thread:
    no thread has an Amaranth version, so every slot's FIFO ports and every topic port is a
    port of the system top and an external pin of the block design."""
    (tmp_path / "project").mkdir()
    cfg = external_threads_project(tmp_path / "project")
    folder = tmp_path / "out"
    assert rosgate(["export-hw", str(cfg), "-o", str(folder)]) == 0
    manifest = json.loads((folder / "manifest.json").read_text())
    assert [s["implementation"] for s in manifest["slots"]] == ["external"] * 3
    ports = verilog_ports(folder / "hdl" / "rosgate_system.v", "rosgate_system")
    for port in ("slot0_nicehwtopic_tdata", "slot1_nicehwtopic_tready",
                 "slot2_nicehwtopic_in_tvalid", "slot2_nicehwtopic_out_tlast",
                 "slot2_osif_sw2hw_data", "slot2_rst"):
        assert port in ports
    text = (folder / "bd" / "design_1.tcl").read_text()
    assert "make_bd_intf_pins_external [get_bd_intf_pins rosgate_system/slot0_nicehwtopic]" in text


def test_gateway_demo_threads_are_inside(exported):
    """The gateway demo as written: Threada, Threadb and the ROS gateway are Amaranth threads
    (the gateway generated from its section), so the hardware topic is inside the system."""
    project, folder, manifest = exported["hwtopic_gateway"]
    assert [s["implementation"] for s in manifest["slots"]] == ["amaranth"] * 3
    ports = verilog_ports(folder / "hdl" / "rosgate_system.v", "rosgate_system")
    assert not [p for p in ports if "nicehwtopic" in p]


def _fusesoc_env():
    from host.toolchain import put_verilator_on_path
    exe = put_verilator_on_path()
    env = dict(os.environ)
    env["PATH"] = f"{Path(exe).parent}{os.pathsep}{env['PATH']}"
    return env


def test_fusesoc_reads_and_lints_the_cores(exported, tmp_path):
    """FuseSoC 2.4 parses every core file; its Verilator lint target passes on a thread core
    and on the system core, and fails on a broken copy (the check can fail)."""
    import shutil
    project, folder, manifest = exported["sort_service"]
    fusesoc = [str(Path(os.sys.executable).parent / "fusesoc"), "--cores-root",
               str(folder / "hdl")]
    env = _fusesoc_env()
    for core, info in manifest["cores"].items():
        r = subprocess.run(fusesoc + ["core-info", info["fusesoc_name"]], capture_output=True,
                           text=True, env=env)
        assert r.returncode == 0 and f"{core}.core" in r.stdout, r.stdout + r.stderr
    for core in ("rt_sortdemo", "rosgate_system"):
        r = subprocess.run(fusesoc + ["run", "--target", "lint", "--build-root",
                                      str(tmp_path / core), manifest["cores"][core]["fusesoc_name"]],
                           capture_output=True, text=True, env=env)
        assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    broken = tmp_path / "broken"
    shutil.copytree(folder / "hdl", broken)
    v = broken / "rt_sortdemo.v"
    v.write_text(v.read_text().replace("endmodule", "endmodul", 1))
    r = subprocess.run([fusesoc[0], "--cores-root", str(broken), "run", "--target", "lint",
                        "--build-root", str(tmp_path / "b"),
                        manifest["cores"]["rt_sortdemo"]["fusesoc_name"]],
                       capture_output=True, text=True, env=env)
    assert r.returncode != 0


def test_export_msg_headers(tmp_path):
    """``rosgate export-msg`` writes a C header per message type of the project; the Image
    data offset is rosidl's (72 on arm64, docs/messages.md)."""
    cfg = ROOT / "examples" / "sobel_dip" / "build.cfg"
    assert rosgate(["export-msg", str(cfg), "-o", str(tmp_path)]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["application_msgs__srv__sobelsrv_request.h",
                     "application_msgs__srv__sobelsrv_response.h", "sensor_msgs__msg__image.h"]
    text = (tmp_path / "sensor_msgs__msg__image.h").read_text()
    assert "#define ROSGATE_OFFSET__sensor_msgs__msg__Image__data__data 72\n" in text


def _copy_inverse(tmp_path):
    import shutil
    folder = tmp_path / "project"
    shutil.copytree(ROOT / "examples" / "inverse_kinematics", folder)
    return folder


def test_manifest_lists_its_files_relative_to_the_folder(tmp_path):
    project = _copy_inverse(tmp_path)
    assert rosgate(["export-hw", str(project / "build.cfg"), "-o", str(tmp_path / "out")]) == 0
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert (tmp_path / "out" / manifest["build_cfg"]).resolve() == \
        (project / "build.cfg").resolve()
    on_disk = sorted(str(p.relative_to(tmp_path / "out")) for p in
                     (tmp_path / "out").rglob("*") if p.is_file())
    assert manifest["files"] == on_disk
    assert str(tmp_path) not in (tmp_path / "out" / "manifest.json").read_text()


def test_reexport_removes_what_it_no_longer_writes(tmp_path, capsys):
    project = _copy_inverse(tmp_path)
    out = tmp_path / "out"
    assert rosgate(["export-hw", str(project / "build.cfg"), "-o", str(out)]) == 0
    assert (out / "hdl" / "rt_inverse.v").is_file()
    # the thread becomes an external core (its Amaranth source gone): its files must go
    import shutil
    shutil.rmtree(project / "src" / "rt_inverse" / "amaranth")
    assert rosgate(["export-hw", str(project / "build.cfg"), "-o", str(out)]) == 0
    assert not (out / "hdl" / "rt_inverse.v").exists()
    assert not (out / "ip" / "package_rt_inverse.tcl").exists()
    assert "removed hdl/rt_inverse.v" in capsys.readouterr().out
    manifest = json.loads((out / "manifest.json").read_text())
    assert "hdl/rt_inverse.v" not in manifest["files"]


def test_export_refuses_a_foreign_folder_without_force(tmp_path, capsys):
    project = _copy_inverse(tmp_path)
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert rosgate(["export-hw", str(project / "build.cfg"), "-o", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert rosgate(["export-hw", str(project / "build.cfg"), "-o", str(out), "--force"]) == 0
    assert (out / "notes.txt").read_text() == "mine" and (out / "manifest.json").is_file()
    # a folder with only other subfolders (rosgate sim's sim/) is not foreign
    beside = tmp_path / "with_sim"
    (beside / "sim").mkdir(parents=True)
    (beside / "sim" / "sim_results.json").write_text("{}")
    assert rosgate(["export-hw", str(project / "build.cfg"), "-o", str(beside)]) == 0
    assert (beside / "sim" / "sim_results.json").read_text() == "{}"


def test_failed_write_leaves_the_old_file_whole(tmp_path, monkeypatch):
    """A full disk in the middle of a write: the old Verilog stays, no temporary file."""
    import errno

    from gen.export import verilog
    path = tmp_path / "core.v"
    verilog.write_if_changed(path, "module old; endmodule\n")

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(verilog.os, "fsync", full)
    with pytest.raises(OSError):
        verilog.write_if_changed(path, "module new; endmodule\n" * 1000)
    assert path.read_text() == "module old; endmodule\n"
    assert [p.name for p in tmp_path.iterdir()] == ["core.v"]


def test_export_killed_half_way_leaves_no_truncated_verilog(tmp_path, monkeypatch):
    """An export that dies after its first core: what it wrote is whole, nothing else is
    there, and no temporary files remain."""
    from gen.export import hw
    project = load_project(_copy_inverse(tmp_path) / "build.cfg")
    calls = []
    real = hw.export_verilog

    def dies_on_the_second(component, name):
        calls.append(name)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(component, name)
    monkeypatch.setattr(hw, "export_verilog", dies_on_the_second)
    with pytest.raises(KeyboardInterrupt):
        hw.export_hw(project, tmp_path / "out")
    files = sorted(p.relative_to(tmp_path / "out").as_posix()
                   for p in (tmp_path / "out").rglob("*") if p.is_file())
    assert not any(".tmp" in f for f in files)
    assert "manifest.json" not in files
    text = (tmp_path / "out" / "hdl" / "rosgate_system.v").read_text()
    assert text.rstrip().endswith("endmodule")
