"""The baselines of Table 2 (baselines/): valid distributions, determinism, and the
property that defines each method, on small problems."""

import json
import math

import numpy as np
import pytest
import shapely

from compact_distributions.backends.numpy_backend import NumpyBackend
from compact_distributions.baselines import (
    fritzsche2005,
    get_method,
    hausner2001,
    hu2016,
    method_names,
    smith2005,
)
from compact_distributions.baselines.common import (
    angle_residual,
    budget_size,
    rasterize_tiles,
    tile_pixels,
    tile_shape,
    tile_voronoi,
)
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.evaluate import evaluate, region_polygon
from compact_distributions.cvt.fields import DirectionField
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.problem import Grid, Problem
from compact_distributions.cvt.shapes import element_polygons

NAMES = ("hausner2001", "fritzsche2005", "smith2005", "hu2016")
SIZE, N = 128, 48


def square_problem(seed=0, n=N, size=SIZE, field=None, mask=None, metric="linf"):
    f = DirectionField.named(field, size, size) if field else None
    return Problem(Grid(size, size, mask), n, make_metric(metric), field=f, seed=seed)


def run(name, problem, iterations=6, **kw):
    return get_method(name)(problem, NumpyBackend(), iterations=iterations, **kw)


def test_every_baseline_is_registered():
    assert set(NAMES) <= set(method_names())


@pytest.mark.parametrize("name", NAMES)
def test_valid_distribution(name):
    problem = square_problem(seed=3)
    calls = []
    dist = run(name, problem, progress=lambda k, total, e: calls.append((k, total)))
    assert dist.method == name
    assert len(dist.elements) == N and len(dist.sites) == N
    assert dist.angles.shape == (N,) and dist.scales.shape == (N,)
    assert len(dist.seconds) == 6 and len(dist.energy) == 6 and calls[-1] == (6, 6)
    assert dist.lloyd_seconds > 0 and dist.setup_seconds >= 0
    assert dist.labels.shape == (SIZE, SIZE) and dist.labels.min() >= 0
    region = region_polygon(problem.grid)
    placed = [e for e in dist.elements if e is not None]
    assert len(placed) >= N - 2
    for e in placed:
        assert region.buffer(1e-6).contains(e), "element outside the region"
    ev = evaluate(dist.elements, problem.grid)
    assert 0.3 < ev.coverage <= 1.0
    assert 0.0 <= ev.overlap < 0.3
    json.dumps(dist.extra)  # JSON-serialisable details


@pytest.mark.parametrize("name", NAMES)
def test_masked_region_keeps_elements_inside(name):
    yy, xx = np.mgrid[0:SIZE, 0:SIZE] + 0.5
    disc = (xx - 64) ** 2 + (yy - 64) ** 2 < 56**2
    problem = square_problem(seed=1, n=40, mask=disc)
    dist = run(name, problem, iterations=4)
    region = region_polygon(problem.grid)
    for e in dist.elements:
        if e is not None:
            assert region.buffer(1e-6).contains(e)
    assert (dist.labels[~disc] == -1).all()
    ev = evaluate(dist.elements, problem.grid)
    assert 0.2 < ev.coverage <= 1.0


@pytest.mark.parametrize("name", NAMES)
def test_deterministic_by_seed(name):
    a = run(name, square_problem(seed=5), iterations=4)
    b = run(name, square_problem(seed=5), iterations=4)
    c = run(name, square_problem(seed=6), iterations=4)
    np.testing.assert_array_equal(a.sites, b.sites)
    np.testing.assert_array_equal(a.angles, b.angles)
    np.testing.assert_array_equal(a.scales, b.scales)
    assert not np.array_equal(a.sites, c.sites)


@pytest.mark.parametrize("name", NAMES)
def test_bad_element_is_an_input_error(name):
    with pytest.raises(InputError, match="heptagon"):
        run(name, square_problem(), iterations=1, element="heptagon")


@pytest.mark.parametrize("name", ["fritzsche2005", "smith2005", "hu2016"])
def test_natural_element_of_the_metric(name):
    dist = run(name, square_problem(metric="l2"), iterations=3)
    assert dist.extra["element"] == "circle"
    assert evaluate(dist.elements, Grid(SIZE, SIZE)).coverage > 0.3


def _edge_angle(poly) -> float:
    (x0, y0), (x1, y1) = list(poly.exterior.coords)[:2]
    return math.atan2(y1 - y0, x1 - x0)


@pytest.mark.parametrize("field", ["constant:30", "radial"])
def test_hausner_tiles_follow_the_field(field):
    problem = square_problem(seed=2, n=64, field=field)
    dist = run("hausner2001", problem, iterations=8)
    want = problem.field.angles_at(dist.sites)
    np.testing.assert_allclose(angle_residual(dist.angles, want, math.pi / 2), 0, atol=1e-12)
    checked = 0
    for poly, a in zip(dist.elements, want, strict=True):
        if poly is not None and len(poly.exterior.coords) == 5:  # an unclipped square
            assert angle_residual(_edge_angle(poly), a, math.pi / 2) < math.radians(3)
            checked += 1
    assert checked >= 48


