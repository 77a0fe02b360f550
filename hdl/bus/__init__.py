"""On-chip buses: AXI4 and AXI4-Lite signatures and a register target."""

from .axi import AXIResp, AXIBurst, AXI4LiteSignature, AXI4Signature, AXI4LiteTarget

__all__ = ["AXIResp", "AXIBurst", "AXI4LiteSignature", "AXI4Signature", "AXI4LiteTarget"]
