// rosgate's main for a cocotb + Verilator simulation: cocotb's event loop with the clocks
// toggled here, in compiled code, instead of by GPI timer callbacks.
//
// The loop is the one of cocotb 2.1's share/lib/verilator/verilator.cpp (same regions in the
// same order: NextSimTime, timed callbacks, evaluation with value-change callbacks settled,
// ReadWrite, ReadOnly), so a test sees the same values at the same times. What differs is
// who toggles a clock: cocotb's GPI clock costs a VPI timer callback, a vpi_put_value and a
// callback registration per half period, three times the model's own work on a system top.
// Here a clock started with rosgate_clock_start() is a pointer to the port's storage and the
// time of its next edge; the loop writes it at the start of that time step, where cocotb's
// clock would have written it (its timer callback), and value-change callbacks (RisingEdge)
// see it as before.
//
// The Python interpreter cocotb embeds keeps its GIL in this thread from its start; every
// callback into Python takes it again (PyGILState_Ensure). While the model runs, the loop lets
// it go, so that Python threads of a test or a node (a socket client, a DDS bridge) run while
// the simulator computes instead of waiting for the next Python callback and the
// interpreter's switch interval (5 ms per hand-over: an RBCP exchange through TAP took 3 s).
//
// Python (host.simulator.start_clock) finds rosgate_clock_start/_stop with ctypes in this
// executable (linked with --export-dynamic-symbol=rosgate_clock_*); a simulator without them
// (Icarus, an older build) keeps cocotb's GPI clock.

#include <dlfcn.h>

#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#ifndef VM_TRACE_FST
#define VM_TRACE_FST 0
#endif

#include "Vtop.h"
#include "verilated.h"
#include "verilated_syms.h"
#include "verilated_vpi.h"

#if VM_TRACE
#if VM_TRACE_FST
#include <verilated_fst_c.h>
using Trace = VerilatedFstC;
#else
#include <verilated_vcd_c.h>
using Trace = VerilatedVcdC;
#endif
static Trace* tfp = nullptr;
#endif

static uint64_t main_time = 0;

double sc_time_stamp() { return main_time; }

extern "C" void vlog_startup_routines_bootstrap(void);

namespace {

const uint64_t NEVER = ~0ULL;

struct CompiledClock {
    uint8_t* value;      // the port's storage (a 1-bit input: CData)
    uint64_t high;       // steps at 1
    uint64_t low;        // steps at 0
    uint64_t next;       // time of the next toggle, NEVER when stopped
};

std::vector<CompiledClock> clocks;

uint64_t next_toggle() {
    uint64_t t = NEVER;
    for (const auto& c : clocks)
        if (c.next < t) t = c.next;
    return t;
}

void toggle_due() {
    for (auto& c : clocks) {
        if (c.next != main_time) continue;
        *c.value ^= 1;
        c.next = main_time + (*c.value ? c.high : c.low);
    }
}

bool settle_value_callbacks() {
    bool called = VerilatedVpi::callValueCbs();
    bool again = called;
    while (again) again = VerilatedVpi::callValueCbs();
    return called;
}

// The embedded interpreter's GIL, found at run time (the executable does not link Python)
struct PythonLock {
    void* (*save)() = nullptr;
    void (*restore)(void*) = nullptr;
    int (*held)() = nullptr;
    int (*alive)() = nullptr;
    void* state = nullptr;

    void release() {
        if (!save) {
            alive = reinterpret_cast<int (*)()>(dlsym(RTLD_DEFAULT, "Py_IsInitialized"));
            save = reinterpret_cast<void* (*)()>(dlsym(RTLD_DEFAULT, "PyEval_SaveThread"));
            restore = reinterpret_cast<void (*)(void*)>(dlsym(RTLD_DEFAULT, "PyEval_RestoreThread"));
            held = reinterpret_cast<int (*)()>(dlsym(RTLD_DEFAULT, "PyGILState_Check"));
        }
        // not when the tests ended before the first time step (Python finalized then)
        if (save && restore && held && alive && !state && alive() && held()) state = save();
    }
    void take_back() {
        // cocotb's shutdown may have taken it already (its finalize does not give it back)
        if (state && alive() && !held()) restore(state);
        state = nullptr;
    }
} python_lock;

void wrap_up() {
    python_lock.take_back();
    VerilatedVpi::callCbs(cbEndOfSimulation);
#if VM_TRACE
    if (tfp) tfp->close();
#endif
}

}  // namespace

