"""rosgate generators: configs and messages in, Verilog, TCL, cores and reports out."""
