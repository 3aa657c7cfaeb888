"""The fidelity measures (cvt/evaluate.py: size, direction, grout) against hand
computations on tiny cases and against constructed cases whose answer is known."""

import math

import numpy as np
import pytest
import shapely
from shapely import affinity

from compact_distributions.cvt.evaluate import (
    MEASURES,
    direction_errors,
    fidelity,
    grout,
    measures,
    neighbour_pairs,
    size_fidelity,
)
from compact_distributions.cvt.fields import DensityMap, DirectionField
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.problem import Grid, Problem, lattice_sites
from compact_distributions.cvt.shapes import element_polygons


def _problem(size=120, n=36, density=None, field=None):
    fld = None if field is None else DirectionField.named(field, size, size)
    return Problem(Grid(size, size), n, make_metric("linf"), density=density, field=fld)


def _radial_density(size, contrast=3.0):
    yy, xx = np.mgrid[0:size, 0:size] + 0.5
    r = np.hypot(xx - size / 2, yy - size / 2) / (size / 2 * math.sqrt(2))
    return DensityMap(contrast - (contrast - 1) * r)


# ------------------------------------------------------------------ size fidelity
def test_size_fidelity_by_hand():
    # log2(area/target) = 0, 1, 2: mean 1, RMS about it sqrt((1 + 0 + 1) / 3)
    assert size_fidelity([1.0, 2.0, 4.0], [1.0, 1.0, 1.0]) == pytest.approx(math.sqrt(2 / 3))
    # the scale is fitted: targets 10x the areas change nothing
    assert size_fidelity([1.0, 2.0, 4.0], [10.0, 10.0, 10.0]) == pytest.approx(math.sqrt(2 / 3))
    assert size_fidelity([3.0, 6.0], [1.0, 2.0]) == pytest.approx(0.0, abs=1e-12)


def test_elements_sized_by_the_density_score_zero_and_doubled_half_scores_half():
    size = 120
    density = _radial_density(size)
    problem = _problem(size, density=density)
    centres = lattice_sites(size, size, 6) + 0.5  # pixel centres: off the pixels' edges
    # area ∝ 1/density at the centre: side ∝ 1/sqrt(density)
    d = density.values[centres[:, 1].astype(int), centres[:, 0].astype(int)]
    sides = 6.0 / np.sqrt(d)
    assert np.ptp(sides) > 1.0  # the density really varies
    x, y = centres.T
    exact = list(shapely.box(x - sides / 2, y - sides / 2, x + sides / 2, y + sides / 2))
    assert fidelity(exact, problem, "square")["size_fidelity"] == pytest.approx(0.0, abs=1e-9)
    # every other element twice the area: log2 ratio 0 or 1 in equal numbers, RMS 0.5
    k = math.sqrt(2)
    doubled = [affinity.scale(e, k, k) if i % 2 else e for i, e in enumerate(exact)]
    assert fidelity(doubled, problem, "square")["size_fidelity"] == pytest.approx(0.5)
    # the same elements under a uniform density are off by the density's own spread
    flat = fidelity(exact, _problem(size), "square")["size_fidelity"]
    q = np.log2(1 / d)
    assert flat == pytest.approx(np.sqrt(np.mean((q - q.mean()) ** 2)))


# ------------------------------------------------------------- direction fidelity
@pytest.mark.parametrize("turn,field_deg,expected", [(10, 0, 10), (50, 0, 40), (-30, 0, 30), (95, 5, 0)])
def test_square_direction_by_hand(turn, field_deg, expected):
    square = affinity.rotate(shapely.box(-3, -3, 3, 3), turn, origin=(0, 0))
    err = direction_errors(np.array([square], dtype=object), [math.radians(field_deg)], "square", 1.0)
    assert err[0] == pytest.approx(expected, abs=1e-9)


def test_triangle_and_rectangle_direction_by_hand():
    tri = element_polygons("triangle", 1.0, [[0.0, 0.0]], [math.radians(70)], [5.0])
    # a triangle repeats every 120°: 70° is 50° from 0° (the other way)
    assert direction_errors(tri, [0.0], "triangle", 1.0)[0] == pytest.approx(50, abs=1e-9)
    # a rectangle 4 x 2 (long side along x) against a field of 100°: 80° apart modulo 180°
    rect = np.array([shapely.box(-2, -1, 2, 1)], dtype=object)
    assert direction_errors(rect, [math.radians(100)], "rectangle", 0.5)[0] == pytest.approx(80, abs=1e-9)


@pytest.mark.parametrize("shape", ["square", "rectangle", "ellipse", "triangle"])
def test_lattice_turned_by_a_known_angle_against_a_constant_field(shape):
    problem = _problem(field="constant:5")
    centres = lattice_sites(120, 120, 6)
    elements = element_polygons(shape, 0.5, centres, math.radians(5 + 17), np.full(36, 5.0))
    assert fidelity(list(elements), problem, shape, 0.5)["direction_fidelity"] == pytest.approx(17, abs=1e-6)


