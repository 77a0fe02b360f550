"""Vivado TCL for an exported project (docs/reconos.md): IP packaging of each core with
ReconOS' VLNVs and FIFO bus definitions, the block design ``design_1`` with the ReconROS
address map, interrupt positions and clocks, and ``build.tcl`` (synthesis, implementation,
bitstream and ``.bin``).

Every file a script uses is named as ``[file join $here <relative path>]``, ``$here`` being
the script's own folder, so the export can be moved and the tests can check each reference.
"""

from hdl.reconos.protocol import arch as get_arch

from .interfaces import reconos_fifo_bus

__all__ = ["BOARDS", "VENDOR", "LIBRARY", "package_tcl", "busdef_xml", "block_design_tcl",
           "build_tcl", "address_map", "clock_constraints"]

VENDOR = "cs.upb.de"
LIBRARY = "reconos"
CONTROL_RANGE = 0x1_0000

#: processing system of each TargetBoard (docs/reconos.md: control through the general-purpose
#: master, memory through HPC0 (ZynqMP) or ACP (Zynq), osif_intc and page-fault interrupts on
#: the concat inputs of the ReconROS templates)
BOARDS = {
    "zcu104": {
        "ps": "xilinx.com:ip:zynq_ultra_ps_e:3.3", "rule": "xilinx.com:bd_rule:zynq_ultra_ps_e",
        "board_part": "xilinx.com:zcu104:part0:1.1",
        "config": {"PSU__USE__M_AXI_GP0": 1, "PSU__USE__M_AXI_GP1": 0,
                   "PSU__USE__S_AXI_GP0": 1, "PSU__USE__IRQ0": 1},
        "clock_config": "PSU__CRL_APB__PL0_REF_CTRL__FREQMHZ",
        "control": "M_AXI_HPM0_FPD", "memory": "S_AXI_HPC0_FPD",
        "irq_pin": "pl_ps_irq0", "irq_ports": 8, "irq_osif": 6, "irq_pgf": 7,
        "clk": "pl_clk0", "resetn": "pl_resetn0",
        "bus_clocks": ("maxihpm0_fpd_aclk", "saxihpc0_fpd_aclk"),
        "memory_segment": "SAXIGP0/HPC0_DDR_LOW", "memory_base": 0x0, "memory_range": "2G"},
    "zedboard": {
        "ps": "xilinx.com:ip:processing_system7:5.5",
        "rule": "xilinx.com:bd_rule:processing_system7",
        "board_part": "em.avnet.com:zed:part0:1.4",
        "config": {"PCW_USE_M_AXI_GP0": 1, "PCW_USE_S_AXI_ACP": 1,
                   "PCW_USE_DEFAULT_ACP_USER_VAL": 1, "PCW_USE_FABRIC_INTERRUPT": 1,
                   "PCW_IRQ_F2P_INTR": 1},
        "clock_config": "PCW_FPGA0_PERIPHERAL_FREQMHZ",
        "control": "M_AXI_GP0", "memory": "S_AXI_ACP",
        "irq_pin": "IRQ_F2P", "irq_ports": 16, "irq_osif": 14, "irq_pgf": 15,
        "clk": "FCLK_CLK0", "resetn": "FCLK_RESET0_N",
        "bus_clocks": ("M_AXI_GP0_ACLK", "S_AXI_ACP_ACLK"),
        "memory_segment": "S_AXI_ACP/ACP_DDR_LOWOCM", "memory_base": 0x0,
        "memory_range": "512M"},
}
BOARDS["pynqz1"] = dict(BOARDS["zedboard"], board_part="www.digilentinc.com:pynq-z1:part0:1.0")
BOARDS["miniitx"] = dict(BOARDS["zedboard"], board_part=None, memory_range="1G")


def address_map(arch):
    """The AXI-Lite slaves of the system top and their ReconROS base addresses."""
    a = get_arch(arch)
    return {"s_axi_osif": a.osif_base, "s_axi_intc": a.intc_base,
            "s_axi_proc": a.proc_control_base}


def _dict(props):
    return " ".join(f"CONFIG.{k} {{{v}}}" for k, v in props.items())


