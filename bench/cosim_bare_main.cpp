// The bare model of a co-simulated top: its Verilator model with this main instead of
// cocotb's, the clocks toggled in C++, the reset released, every other input idle. What it
// reaches in cycles per CPU-second is the most the co-simulation can reach (bench/cosim.py).
//
// bench/cosim.py compiles a copy with these defined in front:
//   BARE_CLOCKS      X(name, half period in ps) for every clock, the first one counted
//   BARE_RESET_N     the active-low reset port
//   BARE_AXI_RAM     defined when the top has the compiled AXI memory (attached, 32 MiB)
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <vector>

#include "Vtop.h"
#include "verilated.h"

#ifdef BARE_AXI_RAM
extern "C" uint8_t *rosgate_axi_ram_attach(uint64_t size);
#endif

double sc_time_stamp() { return 0; }

static double cpu_seconds() {
    timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

struct Clock {
    CData *port;
    uint64_t half_ps;
    uint64_t next_ps;
};

int main(int argc, char **argv) {
    Verilated::commandArgs(argc, argv);
    const uint64_t cycles = argc > 1 ? strtoull(argv[1], nullptr, 0) : 1000000;
#ifdef BARE_AXI_RAM
    rosgate_axi_ram_attach(1 << 25);
#endif
    Vtop *top = new Vtop;
    std::vector<Clock> clocks;
#define X(name, half) clocks.push_back({&top->name, (half), (half)});
    BARE_CLOCKS
#undef X
    for (Clock &c : clocks) *c.port = 0;
    top->BARE_RESET_N = 0;
    top->eval();
    // the first clock's rising edges: reset held for 4, released, then counted
    uint64_t rising = 0, counted = 0, now = 0;
    double start = 0;
    while (counted < cycles) {
        now = UINT64_MAX;
        for (const Clock &c : clocks) now = c.next_ps < now ? c.next_ps : now;
        bool counted_edge = false;
        for (size_t i = 0; i < clocks.size(); i++) {
            Clock &c = clocks[i];
            if (c.next_ps != now) continue;
            *c.port ^= 1;
            c.next_ps += c.half_ps;
            if (i == 0 && *c.port) counted_edge = true;
        }
        top->eval();
        if (!counted_edge) continue;
        rising++;
        if (rising == 4) top->BARE_RESET_N = 1;
        if (rising == 8) start = cpu_seconds();
        if (rising > 8) counted++;
    }
    const double used = cpu_seconds() - start;
    printf("{\"cycles\": %llu, \"cpu_seconds\": %.6f}\n", (unsigned long long)cycles, used);
    top->final();
    delete top;
    return 0;
}
