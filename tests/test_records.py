"""Whole records: every fact about a shape lives in its record, in the one table.

Parsed with ``ast`` over the suite's modules (like the layering test): no comparison of
a value with a shape's or a metric's name written out, nor with a ball's type tag
(``"ellipse"``, ``"polygon"``); no literal list of two or more shape or metric names; and
no function over 100 lines.  The table itself (``cvt/metrics.py``) builds its records
with their names, in calls, which none of these checks counts.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ["compact_distributions", "cvt", "backends", "baselines", "bench"]
MAX_FUNCTION_LINES = 100
TAGS = {"ellipse", "polygon"}


def shape_and_metric_names() -> set[str]:
    from compact_distributions.cvt.metrics import METRIC_NAMES, SHAPES

    return set(SHAPES) | set(METRIC_NAMES)


def _texts(node) -> list[str]:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)]
    return []


def record_violations(source: str, names: set[str]) -> list[str]:
    """What in ``source`` reads a shape by its name or a ball by its tag, lists shape
    names of its own, or is a function too long to read."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare):
            texts = [t for side in [node.left, *node.comparators] for t in _texts(side)]
            hits = sorted({t for t in texts if t in names or t in TAGS})
            if hits:
                found.append(f"line {node.lineno}: compares with {', '.join(hits)}")
        elif isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            hits = [t for t in _texts(node) if t in names]
            if len(hits) >= 2:
                found.append(f"line {node.lineno}: lists {', '.join(hits)}")
        elif isinstance(node, ast.Dict):
            keys = [k.value for k in node.keys if isinstance(k, ast.Constant) and isinstance(k.value, str)]
            hits = [k for k in keys if k in names]
            if len(hits) >= 2:
                found.append(f"line {node.lineno}: a table of {', '.join(hits)}")
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            length = node.end_lineno - node.lineno + 1
            if length > MAX_FUNCTION_LINES:
                found.append(f"line {node.lineno}: {node.name} is {length} lines")
    return found


def suite_modules():
    for package in PACKAGES:
        yield from sorted((ROOT / package).rglob("*.py"))


@pytest.mark.parametrize("path", list(suite_modules()), ids=lambda p: str(p.relative_to(ROOT)))
def test_records_not_names(path):
    assert record_violations(path.read_text(), shape_and_metric_names()) == []


@pytest.mark.parametrize(
    "snippet,caught",
    [
        ("if shape == 'circle':\n    pass\n", True),
        ("x = metric.name in ('l1', 'x')\n", True),
        ("y = ball.kind == 'ellipse'\n", True),
        ("z = ['square', 'triangle']\n", True),
        ("P = {'l2': 2, 'l1': 1}\n", True),
        ("def f():\n" + "    x = 1\n" * 101, True),
        ("if record.curved and shape == DEFAULT:\n    pass\n", False),
        ("w = ['square']\nv = {'square': 1}\n", False),  # one name is a value, not a list
        ("def f():\n" + "    x = 1\n" * 99, False),
    ],
)
def test_the_record_check(snippet, caught):
    names = {"circle", "square", "triangle", "l1", "l2"}
    assert bool(record_violations(snippet, names)) is caught


def test_the_papers_shapes_are_a_selection_of_the_table():
    from compact_distributions.cvt.metrics import PAPER_METRICS, PAPER_SHAPES, SHAPES

    assert PAPER_SHAPES == tuple(s.name for s in SHAPES.values() if s.paper)
    assert len(PAPER_SHAPES) == 5 and len(PAPER_METRICS) == 6
    assert {SHAPES[s].metric for s in PAPER_SHAPES} < set(PAPER_METRICS)


def test_a_paper_shape_is_built_from_its_record_alone():
    """Change the square's record and its metric follows: its geometry has one place."""
    from dataclasses import replace

    from compact_distributions.cvt import metrics

    record = metrics.SHAPES["square"]
    wide = replace(record, facets=((0.0, 2.0), (90.0, 1.0), (180.0, 2.0), (270.0, 1.0)))
    ball = wide.ball()
    # max(|x| / 2, |y|) by hand
    v = np.random.default_rng(3).uniform(-3, 3, (200, 2))
    np.testing.assert_allclose(ball.gauge(v), np.maximum(np.abs(v[:, 0]) / 2, np.abs(v[:, 1])), rtol=1e-12)
    assert ball.name == "linf" and ball.element == "square" and not ball.curved


