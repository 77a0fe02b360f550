// The bare model of a co-simulated system: its Verilator model with this main instead of
// cocotb's, the clock toggled in C++, the reset released, every other input idle. What it
// reaches in cycles per CPU-second is the most the co-simulation can reach (bench/cosim.py).
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>

#include "Vtop.h"
#include "verilated.h"

extern "C" uint8_t *rosgate_axi_ram_attach(uint64_t size);

double sc_time_stamp() { return 0; }

static double cpu_seconds() {
    timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

int main(int argc, char **argv) {
    Verilated::commandArgs(argc, argv);
    const uint64_t cycles = argc > 1 ? strtoull(argv[1], nullptr, 0) : 1000000;
    rosgate_axi_ram_attach(1 << 25);
    Vtop *top = new Vtop;
    top->aclk = 0;
    top->aresetn = 0;
    top->eval();
    for (int i = 0; i < 8; i++) {
        top->aclk = 1;
        top->eval();
        top->aclk = 0;
        top->eval();
        if (i == 4) top->aresetn = 1;
    }
    const double start = cpu_seconds();
    for (uint64_t i = 0; i < cycles; i++) {
        top->aclk = 1;
        top->eval();
        top->aclk = 0;
        top->eval();
    }
    const double used = cpu_seconds() - start;
    printf("{\"cycles\": %llu, \"cpu_seconds\": %.6f}\n", (unsigned long long)cycles, used);
    top->final();
    delete top;
    return 0;
}