def package_tcl(core, part, interfaces, *, description):
    """Package the Verilog of ``core`` as IP ``cs.upb.de:reconos:<core>:1.0`` into
    ``ip/<core>`` with exactly the given interfaces (inference is replaced by explicit port
    maps so that the packaged core does not depend on Vivado's heuristics)."""
    lines = [
        f"# rosgate: package {core} as IP {VENDOR}:{LIBRARY}:{core}:1.0 ({description})",
        "set here [file dirname [file normalize [info script]]]",
        f"create_project -in_memory -part {part}",
        "set_property ip_repo_paths [list [file join $here busdefs]] [current_project]",
        "update_ip_catalog",
        f"add_files -norecurse [file join $here .. hdl {core}.v]",
        f"set_property top {core} [current_fileset]",
        "update_compile_order -fileset sources_1",
        f"ipx::package_project -root_dir [file join $here {core}] -vendor {VENDOR} "
        f"-library {LIBRARY} -taxonomy /ReconOS -import_files -set_current true",
        "set core [ipx::current_core]",
        f"set_property name {core} $core",
        "set_property version 1.0 $core",
        f"set_property display_name {core} $core",
        f"set_property description {{{description}}} $core",
        "foreach bif [ipx::get_bus_interfaces -of_objects $core] { ipx::remove_bus_interface "
        "[get_property name $bif] $core }",
    ]
    for bif in interfaces:
        bus, abstraction = bif.bus
        lines += [
            f"set bif [ipx::add_bus_interface {bif.name} $core]",
            f"set_property bus_type_vlnv {bus} $bif",
            f"set_property abstraction_type_vlnv {abstraction} $bif",
            f"set_property interface_mode {bif.mode} $bif",
        ]
        for logical, physical in bif.ports.items():
            lines.append(f"set_property physical_name {physical} "
                         f"[ipx::add_port_map {logical} $bif]")
        for key, value in bif.parameters.items():
            lines.append(f"set_property value {{{value}}} "
                         f"[ipx::add_bus_parameter {key} $bif]")
        if bif.kind == "aximm" and bif.mode == "slave":
            lines += [
                f"set map [ipx::add_memory_map {bif.name} $core]",
                f"set_property slave_memory_map_ref {bif.name} $bif",
                "set block [ipx::add_address_block reg0 $map]",
                f"set_property range {CONTROL_RANGE} $block",
            ]
        if bif.kind == "aximm" and bif.mode == "master":
            lines += [f"set space [ipx::add_address_space {bif.name} $core]",
                      f"set_property master_address_space_ref {bif.name} $bif",
                      "set_property range 1T $space", "set_property width 64 $space"]
    lines += ["ipx::create_xgui_files $core", "ipx::update_checksums $core",
              "ipx::check_integrity $core", "ipx::save_core $core", "close_project", ""]
    return "\n".join(lines)


def busdef_xml(kind, width):
    """IP-XACT bus and abstraction definitions of ReconOS' FIFO bus (``FIFO64_M`` etc.).

    Returns ``{filename: text}``."""
    name, (bus_vlnv, abs_vlnv) = reconos_fifo_bus(kind, width)
    _, lib, _, version = bus_vlnv.split(":")
    ports = ({"Data": ("out", width), "WE": ("out", 1), "Full": ("in", 1)} if kind == "M" else
             {"Data": ("in", width), "RE": ("out", 1), "Empty": ("in", 1)})
    ns = ('xmlns:spirit="http://www.spiritconsortium.org/XMLSchema/SPIRIT/1685-2009" '
          'xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"')
    bus = (f'<?xml version="1.0" encoding="UTF-8"?>\n<spirit:busDefinition {ns}>\n'
           f"  <spirit:vendor>{VENDOR}</spirit:vendor>\n  <spirit:library>{lib}</spirit:library>\n"
           f"  <spirit:name>{name}</spirit:name>\n  <spirit:version>{version}</spirit:version>\n"
           "  <spirit:directConnection>true</spirit:directConnection>\n"
           "  <spirit:isAddressable>false</spirit:isAddressable>\n</spirit:busDefinition>\n")
    body = []
    for port, (direction, w) in ports.items():
        slave = {"out": "in", "in": "out"}[direction]
        body.append(
            f"    <spirit:port>\n      <spirit:logicalName>{name}_{port}</spirit:logicalName>\n"
            "      <spirit:wire>\n"
            f"        <spirit:onMaster><spirit:presence>required</spirit:presence>"
            f"<spirit:width>{w}</spirit:width><spirit:direction>{direction}</spirit:direction>"
            "</spirit:onMaster>\n"
            f"        <spirit:onSlave><spirit:presence>required</spirit:presence>"
            f"<spirit:width>{w}</spirit:width><spirit:direction>{slave}</spirit:direction>"
            "</spirit:onSlave>\n      </spirit:wire>\n    </spirit:port>")
    abstraction = (
        f'<?xml version="1.0" encoding="UTF-8"?>\n<spirit:abstractionDefinition {ns}>\n'
        f"  <spirit:vendor>{VENDOR}</spirit:vendor>\n  <spirit:library>{lib}</spirit:library>\n"
        f"  <spirit:name>{name}_rtl</spirit:name>\n  <spirit:version>{version}</spirit:version>\n"
        f'  <spirit:busType spirit:vendor="{VENDOR}" spirit:library="{lib}" '
        f'spirit:name="{name}" spirit:version="{version}"/>\n'
        "  <spirit:ports>\n" + "\n".join(body) + "\n  </spirit:ports>\n"
        "</spirit:abstractionDefinition>\n")
    return {f"{name}.xml": bus, f"{name}_rtl.xml": abstraction}


