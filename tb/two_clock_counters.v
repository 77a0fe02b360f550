// two_clock_counters: a test top for the compiled clocks (tb/test_compiled_clock.py): a
// counter on each of two clocks, and on the first clock's falling edge a copy of the second's.
module two_clock_counters(clk_a, clk_b, count_a, count_b, fall_copy);
    input clk_a;
    input clk_b;
    output reg [31:0] count_a = 32'd0;
    output reg [31:0] count_b = 32'd0;
    output reg [31:0] fall_copy = 32'd0;
    always @(posedge clk_a) count_a <= count_a + 32'd1;
    always @(posedge clk_b) count_b <= count_b + 32'd1;
    always @(negedge clk_a) fall_copy <= count_b;
endmodule
