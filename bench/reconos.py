"""ReconOS infrastructure benchmark (issue: ReconOS-compatible infrastructure §4;
docs/reconos.md).

* MEMIF bandwidth: copies of 4 B .. 10 MiB by a memory-test thread through the MEMIF engine,
  MMU (16-entry TLB, page walks included) and AXI4 controller, into cocotbext-axi's AxiRam
  (zero-wait), under Verilator; every copy checked byte for byte. Bytes moved = read + written.
* OS calls: hardware-side cycles per call (command word written to last reply consumed) with a
  delegate that answers at once, in amaranth.sim (FIFO latencies included).
* Resources: the infrastructure for 1, 2 and 4 empty slots (Debian Yosys synth_xilinx xc7).
"""

import json

from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.sim import Simulator

from bench.report import component_resources, resource_table, write_report
from gen.export.resources import YOSYS_COMMAND
from hdl.reconos import ReconosSystem
from hdl.reconos.fifo import OSIF_FIFO_DEPTH, ReconosFifo
from hdl.reconos.hwt import OsifEngine
from hdl.reconos.protocol import CALLS
from hdl.reconos.protocol import arch as get_arch
from tb.harness import SIM_BUILD, run_bench

CLOCK_MHZ = 100
SIZES = [4, 8192, 1 << 20, 6 << 20, 10 << 20]
#: lengths of the single read requests (MEMIF bursts never exceed 256 B)
BURSTS = [4, 8, 16, 32, 64, 128, 256]
LABELS = {4: "4 B", 8192: "8 KiB", 1 << 20: "1 MiB", 6 << 20: "6 MiB", 10 << 20: "10 MiB"}
#: P-RR Table 4, raw copy columns (ms): SW (ARM), HW (ReconROS HLS thread, 100 MHz)
PAPER_RAW_COPY = {4: (0.01, 0.01), 8192: (0.03, 0.13), 1 << 20: (3.59, 12.81),
                  6 << 20: (18.91, 76.35), 10 << 20: (31.54, 127.19)}


def measure_copies(arch, log=print):
    a = get_arch(arch)
    sizes = [max(s, a.word_bytes) for s in SIZES]
    out = SIM_BUILD / f"bench-reconos-{arch}.json"
    log(f"  simulating copies {', '.join(LABELS.get(s, f'{s} B') for s in SIZES)} on {arch} "
        f"(Verilator)...")
    bursts = [n for n in BURSTS if n >= a.word_bytes]
    run_bench("bench.reconos_bench", "reconos", f"bench-memtest_{arch}",
              {"arch": arch, "threads": [{"kind": "memtest", "h_cmd": 0, "h_result": 1}]},
              "verilator", quiet=True, optimise=True,
              extra_env={"ROSGATE_BENCH_CASE": json.dumps({"sizes": sizes, "bursts": bursts}),
                         "ROSGATE_BENCH_OUT": str(out)})
    measured = json.loads(out.read_text())
    rows = measured["copies"]
    for row, nominal in zip(rows, SIZES):
        moved = 2 * row["bytes"]
        row.update(
            arch=arch, nominal=nominal, word_bytes=a.word_bytes,
            bus_bytes_per_cycle=moved / row["bus_cycles"],
            bus_efficiency=moved / row["bus_cycles"] / a.word_bytes,
            # each channel moves size / W words of the copy within the bus cycles
            channel_share=row["bytes"] / a.word_bytes / row["bus_cycles"],
            op_efficiency=moved / row["op_cycles"] / a.word_bytes,
            op_ms=row["op_cycles"] / (CLOCK_MHZ * 1e3),
            paper_sw_ms=PAPER_RAW_COPY[nominal][0], paper_hw_ms=PAPER_RAW_COPY[nominal][1])
    for row in measured["bursts"]:
        row.update(arch=arch, word_bytes=a.word_bytes,
                   bytes_per_cycle=row["length"] / row["bus_cycles"])
    return rows, measured["bursts"]


class _OsifBench(wiring.Component):
    def __init__(self, arch):
        self.a = get_arch(arch)
        self.engine = OsifEngine(self.a)
        self.sw2hw = ReconosFifo(self.a.word_bits, OSIF_FIFO_DEPTH)
        self.hw2sw = ReconosFifo(self.a.word_bits, OSIF_FIFO_DEPTH)
        super().__init__({})

    def elaborate(self, platform):
        m = Module()
        m.submodules.engine, m.submodules.sw2hw, m.submodules.hw2sw = \
            self.engine, self.sw2hw, self.hw2sw
        wiring.connect(m, self.engine.osif_sw2hw, self.sw2hw.r)
        wiring.connect(m, self.engine.osif_hw2sw, self.hw2sw.w)
        return m