def block_design_tcl(project, system, interfaces):
    """The block design ``design_1``: processing system, ``axi_hwt`` (control) and ``axi_mem``
    (memory) interconnects, the system core, reset, interrupts, clocks and addresses."""
    b = BOARDS[project.board]
    amap = address_map(project.arch)
    core = "rosgate_system"
    mhz = project.system_clock.freq / 1e6
    names = {i.name for i in interfaces}
    lines = [
        f"# rosgate: block design of {project.name} ({project.board}, {project.arch}); "
        "source from build.tcl",
        "create_bd_design design_1",
        f"create_bd_cell -type ip -vlnv {b['ps']} ps",
        f'apply_bd_automation -rule {b["rule"]} -config {{apply_board_preset "1"}} '
        "[get_bd_cells ps]" if b["board_part"] else "# no board preset: part only",
        f"set_property -dict [list {_dict({**b['config'], b['clock_config']: f'{mhz:g}'})}] "
        "[get_bd_cells ps]",
        "create_bd_cell -type ip -vlnv xilinx.com:ip:proc_sys_reset:5.0 rst_sys",
        f"create_bd_cell -type ip -vlnv {VENDOR}:{LIBRARY}:{core}:1.0 {core}",
        "create_bd_cell -type ip -vlnv xilinx.com:ip:smartconnect:1.0 axi_hwt",
        f"set_property -dict [list CONFIG.NUM_SI {{1}} CONFIG.NUM_MI {{{len(amap)}}}] "
        "[get_bd_cells axi_hwt]",
        "create_bd_cell -type ip -vlnv xilinx.com:ip:smartconnect:1.0 axi_mem",
        "set_property -dict [list CONFIG.NUM_SI {1} CONFIG.NUM_MI {1}] [get_bd_cells axi_mem]",
        "create_bd_cell -type ip -vlnv xilinx.com:ip:xlconcat:2.1 irq_concat",
        f"set_property -dict [list CONFIG.NUM_PORTS {{{b['irq_ports']}}}] "
        "[get_bd_cells irq_concat]",
        f"connect_bd_intf_net [get_bd_intf_pins ps/{b['control']}] "
        "[get_bd_intf_pins axi_hwt/S00_AXI]",
    ]
    for i, slave in enumerate(amap):
        lines.append(f"connect_bd_intf_net [get_bd_intf_pins axi_hwt/M{i:02d}_AXI] "
                     f"[get_bd_intf_pins {core}/{slave}]")
    lines += [
        f"connect_bd_intf_net [get_bd_intf_pins {core}/m_axi_mem] "
        "[get_bd_intf_pins axi_mem/S00_AXI]",
        f"connect_bd_intf_net [get_bd_intf_pins axi_mem/M00_AXI] "
        f"[get_bd_intf_pins ps/{b['memory']}]",
        f"connect_bd_net [get_bd_pins {core}/irq_osif] "
        f"[get_bd_pins irq_concat/In{b['irq_osif']}]",
        f"connect_bd_net [get_bd_pins {core}/irq_pgf] [get_bd_pins irq_concat/In{b['irq_pgf']}]",
        f"connect_bd_net [get_bd_pins irq_concat/dout] [get_bd_pins ps/{b['irq_pin']}]",
        f"connect_bd_net [get_bd_pins ps/{b['resetn']}] [get_bd_pins rst_sys/ext_reset_in]",
    ]
    clocked = [f"{core}/aclk", "axi_hwt/aclk", "axi_mem/aclk", "rst_sys/slowest_sync_clk"]
    clocked += [f"ps/{p}" for p in b["bus_clocks"]]
    lines.append(f"connect_bd_net [get_bd_pins ps/{b['clk']}] " +
                 " ".join(f"[get_bd_pins {p}]" for p in clocked))
    lines.append("connect_bd_net [get_bd_pins rst_sys/peripheral_aresetn] " +
                 " ".join(f"[get_bd_pins {p}]" for p in
                          (f"{core}/aresetn", "axi_hwt/aresetn", "axi_mem/aresetn")))
    # slot clocks other than the system clock: one clocking wizard output per clock
    others = sorted({s.clock.name: s.clock for s in project.slots
                     if s.clock is not project.system_clock}.values(), key=lambda c: c.id)
    if others:
        lines += ["create_bd_cell -type ip -vlnv xilinx.com:ip:clk_wiz:6.0 slot_clocks",
                  f"set_property -dict [list CONFIG.NUM_OUT_CLKS {{{len(others)}}} " +
                  " ".join(f"CONFIG.CLKOUT{k + 1}_USED {{true}} "
                           f"CONFIG.CLKOUT{k + 1}_REQUESTED_OUT_FREQ {{{c.freq / 1e6:g}}}"
                           for k, c in enumerate(others)) +
                  " CONFIG.USE_RESET {false} CONFIG.USE_LOCKED {false}] "
                  "[get_bd_cells slot_clocks]",
                  f"connect_bd_net [get_bd_pins ps/{b['clk']}] "
                  "[get_bd_pins slot_clocks/clk_in1]"]
        for k, clock in enumerate(others):
            pins = [f"[get_bd_pins {core}/slot{s.id}_clk]" for s in project.slots
                    if s.clock is clock and f"slot{s.id}_clk" in names]
            lines.append(f"connect_bd_net [get_bd_pins slot_clocks/clk_out{k + 1}] " +
                         " ".join(pins))
    external = [i for i in interfaces if i.name.startswith("slot") and
                i.kind in ("fifo", "axis", "reset")]
    for bif in external:
        if bif.kind == "reset":
            lines.append(f"make_bd_pins_external [get_bd_pins {core}/{bif.name}]")
        else:
            lines.append(f"make_bd_intf_pins_external [get_bd_intf_pins {core}/{bif.name}]")
    if external:
        lines.insert(2, "# slots without an Amaranth thread: their ports are made external; "
                        "connect the thread cores (rt_<name>) there")
    for slave, base in amap.items():
        lines.append(f"assign_bd_address -target_address_space /ps/Data "
                     f"-offset 0x{base:08X} -range 64K [get_bd_addr_segs {core}/{slave}/reg0]")
    lines += [
        f"assign_bd_address -target_address_space /{core}/m_axi_mem "
        f"-offset 0x{b['memory_base']:08X} -range {b['memory_range']} "
        f"[get_bd_addr_segs ps/{b['memory_segment']}]",
        "validate_bd_design", "save_bd_design", ""]
    return "\n".join(lines)


