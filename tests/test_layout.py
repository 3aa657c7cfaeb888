"""The layout rules: dependencies flow one way, cvt <- backends <- baselines <- bench.

Every import of the four packages (absolute, relative, and module paths written as
strings for lazy registries) is parsed with ``ast``; a module may import from its own
package or from one to its left, never from one to its right.
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
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.startswith(PACKAGE + "."):
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


@pytest.mark.parametrize("layer,module_path,path", list(modules()),
                         ids=[str(p.relative_to(ROOT)) for _, _, p in modules()])
def test_no_upward_import(layer, module_path, path):
    assert upward_imports(path.read_text(), layer, module_path) == []


@pytest.mark.parametrize("layer,snippet", [
    ("cvt", "from compact_distributions.bench.report import provenance\n"),
    ("cvt", "from ..backends import create_backend\n"),
    ("backends", "import compact_distributions.baselines.hu2016\n"),
    ("backends", "from compact_distributions import bench\n"),
    ("baselines", "REGISTRY = {'x': 'compact_distributions.bench.cli:main'}\n"),
    ("bench", "from bench import runner\n"),  # the old top-level package
])
def test_the_check_catches_an_upward_import(layer, snippet):
    assert upward_imports(snippet, layer, ["some_module"]), snippet


@pytest.mark.parametrize("layer,snippet", [
    ("bench", "from compact_distributions.cvt.problem import Grid\nfrom ..baselines import REGISTRY\n"),
    ("baselines", "from .common import tile_shape\nfrom compact_distributions.backends import REFERENCE\n"),
    ("cvt", "from .metrics import make_metric\nimport numpy\n"),
])
def test_the_check_allows_imports_to_the_left(layer, snippet):
    assert upward_imports(snippet, layer, ["some_module"]) == []


def test_each_baseline_is_registered_and_cites_its_paper():
    from compact_distributions.baselines import REGISTRY

    files = {p.stem for p in (ROOT / "baselines").glob("*.py")} - {"__init__", "common"}
    assert files == set(REGISTRY)
    for name in REGISTRY:
        doc = ast.get_docstring(ast.parse((ROOT / "baselines" / f"{name}.py").read_text()))
        assert doc and name[-4:] in doc and "depart" in doc.lower(), name
