"""The layout rules: dependencies flow one way, cvt <- backends <- baselines <- bench,
and no module depends on itself through others.

Every import of the four packages (absolute, relative, and module paths written as
strings for lazy registries) is parsed with ``ast``; a module may import from its own
package or from one to its left, never from one to its right; and the graph of imports
between the suite's modules (at any depth: a function's lazy import counts too) has no
cycle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "compact_distributions"
LAYERS = ["cvt", "backends", "baselines", "bench"]


def _layer_of(dotted: str) -> str | None:
    parts = dotted.split(".")
    if parts[0] in LAYERS:  # an old top-level name: would not even import when installed
        return "top-level " + parts[0]
    if parts[0] == PACKAGE and len(parts) > 1 and parts[1] in LAYERS:
        return parts[1]
    return None


def imported_layers(source: str, layer: str, module_path: list[str]) -> list[tuple[int, str]]:
    """(line, target layer) of every import of ``source`` that names one of the four
    packages; ``module_path`` is the module's dotted path inside its layer (for relative
    imports)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = [PACKAGE, layer, *module_path][: -node.level] if node.level else []
                dotted = ".".join(base + ([node.module] if node.module else []))
                names = [dotted] + ([f"{dotted}.{a.name}" for a in node.names] if len(base) == 1 else [])
            else:
                names = [node.module or ""]
                if node.module == PACKAGE:
                    names = [f"{PACKAGE}.{a.name}" for a in node.names]
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and node.value.startswith(PACKAGE + ".")
        ):
            names = [node.value.split(":")[0]]  # "package.module:attr" in a lazy registry
        for name in names:
            target = _layer_of(name)
            if target is not None:
                found.append((node.lineno, target))
    return found


def upward_imports(source: str, layer: str, module_path: list[str]) -> list[str]:
    rank = LAYERS.index(layer)
    bad = []
    for line, target in imported_layers(source, layer, module_path):
        if target.startswith("top-level") or LAYERS.index(target) > rank:
            bad.append(f"line {line}: {layer} imports {target}")
    return bad


def modules():
    for layer in LAYERS:
        for path in sorted((ROOT / layer).rglob("*.py")):
            rel = path.relative_to(ROOT / layer).with_suffix("").parts
            yield layer, list(rel), path


@pytest.mark.parametrize(
    "layer,module_path,path", list(modules()), ids=[str(p.relative_to(ROOT)) for _, _, p in modules()]
)
def test_no_upward_import(layer, module_path, path):
    assert upward_imports(path.read_text(), layer, module_path) == []


@pytest.mark.parametrize(
    "layer,snippet",
    [
        ("cvt", "from compact_distributions.bench.report import provenance\n"),
        ("cvt", "from ..backends import create_backend\n"),
        ("backends", "import compact_distributions.baselines.hu2016\n"),
        ("backends", "from compact_distributions import bench\n"),
        ("baselines", "REGISTRY = {'x': 'compact_distributions.bench.commands.cli:main'}\n"),
        ("bench", "from bench import runner\n"),  # the old top-level package
    ],
)
def test_the_check_catches_an_upward_import(layer, snippet):
    assert upward_imports(snippet, layer, ["some_module"]), snippet


@pytest.mark.parametrize(
    "layer,snippet",
    [
        ("bench", "from compact_distributions.cvt.problem import Grid\nfrom ..baselines import REGISTRY\n"),
        (
            "baselines",
            "from .common import tile_shape\nfrom compact_distributions.backends import REFERENCE\n",
        ),
        ("cvt", "from .metrics import make_metric\nimport numpy\n"),
    ],
)
def test_the_check_allows_imports_to_the_left(layer, snippet):
    assert upward_imports(snippet, layer, ["some_module"]) == []


def test_each_baseline_is_registered_and_cites_its_paper():
    from compact_distributions.baselines import METHODS
    from compact_distributions.cvt.registry import method_names

    files = {p.stem for p in (ROOT / "baselines").glob("*.py")} - {"__init__", "common"}
    assert files == {m.name for m in METHODS}
    assert files <= set(method_names())  # found by the registry through the entry point
    for record in METHODS:
        doc = ast.get_docstring(ast.parse((ROOT / "baselines" / f"{record.name}.py").read_text()))
        assert doc and record.name[-4:] in doc and "depart" in doc.lower(), record.name
        assert record.paper and str(record.year) in record.paper, record.name


