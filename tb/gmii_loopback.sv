// gmii_loopback: a test top for the compiled TAP port (tb/test_compiled_gmii_tap.py). Its GMII
// port sends back what it receives one clock later; `spoil_er` raises TX_ER through a frame,
// `flip` inverts bit 0 of each byte after the SFD (the FCS no longer matches); `mon_*` copy
// the receive pins so that a GMII monitor sees the pump's bytes.
module gmii_loopback(aclk, spoil_er, flip, gmii_rxd, gmii_rx_dv, gmii_rx_er, gmii_txd, gmii_tx_en, gmii_tx_er, mon_rxd, mon_rx_dv, mon_rx_er);
    input        aclk;
    input        spoil_er;
    input        flip;
    input  [7:0] gmii_rxd;
    input        gmii_rx_dv;
    input        gmii_rx_er;
    output reg [7:0] gmii_txd;
    output reg       gmii_tx_en;
    output reg       gmii_tx_er;
    output [7:0] mon_rxd;
    output       mon_rx_dv;
    output       mon_rx_er;
    reg after_sfd = 1'b0;
    assign mon_rxd = gmii_rxd;
    assign mon_rx_dv = gmii_rx_dv;
    assign mon_rx_er = gmii_rx_er;
    always @(posedge aclk) begin
        after_sfd <= gmii_rx_dv && (after_sfd || gmii_rxd == 8'hd5);
        gmii_txd <= gmii_rxd ^ {7'd0, flip && after_sfd};
        gmii_tx_en <= gmii_rx_dv;
        gmii_tx_er <= gmii_rx_er || (spoil_er && gmii_rx_dv);
    end
endmodule
