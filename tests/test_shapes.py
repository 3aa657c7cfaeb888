"""Shapes as records: hexagons, octagons, the user's convex polygon, and a shape that is
one record defined here, each checked against independent geometry and run end to end."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely

from compact_distributions.bench.commands.cli import main
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.metrics import SHAPES, Shape, convex_unit_ball, make_metric
from compact_distributions.cvt.problem import Grid

from .cli_errors import one_error


def brute_gauge(vertices: np.ndarray, v: np.ndarray) -> np.ndarray:
    """min t with v in t·P, by bisection on shapely's point-in-polygon test."""
    poly = shapely.Polygon(vertices)
    lo, hi = np.zeros(len(v)), np.full(len(v), 10.0)
    for _ in range(50):
        mid = (lo + hi) / 2
        inside = shapely.contains_xy(poly, v[:, 0] / mid, v[:, 1] / mid)
        hi = np.where(inside, mid, hi)
        lo = np.where(inside, lo, mid)
    return hi


@pytest.mark.parametrize("name,sides", [("hexagon", 6), ("octagon", 8)])
def test_gauge_of_the_regular_polygons_against_point_in_polygon(name, sides):
    m = make_metric(name)
    t = np.radians(SHAPES[name].phase + 360.0 * np.arange(sides) / sides)
    vertices = np.stack([np.cos(t), np.sin(t)], axis=1)  # circumradius 1, by hand
    v = np.random.default_rng(sides).uniform(-3, 3, (400, 2))
    np.testing.assert_allclose(m.gauge(v), brute_gauge(vertices, v), atol=1e-9)
    assert m.inradius == pytest.approx(math.cos(math.pi / sides)) and m.circumradius == pytest.approx(1.0)


def test_numpy_labels_are_the_per_pixel_minimum(reference):
    rng = np.random.default_rng(5)
    w, h, n = 40, 32, 12
    sites = rng.random((n, 2)) * [w, h]
    angles, scales = rng.uniform(-np.pi, np.pi, n), rng.uniform(0.7, 1.4, n)
    for name in ("hexagon", "octagon"):
        m = make_metric(name)
        labels = reference.label(sites, angles=angles, scales=scales, metric=m, grid=Grid(w, h))
        ys, xs = np.mgrid[0:h, 0:w] + 0.5
        d = np.empty((n, h, w))
        for i in range(n):  # each site's distance by its own turned and scaled gauge
            vx, vy = xs - sites[i, 0], ys - sites[i, 1]
            c, s = math.cos(angles[i]), math.sin(angles[i])
            local = np.stack([c * vx + s * vy, -s * vx + c * vy], axis=-1)  # R(-θ) v
            d[i] = m.gauge(local) / scales[i]
        best = d.min(axis=0)
        # the label is a site at the minimum distance (ties may go either way in float)
        got = np.take_along_axis(d, labels[None], axis=0)[0]
        np.testing.assert_allclose(got, best, atol=1e-9)
        assert (labels == d.argmin(axis=0)).mean() > 0.999


def irregular_pentagon(tmp_path, fmt="json"):
    pts = [[0, 0], [4, 0], [5, 2.5], [2, 4.2], [-0.6, 2]]
    path = tmp_path / f"penta.{fmt}"
    if fmt == "json":
        path.write_text(json.dumps(pts[::-1]))  # any order
    else:
        path.write_text("x,y\n" + "\n".join(f"{10 * x},{10 * y}" for x, y in pts))  # any scale
    return path


@pytest.mark.parametrize("fmt", ["json", "csv"])
def test_the_users_polygon_is_normalised_about_its_centroid(tmp_path, fmt):
    path = irregular_pentagon(tmp_path, fmt)
    m = make_metric(f"polygon:{path}")
    ring = m.outline()
    poly = shapely.Polygon(ring)
    assert poly.is_valid and len(ring) == 5
    assert poly.centroid.x == pytest.approx(0, abs=1e-12) and poly.centroid.y == pytest.approx(0, abs=1e-12)
    assert np.hypot(*ring.T).max() == pytest.approx(1.0)
    v = np.random.default_rng(1).uniform(-2, 2, (300, 2))
    np.testing.assert_allclose(m.gauge(v), brute_gauge(ring, v), atol=1e-9)


def test_opencl_labels_the_users_polygon_as_numpy(tmp_path, reference, ocl):
    m = make_metric(f"polygon:{irregular_pentagon(tmp_path)}")
    rng = np.random.default_rng(2)
    sites = rng.random((50, 2)) * [96, 80]
    a, s = rng.uniform(-np.pi, np.pi, 50), rng.uniform(0.6, 1.5, 50)
    ref = reference.label(sites, angles=a, scales=s, metric=m, grid=Grid(96, 80))
    got = ocl.label(sites, angles=a, scales=s, metric=m, grid=Grid(96, 80))
    assert (got != ref).mean() < 1e-3  # float32 ties at most