# ----------------------------------------------------------------------- cvt's rooms
# Inside cvt the core sits at the top; placement builds on the core, mosaic on both.
CVT_ROOMS = ["core", "placement", "mosaic"]


def room_of(dotted: str) -> str | None:
    """The room of cvt that a dotted module path (inside the package) lies in."""
    parts = dotted.split(".")
    if parts[:2] != [PACKAGE, "cvt"] or len(parts) < 3:
        return None
    return parts[2] if parts[2] in CVT_ROOMS[1:] else "core"


def upward_room_imports(source: str, module_path: list[str]) -> list[str]:
    """Imports of a cvt module (``module_path`` inside cvt) from a room above its own."""
    own = room_of(".".join([PACKAGE, "cvt", *module_path]))
    bad = []
    for node in ast.walk(ast.parse(source)):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level:
                base = [PACKAGE, "cvt", *module_path][: -node.level]
                module = ".".join(base + ([node.module] if node.module else []))
            names = [module] + [f"{module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            names = [node.value.split(":")[0]] if node.value.startswith(PACKAGE + ".cvt.") else []
        for name in names:
            target = room_of(name)
            if target is not None and CVT_ROOMS.index(target) > CVT_ROOMS.index(own):
                bad.append(f"line {node.lineno}: cvt.{own} imports cvt.{target}")
    return sorted(set(bad))


@pytest.mark.parametrize(
    "module_path",
    [rel for layer, rel, _ in modules() if layer == "cvt"],
    ids=[".".join(rel) for layer, rel, _ in modules() if layer == "cvt"],
)
def test_no_import_from_a_higher_room(module_path):
    path = ROOT / "cvt" / Path(*module_path).with_suffix(".py")
    assert upward_room_imports(path.read_text(), module_path) == []


@pytest.mark.parametrize(
    "module_path,snippet,caught",
    [
        (["lloyd"], "from .placement.fit import parse_gap\n", True),
        (["metrics"], "from compact_distributions.cvt.mosaic import render\n", True),
        (["placement", "fit"], "from ..mosaic.render import draw_elements\n", True),
        (["placement", "fit"], "from ..metrics import make_metric\nfrom .compaction import compact\n", False),
        (["mosaic", "pipeline"], "from ..placement.ours import run_ours\nfrom ..lloyd import lloyd\n", False),
    ],
)
def test_the_room_check(module_path, snippet, caught):
    assert bool(upward_room_imports(snippet, module_path)) is caught


def test_cvt_keeps_its_top_small():
    """The core at cvt's top, at most 20 modules; the rest in its rooms."""
    top = sorted(p.name for p in (ROOT / "cvt").glob("*.py"))
    assert len(top) <= 20, top
    for room in CVT_ROOMS[1:]:
        assert (ROOT / "cvt" / room / "__init__.py").is_file()


def test_each_command_is_a_module_of_bench_commands():
    """``cvtbench``'s subcommands are the modules of bench/commands (besides the entry point)."""
    from compact_distributions.bench.commands.cli import build_parser

    commands = set(build_parser()._subparsers._group_actions[0].choices)
    modules_ = {p.stem for p in (ROOT / "bench" / "commands").glob("*.py")} - {"__init__", "cli"}
    assert commands == modules_


# ---------------------------------------------------------------------------- cycles
def module_name(layer: str, module_path: list[str]) -> str:
    return ".".join([PACKAGE, layer, *module_path]).removesuffix(".__init__")


def import_graph(sources: dict[str, tuple[str, bool]]) -> dict[str, set[str]]:
    """module -> the suite's modules it imports, from ``{module: (source, is_package)}``
    (an import of a name inside a module counts as an import of that module)."""
    graph = {}
    for name, (source, is_package) in sources.items():
        found = set()
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.Import):
                candidates = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                module = node.module or ""
                if node.level:
                    base = name.split(".")[: None if is_package else -1]
                    base = base[: len(base) - (node.level - 1)]
                    module = ".".join(base + ([node.module] if node.module else []))
                candidates = [module] + [f"{module}.{a.name}" for a in node.names]
            else:
                continue
            for c in candidates:
                while c and c not in sources:
                    c = c.rpartition(".")[0]
                if c and c != name:
                    found.add(c)
        graph[name] = found
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, on_stack, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    component = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        component.append(w)
                        if w == v:
                            break
                    if len(component) > 1:
                        out.append(sorted(component))
    return out