def test_hausner_cells_line_up_with_the_field():
    """The L1 metric turned by field + 45° makes square cells along the field: the
    directions to the nearest neighbours cluster at the field angle (modulo 90°)."""
    from scipy.spatial import cKDTree

    problem = square_problem(seed=2, n=250, size=256, field="constant:30")
    dist = run("hausner2001", problem, iterations=20)
    _, idx = cKDTree(dist.sites).query(dist.sites, k=5)
    v = dist.sites[idx[:, 1:]] - dist.sites[:, None, :]
    res = angle_residual(np.arctan2(v[..., 1], v[..., 0]), math.radians(30), math.pi / 2)
    assert np.mean(res < math.radians(15)) > 0.37  # 1/3 if directions were uniform


def test_hausner_keeps_tiles_away_from_the_border():
    problem = square_problem(seed=4, n=64)
    dist = run("hausner2001", problem, iterations=10)
    side = dist.extra["tile_side_px"]
    x, y = dist.sites[:, 0], dist.sites[:, 1]
    border = np.minimum.reduce([x, y, SIZE - x, SIZE - y])
    assert border.min() >= 0.5 * side - 0.5
    # without the edge band the same Lloyd run lets centres come closer to the border
    assert dist.extra["edge_band_px"] == pytest.approx(0.5 * side)


@pytest.mark.parametrize("name", ["fritzsche2005", "smith2005"])
def test_tile_lloyd_steps_raise_coverage_on_average(name):
    before, after, one = [], [], []
    for seed in range(4):
        problem = square_problem(seed=seed)
        before.append(evaluate(run(name, problem, iterations=0).elements, problem.grid).coverage)
        one.append(evaluate(run(name, problem, iterations=1).elements, problem.grid).coverage)
        after.append(evaluate(run(name, problem, iterations=5).elements, problem.grid).coverage)
    assert np.mean(one) >= np.mean(before)
    assert np.mean(after) >= np.mean(before) + 0.02
    assert min(a - b for a, b in zip(after, before, strict=True)) > -0.01


def test_tile_voronoi_is_distance_to_the_tile_not_its_centre():
    # a long thin rectangle and a small square: a point near the rectangle's end is
    # nearer to the rectangle than to the square although nearer to the square's centre
    grid = Grid(100, 40)
    shape = tile_shape(square_problem(metric="linf-axial"), "rectangle")  # aspect 0.5: 4 x 1
    tiles = rasterize_tiles(
        shape, np.array([[30.0, 20.0], [80.0, 20.0]]), np.zeros(2), np.array([10.0, 1.0]), grid
    )
    labels, dist = tile_voronoi(tiles, grid.inside())
    assert labels[20, 62] == 0  # 12 px from the rectangle's end (x=50), 18 from the square
    assert abs(62.5 - 30) > abs(62.5 - 80)  # while the square's centre is nearer
    assert dist[20, 62] == pytest.approx(62 - 49, abs=0.01)
    assert labels[20, 70] == 1


def _pixel_centres_inside(poly, height, width):
    """(rows, columns) of the pixel centres a shapely polygon contains: the truth the
    raster tests are held to."""
    jj, ii = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    inside = shapely.contains_xy(poly, jj.ravel(), ii.ravel()).reshape(height, width)
    return inside


@pytest.mark.parametrize(
    "element,metric",
    [("square", "linf"), ("triangle", "triangle"), ("ellipse", "l2-axial"), ("rectangle", "linf-axial")],
)
def test_tile_pixels_are_the_pixel_centres_inside_the_outline(element, metric):
    grid = Grid(60, 50)
    shape = tile_shape(square_problem(metric=metric), element)
    rng = np.random.default_rng(3)
    for _ in range(6):
        centre = rng.uniform(-5, 65, 2)  # some tiles hang over the raster's edge
        angle, size = rng.uniform(0, math.pi), rng.uniform(2, 12)
        poly = element_polygons(element, shape.aspect, centre, angle, size)[0]
        truth = _pixel_centres_inside(poly, 50, 60)
        got = np.zeros((50, 60), bool)
        got[tile_pixels(shape, centre, angle, size, grid)] = True
        # curved outlines are 128-gons: a pixel centre within a hair of the curve may differ
        assert (got != truth).sum() <= (2 if element == "ellipse" else 0)
    assert len(tile_pixels(shape, (30.0, 20.0), 0.0, 0.0, grid)[0]) == 0


