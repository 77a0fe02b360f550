// Cycle-level simulation models of the Lattice ECP5 primitives rosgate instantiates
// (docs/boards.md "Simulating a board top"), written from Lattice's descriptions (TN1262,
// TN1263, TN1265, TN1267) for simulation without timing: Verilator and Icarus.
//
// EHXPLLL makes no frequencies: the simulation drives the oscillator pin at CLKOP's
// frequency, CLKOP follows CLKI, and CLKOS is CLKI divided by CLKOS_DIV / CLKOP_DIV (an even
// whole number); LOCK rises after 64 cycles of CLKI. DELAYG delays nothing (a simulation
// without timing has nothing to skew). IDDRX1F and ODDRX1F move data on both clock edges as
// the silicon does. MULT18X18D multiplies with the registers its parameters enable on CLK0
// (see the module). With ROSGATE_ECP5_NETLIST defined, the I/O buffers are left to Yosys'
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

// MULT18X18D: P = A * B, each operand two's complement when its SIGNEDA / SIGNEDB is 1,
// through the registers that REG_INPUTA_CLK, REG_INPUTB_CLK (the operands and their sign
// inputs), REG_PIPELINE_CLK and REG_OUTPUT_CLK enable, as TN1267 (ECP5 sysDSP) describes.
// Modelled is what rosgate's instances use: the registers on CLK0 with CE0 and a synchronous
// RST0, the A and B inputs (SOURCEA and SOURCEB low); other clocks, the asynchronous reset
// and the multiplier's bypass are refused when the model is elaborated. SIGNEDP is P's top bit.
/* verilator lint_off UNUSEDSIGNAL */
/* verilator lint_off UNUSEDPARAM */
module MULT18X18D #(parameter REG_INPUTA_CLK = "NONE", parameter REG_INPUTB_CLK = "NONE",
                    parameter REG_PIPELINE_CLK = "NONE", parameter REG_OUTPUT_CLK = "NONE",
                    parameter RESETMODE = "SYNC", parameter GSR = "ENABLED",
                    parameter SOURCEB_MODE = "B_SHIFT", parameter MULT_BYPASS = "DISABLED")
  (input A0, A1, A2, A3, A4, A5, A6, A7, A8, A9, A10, A11, A12, A13, A14, A15, A16, A17,
   input B0, B1, B2, B3, B4, B5, B6, B7, B8, B9, B10, B11, B12, B13, B14, B15, B16, B17,
   input SIGNEDA, input SIGNEDB, input SOURCEA, input SOURCEB,
   input CLK0, input CE0, input RST0,
   output P0, P1, P2, P3, P4, P5, P6, P7, P8, P9, P10, P11, P12, P13, P14, P15, P16, P17,
   output P18, P19, P20, P21, P22, P23, P24, P25, P26, P27, P28, P29, P30, P31, P32, P33,
   output P34, P35, SIGNEDP);
  initial begin
    if ((REG_INPUTA_CLK != "NONE" && REG_INPUTA_CLK != "CLK0") ||
        (REG_INPUTB_CLK != "NONE" && REG_INPUTB_CLK != "CLK0") ||
        (REG_PIPELINE_CLK != "NONE" && REG_PIPELINE_CLK != "CLK0") ||
        (REG_OUTPUT_CLK != "NONE" && REG_OUTPUT_CLK != "CLK0") ||
        RESETMODE != "SYNC" || MULT_BYPASS != "DISABLED") begin
      $display("MULT18X18D model: registers on CLK0 only, RESETMODE SYNC, no bypass");
      $finish;
    end
  end
  wire [17:0] a_in = {A17, A16, A15, A14, A13, A12, A11, A10, A9, A8, A7, A6, A5, A4, A3, A2,
                      A1, A0};
  wire [17:0] b_in = {B17, B16, B15, B14, B13, B12, B11, B10, B9, B8, B7, B6, B5, B4, B3, B2,
                      B1, B0};
  reg [17:0] a_reg, b_reg;
  reg signed_a_reg, signed_b_reg;
  reg [35:0] pipeline_reg, output_reg;
  initial begin
    a_reg = 0; b_reg = 0; signed_a_reg = 0; signed_b_reg = 0;
    pipeline_reg = 0; output_reg = 0;
  end
  wire [17:0] a = REG_INPUTA_CLK == "NONE" ? a_in : a_reg;
  wire [17:0] b = REG_INPUTB_CLK == "NONE" ? b_in : b_reg;
  wire signed_a = REG_INPUTA_CLK == "NONE" ? SIGNEDA : signed_a_reg;
  wire signed_b = REG_INPUTB_CLK == "NONE" ? SIGNEDB : signed_b_reg;
  wire signed [18:0] a_ext = {signed_a & a[17], a};
  wire signed [18:0] b_ext = {signed_b & b[17], b};
  wire signed [37:0] full = a_ext * b_ext;
  wire [35:0] product = full[35:0];
  wire [35:0] piped = REG_PIPELINE_CLK == "NONE" ? product : pipeline_reg;
  wire [35:0] p = REG_OUTPUT_CLK == "NONE" ? piped : output_reg;
  always @(posedge CLK0) begin
    if (RST0) begin
      a_reg <= 0; b_reg <= 0; signed_a_reg <= 0; signed_b_reg <= 0;
      pipeline_reg <= 0; output_reg <= 0;
    end else if (CE0) begin
      a_reg <= a_in; b_reg <= b_in; signed_a_reg <= SIGNEDA; signed_b_reg <= SIGNEDB;
      pipeline_reg <= product; output_reg <= piped;
    end
  end
  assign {P35, P34, P33, P32, P31, P30, P29, P28, P27, P26, P25, P24, P23, P22, P21, P20, P19,
          P18, P17, P16, P15, P14, P13, P12, P11, P10, P9, P8, P7, P6, P5, P4, P3, P2, P1,
          P0} = p;
  assign SIGNEDP = p[35];
endmodule
/* verilator lint_on UNUSEDPARAM */
/* verilator lint_on UNUSEDSIGNAL */