def build_tcl(project, cores):
    """``vivado -mode batch -source build.tcl``: package the cores, build the block design,
    synthesise, implement and write the bitstream and ``.bin``."""
    b = BOARDS[project.board]
    name = project.name.lower()
    lines = [
        f"# rosgate: Vivado build of {project.name} ({project.part}); "
        "run: vivado -mode batch -source build.tcl",
        "set here [file dirname [file normalize [info script]]]",
    ]
    for core in cores:
        lines.append(f"source [file join $here ip package_{core}.tcl]")
    lines += [
        f"create_project -force {name} [file join $here vivado] -part {project.part}",
        f"set_property board_part {b['board_part']} [current_project]" if b["board_part"]
        else "# no board part for this board: the part alone",
        "set_property ip_repo_paths [list [file join $here ip]] [current_project]",
        "update_ip_catalog -rebuild",
        "source [file join $here bd design_1.tcl]",
        "set bd [get_files design_1.bd]",
        "generate_target all $bd",
        "add_files -norecurse [make_wrapper -files $bd -top]",
        "set_property top design_1_wrapper [current_fileset]",
        "update_compile_order -fileset sources_1",
        "set_property STEPS.WRITE_BITSTREAM.ARGS.BIN_FILE true [get_runs impl_1]",
        "launch_runs synth_1 -jobs 4",
        "wait_on_run synth_1",
        "launch_runs impl_1 -to_step write_bitstream -jobs 4",
        "wait_on_run impl_1",
        'if {[get_property PROGRESS [get_runs impl_1]] != "100%"} { error "implementation failed" }',
        "",
    ]
    return "\n".join(lines)


def clock_constraints(clocks_hz):
    """Out-of-context XDC for a core's clock ports (``{port: Hz}``): a clock per port and,
    with several, the clocks asynchronous to each other (the core crosses between them only
    through its synchronizers and asynchronous FIFOs)."""
    lines = ["# the core's clocks (out-of-context synthesis; in a design the board's clocks "
             "replace them)"]
    for port, hz in clocks_hz.items():
        lines.append(f"create_clock -name {port} -period {1e9 / hz:.3f} [get_ports {port}]")
    if len(clocks_hz) > 1:
        groups = " ".join(f"-group [get_clocks {port}]" for port in clocks_hz)
        lines.append(f"set_clock_groups -asynchronous {groups}")
    return "\n".join(lines) + "\n"
