"""``make lint``: export every top of every bench configuration, every top ``make bench``
simulates and the system of every example project, and lint them."""

import importlib
import sys

from host.lint import WAIVERS, lint_verilog
from tb.harness import SIM_BUILD, config_params, export_bench_top

#: bench module -> top name
BENCHES = {"tb.test_topic": "topic", "tb.test_msg_codec": "msg_codec",
           "tb.test_reconos_pingpong": "reconos", "tb.test_reconos_memory": "reconos",
           "tb.test_reconos_calls": "reconos", "tb.test_reconos_apps": "reconos",
           "tb.test_kernels_image": "kernels", "tb.test_kernels_control": "kernels",
           "tb.test_kernels_mnist": "kernels", "tb.test_net_stack": "net",
           "tb.test_ros1_registers": "ros1_node", "tb.test_finemb_node": "finemb_node",
           "tb.test_services": "services", "tb.test_av_chain": "av_chain"}
#: bench module -> its configuration tables besides ``CONFIGS``
MORE_CONFIGS = {"tb.test_net_stack": ("SMALL_RING", "WIDE_USER")}


def benchmark_tops():
    """(top, configuration, parameters, build) of every top ``make bench`` simulates that
    is not in :data:`gen.tops.TOPS` (its own bench tops, built by ``run_bench(build=...)``)."""
    from tb.net_bench_tops import (
        NET_BENCH_CONFIGS,
        ROS1_BENCH_CONFIG,
        build_net_bench_top,
        build_ros1_bench_top,
    )
    from tb.topic_traffic import TOPOLOGIES, WIDTHS, build_topic_bench_top
    from tb.finemb_line_top import build_finemb_line_bench_top
    from tb.finemb_tb import PID_IO
    for case, params in NET_BENCH_CONFIGS.items():
        yield "net_bench", case, params, build_net_bench_top
    yield "finemb_line", "n2", {"io": PID_IO, "nodes": 2}, build_finemb_line_bench_top
    yield "ros1_bench", "images", ROS1_BENCH_CONFIG, build_ros1_bench_top
    for width in WIDTHS:
        for pubs, subs in TOPOLOGIES:
            yield ("topic_bench", f"{pubs}x{subs}_w{width}",
                   {"pubs": pubs, "subs": subs, "data_width": width}, build_topic_bench_top)


def main():
    reports = []

    def lint(vfile, top, label):
        report = lint_verilog(vfile, top)
        reports.append(report)
        print(f"lint {top} [{label}]: {'clean' if not report else 'WARNINGS'}")
        if report:
            print(report)

    seen = set()
    for module_name, top in BENCHES.items():
        module = importlib.import_module(module_name)
        configs = dict(module.CONFIGS)
        for name in MORE_CONFIGS.get(module_name, ()):
            configs.update(getattr(module, name))
        for config_id, params in configs.items():
            if (top, config_id) in seen:   # benches may share a configuration
                continue
            seen.add((top, config_id))
            params, _ = config_params(params)
            lint(export_bench_top(top, params, SIM_BUILD / "lint" / f"{top}-{config_id}"),
                 top, config_id)
    for top, config_id, params, build in benchmark_tops():
        lint(export_bench_top(top, params, SIM_BUILD / "lint" / f"{top}-{config_id}",
                              build=build), top, f"{config_id}, make bench")
    from gen.config import load_project
    from gen.export.verilog import export_verilog, write_if_changed
    from gen.system import build_system
    from tb.projects import EXAMPLES, example_cfg
    for name in EXAMPLES:
        system = build_system(load_project(example_cfg(name)))
        text, _ = export_verilog(system, "rosgate_system")
        vfile = SIM_BUILD / "lint" / f"rosgate_system-{name}" / "rosgate_system.v"
        write_if_changed(vfile, text)
        lint(vfile, "rosgate_system", f"examples/{name}")
    failed = sum(1 for report in reports if report)
    print(f"{len(reports) - failed} of {len(reports)} tops lint-clean (verilator --lint-only "
          f"-Wall, waived: {', '.join(WAIVERS)})")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
