// rosgate_gmii_tap: a design's GMII port on a TAP device, compiled into the simulator's model
// instead of cocotbext-eth's GmiiSource and GmiiSink, which wake Python on every byte.
//
// Receive side (to the design): at each rising edge of rx_clk the C++ side (gmii_tap.cpp)
// gives the next byte of the frame it is sending (preamble, SFD, the kernel's frame padded to
// 60 bytes, FCS), then 12 idle cycles; between frames it reads the TAP device every
// POLL_CYCLES cycles. Like GmiiSource, the values change after the edge and the design takes
// them at the next. Transmit side (from the design): at each rising edge of tx_clk the byte,
// TX_EN and TX_ER the design drives; at the end of a frame its FCS is checked and the frame
// without preamble and FCS written to the TAP device (a frame with a bad FCS or TX_ER is
// counted and dropped).
/* verilator lint_off UNUSEDSIGNAL */
/* verilator lint_off DECLFILENAME */
/* verilator lint_off BLKSEQ */
/* verilator lint_off MULTIDRIVEN */
module rosgate_gmii_tap #(
    parameter int PORT = 0
) (
    input  logic       rx_clk,
    output logic [7:0] rxd,
    output logic       rx_dv,
    output logic       rx_er,
    input  logic       tx_clk,
    input  logic [7:0] txd,
    input  logic       tx_en,
    input  logic       tx_er
);
    import "DPI-C" function int rosgate_gmii_tap_rx(input int port);
    import "DPI-C" function void rosgate_gmii_tap_tx(input int port, input int data,
                                                      input int en, input int er);
    int rx_next;
    initial begin
        rxd = 8'd0;
        rx_dv = 1'b0;
        rx_er = 1'b0;
    end
    always @(posedge rx_clk) begin
        rx_next = rosgate_gmii_tap_rx(PORT);
        rxd <= rx_next[7:0];
        rx_dv <= rx_next[8];
        rx_er <= 1'b0;
    end
    always @(posedge tx_clk)
        rosgate_gmii_tap_tx(PORT, {24'd0, txd}, {31'd0, tx_en}, {31'd0, tx_er});
endmodule