@pytest.mark.parametrize("element,metric", [("square", "linf"), ("triangle", "triangle")])
def test_smith_fit_counts_match_a_pixel_count_by_point_in_polygon(element, metric):
    # labels: a hand-made partition of a 40x30 raster into three vertical bands
    labels = np.full((30, 40), -1, np.int32)
    labels[:, 2:14], labels[:, 14:27], labels[:, 27:39] = 0, 1, 2
    shape = tile_shape(square_problem(metric=metric), element)
    centres = np.array([[8.3, 14.2], [20.1, 15.7], [33.0, 9.4]])
    sizes = np.array([7.0, 9.5, 6.0])
    angles = np.array([[0.0, 0.3, 0.7], [0.1, 0.5, 1.2], [-0.4, 0.25, 2.0]])
    counts = smith2005.fit_counts(shape, labels, centres, sizes, angles)
    for i in range(3):
        for a in range(3):
            poly = element_polygons(element, shape.aspect, centres[i], angles[i, a], sizes[i])[0]
            truth = (_pixel_centres_inside(poly, 30, 40) & (labels == i)).sum()
            assert counts[i, a] == truth, (i, a)


def _random_state(seed, n=30, size=96):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0, size, (n, 2))
    angles = rng.uniform(0, math.pi / 2, n)
    sizes = rng.uniform(0.5, 7.0, n)
    sizes[rng.random(n) < 0.2] = 0.0  # some absent tiles
    return centres, angles, sizes


def test_hu_combinatorial_step_never_lowers_coverage():
    grid = Grid(96, 96)
    shape = tile_shape(square_problem(), "square")
    accepted = 0
    for seed in range(8):
        centres, angles, sizes = _random_state(seed)
        shape_elems = hu2016.make_elements(shape, centres, angles, sizes, grid)[0]
        before = evaluate(shape_elems, grid).coverage
        c2, a2, s2, info = hu2016.combinatorial_step(shape, centres, angles, sizes, grid, moves=6)
        after = evaluate(hu2016.make_elements(shape, c2, a2, s2, grid)[0], grid).coverage
        assert after >= before - 1e-12
        assert after - before == pytest.approx(info["gain"], abs=1e-9)
        accepted += info["accepted"]
    assert accepted > 0


def test_hu_combinatorial_step_moves_a_tiny_tile_into_a_hole():
    grid = Grid(64, 64)
    shape = tile_shape(square_problem(), "square")
    # a 4 x 4 lattice of 16 px cells, tiles of half-side 7, one of them tiny, one missing
    xs = (np.arange(4) + 0.5) * 16
    centres = np.stack(np.meshgrid(xs, xs), axis=-1).reshape(-1, 2)
    sizes = np.full(16, 7.0)
    sizes[5] = 0.5
    sizes[10] = 0.0
    angles = np.zeros(16)
    before = evaluate(hu2016.make_elements(shape, centres, angles, sizes, grid)[0], grid).coverage
    c2, a2, s2, info = hu2016.combinatorial_step(shape, centres, angles, sizes, grid, moves=2)
    after = evaluate(hu2016.make_elements(shape, c2, a2, s2, grid)[0], grid).coverage
    assert info["accepted"] == 2
    assert after > before + 0.015
    assert s2[10] > 6.0 and s2[5] > 6.0


def test_hu_tiles_do_not_overlap_and_coverage_grows():
    problem = square_problem(seed=7)
    short = run("hu2016", problem, iterations=2)
    longer = run("hu2016", problem, iterations=8)
    ev_s = evaluate(short.elements, problem.grid)
    ev_l = evaluate(longer.elements, problem.grid)
    assert ev_l.overlap < 0.005  # each tile is fitted inside its own region
    assert ev_l.coverage > ev_s.coverage
    cov = longer.extra["raster_coverage_before_step"]
    assert cov[-1] > cov[0]


def test_fixed_size_budget_is_the_same_for_every_fixed_tile_method():
    problem = square_problem()
    want = budget_size(tile_shape(problem, "square"), problem.grid, N)
    assert want == pytest.approx(0.95 * math.sqrt(SIZE * SIZE / N) / 2)
    for mod in (hausner2001, fritzsche2005, smith2005):
        dist = mod.run(problem, NumpyBackend(), iterations=2)
        inner = [
            e for e in dist.elements if e is not None and min(e.bounds) > 1e-6 and max(e.bounds) < SIZE - 1e-6
        ]  # not clipped
        assert len(inner) > N // 2
        assert np.allclose([e.area for e in inner], (2 * want) ** 2)


def test_gap_shrinks_fixed_tiles():
    problem = square_problem()
    plain = fritzsche2005.run(problem, None, iterations=2)
    grout = fritzsche2005.run(problem, None, iterations=2, gap=2.0)
    a = shapely.area(np.array([e for e in plain.elements if e is not None])).max()
    b = shapely.area(np.array([e for e in grout.elements if e is not None])).max()
    side = math.sqrt(a)
    assert math.sqrt(b) == pytest.approx(side - 2.0)


def test_cli_runs_a_baseline(tmp_path, capsys):
    from compact_distributions.bench.commands.cli import main

    out = tmp_path / "run"
    code = main(
        [
            "run",
            "--method",
            "smith2005",
            "--metric",
            "linf",
            "--size",
            "96",
            "--elements",
            "30",
            "--iterations",
            "3",
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert code == 0
    result = json.loads((out / "result.json").read_text())
    assert result["method"] == "smith2005" and result["iterations"] == 3
    assert (out / "cells.png").is_file()
    assert 0 < result["coverage"] <= 1 and result["overlap"] >= 0