extern "C" {

// Start toggling the 1-bit port `name` (a VPI name such as "top.aclk") with `high` and `low`
// time steps per half, from `start_high` now; the first toggle comes after that half.
// Returns a clock id >= 0, or -1 when the name is not a 1-bit variable of a visible scope.
int rosgate_clock_start(const char* name, uint64_t high, uint64_t low, int start_high) {
    if (high == 0 || low == 0) return -1;
    std::string full{name};
    const auto dot = full.rfind('.');
    if (dot == std::string::npos) return -1;
    // the variable vpi_handle_by_name finds: a port of the top level is the model's input
    // (scope TOP), not the copy in the top module's own scope that each evaluation overwrites
    const std::string scope_name = full.substr(0, dot), base = full.substr(dot + 1);
    VerilatedVar* var = nullptr;
    if (scope_name.find('.') == std::string::npos) {
        if (const VerilatedScope* top_scope = Verilated::threadContextp()->scopeFind("TOP"))
            var = top_scope->varFind(base.c_str());
    }
    if (!var) {
        const VerilatedScope* scope = Verilated::threadContextp()->scopeFind(scope_name.c_str());
        if (!scope) return -1;
        var = scope->varFind(base.c_str());
    }
    if (!var || var->vltype() != VLVT_UINT8 || var->udims() != 0) return -1;
    // the first value as cocotb's clock sets it (through VPI: the loop evaluates it now)
    vpiHandle handle = vpi_handle_by_name(const_cast<PLI_BYTE8*>(name), nullptr);
    if (!handle) return -1;
    s_vpi_value v{};
    v.format = vpiIntVal;
    v.value.integer = start_high ? 1 : 0;
    vpi_put_value(handle, &v, nullptr, vpiNoDelay);
    vpi_release_handle(handle);
    clocks.push_back({static_cast<uint8_t*>(var->datap()), high, low,
                      main_time + (start_high ? high : low)});
    return static_cast<int>(clocks.size() - 1);
}

void rosgate_clock_stop(int id) {
    if (id >= 0 && static_cast<size_t>(id) < clocks.size()) clocks[id].next = NEVER;
}

}  // extern "C"

int main(int argc, char** argv) {
    const char* trace_file = "dump.fst";
    bool trace_on = false;
    for (int i = 1; i < argc; i++) {
        const std::string arg{argv[i]};
        if (arg == "--trace") {
#if VM_TRACE
            trace_on = true;
#else
            std::fprintf(stderr, "Error: --trace requires a build with trace support\n");
            return -1;
#endif
        } else if (arg == "--trace-file" && i + 1 < argc) {
            trace_file = argv[++i];
        }
    }
    (void)trace_file;
    (void)trace_on;

    Verilated::commandArgs(argc, argv);
    std::unique_ptr<Vtop> top{new Vtop{""}};
    Verilated::fatalOnVpiError(false);

#if VM_TRACE
    Verilated::traceEverOn(true);
    if (trace_on) {
        tfp = new Trace;
        top->trace(tfp, 99);
        tfp->open(trace_file);
    }
#endif

    vlog_startup_routines_bootstrap();
    Verilated::addExitCb([](void*) { wrap_up(); }, nullptr);
    VerilatedVpi::callCbs(cbStartOfSimulation);
    settle_value_callbacks();
    python_lock.release();

    while (!Verilated::gotFinish()) {
        do {
            do {
                top->eval_step();
                VerilatedVpi::clearEvalNeeded();
                VerilatedVpi::doInertialPuts();
                settle_value_callbacks();
            } while (VerilatedVpi::evalNeeded());
            const bool called = VerilatedVpi::callCbs(cbReadWriteSynch);
            VerilatedVpi::doInertialPuts();
            if (called || VerilatedVpi::evalNeeded()) settle_value_callbacks();
        } while (VerilatedVpi::evalNeeded());

        top->eval_end_step();
        VerilatedVpi::callCbs(cbReadOnlySynch);
#if VM_TRACE
        if (tfp) tfp->dump(main_time);
#endif
        const uint64_t timed_time = VerilatedVpi::cbNextDeadline();
        uint64_t next_time = timed_time;
        if (top->eventsPending() && top->nextTimeSlot() < next_time)
            next_time = top->nextTimeSlot();
        const uint64_t clock_time = next_toggle();
        if (clock_time < next_time) next_time = clock_time;
        if (next_time == NEVER) break;
        main_time = next_time;

        if (VerilatedVpi::callCbs(cbNextSimTime)) settle_value_callbacks();
        // where cocotb's clock toggles: first among the timed callbacks of this time step
        if (clock_time == main_time) toggle_due();
        if (timed_time == main_time) VerilatedVpi::callTimedCbs();
        // value-change callbacks see what changed since they last ran: skipping them when
        // nothing did (no callback wrote, no clock toggled) changes nothing but the time
        if (clock_time == main_time || timed_time == main_time) settle_value_callbacks();
    }

    top->final();
    wrap_up();
#if VM_TRACE
    if (tfp) {
        delete tfp;
        tfp = nullptr;
    }
#endif
    return Verilated::threadContextp()->errorCount() > 0 ? 1 : 0;
}
