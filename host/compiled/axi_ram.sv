// rosgate_axi_ram: the process memory behind a system's AXI4 master port, compiled into
// the simulator's model instead of a Python bus model waking on every clock edge.
//
// Its handshakes are cycle for cycle those of cocotbext-axi 0.1.28's AxiRam, so a system
// simulated with either takes the same cycles: each channel is the 2-deep queue AxiRam's
// sinks and sources keep (a sink's ready is "fewer than two waiting", set at an edge from the
// count before the burst process takes from it), and the burst processes run after the
// channels at every edge, reading a beat when it enters the R queue and writing a beat when
// it leaves the W queue. Addresses outside the memory answer SLVERR (reads return zero).
// A word written and read at the same edge is read as written: AXI leaves the order of the
// two channels open there, and AxiRam's depends on the order its coroutines last woke in.
// The bytes live in C++ (axi_ram.cpp), which Python reads and writes in place.
/* verilator lint_off BLKSEQ */
/* verilator lint_off UNUSEDSIGNAL */
/* verilator lint_off WIDTHEXPAND */
/* verilator lint_off WIDTHTRUNC */
/* verilator lint_off DECLFILENAME */
/* verilator lint_off MULTIDRIVEN */
module rosgate_axi_ram #(
    parameter int ADDR_W = 40,
    parameter int DATA_W = 64,
    parameter int ID_W = 1
) (
    input  logic              aclk,
    input  logic              aresetn,
    input  logic [ID_W-1:0]   awid,
    input  logic [ADDR_W-1:0] awaddr,
    input  logic [7:0]        awlen,
    input  logic [2:0]        awsize,
    input  logic [1:0]        awburst,
    input  logic              awvalid,
    output logic              awready,
    input  logic [DATA_W-1:0] wdata,
    input  logic [DATA_W/8-1:0] wstrb,
    input  logic              wlast,
    input  logic              wvalid,
    output logic              wready,
    output logic [ID_W-1:0]   bid,
    output logic [1:0]        bresp,
    output logic              bvalid,
    input  logic              bready,
    input  logic [ID_W-1:0]   arid,
    input  logic [ADDR_W-1:0] araddr,
    input  logic [7:0]        arlen,
    input  logic [2:0]        arsize,
    input  logic [1:0]        arburst,
    input  logic              arvalid,
    output logic              arready,
    output logic [ID_W-1:0]   rid,
    output logic [DATA_W-1:0] rdata,
    output logic [1:0]        rresp,
    output logic              rlast,
    output logic              rvalid,
    input  logic              rready
);
    import "DPI-C" function longint unsigned rosgate_axi_ram_read(
        input longint unsigned addr, input int unsigned nbytes);
    import "DPI-C" function void rosgate_axi_ram_write(
        input longint unsigned addr, input longint unsigned data, input int unsigned strb,
        input int unsigned nbytes);
    import "DPI-C" function bit rosgate_axi_ram_present(
        input longint unsigned addr, input int unsigned nbytes);

    localparam int LANES = DATA_W / 8;
    localparam int CHUNKS = (LANES + 7) / 8;
    localparam logic [1:0] FIXED = 2'd0, WRAP = 2'd2, OKAY = 2'd0, SLVERR = 2'd2;

    // an AR or AW request as its channel queue keeps it
    typedef struct packed {
        logic [ID_W-1:0] id;
        logic [63:0] addr;
        logic [7:0] len;
        logic [2:0] size;
        logic [1:0] burst;
    } request_t;

    // a burst's address sequence, as AxiSlaveRead/AxiSlaveWrite step it
    typedef struct packed {
        logic [ID_W-1:0] id;
        logic [63:0] addr;
        logic [8:0] left;
        logic [7:0] step;
        logic [1:0] burst;
        logic [63:0] lower, upper;
    } burst_t;

    function automatic burst_t start_burst(input request_t q, input string channel);
        burst_t b;
        logic [63:0] bytes, total, addr;
        addr = q.addr;
        bytes = 64'd1 << q.size;
        total = bytes * (q.len + 1);
        if (bytes > LANES)
            $fatal(1, "rosgate_axi_ram: %s size %0d is wider than the %0d-bit bus", channel,
                   q.size, DATA_W);
        if (q.burst != FIXED && q.burst != WRAP && 64'h1000 - ((addr & ~(bytes - 1)) & 64'hfff) < total)
            $fatal(1, "rosgate_axi_ram: %s burst at 0x%0h of %0d bytes crosses a 4 KiB boundary",
                   channel, addr, total);
        b.id = q.id;
        b.addr = addr & ~(bytes - 1);
        b.left = q.len + 1;
        b.step = bytes[7:0];
        b.burst = q.burst;
        b.lower = addr / total * total;
        b.upper = addr / total * total + total;
        return b;
    endfunction

    function automatic burst_t next_beat(input burst_t b);
        burst_t n = b;
        n.left = b.left - 1;
        if (b.burst != FIXED) begin
            n.addr = b.addr + b.step;
            if (b.burst == WRAP && n.addr == b.upper) n.addr = b.lower;
        end
        return n;
    endfunction

    function automatic logic [DATA_W-1:0] read_word(input logic [63:0] addr);
        logic [CHUNKS*64-1:0] wide = '0;
        for (int c = 0; c < CHUNKS; c++)
            wide[c*64 +: 64] = rosgate_axi_ram_read(addr + 8 * c, LANES - 8 * c < 8 ? LANES - 8 * c : 8);
        return wide[DATA_W-1:0];
    endfunction

    function automatic void write_word(input logic [63:0] addr, input logic [DATA_W-1:0] data,
                                       input logic [LANES-1:0] strb);
        logic [CHUNKS*64-1:0] wide = '0;
        logic [CHUNKS*8-1:0] lanes = '0;
        wide[DATA_W-1:0] = data;
        lanes[LANES-1:0] = strb;
        for (int c = 0; c < CHUNKS; c++)
            if (lanes[c*8 +: 8] != 0)
                rosgate_axi_ram_write(addr + 8 * c, wide[c*64 +: 64], lanes[c*8 +: 8],
                                      LANES - 8 * c < 8 ? LANES - 8 * c : 8);
    endfunction

    // the channel queues (entries, head, count): state of this block only
    request_t arq[2], awq[2];
    logic [ID_W-1:0] rq_id[2], bq_id[2];
    logic [1:0] rq_resp[2], bq_resp[2];
    logic [DATA_W-1:0] rq_data[2], wq_data[2];
    logic [LANES-1:0] wq_strb[2];
    logic rq_last[2], wq_last[2];
    logic arq_head, awq_head, rq_head, bq_head, wq_head;
    logic [1:0] arq_n, awq_n, rq_n, bq_n, wq_n;
    // the burst processes
    burst_t rb, wb;
    logic r_busy, w_busy, w_respond;
    logic [1:0] w_resp;

    always @(posedge aclk) begin
        if (!aresetn) begin
            arready <= 1'b0; awready <= 1'b0; wready <= 1'b0;
            rvalid <= 1'b0; bvalid <= 1'b0;
            arq_n = 0; awq_n = 0; wq_n = 0; rq_n = 0; bq_n = 0;
            arq_head = 0; awq_head = 0; wq_head = 0; rq_head = 0; bq_head = 0;
            r_busy = 0; w_busy = 0; w_respond = 0; w_resp = OKAY;
        end else begin
            // the channels at the edge: sinks take what their ready and valid agreed on, and
            // say ready while fewer than two wait; sources drive their next entry
            if (arready && arvalid) begin
                arq[arq_head ^ arq_n[0]] = '{arid, 64'(araddr), arlen, arsize, arburst};
                arq_n = arq_n + 1;
            end
            arready <= arq_n < 2;
            if (awready && awvalid) begin
                awq[awq_head ^ awq_n[0]] = '{awid, 64'(awaddr), awlen, awsize, awburst};
                awq_n = awq_n + 1;
            end
            awready <= awq_n < 2;
            if (wready && wvalid) begin
                wq_data[wq_head ^ wq_n[0]] = wdata; wq_strb[wq_head ^ wq_n[0]] = wstrb;
                wq_last[wq_head ^ wq_n[0]] = wlast;
                wq_n = wq_n + 1;
            end
            wready <= wq_n < 2;
            if (!rvalid || rready) begin
                if (rq_n != 0) begin
                    rid <= rq_id[rq_head]; rdata <= rq_data[rq_head];
                    rresp <= rq_resp[rq_head]; rlast <= rq_last[rq_head];
                    rvalid <= 1'b1;
                    rq_head = !rq_head; rq_n = rq_n - 1;
                end else
                    rvalid <= 1'b0;
            end
            if (!bvalid || bready) begin
                if (bq_n != 0) begin
                    bid <= bq_id[bq_head]; bresp <= bq_resp[bq_head];
                    bvalid <= 1'b1;
                    bq_head = !bq_head; bq_n = bq_n - 1;
                end else
                    bvalid <= 1'b0;
            end
            // the write process: an AW, its W beats into memory, then its B
            for (int i = 0; i < 8; i++) begin
                if (!w_busy && !w_respond) begin
                    if (awq_n == 0) break;
                    wb = start_burst(awq[awq_head], "write");
                    awq_head = !awq_head; awq_n = awq_n - 1;
                    w_busy = 1; w_resp = OKAY;
                end
                if (w_busy) begin
                    logic [63:0] word;
                    if (wq_n == 0) break;
                    word = wb.addr & ~64'(LANES - 1);
                    if (wq_strb[wq_head] != 0) begin
                        if (rosgate_axi_ram_present(word, LANES))
                            write_word(word, wq_data[wq_head], wq_strb[wq_head]);
                        else
                            w_resp = SLVERR;
                    end
                    if (wq_last[wq_head] != (wb.left == 1))
                        $fatal(1, "rosgate_axi_ram: wlast %0d on beat %0d of a write burst",
                               wq_last[wq_head], wb.left);
                    wq_head = !wq_head; wq_n = wq_n - 1;
                    wb = next_beat(wb);
                    if (wb.left == 0) begin w_busy = 0; w_respond = 1; end
                    continue;
                end
                if (w_respond) begin
                    if (bq_n == 2) break;
                    bq_id[bq_head ^ bq_n[0]] = wb.id; bq_resp[bq_head ^ bq_n[0]] = w_resp;
                    bq_n = bq_n + 1;
                    w_respond = 0;
                end
            end
            // the read process: an AR, then its beats into the R queue as it has room
            for (int i = 0; i < 6; i++) begin
                logic [63:0] word;
                if (!r_busy) begin
                    if (arq_n == 0) break;
                    rb = start_burst(arq[arq_head], "read");
                    arq_head = !arq_head; arq_n = arq_n - 1;
                    r_busy = 1;
                end
                if (rq_n == 2) break;
                word = rb.addr & ~64'(LANES - 1);
                rq_id[rq_head ^ rq_n[0]] = rb.id;
                rq_last[rq_head ^ rq_n[0]] = rb.left == 1;
                if (rosgate_axi_ram_present(word, LANES)) begin
                    rq_data[rq_head ^ rq_n[0]] = read_word(word);
                    rq_resp[rq_head ^ rq_n[0]] = OKAY;
                end else begin
                    rq_data[rq_head ^ rq_n[0]] = '0;
                    rq_resp[rq_head ^ rq_n[0]] = SLVERR;
                end
                rq_n = rq_n + 1;
                rb = next_beat(rb);
                if (rb.left == 0) r_busy = 0;
            end
        end
    end
endmodule
