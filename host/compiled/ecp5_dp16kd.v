// A cycle-level model of the ECP5 DP16KD block RAM for simulating Yosys netlists (Yosys'
// own cells_sim.v declares it as a black box), written from Lattice's memory usage guide
// (FPGA-TN-02204): 18 Kbit, data widths 1, 2, 4 (16 Kbit, no parity bits), 9 and 18 per
// port; an x18 port's ADx1:ADx0 are its byte-write enables and its word j holds the x9 words
// 2j (bits 8:0) and 2j+1 (bits 17:9); outputs after the clock edge (NOREG) or one edge later
// (OUTREG); NORMAL, WRITETHROUGH and READBEFOREWRITE writes; the chip selects decode 0b000.
// What the model does not support (initial contents, another CSDECODE) stops the simulation
// with a message rather than simulating something else.
module DP16KD #(
  parameter DATA_WIDTH_A = 18, DATA_WIDTH_B = 18,
  parameter REGMODE_A = "NOREG", REGMODE_B = "NOREG",
  parameter RESETMODE = "SYNC", ASYNC_RESET_RELEASE = "SYNC",
  parameter CSDECODE_A = "0b000", CSDECODE_B = "0b000",
  parameter WRITEMODE_A = "NORMAL", WRITEMODE_B = "NORMAL",
  parameter GSR = "ENABLED", WID = 0, INIT_DATA = "STATIC",
  parameter DIA17MUX = "DIA17",
  parameter DIA16MUX = "DIA16",
  parameter DIA15MUX = "DIA15",
  parameter DIA14MUX = "DIA14",
  parameter DIA13MUX = "DIA13",
  parameter DIA12MUX = "DIA12",
  parameter DIA11MUX = "DIA11",
  parameter DIA10MUX = "DIA10",
  parameter DIA9MUX = "DIA9",
  parameter DIA8MUX = "DIA8",
  parameter DIA7MUX = "DIA7",
  parameter DIA6MUX = "DIA6",
  parameter DIA5MUX = "DIA5",
  parameter DIA4MUX = "DIA4",
  parameter DIA3MUX = "DIA3",
  parameter DIA2MUX = "DIA2",
  parameter DIA1MUX = "DIA1",
  parameter DIA0MUX = "DIA0",
  parameter ADA13MUX = "ADA13",
  parameter ADA12MUX = "ADA12",
  parameter ADA11MUX = "ADA11",
  parameter ADA10MUX = "ADA10",
  parameter ADA9MUX = "ADA9",
  parameter ADA8MUX = "ADA8",
  parameter ADA7MUX = "ADA7",
  parameter ADA6MUX = "ADA6",
  parameter ADA5MUX = "ADA5",
  parameter ADA4MUX = "ADA4",
  parameter ADA3MUX = "ADA3",
  parameter ADA2MUX = "ADA2",
  parameter ADA1MUX = "ADA1",
  parameter ADA0MUX = "ADA0",
  parameter CEAMUX = "CEA",
  parameter OCEAMUX = "OCEA",
  parameter CLKAMUX = "CLKA",
  parameter WEAMUX = "WEA",
  parameter RSTAMUX = "RSTA",
  parameter CSA2MUX = "CSA2",
  parameter CSA1MUX = "CSA1",
  parameter CSA0MUX = "CSA0",
  parameter DOA17MUX = "DOA17",
  parameter DOA16MUX = "DOA16",
  parameter DOA15MUX = "DOA15",
  parameter DOA14MUX = "DOA14",
  parameter DOA13MUX = "DOA13",
  parameter DOA12MUX = "DOA12",
  parameter DOA11MUX = "DOA11",
  parameter DOA10MUX = "DOA10",
  parameter DOA9MUX = "DOA9",
  parameter DOA8MUX = "DOA8",
  parameter DOA7MUX = "DOA7",
  parameter DOA6MUX = "DOA6",
  parameter DOA5MUX = "DOA5",
  parameter DOA4MUX = "DOA4",
  parameter DOA3MUX = "DOA3",
  parameter DOA2MUX = "DOA2",
  parameter DOA1MUX = "DOA1",
  parameter DOA0MUX = "DOA0",
  parameter DIB17MUX = "DIB17",
  parameter DIB16MUX = "DIB16",
  parameter DIB15MUX = "DIB15",
  parameter DIB14MUX = "DIB14",
  parameter DIB13MUX = "DIB13",
  parameter DIB12MUX = "DIB12",
  parameter DIB11MUX = "DIB11",
  parameter DIB10MUX = "DIB10",
  parameter DIB9MUX = "DIB9",
  parameter DIB8MUX = "DIB8",
  parameter DIB7MUX = "DIB7",
  parameter DIB6MUX = "DIB6",
  parameter DIB5MUX = "DIB5",
  parameter DIB4MUX = "DIB4",
  parameter DIB3MUX = "DIB3",
  parameter DIB2MUX = "DIB2",
  parameter DIB1MUX = "DIB1",
  parameter DIB0MUX = "DIB0",
  parameter ADB13MUX = "ADB13",
  parameter ADB12MUX = "ADB12",
  parameter ADB11MUX = "ADB11",
  parameter ADB10MUX = "ADB10",
  parameter ADB9MUX = "ADB9",
  parameter ADB8MUX = "ADB8",
  parameter ADB7MUX = "ADB7",
  parameter ADB6MUX = "ADB6",
  parameter ADB5MUX = "ADB5",
  parameter ADB4MUX = "ADB4",
  parameter ADB3MUX = "ADB3",
  parameter ADB2MUX = "ADB2",
  parameter ADB1MUX = "ADB1",
  parameter ADB0MUX = "ADB0",
  parameter CEBMUX = "CEB",
  parameter OCEBMUX = "OCEB",
  parameter CLKBMUX = "CLKB",
  parameter WEBMUX = "WEB",
  parameter RSTBMUX = "RSTB",
  parameter CSB2MUX = "CSB2",
  parameter CSB1MUX = "CSB1",
  parameter CSB0MUX = "CSB0",
  parameter DOB17MUX = "DOB17",
  parameter DOB16MUX = "DOB16",
  parameter DOB15MUX = "DOB15",
  parameter DOB14MUX = "DOB14",
  parameter DOB13MUX = "DOB13",
  parameter DOB12MUX = "DOB12",
  parameter DOB11MUX = "DOB11",
  parameter DOB10MUX = "DOB10",
  parameter DOB9MUX = "DOB9",
  parameter DOB8MUX = "DOB8",
  parameter DOB7MUX = "DOB7",
  parameter DOB6MUX = "DOB6",
  parameter DOB5MUX = "DOB5",
  parameter DOB4MUX = "DOB4",
  parameter DOB3MUX = "DOB3",
  parameter DOB2MUX = "DOB2",
  parameter DOB1MUX = "DOB1",
  parameter DOB0MUX = "DOB0",
  parameter INITVAL_00 = 320'h0,
  parameter INITVAL_01 = 320'h0,
  parameter INITVAL_02 = 320'h0,
  parameter INITVAL_03 = 320'h0,
  parameter INITVAL_04 = 320'h0,
  parameter INITVAL_05 = 320'h0,
  parameter INITVAL_06 = 320'h0,
  parameter INITVAL_07 = 320'h0,
  parameter INITVAL_08 = 320'h0,
  parameter INITVAL_09 = 320'h0,
  parameter INITVAL_0A = 320'h0,
  parameter INITVAL_0B = 320'h0,
  parameter INITVAL_0C = 320'h0,
  parameter INITVAL_0D = 320'h0,
  parameter INITVAL_0E = 320'h0,
  parameter INITVAL_0F = 320'h0,
  parameter INITVAL_10 = 320'h0,
  parameter INITVAL_11 = 320'h0,
  parameter INITVAL_12 = 320'h0,
  parameter INITVAL_13 = 320'h0,
  parameter INITVAL_14 = 320'h0,
  parameter INITVAL_15 = 320'h0,
  parameter INITVAL_16 = 320'h0,
  parameter INITVAL_17 = 320'h0,
  parameter INITVAL_18 = 320'h0,
  parameter INITVAL_19 = 320'h0,
  parameter INITVAL_1A = 320'h0,
  parameter INITVAL_1B = 320'h0,
  parameter INITVAL_1C = 320'h0,
  parameter INITVAL_1D = 320'h0,
  parameter INITVAL_1E = 320'h0,
  parameter INITVAL_1F = 320'h0,
  parameter INITVAL_20 = 320'h0,
  parameter INITVAL_21 = 320'h0,
  parameter INITVAL_22 = 320'h0,
  parameter INITVAL_23 = 320'h0,
  parameter INITVAL_24 = 320'h0,
  parameter INITVAL_25 = 320'h0,
  parameter INITVAL_26 = 320'h0,
  parameter INITVAL_27 = 320'h0,
  parameter INITVAL_28 = 320'h0,
  parameter INITVAL_29 = 320'h0,
  parameter INITVAL_2A = 320'h0,
  parameter INITVAL_2B = 320'h0,
  parameter INITVAL_2C = 320'h0,
  parameter INITVAL_2D = 320'h0,
  parameter INITVAL_2E = 320'h0,
  parameter INITVAL_2F = 320'h0,
  parameter INITVAL_30 = 320'h0,
  parameter INITVAL_31 = 320'h0,
  parameter INITVAL_32 = 320'h0,
  parameter INITVAL_33 = 320'h0,
  parameter INITVAL_34 = 320'h0,
  parameter INITVAL_35 = 320'h0,
  parameter INITVAL_36 = 320'h0,
  parameter INITVAL_37 = 320'h0,
  parameter INITVAL_38 = 320'h0,
  parameter INITVAL_39 = 320'h0,
  parameter INITVAL_3A = 320'h0,
  parameter INITVAL_3B = 320'h0,
  parameter INITVAL_3C = 320'h0,
  parameter INITVAL_3D = 320'h0,
  parameter INITVAL_3E = 320'h0,
  parameter INITVAL_3F = 320'h0
) (
  input DIA17, DIA16, DIA15, DIA14, DIA13, DIA12, DIA11, DIA10, DIA9, DIA8, DIA7, DIA6, DIA5, DIA4, DIA3, DIA2, DIA1, DIA0,
  input ADA13, ADA12, ADA11, ADA10, ADA9, ADA8, ADA7, ADA6, ADA5, ADA4, ADA3, ADA2, ADA1, ADA0,
  input CEA, OCEA, CLKA, WEA, RSTA, CSA2, CSA1, CSA0,
  output DOA17, DOA16, DOA15, DOA14, DOA13, DOA12, DOA11, DOA10, DOA9, DOA8, DOA7, DOA6, DOA5, DOA4, DOA3, DOA2, DOA1, DOA0,
  input DIB17, DIB16, DIB15, DIB14, DIB13, DIB12, DIB11, DIB10, DIB9, DIB8, DIB7, DIB6, DIB5, DIB4, DIB3, DIB2, DIB1, DIB0,
  input ADB13, ADB12, ADB11, ADB10, ADB9, ADB8, ADB7, ADB6, ADB5, ADB4, ADB3, ADB2, ADB1, ADB0,
  input CEB, OCEB, CLKB, WEB, RSTB, CSB2, CSB1, CSB0,
  output DOB17, DOB16, DOB15, DOB14, DOB13, DOB12, DOB11, DOB10, DOB9, DOB8, DOB7, DOB6, DOB5, DOB4, DOB3, DOB2, DOB1, DOB0
);
  reg [8:0] units [0:2047];        // the x9 and x18 view
  reg bits [0:16383];              // the x1, x2 and x4 view
  reg [17:0] doa, dob, doa_reg, dob_reg;
  integer i;
  initial begin
    for (i = 0; i < 2048; i = i + 1) units[i] = 9'd0;
    for (i = 0; i < 16384; i = i + 1) bits[i] = 1'b0;
    doa = 0; dob = 0; doa_reg = 0; dob_reg = 0;
    if ((INITVAL_00 | INITVAL_01 | INITVAL_02 | INITVAL_03 | INITVAL_04 | INITVAL_05 | INITVAL_06 | INITVAL_07 | INITVAL_08 | INITVAL_09 | INITVAL_0A | INITVAL_0B | INITVAL_0C | INITVAL_0D | INITVAL_0E | INITVAL_0F | INITVAL_10 | INITVAL_11 | INITVAL_12 | INITVAL_13 | INITVAL_14 | INITVAL_15 | INITVAL_16 | INITVAL_17 | INITVAL_18 | INITVAL_19 | INITVAL_1A | INITVAL_1B | INITVAL_1C | INITVAL_1D | INITVAL_1E | INITVAL_1F | INITVAL_20 | INITVAL_21 | INITVAL_22 | INITVAL_23 | INITVAL_24 | INITVAL_25 | INITVAL_26 | INITVAL_27 | INITVAL_28 | INITVAL_29 | INITVAL_2A | INITVAL_2B | INITVAL_2C | INITVAL_2D | INITVAL_2E | INITVAL_2F | INITVAL_30 | INITVAL_31 | INITVAL_32 | INITVAL_33 | INITVAL_34 | INITVAL_35 | INITVAL_36 | INITVAL_37 | INITVAL_38 | INITVAL_39 | INITVAL_3A | INITVAL_3B | INITVAL_3C | INITVAL_3D | INITVAL_3E | INITVAL_3F) != 320'h0) begin
      $display("DP16KD model: initial contents (INITVAL_xx) are not modelled");
      $finish;
    end
    if (CSDECODE_A != "0b000" || CSDECODE_B != "0b000") begin
      $display("DP16KD model: CSDECODE other than 0b000 is not modelled");
      $finish;
    end
  end
  wire [17:0] dia = {DIA17, DIA16, DIA15, DIA14, DIA13, DIA12, DIA11, DIA10, DIA9, DIA8, DIA7, DIA6, DIA5, DIA4, DIA3, DIA2, DIA1, DIA0};
  wire [13:0] ada = {ADA13, ADA12, ADA11, ADA10, ADA9, ADA8, ADA7, ADA6, ADA5, ADA4, ADA3, ADA2, ADA1, ADA0};
  wire [17:0] dib = {DIB17, DIB16, DIB15, DIB14, DIB13, DIB12, DIB11, DIB10, DIB9, DIB8, DIB7, DIB6, DIB5, DIB4, DIB3, DIB2, DIB1, DIB0};
  wire [13:0] adb = {ADB13, ADB12, ADB11, ADB10, ADB9, ADB8, ADB7, ADB6, ADB5, ADB4, ADB3, ADB2, ADB1, ADB0};
  wire csa = {CSA2, CSA1, CSA0} == 3'b000;
  wire csb = {CSB2, CSB1, CSB0} == 3'b000;

  task automatic access(input integer width, input [13:0] ad, input [17:0] di, input we,
                        input integer mode, output [17:0] old);
    integer k, base;
    begin
      old = 18'd0;
      if (width == 18) begin
        old = {units[{ad[13:4], 1'b1}], units[{ad[13:4], 1'b0}]};
        if (we && ad[0]) units[{ad[13:4], 1'b0}] = di[8:0];
        if (we && ad[1]) units[{ad[13:4], 1'b1}] = di[17:9];
      end else if (width == 9) begin
        old[8:0] = units[ad[13:3]];
        if (we) units[ad[13:3]] = di[8:0];
      end else begin
        base = (width == 4) ? {ad[13:2], 2'b00} : (width == 2) ? {ad[13:1], 1'b0} : ad;
        for (k = 0; k < width; k = k + 1) begin
          old[k] = bits[base + k];
          if (we) bits[base + k] = di[k];
        end
      end
      // 0: NORMAL keeps the output, 1: WRITETHROUGH shows the new data
      if (we && mode == 1) old = di;
    end
  endtask

  localparam MODE_A = WRITEMODE_A == "WRITETHROUGH" ? 1 : WRITEMODE_A == "NORMAL" ? 0 : 2;
  localparam MODE_B = WRITEMODE_B == "WRITETHROUGH" ? 1 : WRITEMODE_B == "NORMAL" ? 0 : 2;
  reg [17:0] got_a, got_b;
  always @(posedge CLKA) begin
    if (RSTA) doa <= 18'd0;
    else if (CEA && csa) begin
      access(DATA_WIDTH_A, ada, dia, WEA, MODE_A, got_a);
      if (!(WEA && MODE_A == 0)) doa <= got_a;
    end
    if (OCEA) doa_reg <= doa;
  end
  always @(posedge CLKB) begin
    if (RSTB) dob <= 18'd0;
    else if (CEB && csb) begin
      access(DATA_WIDTH_B, adb, dib, WEB, MODE_B, got_b);
      if (!(WEB && MODE_B == 0)) dob <= got_b;
    end
    if (OCEB) dob_reg <= dob;
  end
  assign {DOA17, DOA16, DOA15, DOA14, DOA13, DOA12, DOA11, DOA10, DOA9, DOA8, DOA7, DOA6, DOA5, DOA4, DOA3, DOA2, DOA1, DOA0} = REGMODE_A == "OUTREG" ? doa_reg : doa;
  assign {DOB17, DOB16, DOB15, DOB14, DOB13, DOB12, DOB11, DOB10, DOB9, DOB8, DOB7, DOB6, DOB5, DOB4, DOB3, DOB2, DOB1, DOB0} = REGMODE_B == "OUTREG" ? dob_reg : dob;
endmodule