def measure_calls(arch):
    """Cycles from the call's start to ``done`` with an instant delegate, per call."""
    results = {}
    for name, c in CALLS.items():
        if name in ("thread_exit", "ros_take_interruptable_cancel") or not c.blocking:
            continue
        dut = _OsifBench(arch)
        e = dut.engine
        sim = Simulator(dut)
        sim.add_clock(1e-8)
        cycles = []

        async def delegate(ctx, c=c):
            words = 0 if c.command is None else 1 + len(c.args)
            ctx.set(dut.hw2sw.r.re, 1)
            while words:
                _, _, empty = await ctx.tick().sample(dut.hw2sw.r.empty)
                words -= not empty
            ctx.set(dut.hw2sw.r.re, 0)
            for k in range(len(c.replies)):
                ctx.set(dut.sw2hw.w.data, 100 + k)
                ctx.set(dut.sw2hw.w.we, 1)
                await ctx.tick()
            ctx.set(dut.sw2hw.w.we, 0)

        async def thread(ctx, c=c):
            ctx.set(e.mode, 0)
            ctx.set(e.has_cmd, c.command is not None)
            ctx.set(e.cmd, 0 if c.command is None else int(c.command))
            ctx.set(e.nargs, len(c.args))
            ctx.set(e.nreplies, len(c.replies))
            ctx.set(e.start, 1)
            n = 0
            await ctx.tick()
            ctx.set(e.start, 0)
            while True:
                n += 1
                _, _, done = await ctx.tick().sample(e.done)
                if done:
                    break
            cycles.append(n)

        sim.add_testbench(delegate)
        sim.add_testbench(thread)
        sim.run()
        results[name] = {"command": None if c.command is None else int(c.command),
                         "words": (1 if c.command is not None else 0) + len(c.args),
                         "replies": len(c.replies), "cycles": cycles[0]}
    return results


def measure_resources(log=print):
    rows = []
    for arch in ("r64", "r32"):
        for n in (1, 2, 4):
            log(f"  yosys {YOSYS_COMMAND}: {arch} infrastructure, {n} slot(s)...")
            rows.append({"config": f"{arch}, {n} slot{'s' if n > 1 else ''}",
                         **component_resources(ReconosSystem(arch, [None] * n),
                                               "reconos_infra", f"reconos-{arch}-{n}")})
    return rows


def measure(log=print):
    copies, bursts = [], []
    for arch in ("r64", "r32"):
        rows, reads = measure_copies(arch, log)
        copies += rows
        bursts += reads
    log("  OS-call cycles (amaranth.sim)...")
    calls = {arch: measure_calls(arch) for arch in ("r64", "r32")}
    return {"clock_mhz": CLOCK_MHZ, "copies": copies, "bursts": bursts, "calls": calls}


def markdown(results, resources):
    lines = ["# ReconOS infrastructure benchmark", "",
             f"Time at {CLOCK_MHZ} MHz. Copies: a hardware thread copies through the MEMIF "
             "engine (256-B requests, read and write streaming at once), arbiter, MMU (16-entry "
             "TLB; page walks included) and AXI4 controller into a zero-wait AxiRam "
             "(Verilator); every copy checked byte for byte. A copy moves 2 x size bytes "
             "(read + write); efficiency = moved bytes per cycle / W, i.e. 100 % is one word "
             "per cycle. AXI4 reads and writes have channels of their own and the controller "
             "overlaps reads and writes of different pages, so a copy can pass 100 % (at most "
             "200 %); 'R, W' is the share of bus cycles in which each of the two channels "
             "moved a word. "
             "'bus' counts from the first address handshake to the last response, 'op' from "
             "the command to the thread's result (OSIF mailbox words included). Copies smaller "
             "than a word are rounded up to one word.", "",
             "| arch | size | op cycles | op ms | bus cycles | B/cycle (bus) | efficiency bus "
             "/ op | R, W | paper raw copy SW / HW ms |", "|---|---|---|---|---|---|---|---|---|"]
    for r in results["copies"]:
        lines.append(
            f"| {r['arch']} | {LABELS[r['nominal']]} | {r['op_cycles']} | {r['op_ms']:.4f} | "
            f"{r['bus_cycles']} | {r['bus_bytes_per_cycle']:.3f} | "
            f"{100 * r['bus_efficiency']:.1f} % / {100 * r['op_efficiency']:.1f} % | "
            f"{100 * r['channel_share']:.1f} % | "
            f"{r['paper_sw_ms']} / {r['paper_hw_ms']} |")
    lines += ["", "## Single read requests (MEMIF bursts)", "",
              "One raw read request of each length at a 256-B boundary, from the first AXI "
              "address handshake to the last data beat (MMU hit: the TLB is warm).", "",
              "| arch | burst bytes | bus cycles | bytes/cycle | share of one word/cycle |",
              "|---|---|---|---|---|"]
    for r in results.get("bursts", []):
        lines.append(f"| {r['arch']} | {r['length']} | {r['bus_cycles']} | "
                     f"{r['bytes_per_cycle']:.2f} | "
                     f"{100 * r['bytes_per_cycle'] / r['word_bytes']:.0f} % |")
    lines += ["", "![MEMIF throughput](memif_throughput.png)", "",
              "## OS calls (hardware side, delegate answering at once)", "",
              "| call | command | words written | replies | cycles r64 | cycles r32 |",
              "|---|---|---|---|---|---|"]
    r64, r32 = results["calls"]["r64"], results["calls"]["r32"]
    for name, row in r64.items():
        cmd = "-" if row["command"] is None else f"0x{row['command']:03X}"
        lines.append(f"| {name} | {cmd} | {row['words']} | {row['replies']} | "
                     f"{row['cycles']} | {r32[name]['cycles']} |")
    lines += resource_table(resources, "config", "configuration")
    lines += ["", "Infrastructure only (empty slots): OSIF/MEMIF FIFOs, reconos_osif, "
              "osif_intc, proc_control, arbiter, MMU with 16-entry TLB, AXI4 memory "
              "controller."]
    lines.append("")
    return "\n".join(lines)


def write_results(results, resources, folder):
    return write_report(folder, "reconos", dict(results, resources=resources),
                        markdown(results, resources))
