"""Exporters: Verilog tops for Vivado and simulators, manifests."""

from .verilog import VivadoTop, export_verilog, port_name, write_if_changed, write_manifest

__all__ = ["VivadoTop", "export_verilog", "port_name", "write_if_changed", "write_manifest"]