def test_the_turned_ball_is_the_square_turned():
    """l1 is the square's ball turned by 45° and scaled by 1/√2: |x| + |y| by hand."""
    from compact_distributions.cvt.metrics import make_metric

    ball = make_metric("l1")
    v = np.random.default_rng(4).uniform(-3, 3, (200, 2))
    np.testing.assert_allclose(ball.gauge(v), np.abs(v).sum(axis=1), rtol=1e-12)
    assert ball.element == "square" and ball.turn == pytest.approx(np.pi / 4)


def test_a_users_polygon_is_not_added_to_the_table(tmp_path):
    import json

    from compact_distributions.cvt.metrics import SHAPES, make_metric

    path = tmp_path / "tri.json"
    path.write_text(json.dumps([[0, 0], [3, 0], [0, 2]]))
    before = dict(SHAPES)
    ball = make_metric(f"polygon:{path}")
    assert len(ball.normals) == 3 and SHAPES == before


def test_one_unit_element_type():
    """The unit ball is the one unit-element record: no other class of the suite defines
    a support function, a gauge or an area of its own (the fit's evaluator of compiled
    per-site balls reads :func:`compile_sites`' coefficients, not a shape)."""
    geometry = {"support", "gauge", "gauge_turned", "face_normals", "unit_area", "size_for_area"}
    owners = []
    for path in suite_modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                defined = {f.name for f in node.body if isinstance(f, ast.FunctionDef)}
                if defined & geometry:
                    owners.append(f"{path.relative_to(ROOT)}:{node.name}")
    assert owners == ["cvt/metrics.py:Metric"]


def _turned_outlines(ball, theta, size=1.0):
    from compact_distributions.cvt.metrics import CURVE_SEGMENTS

    c, s = np.cos(theta), np.sin(theta)
    v = ball.outline(4 * CURVE_SEGMENTS) * size
    return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=1)


def _boundary_point(outline, rng):
    """A random point on a closed outline's edges (its vertices for a curved one)."""
    k = rng.integers(len(outline))
    t = rng.uniform()
    return (1 - t) * outline[k] + t * outline[(k + 1) % len(outline)] if len(outline) < 64 else outline[k]


@pytest.mark.parametrize("shape", ["square", "rectangle", "triangle", "circle", "ellipse", "hexagon"])
def test_the_unit_element_against_its_own_outline(shape):
    """Support, gauge, reach, area and symmetry of the element record, each against the
    outline it draws (brute force over its vertices, shapely's area, a turned copy)."""
    import shapely

    from compact_distributions.cvt.shapes import element_ball

    ball = element_ball(shape, 0.5)
    rng = np.random.default_rng(7)
    theta = rng.uniform(0, 2 * np.pi, 50)
    phi = rng.uniform(0, 2 * np.pi, 50)
    nx, ny = np.cos(phi), np.sin(phi)
    brute = np.array(
        [(_turned_outlines(ball, t) @ [x, y]).max() for t, x, y in zip(theta, nx, ny, strict=True)]
    )
    np.testing.assert_allclose(ball.support(nx, ny, np.cos(theta), np.sin(theta)), brute, rtol=2e-4)
    # a point on the boundary of the element of size 3 turned by θ has gauge 3
    on = np.array([_boundary_point(_turned_outlines(ball, t, 3.0), rng) for t in theta])
    g = ball.gauge_turned(on[:, 0], on[:, 1], np.cos(theta), np.sin(theta))
    np.testing.assert_allclose(g, 3.0, rtol=1e-9)
    np.testing.assert_array_equal(ball.reach(on[:, 0], on[:, 1], theta, 0.0), g)
    # with a gap G the element of size reach keeps G/2 off the point, and not much more
    # (shapely's distance to the drawn element)
    far = on * 1.5
    size = ball.reach(far[:, 0], far[:, 1], theta, 0.4)
    gaps = np.array(
        [
            shapely.Polygon(_turned_outlines(ball, t, r)).distance(shapely.Point(p))
            for t, r, p in zip(theta, size, far, strict=True)
        ]
    )
    assert np.all(gaps >= 0.2 - 1e-6) and np.median(gaps) < 0.5
    assert ball.unit_area == pytest.approx(shapely.area(shapely.Polygon(ball.outline(128))), rel=1e-12)
    assert ball.size_for_area(4 * ball.unit_area) == pytest.approx(2.0)
    # turned by its symmetry turn the outline maps onto itself; by half of it, not
    if ball.turns_freely:
        assert shape == "circle"
        return
    a = shapely.Polygon(_turned_outlines(ball, 0.0))
    b = shapely.Polygon(_turned_outlines(ball, ball.symmetry_turn))
    half = shapely.Polygon(_turned_outlines(ball, ball.symmetry_turn / 2))
    assert a.symmetric_difference(b).area < 1e-3 * a.area
    assert a.symmetric_difference(half).area > 1e-2 * a.area
