// rosgate_axis_source and rosgate_axis_sink: a design's AXI4-Stream ports fed and drained by
// packet FIFOs compiled into the simulator, instead of cocotbext-axi's AxiStreamSource and
// AxiStreamSink, which wake Python at every clock edge a packet is on its way.
//
// Python puts whole packets into a source's FIFO and takes whole packets out of a sink's
// (axis_stream.cpp, in place through ctypes: host/compiled/streams.py); the beats move here.
// Both take their handshake at the rising edge of aclk and drive their outputs after it, as
// cocotbext-axi's do: a source takes its next packet at the edge after its last beat was taken
// and presents its first beat after that edge; a sink's tready for the next cycle is set at
// each edge. Idle cycles (source) and backpressure (sink) come from a pause drawn at every edge
// in C++: none, always (``pause``), or random runs with a seed. While aresetn is low a source
// drops the packet it was sending and drives tvalid low, and a sink takes no beat and drops
// the packet it was receiving. ``sent`` and ``received`` count the whole packets taken from a
// source and completed in a sink: Python waits on their changes instead of on the clock.
//
// Widths: tdata up to 1024 bits in 8-bit lanes, tkeep one bit per lane (HAS_KEEP = 0: the
// port has none, every lane counts), tuser up to 64 bits.
/* verilator lint_off UNUSEDSIGNAL */
/* verilator lint_off DECLFILENAME */
/* verilator lint_off BLKSEQ */
/* verilator lint_off WIDTHEXPAND */
/* verilator lint_off WIDTHTRUNC */
// the C++ side of both (axis_stream.cpp)
package rosgate_axis_dpi;
    import "DPI-C" function int rosgate_axis_open(input string name, input int sink,
                                                  input int data_w, input int user_w,
                                                  input int has_keep);
    import "DPI-C" function int rosgate_axis_source_step(
        input int port, input int resetn, input int valid, input int ready, input int last,
        output bit [1023:0] data, output bit [127:0] keep, output bit [63:0] user);
    import "DPI-C" function int rosgate_axis_sink_step(
        input int port, input int resetn, input int valid, input int ready, input int last,
        input bit [1023:0] data, input bit [127:0] keep, input bit [63:0] user);
endpackage

module rosgate_axis_source #(
    parameter string NAME = "",
    parameter int DATA_W = 64,
    parameter int USER_W = 1,
    parameter int HAS_KEEP = 1
) (
    input  logic                aclk,
    input  logic                aresetn,
    output logic [DATA_W-1:0]   tdata,
    output logic [DATA_W/8-1:0] tkeep,
    output logic [USER_W-1:0]   tuser,
    output logic                tlast,
    output logic                tvalid,
    input  logic                tready,
    output logic [31:0]         sent
);
    import rosgate_axis_dpi::*;

    int port;
    int step;
    bit [1023:0] data;
    bit [127:0] keep;
    bit [63:0] user;
    initial begin
        port = rosgate_axis_open(NAME, 0, DATA_W, USER_W, HAS_KEEP);
        tdata = '0;
        tkeep = '0;
        tuser = '0;
        tlast = 1'b0;
        tvalid = 1'b0;
        sent = 32'd0;
    end
    // step: bit 0 drive the outputs (else hold the beat), bit 1 tvalid, bit 2 tlast,
    // bit 3 a packet's last beat was taken at this edge
    always @(posedge aclk) begin
        step = rosgate_axis_source_step(port, {31'd0, aresetn}, {31'd0, tvalid},
                                        {31'd0, tready}, {31'd0, tlast}, data, keep, user);
        if (step[0]) begin
            tvalid <= step[1];
            tlast <= step[2];
            if (step[1] || !aresetn) begin
                tdata <= data[DATA_W-1:0];
                tkeep <= keep[DATA_W/8-1:0];
                tuser <= user[USER_W-1:0];
            end
        end
        if (step[3]) sent <= sent + 32'd1;
    end
endmodule

module rosgate_axis_sink #(
    parameter string NAME = "",
    parameter int DATA_W = 64,
    parameter int USER_W = 1,
    parameter int HAS_KEEP = 1
) (
    input  logic                aclk,
    input  logic                aresetn,
    input  logic [DATA_W-1:0]   tdata,
    input  logic [DATA_W/8-1:0] tkeep,
    input  logic [USER_W-1:0]   tuser,
    input  logic                tlast,
    input  logic                tvalid,
    output logic                tready,
    output logic [31:0]         received
);
    import rosgate_axis_dpi::*;

    int port;
    int step;
    bit [1023:0] data;
    bit [127:0] keep;
    bit [63:0] user;
    initial begin
        port = rosgate_axis_open(NAME, 1, DATA_W, USER_W, HAS_KEEP);
        tready = 1'b0;
        received = 32'd0;
        data = '0;
        keep = '0;
        user = '0;
    end
    // step: bit 0 tready for the next cycle, bit 1 a packet was completed at this edge
    always @(posedge aclk) begin
        data[DATA_W-1:0] = tdata;
        keep[DATA_W/8-1:0] = tkeep;
        user[USER_W-1:0] = tuser;
        step = rosgate_axis_sink_step(port, {31'd0, aresetn}, {31'd0, tvalid}, {31'd0, tready},
                                      {31'd0, tlast}, data, keep, user);
        tready <= step[0];
        if (step[1]) received <= received + 32'd1;
    end
endmodule