def test_circles_have_no_direction():
    problem = _problem(field="constant:5")
    circles = element_polygons("circle", 1.0, lattice_sites(120, 120, 6), 0.3, np.full(36, 5.0))
    assert math.isnan(fidelity(list(circles), problem, "circle")["direction_fidelity"])


# ------------------------------------------------------------------- grout
def test_grout_by_hand_three_in_a_row():
    # gaps 2 and 4 between three boxes in a row (collinear centres: consecutive pairs)
    boxes = np.array([shapely.box(0, 0, 10, 10), shapely.box(12, 0, 22, 10), shapely.box(26, 0, 36, 10)])
    mean, cv = grout(boxes)
    assert mean == pytest.approx(3.0) and cv == pytest.approx(1 / 3)


@pytest.mark.parametrize("gx,gy,mean,cv", [(4.0, 4.0, 4.0, 0.0), (2.0, 4.0, 3.0, 1 / 3)])
def test_square_lattice_with_known_gaps(gx, gy, mean, cv):
    side, k = 10.0, 7
    xs, ys = np.meshgrid(np.arange(k) * (side + gx), np.arange(k) * (side + gy))
    boxes = shapely.box(xs.ravel(), ys.ravel(), xs.ravel() + side, ys.ravel() + side)
    m, c = grout(boxes)
    # k(k-1) horizontal joints of gx and as many vertical ones of gy; no diagonal pair
    assert m == pytest.approx(mean) and c == pytest.approx(cv, abs=1e-9)
    a, b = neighbour_pairs(shapely.get_coordinates(shapely.centroid(boxes)))
    assert len(a) == 2 * k * (k - 1)


def test_neighbours_keep_a_hexagonal_lattice_whole():
    # equilateral triangles have no strictly longest edge: all Delaunay edges stay
    k = 6
    i, j = np.meshgrid(np.arange(k), np.arange(k))
    pts = np.stack([i.ravel() + 0.5 * (j.ravel() % 2), j.ravel() * math.sqrt(3) / 2], axis=1)
    a, b = neighbour_pairs(pts)
    d = np.hypot(*(pts[a] - pts[b]).T)
    assert np.allclose(d, 1.0)
    assert len(a) == 3 * k * k - 4 * k + 1  # the edges of a k x k hexagonal patch


def test_neighbours_of_more_points_than_int32_pairs_hold():
    # 48 400 points: a pair's key a·n + b passes 2**31 (qhull gives int32 indices)
    k = 220
    i, j = np.meshgrid(np.arange(k), np.arange(k))
    rng = np.random.default_rng(0)
    pts = np.stack([i.ravel(), j.ravel()], axis=1) + rng.uniform(-0.2, 0.2, (k * k, 2))
    a, b = neighbour_pairs(pts)
    assert (a < b).all() and np.hypot(*(pts[a] - pts[b]).T).max() < 1.6
    assert len(a) > 1.9 * k * (k - 1)


def test_overlapping_neighbours_are_zero_apart():
    boxes = np.array([shapely.box(0, 0, 10, 10), shapely.box(8, 0, 18, 10)])
    assert grout(boxes)[0] == 0.0


# ------------------------------------------------------------------- all measures
def test_measures_lists_every_measure_once_and_skips_missing_elements():
    problem = _problem(field="constant:0")
    centres = lattice_sites(120, 120, 6)
    els = list(element_polygons("square", 1.0, centres, 0.0, np.full(36, 8.0)))  # 16 px squares, pitch 20
    els[3] = None
    out = measures(els, problem, "square")
    assert list(out) == list(MEASURES)
    assert out["coverage"] == pytest.approx(35 * 256 / 120**2)
    assert out["overlap"] == 0.0 and out["direction_fidelity"] == pytest.approx(0.0, abs=1e-9)
    assert out["size_fidelity"] == pytest.approx(0.0, abs=1e-12)
    # the elements beside the hole at 3 (40 px apart) are the longest edge of their triangle
    # with the one below: no joint across the hole, every other joint is 4 px
    assert out["grout_mean"] == pytest.approx(4.0) and out["grout_cv"] == pytest.approx(0.0, abs=1e-9)
    # scaled by 1.2 the squares (19.2 px, pitch 20) still do not overlap: the curve's best
    assert out["coverage_at_1pct_overlap"] == pytest.approx(35 * 19.2**2 / 120**2)


def test_coverage_at_the_overlap_limit_stops_early_with_the_full_curves_answer():
    from compact_distributions.cvt.evaluate import (
        coverage_at_overlap,
        coverage_at_overlap_limit,
        coverage_overlap_curve,
    )

    grid = Grid(120, 120)
    rng = np.random.default_rng(3)
    centres = lattice_sites(120, 120, 6) + rng.uniform(-2, 2, (36, 2))
    els = list(element_polygons("square", 1.0, centres, rng.uniform(0, 0.3, 36), np.full(36, 8.5)))
    full = coverage_at_overlap(coverage_overlap_curve(els, grid), 0.01)
    assert 0 < full < 1
    assert coverage_at_overlap_limit(els, grid, 0.01) == pytest.approx(full, rel=1e-12)
