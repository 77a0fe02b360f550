"""``rosgate export-hw``: a project's hardware for Vivado and FuseSoC (docs/reconos.md).

Layout of the output folder::

    hdl/rosgate_system.v      the whole system (ReconOS infrastructure, threads, topics)
    hdl/rt_<thread>.v         each Amaranth thread alone, with its slot ports
    hdl/<core>.core           FuseSoC CAPI2 core of each
    ip/package_<core>.tcl     Vivado IP packaging (cs.upb.de:reconos:<core>:1.0)
    ip/busdefs/FIFO*.xml      ReconOS' FIFO bus definitions
    bd/design_1.tcl           the block design
    build.tcl                 synthesis, implementation, bitstream
    manifest.json             cores, ports, interfaces, address map, topics, handles
"""

import json
import os
import time
from pathlib import Path

from .interfaces import bus_interfaces
from .verilog import export_verilog, write_if_changed
from .vivado import address_map, block_design_tcl, build_tcl, busdef_xml, package_tcl

__all__ = ["SYSTEM_CORE", "export_hw", "fusesoc_core", "core_vlnv"]

SYSTEM_CORE = "rosgate_system"


def core_vlnv(project, core):
    """FuseSoC name of ``core`` in ``project``."""
    return f"rosgate:{project.name.lower()}:{core}:1.0"


def fusesoc_core(project, core, description):
    """A FuseSoC CAPI2 ``.core`` for ``hdl/<core>.v`` with a Verilator lint target."""
    return "\n".join([
        "CAPI=2:",
        f"name: {core_vlnv(project, core)}",
        f'description: "{description}"',
        "filesets:",
        "  rtl:",
        "    files:",
        f"      - {core}.v",
        "    file_type: verilogSource",
        "targets:",
        "  default: &default",
        "    filesets: [rtl]",
        f"    toplevel: {core}",
        "  lint:",
        "    <<: *default",
        "    default_tool: verilator",
        "    tools:",
        "      verilator:",
        "        mode: lint-only",
        "        verilator_options: [-Wno-fatal]",
        "  synth:",
        "    <<: *default",
        "    default_tool: vivado",
        "    tools:",
        "      vivado:",
        f"        part: {project.part}",
        "",
    ])


#: the folders an export writes into
EXPORT_FOLDERS = ("hdl", "ip", "bd")


class ExportFolderError(ValueError):
    """The output folder of an export holds files that are not an earlier export's."""


def _previous_files(out, force):
    """The files an earlier export wrote into ``out`` (from its manifest.json); an existing
    folder with other files and no manifest is refused unless ``force``."""
    manifest = out / "manifest.json"
    if manifest.is_file():
        try:
            return set(json.loads(manifest.read_text()).get("files", []))
        except (ValueError, AttributeError):
            pass
    foreign = _foreign_files(out) if out.is_dir() and not force else []
    if foreign:
        raise ExportFolderError(f"-o {out}: the folder holds files that are not a rosgate "
                                f"export (no manifest.json listing them, e.g. {foreign[0]}); "
                                f"choose a new folder or pass --force to write into it")
    return set()


def _foreign_files(out):
    """Files in ``out`` an export could overwrite or leave stale: at its top and in the
    folders it writes (other folders, such as ``rosgate sim``'s ``sim/``, are left alone)."""
    found = [f.name for f in out.iterdir() if f.is_file()]
    for sub in EXPORT_FOLDERS:
        if (out / sub).is_dir():
            found += [str(f.relative_to(out)) for f in (out / sub).rglob("*") if f.is_file()]
    return sorted(found)


