// axi_traffic_master: random AXI4 traffic for comparing two memory slaves cycle by cycle
// (tb/test_compiled_axi_ram.py). Bursts are a pure function of (seed, burst number): INCR,
// FIXED and WRAP, 1 to 16 beats, full-width and narrow, some at addresses past the memory.
// W beats may run ahead of their AW; every valid idles and every ready backpressures at
// random. Every handshake, with its cycle and payload, is folded into ``signature``.
// Writes go to pages 0-3 and reads to pages 4-7: AXI leaves the order of a read and a write
// of one word in the same cycle open, and AxiRam's follows its coroutines' order.
module axi_traffic_master(aclk, aresetn, seed, bursts, done, signature, cycles, errors, m_axi_mem_awid, m_axi_mem_awaddr, m_axi_mem_awlen, m_axi_mem_awsize, m_axi_mem_awburst, m_axi_mem_awvalid, m_axi_mem_awready, m_axi_mem_wdata, m_axi_mem_wstrb, m_axi_mem_wlast, m_axi_mem_wvalid, m_axi_mem_wready, m_axi_mem_bid, m_axi_mem_bresp, m_axi_mem_bvalid, m_axi_mem_bready, m_axi_mem_arid, m_axi_mem_araddr, m_axi_mem_arlen, m_axi_mem_arsize, m_axi_mem_arburst, m_axi_mem_arvalid, m_axi_mem_arready, m_axi_mem_rid, m_axi_mem_rdata, m_axi_mem_rresp, m_axi_mem_rlast, m_axi_mem_rvalid, m_axi_mem_rready);
    // ports with numeric widths, as Yosys writes them: host.compiled reads them
    localparam int DATA_W = 64;
    localparam int OUTSIDE = 32'h0010_0000;
    input logic aclk;
    input logic aresetn;
    input logic [31:0] seed;
    input logic [15:0] bursts;
    output logic done;
    output logic [63:0] signature;
    output logic [31:0] cycles;
    output logic [31:0] errors;
    output logic m_axi_mem_awid;
    output logic [39:0] m_axi_mem_awaddr;
    output logic [7:0] m_axi_mem_awlen;
    output logic [2:0] m_axi_mem_awsize;
    output logic [1:0] m_axi_mem_awburst;
    output logic m_axi_mem_awvalid;
    input logic m_axi_mem_awready;
    output logic [63:0] m_axi_mem_wdata;
    output logic [7:0] m_axi_mem_wstrb;
    output logic m_axi_mem_wlast;
    output logic m_axi_mem_wvalid;
    input logic m_axi_mem_wready;
    input logic m_axi_mem_bid;
    input logic [1:0] m_axi_mem_bresp;
    input logic m_axi_mem_bvalid;
    output logic m_axi_mem_bready;
    output logic m_axi_mem_arid;
    output logic [39:0] m_axi_mem_araddr;
    output logic [7:0] m_axi_mem_arlen;
    output logic [2:0] m_axi_mem_arsize;
    output logic [1:0] m_axi_mem_arburst;
    output logic m_axi_mem_arvalid;
    input logic m_axi_mem_arready;
    input logic m_axi_mem_rid;
    input logic [63:0] m_axi_mem_rdata;
    input logic [1:0] m_axi_mem_rresp;
    input logic m_axi_mem_rlast;
    input logic m_axi_mem_rvalid;
    output logic m_axi_mem_rready;
    localparam int LANES = DATA_W / 8;
    localparam int MAXSIZE = $clog2(LANES);

    function automatic logic [63:0] mix(input logic [63:0] x);
        x = (x ^ (x >> 30)) * 64'hbf58476d1ce4e5b9;
        x = (x ^ (x >> 27)) * 64'h94d049bb133111eb;
        return x ^ (x >> 31);
    endfunction

    typedef struct packed {
        logic id;
        logic [39:0] addr;
        logic [7:0] len;
        logic [2:0] size;
        logic [1:0] burst;
    } burst_t;

    // burst ``k`` of stream ``which`` (0: writes, 1: reads)
    function automatic burst_t plan(input logic [31:0] s, input logic [15:0] k, input logic which);
        burst_t b;
        logic [63:0] h = mix({s, 15'd0, which, k});
        logic [15:0] bytes, room, offset;
        b.id = h[0];
        b.len = {4'd0, h[4:1]};
        b.size = h[6:5] == 0 ? 3'(h[8:7] % (MAXSIZE + 1)) : 3'(MAXSIZE);
        b.burst = h[10:9] == 0 ? 2'd0 : 2'd1;
        if (h[12:11] == 0 && (b.len == 1 || b.len == 3 || b.len == 7 || b.len == 15))
            b.burst = 2'd2;
        bytes = 16'(b.len + 1) << b.size;
        room = 16'd4096 - bytes;
        offset = 16'(h[34:20] % (32'(room) + 1));
        b.addr = 40'({which, h[38:37]}) * 40'h1000 + 40'(offset) +
                 (h[44:41] == 0 ? 40'(OUTSIDE) : 40'd0);
        if (b.burst == 2'd2) b.addr = b.addr & ~40'((1 << b.size) - 1);
        return b;
    endfunction

    logic [63:0] rnd;
    logic [15:0] aw_k, w_k, ar_k, b_n, r_n;
    logic [8:0] w_beat;
    burst_t aw_b, w_b, ar_b;
    logic [31:0] s;

    always_comb begin
        aw_b = plan(s, aw_k, 1'b0);
        w_b = plan(s, w_k, 1'b0);
        ar_b = plan(s, ar_k, 1'b1);
    end

    assign done = b_n == bursts && r_n == bursts;

    always_ff @(posedge aclk) begin
        if (!aresetn) begin
            s <= seed;
            rnd <= mix({32'd0, seed}) | 64'd1;
            aw_k <= 0; w_k <= 0; ar_k <= 0; b_n <= 0; r_n <= 0; w_beat <= 0;
            m_axi_mem_awvalid <= 0; m_axi_mem_wvalid <= 0; m_axi_mem_arvalid <= 0;
            m_axi_mem_bready <= 0; m_axi_mem_rready <= 0;
            signature <= 0; cycles <= 0; errors <= 0;
        end else begin
            logic [63:0] r, sig;
            sig = signature;
            r = rnd ^ (rnd << 13);
            r = r ^ (r >> 7);
            r = r ^ (r << 17);
            rnd <= r;
            cycles <= cycles + 1;
            // handshakes at this edge, into the signature
            if (m_axi_mem_awvalid && m_axi_mem_awready) begin
                sig = mix(sig ^ {cycles, 32'h1});
                aw_k <= aw_k + 1;
            end
            if (m_axi_mem_wvalid && m_axi_mem_wready) begin
                sig = mix(sig ^ {cycles, 32'h2});
                if (m_axi_mem_wlast) begin w_k <= w_k + 1; w_beat <= 0; end
                else w_beat <= w_beat + 1;
            end
            if (m_axi_mem_arvalid && m_axi_mem_arready) begin
                sig = mix(sig ^ {cycles, 32'h3});
                ar_k <= ar_k + 1;
            end
            if (m_axi_mem_bvalid && m_axi_mem_bready) begin
                sig = mix(sig ^ {cycles, 28'h4, 1'b0, m_axi_mem_bid, m_axi_mem_bresp});
                b_n <= b_n + 1;
                if (m_axi_mem_bresp != 0) errors <= errors + 1;
            end
            if (m_axi_mem_rvalid && m_axi_mem_rready) begin
                sig = mix(sig ^ {cycles, 27'h5, m_axi_mem_rlast, m_axi_mem_rid,
                                              m_axi_mem_rresp} ^ 64'(m_axi_mem_rdata));
                if (m_axi_mem_rlast) r_n <= r_n + 1;
                if (m_axi_mem_rresp != 0) errors <= errors + 1;
            end
            signature <= sig;
            // next valids (held until taken) and readies, at random
            if (!m_axi_mem_awvalid || m_axi_mem_awready) begin
                automatic logic [15:0] k = m_axi_mem_awvalid ? aw_k + 1 : aw_k;
                automatic burst_t b = plan(s, k, 1'b0);
                m_axi_mem_awvalid <= k < bursts && r[2:0] != 0;
                {m_axi_mem_awid, m_axi_mem_awaddr, m_axi_mem_awlen, m_axi_mem_awsize,
                 m_axi_mem_awburst} <= b;
            end
            if (!m_axi_mem_wvalid || m_axi_mem_wready) begin
                automatic logic last_taken = m_axi_mem_wvalid && m_axi_mem_wlast;
                automatic logic [15:0] k = last_taken ? w_k + 1 : w_k;
                automatic logic [8:0] beat = !m_axi_mem_wvalid ? w_beat : last_taken ? 0 : w_beat + 1;
                automatic burst_t b = plan(s, k, 1'b0);
                m_axi_mem_wvalid <= k < bursts && r[5:3] != 0;
                m_axi_mem_wdata <= DATA_W'(mix(r ^ 64'(beat)));
                m_axi_mem_wstrb <= r[9:6] == 0 ? '0 : r[11:10] == 0 ? LANES'(r >> 20) : '1;
                m_axi_mem_wlast <= beat == 9'(b.len);
            end
            if (!m_axi_mem_arvalid || m_axi_mem_arready) begin
                automatic logic [15:0] k = m_axi_mem_arvalid ? ar_k + 1 : ar_k;
                automatic burst_t b = plan(s, k, 1'b1);
                m_axi_mem_arvalid <= k < bursts && r[14:12] != 0;
                {m_axi_mem_arid, m_axi_mem_araddr, m_axi_mem_arlen, m_axi_mem_arsize,
                 m_axi_mem_arburst} <= b;
            end
            m_axi_mem_bready <= r[17:15] != 0;
            m_axi_mem_rready <= r[19:18] != 0;
        end
    end
endmodule