def test_no_import_cycle():
    sources = {
        module_name(layer, rel): (path.read_text(), path.name == "__init__.py")
        for layer, rel, path in modules()
    }
    assert cycles(import_graph(sources)) == []


def test_the_check_catches_a_cycle():
    pkg = f"{PACKAGE}.cvt"
    sources = {
        f"{pkg}.a": ("from .b import x\n", False),
        f"{pkg}.b": ("def f():\n    from .c import y\n", False),
        f"{pkg}.c": (f"import {pkg}.a\n", False),
        f"{pkg}.d": ("from .a import z\n", False),
    }
    assert cycles(import_graph(sources)) == [[f"{pkg}.a", f"{pkg}.b", f"{pkg}.c"]]
    sources[f"{pkg}.c"] = ("import numpy\n", False)
    assert cycles(import_graph(sources)) == []


# ------------------------------------------------------------------ method names in bench
def method_name_comparisons(source: str, names: set[str]) -> list[int]:
    """Lines where ``source`` compares something with a method's name written out (``==``,
    ``!=``, ``in``, ``.startswith``): bench/ reads methods' records instead."""
    found = []
    for node in ast.walk(ast.parse(source)):
        texts = []
        if isinstance(node, ast.Compare):
            for side in [node.left, *node.comparators]:
                if isinstance(side, ast.Constant):
                    texts.append(side.value)
                elif isinstance(side, (ast.Tuple, ast.List, ast.Set)):
                    texts += [e.value for e in side.elts if isinstance(e, ast.Constant)]
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr in ("startswith", "endswith")
            and node.args
            and isinstance(node.args[0], ast.Constant)
        ):
            texts.append(node.args[0].value)
            if node.func.attr == "startswith":
                texts += [
                    n
                    for n in names
                    if isinstance(node.args[0].value, str) and n.startswith(node.args[0].value)
                ]
        if any(isinstance(t, str) and t in names for t in texts):
            found.append(node.lineno)
    return found


def test_bench_never_compares_a_method_name():
    from compact_distributions.cvt.registry import method_names

    names = set(method_names())
    bad = {
        str(p.relative_to(ROOT)): lines
        for p in sorted((ROOT / "bench").rglob("*.py"))
        if (lines := method_name_comparisons(p.read_text(), names))
    }
    assert bad == {}


def test_the_name_check_catches_a_comparison():
    names = {"ours", "ours-compact", "hu2016"}
    assert method_name_comparisons("if m == 'ours':\n    pass\n", names) == [1]
    assert method_name_comparisons("x = m in ('hu2016', 'a')\n", names) == [1]
    assert method_name_comparisons("y = m.startswith('ours')\n", names) == [1]
    assert method_name_comparisons("z = record.role == 'paper'\nw = m == other\n", names) == []


@pytest.mark.parametrize(
    "layer,module_path,path", list(modules()), ids=[str(p.relative_to(ROOT)) for _, _, p in modules()]
)
def test_every_module_declares_its_public_names(layer, module_path, path):
    """``__all__`` in every module (a package's too, where it defines anything), and each
    name in it defined there."""
    import importlib

    tree = ast.parse(path.read_text())
    declared = [
        n
        for n in tree.body
        if isinstance(n, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets)
    ]
    defines = any(isinstance(n, (ast.FunctionDef, ast.ClassDef)) for n in tree.body)
    if module_path[-1] == "__init__" and not defines and not declared:
        return
    assert declared, f"{path.relative_to(ROOT)} has no __all__"
    name = ".".join([PACKAGE, layer, *module_path]).removesuffix(".__init__")
    module = importlib.import_module(name)
    missing = [n for n in module.__all__ if not hasattr(module, n)]
    assert missing == []
