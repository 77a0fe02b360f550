"""The repository's layering: ``hdl`` (Amaranth, no simulator) <- ``gen`` (messages, config,
system assembly, export) <- ``host`` (what runs on the host computer) <- ``tb`` (tests,
fixtures, golden models) <- ``bench``; test modules are leaves; no import cycles; the example
projects import the product only; nothing points outside the repository; the installed
distribution holds the product packages and the ``rosgate`` command, nothing else."""

import ast
import subprocess
import sys
import zipfile
from pathlib import Path

from .harness import ROOT

#: each top-level package and the packages it may import
LAYERS = {"hdl": {"hdl"}, "gen": {"hdl", "gen"}, "host": {"hdl", "gen", "host"},
          "tb": {"hdl", "gen", "host", "tb"}, "bench": {"hdl", "gen", "host", "tb", "bench"}}
PRODUCT = ("hdl", "gen", "host")
#: modules that run a simulator; the hardware description imports none of them
SIMULATOR_MODULES = ("cocotb", "cocotbext", "cocotb_tools", "amaranth.sim")


def python_files():
    tracked = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard",
                              "*.py"], cwd=ROOT, capture_output=True, text=True, check=True)
    return [Path(f) for f in tracked.stdout.split() if (ROOT / f).is_file()]


def module_name(path):
    parts = list(path.with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports(path, module):
    """Absolute names of everything ``path`` (module ``module``) imports, with line numbers."""
    tree = ast.parse((ROOT / path).read_text(), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            yield target, node.lineno
            for alias in node.names:
                yield f"{target}.{alias.name}", node.lineno


def project_graph():
    """module -> {imported project module: line} for the project's packages."""
    files = {module_name(p): p for p in python_files() if p.parts[0] in LAYERS}
    graph = {}
    for module, path in files.items():
        edges = {}
        for name, line in imports(path, module):
            while name and name not in files:
                name = name.rpartition(".")[0]
            if name and name != module:
                edges.setdefault(name, line)
        graph[module] = edges
    return files, graph


def is_test_module(module):
    leaf = module.rpartition(".")[2]
    return leaf.startswith("test_") or leaf == "conftest"


def test_no_upward_imports():
    files, graph = project_graph()
    wrong = [f"{files[m]}:{line} imports {d}" for m, deps in graph.items()
             for d, line in deps.items() if d.split(".")[0] not in LAYERS[m.split(".")[0]]]
    assert not wrong, "imports against the layering:\n" + "\n".join(wrong)


def test_no_module_imports_a_test_module():
    files, graph = project_graph()
    wrong = [f"{files[m]}:{line} imports test module {d}" for m, deps in graph.items()
             for d, line in deps.items() if is_test_module(d)]
    assert not wrong, "\n".join(wrong)


def test_no_import_cycles():
    """No cycle among modules, a package's ``__init__`` importing its own modules
    excepted."""
    files, graph = project_graph()

    def edges(m):
        # a package importing its submodules (re-exports) is not a dependency back
        return [d for d in graph[m] if not (files[m].name == "__init__.py" and
                                            d.startswith(m + "."))]
    state, stack, cycles = {}, [], []

    def visit(m):
        state[m] = "open"
        stack.append(m)
        for d in edges(m):
            if state.get(d) == "open":
                cycles.append(stack[stack.index(d):] + [d])
            elif d not in state:
                visit(d)
        stack.pop()
        state[m] = "done"
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for m in graph:
        if m not in state:
            visit(m)
    assert not cycles, "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_hardware_description_imports_no_simulator():
    files, _ = project_graph()
    wrong = [f"{files[m]}:{line} imports {name}" for m in files if m.split(".")[0] == "hdl"
             for name, line in imports(files[m], m)
             if name and name.startswith(SIMULATOR_MODULES)]
    assert not wrong, "\n".join(wrong)


def test_examples_import_the_product_only():
    wrong = []
    for path in python_files():
        if path.parts[0] != "examples":
            continue
        for name, line in imports(path, module_name(path)):
            if name and name.split(".")[0] in ("tb", "bench"):
                wrong.append(f"{path}:{line} imports {name}")
    assert not wrong, "an example is a user's project:\n" + "\n".join(wrong)


def test_nothing_refers_outside_the_repository():
    """Every document a file points to is in the repository (docs/), not in a folder beside
    it that users do not have."""
    found = subprocess.run(["git", "grep", "-n", "-I", "-E", r"(\.\./)?shared[/](spec|seeds)|"
                            r"\.\./shared"], cwd=ROOT, capture_output=True, text=True).stdout
    assert not found.strip(), found


def test_installed_distribution_holds_the_product(tmp_path):
    """The wheel's top-level packages are hdl, gen and host; its entry point is
    ``rosgate = host.cli:main``."""
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                    "-q", "-w", str(tmp_path), str(ROOT)], check=True, capture_output=True)
    wheel = next(tmp_path.glob("rosgate-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if "/" in n and not n.split("/")[0].endswith(
        (".dist-info", ".data"))}
    assert tops == set(PRODUCT), tops
    entry = next(n for n in names if n.endswith("entry_points.txt"))
    text = zipfile.ZipFile(wheel).read(entry).decode()
    assert "rosgate = host.cli:main" in text, text