@pytest.mark.parametrize(
    "points,text",
    [
        ([[0, 0], [4, 0], [1, 1], [0, 4]], "not convex"),
        ([[0, 0], [1, 1], [2, 2]], "degenerate"),
        ([[0, 0], [1, 1], [0, 0], [1, 1]], "2 distinct vertices"),
        ([[0, 0], [1, "a"]], "vertices"),
        ([[0, 0], [4, 4], [4, 0], [0, 4]], "crosses itself"),  # a bow tie: its hull is a square
        # a pentagram: every turn the same way, round twice
        ([[math.cos(a), math.sin(a)] for a in np.radians(90 + 144 * np.arange(5))], "crosses itself"),
        ([[0, 0], [4, 0], [4, 4], [0, 0], [0, 4]], "crosses itself"),  # a vertex visited twice
    ],
)
def test_bad_polygons_are_refused(points, text):
    with pytest.raises(InputError, match=text):
        convex_unit_ball(points)


def test_closed_rings_and_repeated_vertices_are_the_same_polygon():
    square = [[0, 0], [4, 0], [4, 4], [0, 4]]
    plain = convex_unit_ball(square)
    np.testing.assert_allclose(plain, [[-1, -1], [1, -1], [1, 1], [-1, 1]] / np.sqrt(2), atol=1e-15)
    for ring in (
        square + [[0, 0]],  # closed
        [[0, 0], [4, 0], [4, 0], [4, 4], [0, 4], [0, 4]],  # repeated in a row
        square[::-1],  # clockwise
        [[2, 0], [4, 0], [4, 4], [0, 4], [0, 0]],  # a vertex in the middle of a side
    ):
        np.testing.assert_array_equal(convex_unit_ball(ring), plain)


@pytest.mark.parametrize(
    "content,text",
    [
        ("[[0,0],[4,0],[1,1],[0,4]]", "not convex"),
        ("[[0,0],[1,1]]", "2 distinct vertices"),
        ("x,y\n0,0\n1,1\n2,2\n", "degenerate"),
        ("a,b\n0,0\n", "needs columns x and y"),
        ("[[0,0],", "not valid json"),
    ],
)
def test_bad_polygon_files_are_one_line_and_write_nothing(tmp_path, capsys, content, text):
    path = tmp_path / "bad.txt"
    path.write_text(content)
    out = tmp_path / "o"
    line = one_error(
        ["run", "--element", f"polygon:{path}", "--elements", "20", "--size", "64", "--out", out], capsys
    )
    assert text in line and not out.exists()


def test_a_new_shape_is_one_record(monkeypatch, tmp_path, reference, ocl):
    """A heptagon, defined here and nowhere else: Lloyd on NumPy and OpenCL, placement,
    compaction and the SVG, as a user runs them."""
    import compact_distributions as cd

    record = Shape("heptagon", "heptagon", 7, 2 * math.pi / 7, 0.89, sides=7, phase=90.0)
    monkeypatch.setitem(SHAPES, "heptagon", record)
    m = make_metric("heptagon")
    assert len(m.normals) == 7 and m.circumradius == pytest.approx(1.0)
    problem = cd.problem(n_elements=150, size=160, element="heptagon", seed=3)
    on_numpy = cd.run(problem, "ours-compact", backend=reference, iterations=8)
    on_opencl = cd.run(problem, "ours-compact", backend=ocl, iterations=8)
    for r in (on_numpy, on_opencl):
        polys = [p for p in r.elements if p is not None]
        assert len(polys) == 150 and all(len(p.exterior.coords) == 8 for p in polys)
        tree = shapely.STRtree(polys)
        a, b = tree.query(polys, predicate="overlaps")
        assert (a == b).all()  # no two overlap (exact shapely)
        assert r.coverage > 0.8
    assert np.abs(on_numpy.distribution.sites - on_opencl.distribution.sites).max() < 0.5
    assert (
        main(
            [
                "run",
                "--method",
                "ours-compact",
                "--element",
                "heptagon",
                "--elements",
                "60",
                "--size",
                "96",
                "--iterations",
                "4",
                "--quiet",
                "--out",
                str(tmp_path / "r"),
            ]
        )
        == 0
    )
    svg = (tmp_path / "r" / "elements.svg").read_text()
    assert svg.count("<path") + svg.count("<polygon") == 60
    assert json.loads((tmp_path / "r" / "result.json").read_text())["metric"] == "heptagon"
