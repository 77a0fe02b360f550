"""rosgate test benches (cocotb on Icarus and Verilator, amaranth.sim unit tests)."""
