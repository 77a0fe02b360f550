// Cycle-level simulation models of the Lattice ECP5 primitives rosgate's board tops use
// (docs/boards.md "Simulating a board top"), written from Lattice's descriptions (TN1262,
// TN1263, TN1265) for simulation without timing: Verilator and Icarus.
//
// EHXPLLL makes no frequencies: the simulation drives the oscillator pin at CLKOP's
// frequency, CLKOP follows CLKI, and CLKOS is CLKI divided by CLKOS_DIV / CLKOP_DIV (an even
// whole number); LOCK rises after 64 cycles of CLKI. DELAYG delays nothing (a simulation
// without timing has nothing to skew). IDDRX1F and ODDRX1F move data on both clock edges as
// the silicon does. With ROSGATE_ECP5_NETLIST defined, the I/O buffers are left to Yosys'
// own cell models and TRELLIS_IO is modelled here (a synthesised netlist's pads).

`ifndef ROSGATE_ECP5_NETLIST
module IB(input I, output O);
  assign O = I;
endmodule

module OB(input I, output O);
  assign O = I;
endmodule

module OBZ(input I, input T, output O);
  assign O = T ? 1'bz : I;
endmodule

module BB(input I, input T, output O, inout B);
  assign B = T ? 1'bz : I;
  assign O = B;
endmodule
`else
// a synthesised netlist's pads; host/board_sim.py renames its input pads TRELLIS_IO_INPUT
module TRELLIS_IO_INPUT(input B, input I, input T, output O);
  assign O = B;
endmodule

module TRELLIS_IO #(parameter DIR = "OUTPUT") (inout B, input I, input T, output O);
  generate
    if (DIR == "OUTPUT") begin
      assign B = T === 1'b1 ? 1'bz : I;
      assign O = 1'b0;
    end else begin
      assign B = T === 1'b1 ? 1'bz : I;
      assign O = B;
    end
  endgenerate
endmodule
`endif

module DELAYG #(parameter DEL_MODE = "USER_DEFINED", parameter DEL_VALUE = 0)
               (input A, output Z);
  assign Z = A;
endmodule

// D sampled on the rising edge (Q0) and on the falling edge (Q1), both presented after the
// next rising edge
module IDDRX1F #(parameter GSR = "ENABLED") (input D, input SCLK, input RST,
                                             output reg Q0, output reg Q1);
  reg rise, fall;
  initial begin rise = 0; fall = 0; Q0 = 0; Q1 = 0; end
  always @(posedge SCLK) begin
    rise <= D;
    Q0 <= rise;
    Q1 <= fall;
  end
  always @(negedge SCLK) fall <= D;
endmodule

// D0 and D1 taken on the rising edge; D0 out from that edge, D1 from the falling edge. The
// output changes only through registers (never as a function of SCLK itself), so that a
// receiver clocked from the same net samples what the pin held before the edge
module ODDRX1F #(parameter GSR = "ENABLED") (input SCLK, input RST, input D0, input D1,
                                             output reg Q);
  reg d1;
  initial begin d1 = 0; Q = 0; end
  always @(posedge SCLK) begin
    Q <= D0;
    d1 <= D1;
  end
  always @(negedge SCLK) Q <= d1;
endmodule

module EHXPLLL #(
  parameter CLKI_DIV = 1, CLKFB_DIV = 1, CLKOP_DIV = 8, CLKOS_DIV = 8, CLKOS2_DIV = 8,
  parameter CLKOS3_DIV = 8,
  parameter CLKOP_ENABLE = "ENABLED", CLKOS_ENABLE = "DISABLED", CLKOS2_ENABLE = "DISABLED",
  parameter CLKOS3_ENABLE = "DISABLED",
  parameter CLKOP_CPHASE = 0, CLKOS_CPHASE = 0, CLKOS2_CPHASE = 0, CLKOS3_CPHASE = 0,
  parameter CLKOP_FPHASE = 0, CLKOS_FPHASE = 0, CLKOS2_FPHASE = 0, CLKOS3_FPHASE = 0,
  parameter FEEDBK_PATH = "CLKOP", CLKOP_TRIM_POL = "RISING", CLKOP_TRIM_DELAY = 0,
  parameter CLKOS_TRIM_POL = "RISING", CLKOS_TRIM_DELAY = 0,
  parameter OUTDIVIDER_MUXA = "DIVA", OUTDIVIDER_MUXB = "DIVB", OUTDIVIDER_MUXC = "DIVC",
  parameter OUTDIVIDER_MUXD = "DIVD", PLL_LOCK_MODE = 0, PLL_LOCK_DELAY = 200,
  parameter STDBY_ENABLE = "DISABLED", REFIN_RESET = "DISABLED", SYNC_ENABLE = "DISABLED",
  parameter INT_LOCK_STICKY = "ENABLED", DPHASE_SOURCE = "DISABLED",
  parameter PLLRST_ENA = "DISABLED", INTFB_WAKE = "DISABLED", DTR_TEMP = 25
) (
  input CLKI, input CLKFB, input PHASESEL1, input PHASESEL0, input PHASEDIR,
  input PHASESTEP, input PHASELOADREG, input STDBY, input PLLWAKESYNC, input RST,
  input ENCLKOP, input ENCLKOS, input ENCLKOS2, input ENCLKOS3,
  output CLKOP, output reg CLKOS, output CLKOS2, output CLKOS3, output LOCK,
  output INTLOCK, output REFCLK, output CLKINTFB
);
  localparam HALF = CLKOS_DIV / CLKOP_DIV / 2;
  reg [7:0] phase;
  reg [6:0] settle;
  initial begin CLKOS = 0; phase = 0; settle = 0; end
  assign CLKOP = CLKI;
  assign CLKOS2 = 1'b0;
  assign CLKOS3 = 1'b0;
  assign REFCLK = CLKI;
  assign CLKINTFB = 1'b0;
  assign LOCK = settle[6];
  assign INTLOCK = settle[6];
  always @(posedge CLKI) begin
    if (!settle[6]) settle <= settle + 7'd1;
    if (phase == HALF - 1) begin
      phase <= 0;
      CLKOS <= ~CLKOS;
    end else begin
      phase <= phase + 8'd1;
    end
  end
endmodule