def export_hw(project, out, *, log=None, force=False):
    """Write the hardware of ``project`` into ``out``; return the manifest (a dict).

    Every file is written through a temporary file and a rename, ``manifest.json`` last
    (it lists the files, relative to ``out``); what an earlier export into ``out`` wrote and
    this one does not is removed. A non-empty ``out`` that is not an earlier export is
    refused (:class:`ExportFolderError`) unless ``force``."""
    from gen.system import build_system, thread_code, thread_sources

    log = log or (lambda s: None)
    out = Path(out)
    previous = _previous_files(out, force)
    start = time.monotonic()
    log(f"building the system of {project.name} ({len(project.slots)} slots, "
        f"{len(project.topics)} hardware topics)")
    system = build_system(project)
    cores = {}
    written = set()

    def write(relative, text):
        write_if_changed(out / relative, text)
        written.add(relative)

    def emit(name, component, description):
        with thread_code(project):
            text, vtop = export_verilog(component, name)
        write(f"hdl/{name}.v", text)
        interfaces = bus_interfaces(component)
        write(f"hdl/{name}.core", fusesoc_core(project, name, description))
        write(f"ip/package_{name}.tcl",
              package_tcl(name, project.part, interfaces, description=description))
        cores[name] = {"verilog": f"hdl/{name}.v", "fusesoc": f"hdl/{name}.core",
                       "fusesoc_name": core_vlnv(project, name),
                       "package_tcl": f"ip/package_{name}.tcl",
                       "vlnv": f"cs.upb.de:reconos:{name}:1.0", "description": description,
                       "ports": vtop.manifest_ports(),
                       "interfaces": [{"name": i.name, "kind": i.kind, "mode": i.mode,
                                       "bus": i.bus[0], "ports": i.ports,
                                       "parameters": i.parameters} for i in interfaces]}
        log(f"  {name}: {len(vtop.ports) + 2} ports, {len(interfaces)} interfaces")
        return interfaces

    log("writing Verilog (system top)")
    sys_ifs = emit(SYSTEM_CORE, system, f"{project.name}: ReconOS infrastructure, "
                                        f"{len(project.slots)} slots, hardware topics")
    done = set()
    for slot, component in zip(sorted(project.slots, key=lambda s: s.id), system.threads):
        if component is None or slot.thread.core_name in done:
            continue
        done.add(slot.thread.core_name)
        log(f"writing Verilog (thread {slot.thread.name})")
        emit(slot.thread.core_name, component,
             f"ReconOS hardware thread {slot.thread.name} of {project.name}")
    for kind in ("M", "S"):
        for name, text in busdef_xml(kind, 64 if project.arch == "r64" else 32).items():
            write(f"ip/busdefs/{name}", text)
    write("bd/design_1.tcl", block_design_tcl(project, system, sys_ifs))
    write("build.tcl", build_tcl(project, list(cores)))
    sources = thread_sources(project)
    manifest = {
        "project": project.name, "build_cfg": os.path.relpath(Path(project.path).resolve(),
                                                              out.resolve()),
        "board": project.board,
        "part": project.part, "arch": project.arch, "top": SYSTEM_CORE,
        "clocks": [{"name": c.name, "id": c.id, "freq_hz": c.freq, "source": c.source,
                    "system": c is project.system_clock} for c in project.clocks],
        "address_map": {k: {"base": f"0x{v:08X}", "range": "0x10000"}
                        for k, v in address_map(project.arch).items()},
        "interrupts": {"irq_osif": "osif_intc", "irq_pgf": "proc_control page fault"},
        "slots": [{"name": s.name, "id": s.id, "clock": s.clock.name,
                   "thread": s.thread.name if s.thread else None,
                   "implementation": "amaranth" if system.threads[s.id] is not None
                   else "external"} for s in sorted(project.slots, key=lambda s: s.id)],
        "threads": [{"name": t.name, "id": t.id, "core": t.core_name,
                     "slots": [s.id for s in t.slots], "source": sources[t.name],
                     "handles": {r.c_name: h for h, r in enumerate(t.resources)},
                     "resources": [{"handle": h, "name": r.name, "c_name": r.c_name,
                                    "type": r.type, "type_code": r.type_code,
                                    "global_id": r.id, "args": r.args,
                                    "message": r.msgtype} for h, r in enumerate(t.resources)],
                     "hw_topics": [{"topic": e.topic, "direction": e.direction, "port": e.port,
                                    "fifo_depth": e.depth} for e in t.endpoints]}
                    for t in project.threads],
        "topics": {name: {"message": t.msgtype, "topology": t.topology,
                          "publishers": [f"{e.thread.name}.{e.port}" for e in t.pubs],
                          "subscribers": [f"{e.thread.name}.{e.port}" for e in t.subs],
                          "fifo_depths": [e.depth for e in t.subs]}
                   for name, t in project.topics.items()},
        "cores": cores,
        "warnings": project.warnings,
        "files": sorted(written | {"manifest.json"}),
    }
    write_if_changed(out / "manifest.json", json.dumps(manifest, indent=2) + "\n")
    for stale in sorted(previous - written - {"manifest.json"}):
        path = out / stale
        if ".." not in Path(stale).parts and path.is_file():
            path.unlink()
            log(f"removed {stale} (an earlier export's, not written now)")
    log(f"wrote {out} in {time.monotonic() - start:.1f} s")
    return manifest
