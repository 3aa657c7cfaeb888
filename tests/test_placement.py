"""Placement of elements in cells (cvt/placement.py), run_ours with elements, and the
`cvtbench run --element/--gap` and `cvtbench figures` commands."""

import json
import math

import numpy as np
import pytest
import shapely
from PIL import Image

from compact_distributions.backends.numpy_backend import NumpyBackend
from compact_distributions.bench.commands.cli import main
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.evaluate import evaluate
from compact_distributions.cvt.fields import DensityMap, DirectionField
from compact_distributions.cvt.metrics import METRIC_NAMES, make_metric
from compact_distributions.cvt.placement.fit import (
    contour_samples,
    element_for,
    place_elements,
    placement_sizes,
)
from compact_distributions.cvt.placement.ours import run_ours
from compact_distributions.cvt.problem import Grid, Problem, lattice_sites

from .cli_errors import one_error

HEX_DENSITY = math.pi / (2 * math.sqrt(3))


@pytest.fixture(scope="module")
def backend():
    return NumpyBackend()


def hex_sites(width, height, d):
    """Sites of a hexagonal lattice with spacing d (rows d·√3/2 apart, odd rows shifted)."""
    dy = d * math.sqrt(3) / 2
    rows = int(height / dy)
    pts = [
        ((c + 0.25 + 0.5 * (r % 2)) * d, (r + 0.5) * dy) for r in range(rows) for c in range(int(width / d))
    ]
    return np.array(pts)


def cell_polygon(labels, i):
    rows, cols = np.nonzero(labels == i)
    return shapely.coverage_union_all(shapely.box(cols, rows, cols + 1, rows + 1))


# ------------------------------------------------------------------ analytic checks
@pytest.mark.parametrize("width,k", [(120, 5), (100, 7), (90, 4)])
def test_square_lattice_fills_with_squares(backend, width, k):
    """k x k linf lattice: coverage >= 1 - 2/side, no overlap; exact when side is whole."""
    grid = Grid(width, width)
    sites = lattice_sites(width, width, k)
    labels = backend.label(sites, metric=make_metric("linf"), grid=grid)
    els = place_elements(labels, sites, np.zeros(k * k), "square", 1.0, grid)
    ev = evaluate(els, grid)
    side = width / k
    assert ev.skipped == 0 and ev.elements == k * k
    assert ev.coverage >= 1 - 2 / side
    assert ev.overlap < 1e-9
    if side == int(side):
        assert ev.coverage == pytest.approx(1.0, abs=1e-12)


def test_hexagonal_lattice_circles_approach_packing_density(backend):
    """Circles in hexagonal l2 cells: π/(2√3) ≈ 0.9069 in an inner window, closer as the
    cells grow (the raster costs a fraction of a pixel of each radius)."""
    covs = []
    for d, w in ((16, 320), (40, 480)):
        grid = Grid(w, w)
        sites = hex_sites(w, w, d)
        labels = backend.label(sites, metric=make_metric("l2"), grid=grid)
        els = place_elements(labels, sites, None, "circle", 1.0, grid)
        m = 3 * d
        ev = evaluate(els, grid, region=shapely.box(m, m, w - m, w - m))
        r = d / 2
        assert ev.overlap == 0.0
        assert HEX_DENSITY * (1 - 1.0 / r) ** 2 <= ev.coverage <= HEX_DENSITY + 0.01, (d, ev.coverage)
        covs.append(ev.coverage)
    assert HEX_DENSITY - covs[1] < HEX_DENSITY - covs[0]
    assert covs[1] > 0.87


@pytest.mark.parametrize("shape,turn", [("square", 0.3), ("triangle", 1.1), ("ellipse", 0.7)])
def test_element_touches_its_contour(backend, shape, turn):
    """The size is the largest that keeps every contour sample out of the element: the
    element's gauge at the nearest sample is exactly 1 (touching, not crossing)."""
    grid = Grid(80, 80)
    sites = lattice_sites(80, 80, 3) + 0.37
    n = len(sites)
    labels = backend.label(sites, metric=make_metric("l2"), grid=grid)
    angles = np.full(n, turn)
    els = place_elements(labels, sites, angles, shape, 0.5, grid)
    owner, x, y = contour_samples(labels)
    for i, e in enumerate(els):
        pts = shapely.points(x[owner == i], y[owner == i])
        d = shapely.distance(e.boundary, pts)
        # no sample inside (up to rounding: the touching sample lies on the outline)
        assert not shapely.contains_properly(e.buffer(-1e-9, join_style="mitre"), pts).any()
        # one sample on the outline (curves: up to the inscribed 128-gon's sagitta)
        assert d.min() < (1e-6 if shape != "ellipse" else 0.01)


# ------------------------------------------------------------------ random problems
def random_problem(metric, seed, size=112, n=70):
    yy, xx = np.mgrid[0:size, 0:size]
    density = DensityMap(0.2 + xx / size + (yy / size) ** 2)
    field = DirectionField.named("wave:70", size, size)
    return Problem(Grid(size, size), n, make_metric(metric), density, field, seed)


@pytest.mark.parametrize("metric", METRIC_NAMES)
def test_random_problems_stay_in_their_cells(backend, metric):
    """Every metric with angles and scales: overlap < 0.5 %, and no element leaves its
    cell by more than one pixel (half a pixel for all but triangles, whose 60° tip can
    slip √3/2 px between two contour samples)."""
    for seed in (3, 8):
        problem = random_problem(metric, seed)
        dist = run_ours(problem, backend, iterations=8)
        els, labels = dist.elements, dist.labels
        ev = evaluate(els, problem.grid, labels=labels)
        assert ev.overlap < 0.005
        assert ev.coverage > 0.3
        reach = 0.87 if dist.extra["element"] == "triangle" else 0.5
        placed = 0
        for i, e in enumerate(els):
            if e is None:
                continue
            placed += 1
            cell = cell_polygon(labels, i)
            assert e.difference(cell.buffer(1.0, quad_segs=32)).area < 1e-3, (metric, seed, i)
            assert e.difference(cell.buffer(reach + 0.01, quad_segs=32)).area < 1e-3, (metric, seed, i)
        assert placed == ev.elements >= len(els) - ev.skipped


def test_l1_places_diamonds(backend):
    """The l1 ball is the square turned by 45°: squares in an l1 CVT are turned to match."""
    assert element_for(make_metric("l1")) == ("square", pytest.approx(math.pi / 4))
    assert element_for(make_metric("linf")) == ("square", 0.0)
    assert element_for(make_metric("l2"), "triangle") == ("triangle", 0.0)
    grid = Grid(96, 96)
    # a diamond lattice: sites on a square lattice turned by 45°
    s = [(x, y) for x in range(8, 96, 16) for y in range(8, 96, 16)]
    s += [(x + 8, y + 8) for x, y in s if x + 8 < 96 and y + 8 < 96]
    sites = np.array(s, dtype=float) + 0.01
    labels = backend.label(sites, metric=make_metric("l1"), grid=grid)
    shape, turn = element_for(make_metric("l1"))
    diamonds = place_elements(labels, sites, np.full(len(sites), turn), shape, 1.0, grid)
    upright = place_elements(labels, sites, None, shape, 1.0, grid)
    m = 20
    win = shapely.box(m, m, 96 - m, 96 - m)
    c_d = evaluate(diamonds, grid, region=win).coverage
    c_u = evaluate(upright, grid, region=win).coverage
    assert c_d > 0.85 and c_d > c_u + 0.3


# ------------------------------------------------------------------ gap
def test_gap_shrinks_elements(backend):
    grid = Grid(120, 120)
    sites = lattice_sites(120, 120, 5)  # 24 px cells
    labels = backend.label(sites, metric=make_metric("linf"), grid=grid)
    for g in (0.0, 2.0, 5.0):
        ev = evaluate(place_elements(labels, sites, None, "square", 1.0, grid, gap=g), grid)
        assert ev.coverage == pytest.approx(((24 - g) / 24) ** 2, abs=1e-9)  # joint of g px
    problem = random_problem("l2-axial", 5)
    dist = run_ours(problem, backend, iterations=6)
    covs = [
        evaluate(
            place_elements(dist.labels, dist.sites, dist.angles, "ellipse", 0.5, problem.grid, gap=g),
            problem.grid,
        ).coverage
        for g in (0, 1, 2)
    ]
    assert covs[0] > covs[1] > covs[2] > 0


def test_gap_on_rectangles_is_a_joint_of_g_pixels(backend):
    """A rectangle keeps G/2 from each side of its cell: two 80x20 cells one above the
    other get rectangles 4:1 with a joint of exactly G pixels between them."""
    grid = Grid(80, 40)
    sites = np.array([[40.0, 10.0], [40.0, 30.0]])
    labels = backend.label(sites, metric=make_metric("linf-axial", 0.5), grid=grid)
    assert (labels[:20] == 0).all() and (labels[20:] == 1).all()
    els = place_elements(labels, sites, None, "rectangle", 0.5, grid, gap=4.0)
    minx, miny, maxx, maxy = els[0].bounds
    assert els[1].bounds[1] - maxy == pytest.approx(4.0)  # the joint
    assert miny == pytest.approx(2.0)  # G/2 from the raster's edge too
    assert (maxx - minx) / (maxy - miny) == pytest.approx(4.0)


def test_huge_gap_skips_every_element(backend):
    grid = Grid(60, 60)
    sites = lattice_sites(60, 60, 3)
    labels = backend.label(sites, metric=make_metric("linf"), grid=grid)
    els = place_elements(labels, sites, None, "square", 1.0, grid, gap=25)
    assert els == [None] * 9
    assert evaluate(els, grid).skipped == 9


# ------------------------------------------------------------------ degenerate cells
def test_empty_cell_is_skipped_and_counted(backend):
    grid = Grid(40, 40)
    sites = np.array([[10.5, 10.5], [10.5, 10.5], [30.0, 30.0]])  # site 1 loses every tie
    labels = backend.label(sites, metric=make_metric("l2"), grid=grid)
    assert not (labels == 1).any()
    els = place_elements(labels, sites, None, "circle", 1.0, grid)
    assert els[1] is None and els[0] is not None and els[2] is not None
    ev = evaluate(els, grid, labels=labels)
    assert ev.skipped == 1 and ev.empty_cells == 1 and ev.elements == 2


def test_one_pixel_cell_gets_a_one_pixel_element():
    grid = Grid(9, 9)
    labels = np.zeros((9, 9), dtype=np.int32)
    labels[4, 4] = 1
    sites = np.array([[2.0, 2.0], [4.5, 4.5]])
    els = place_elements(labels, sites, None, "square", 1.0, grid)
    assert els[1].area == pytest.approx(1.0)  # exactly the pixel
    assert shapely.equals(els[1], shapely.box(4, 4, 5, 5))
    assert els[0].area == pytest.approx(16.0)  # the raster's edge, 2 px away, limits it
    assert not els[0].intersects(shapely.box(4, 4, 5, 5).buffer(-0.01))
    tri = place_elements(labels, sites, None, "triangle", 1.0, grid)[1]
    assert 0 < tri.area < 1


def test_sites_on_region_edge_or_outside(backend):
    """A site on the raster's edge, on the region's edge and outside the region: no
    crash; the element is skipped or tiny, and the skip is counted."""
    mask = np.zeros((40, 40), dtype=bool)
    mask[:, :30] = True
    grid = Grid(40, 40, mask)
    sites = np.array([[0.0, 20.0], [30.0, 10.5], [35.0, 30.0], [15.0, 20.0], [25.0, 34.0]])
    labels = backend.label(sites, metric=make_metric("l2"), grid=grid)
    labels[~mask] = -1
    els = place_elements(labels, sites, None, "circle", 1.0, grid)
    assert els[0] is None or els[0].area < 2.0  # on the raster's left edge
    assert els[1] is None  # x = 30 lies in the first pixel outside the region
    assert els[2] is None  # outside the region
    assert els[3] is not None and els[3].area > 20
    ev = evaluate(els, grid, labels=labels)
    assert ev.skipped >= 2 and ev.overlap < 1e-9
    sizes = placement_sizes(labels, sites, None, "circle", 1.0)
    assert (sizes >= 0).all() and sizes[2] == 0


def test_bad_inputs_raise_input_error():
    grid = Grid(10, 10)
    labels = np.zeros((10, 10), dtype=np.int32)
    sites = np.array([[5.0, 5.0]])
    with pytest.raises(InputError, match="heptagon"):
        place_elements(labels, sites, None, "heptagon", 1.0, grid)
    for bad in (-1, float("nan"), float("inf"), "wide"):
        with pytest.raises(InputError, match="gap"):
            place_elements(labels, sites, None, "square", 1.0, grid, gap=bad)
    with pytest.raises(InputError, match="label raster"):
        place_elements(labels[:5], sites, None, "square", 1.0, grid)


def test_run_ours_returns_elements_and_labels(backend):
    problem = random_problem("linf-axial", 1, size=64, n=30)
    dist = run_ours(problem, backend, iterations=3, element="ellipse", gap=0.5)
    assert len(dist.elements) == 30 and dist.labels.shape == (64, 64)
    assert dist.extra["element"] == "ellipse" and dist.extra["gap"] == 0.5
    assert dist.extra["placement_seconds"] >= 0 and dist.extra["final_label_seconds"] >= 0
    assert len(shapely.get_coordinates(next(e for e in dist.elements if e is not None))) > 100


# ------------------------------------------------------------------ CLI
def test_cli_run_with_element_writes_svg_png_and_coverage(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(
        [
            "run",
            "--elements",
            "40",
            "--size",
            "80x64",
            "--iterations",
            "3",
            "--metric",
            "linf",
            "--element",
            "circle",
            "--gap",
            "1",
            "--quiet",
            "--out",
            str(out),
        ]
    )
    err = capsys.readouterr().err
    assert code == 0, err
    r = json.loads((out / "result.json").read_text())
    assert r["element"] == "circle" and r["gap"] == 1.0
    assert 0.2 < r["coverage"] < 1 and 0 <= r["overlap"] < 0.005
    assert r["placed"] + r["skipped"] == 40 and len(r["elements"]) == 40
    assert r["empty_cells"] == 0 and r["min_element_area"] <= r["max_element_area"]
    assert len(r["empty_cells_per_iteration"]) == 3 and r["empty_cells_per_iteration"][-1] == 0
    placed = [e for e in r["elements"] if e is not None]
    assert all(len(e) >= 100 for e in placed)
    import xml.etree.ElementTree as ET

    root = ET.parse(out / "elements.svg").getroot()
    paths = root.findall("{http://www.w3.org/2000/svg}g/{http://www.w3.org/2000/svg}path")
    assert len(paths) == r["placed"] and root.get("viewBox") == "0 0 80 64"
    with Image.open(out / "elements.png") as im:
        assert im.size == (80, 64)


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["--element", "heptagon"], "heptagon"),
        (["--gap", "-1"], "-1"),
        (["--gap", "nan"], "nan"),
    ],
)
def test_cli_bad_element_or_gap_exits_2(tmp_path, capsys, argv, needle):
    out = tmp_path / "bad"
    assert needle in one_error(
        ["run", "--elements", "10", "--size", "32", "--iterations", "1", "--out", out, *argv], capsys
    )
    assert not out.exists()


def test_figures_quick(tmp_path, capsys):
    code = main(["figures", "--quick", "--quiet", "--out", str(tmp_path)])
    assert code == 0, capsys.readouterr().err
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == [
        "fig03_metrics.png",
        "fig14_elements.png",
        "fig14_more_shapes.png",
        "fig15_regions.png",
        "fig18_field_leaf.png",
        "fig18_field_shapes.png",
        "fig19_density_rings.png",
        "fig19_density_shapes.png",
        "mosaic_scene.png",
        "mosaic_scene_edges.png",
        "mosaic_scene_methods.png",
    ]
    for name in names:
        assert (tmp_path / name).stat().st_size < 300_000
        with Image.open(tmp_path / name) as im:
            im.load()
            assert (
                im.size[0] > 200 and len(np.unique(np.asarray(im.convert("RGB")).reshape(-1, 3), axis=0)) > 20
            )


# --- fit="centre": the element's centre moves inside its cell ------------------------------
@pytest.mark.parametrize(
    "metric,shape", [("linf", "square"), ("l2", "circle"), ("l2-axial", "ellipse"), ("triangle", "triangle")]
)
def test_centre_fit_grows_elements_and_stays_in_cell(metric, shape):
    from compact_distributions.cvt.lloyd import final_labels, lloyd
    from compact_distributions.cvt.placement.fit import fit_centres

    p = Problem(Grid(160, 128), 70, make_metric(metric), seed=2)
    b = NumpyBackend()
    r = lloyd(p, b, 6)
    lab = final_labels(p, b, r)
    base = placement_sizes(lab, r.sites, r.angles, shape, p.metric.aspect)
    centres, sizes = fit_centres(lab, r.sites, r.angles, shape, p.metric.aspect)
    assert (sizes >= base - 1e-12).all() and (sizes > base + 1e-6).sum() > len(base) // 3
    j, i = np.floor(centres[sizes > 0]).astype(int).T
    assert (lab[i, j] == np.flatnonzero(sizes > 0)).all()  # centre in a pixel of its own cell
    site = evaluate(place_elements(lab, r.sites, r.angles, shape, p.metric.aspect, p.grid), p.grid)
    fit = evaluate(
        place_elements(lab, r.sites, r.angles, shape, p.metric.aspect, p.grid, fit="centre"), p.grid
    )
    assert fit.coverage > site.coverage and fit.overlap < 0.005


def test_unknown_fit_is_an_input_error():
    g = Grid(8, 8)
    with pytest.raises(InputError, match="unknown fit 'best'"):
        place_elements(np.zeros((8, 8), np.int32), [[4.0, 4.0]], None, "square", 1.0, g, fit="best")


# --- the centre fit against a search written out cell by cell -----------------------------
def _cell_samples_by_hand(labels, i):
    """Midpoints of the unit edges between cell i's pixels and any other (or the border)."""
    h, w = labels.shape
    out = []
    for r, c in zip(*np.nonzero(labels == i), strict=True):
        for dr, dc, x, y in (
            (0, -1, c, r + 0.5),
            (0, 1, c + 1, r + 0.5),
            (-1, 0, c + 0.5, r),
            (1, 0, c + 0.5, r + 1),
        ):
            rr, cc = r + dr, c + dc
            if not (0 <= rr < h and 0 <= cc < w) or labels[rr, cc] != i:
                out.append((x, y))
    return np.array(out, dtype=np.float64)


def _size_by_hand(ball, samples, centre, angle, half, labels, i):
    """Largest size at ``centre``: the textbook gauge ρ(R(-θ)(q - p)), grout kept clear."""
    h, w = labels.shape
    x, y = centre
    if not (0 <= x < w and 0 <= y < h) or labels[int(np.floor(y)), int(np.floor(x))] != i:
        return 0.0
    c, s = math.cos(angle), math.sin(angle)
    v = samples - centre
    u = np.stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]], axis=1)  # R(-θ) v
    if not ball.curved:
        f = ball.normals / ball.offsets[:, None]
        reach = (u @ f.T - half * np.hypot(f[:, 0], f[:, 1])).max(axis=1)
    else:
        a, b = ball.semi_axes
        rho = np.hypot(u[:, 0] / a, u[:, 1] / b)
        grad = np.hypot(u[:, 0] / a**2, u[:, 1] / b**2) / np.where(rho > 0, rho, 1)
        reach = rho - half * np.where(rho > 0, grad, 0)
    return max(float(reach.min()), 0.0)


def _search_by_hand(ball, samples, start, angle, half, labels, i):
    centre = np.array(start, dtype=np.float64)
    best = _size_by_hand(ball, samples, centre, angle, half, labels, i)
    for frac in (0.3, 0.15, 0.075, 0.0375):
        for _ in range(3):
            step, grew = frac * max(best, 1.0), False
            for move in ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)):
                trial = centre + step * np.array(move, dtype=np.float64)
                size = _size_by_hand(ball, samples, trial, angle, half, labels, i)
                if size > best * (1 + 1e-9):
                    centre, best, grew = trial, size, True
            if not grew:
                break
    return centre, best


@pytest.fixture(params=["host", "opencl"])
def search(request):
    """The centre search of fit_centres: the host's (None), or the OpenCL kernel's."""
    return None if request.param == "host" else request.getfixturevalue("ocl").fit_search


@pytest.mark.parametrize(
    "metric,shape,gap,field",
    [
        ("linf", "square", 1.0, None),
        ("l2-axial", "ellipse", 0.0, "circular"),
        ("triangle", "triangle", 1.5, "circular"),
        ("l2", "circle", 2.0, None),
        ("hexagon", "hexagon", 0.0, "wave:30"),
        ("l2", "ellipse", 1.0, "circular"),
    ],
)
def test_centre_fit_matches_a_search_cell_by_cell(metric, shape, gap, field, search):
    """fit_centres (blocks of cells, the samples' projections folded in once; or a
    backend's kernel) gives the sizes of a pattern search written out per cell with the
    textbook gauge, from the same two starts, to rounding; the centres too, except where
    both starts reach one size."""
    from compact_distributions.cvt.lloyd import final_labels, lloyd
    from compact_distributions.cvt.placement.fit import _inscribed_centres, fit_centres
    from compact_distributions.cvt.shapes import element_ball

    grid = Grid(72, 56)
    fld = None if field is None else DirectionField.named(field, grid.width, grid.height)
    p = Problem(grid, 24, make_metric(metric), field=fld, seed=5)
    b = NumpyBackend()
    r = lloyd(p, b, 4)
    lab = final_labels(p, b, r)
    centres, sizes = fit_centres(lab, r.sites, r.angles, shape, p.metric.aspect, gap, search=search)
    starts = _inscribed_centres(lab, shape, p.metric.aspect, len(r.sites))
    ball = element_ball(shape, p.metric.aspect)
    assert (sizes > 0).sum() >= 20
    for i in range(len(r.sites)):
        q = _cell_samples_by_hand(lab, i)
        assert len(q) > 0
        c1, s1 = _search_by_hand(ball, q, r.sites[i], r.angles[i], gap / 2, lab, i)
        c2, s2 = _search_by_hand(ball, q, starts[i], r.angles[i], gap / 2, lab, i)
        assert sizes[i] == pytest.approx(max(s1, s2), rel=1e-9, abs=1e-9)
        if abs(s1 - s2) > 1e-9 * max(s1, s2):
            assert centres[i] == pytest.approx(c2 if s2 > s1 else c1, abs=1e-9)


def _hostile_labels():
    """A label raster with what a search can meet: a region with holes (-1), one-pixel
    cells, a cell split in two pieces, a long thin cell, a cell of many samples (not a
    whole number of a kernel's vectors), and sites outside their own cells."""
    rng = np.random.default_rng(7)
    lab = np.full((61, 83), -1, dtype=np.int32)
    lab[2:40, 3:30] = 0  # a big cell: 130 samples
    lab[10:20, 10:20] = -1  # with a hole
    lab[5, 40], lab[50, 70] = 1, 1  # one cell in two one-pixel pieces
    lab[45:47, 5:80] = 2  # long and thin
    lab[0:30, 35:83] = np.kron(rng.integers(3, 9, (5, 8)), np.ones((6, 6), np.int32))  # ragged cells
    lab[31:44, 33:60] = 9
    lab[60, 82] = 10  # a corner pixel
    sites = np.array(
        [[15.0, 21.0], [40.5, 5.5], [40.0, 46.0], [50.2, 12.7], [60.0, 15.0], [45.0, 3.0], [70.5, 20.5],
         [36.0, 1.0], [80.0, 28.0], [45.0, 37.0], [82.5, 60.5], [1.0, 1.0]]
    )  # fmt: skip
    return lab, sites


@pytest.mark.parametrize(
    "shape,aspect,gap",
    [
        ("square", 1.0, 0.0),
        ("rectangle", 0.5, 1.0),
        ("triangle", 1.0, 0.7),
        ("hexagon", 1.0, 0.0),
        ("octagon", 1.0, 2.0),
        ("circle", 1.0, 0.0),
        ("ellipse", 0.4, 1.3),
    ],
)
def test_opencl_search_is_the_hosts_bit_for_bit(ocl, shape, aspect, gap):
    """The OpenCL kernel's search ends where the host's does, bit for bit (centres and
    sizes), on relaxed cells under a field and on hostile ones; every value finite."""
    from compact_distributions.cvt.lloyd import final_labels, lloyd
    from compact_distributions.cvt.placement.fit import fit_centres

    grid = Grid(150, 110)
    p = Problem(grid, 90, make_metric("l2"), field=DirectionField.named("circular", 150, 110), seed=3)
    r = lloyd(p, NumpyBackend(), 5)
    lab, sites = _hostile_labels()
    angles = np.random.default_rng(1).uniform(0, 3, len(sites))
    relaxed = final_labels(p, NumpyBackend(), r)
    for labels, at, theta, placed in ((relaxed, r.sites, r.angles, 80), (lab, sites, angles, 2)):
        want = fit_centres(labels, at, theta, shape, aspect, gap)
        got = fit_centres(labels, at, theta, shape, aspect, gap, search=ocl.fit_search)
        assert np.isfinite(got[0]).all() and np.isfinite(got[1]).all()
        assert (want[1] > 0).sum() >= placed
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


@pytest.mark.parametrize(
    "shape,aspect", [("square", 1.0), ("circle", 1.0), ("rectangle", 0.5), ("ellipse", 2.0)]
)
def test_opencl_inscribed_starts_are_the_hosts_distance_transform(ocl, shape, aspect):
    """The kernel's second starts (the deepest pixel of each cell, the first in raster
    order) are the host's distance transform's, bit for bit: under a grout wider than
    every cell no element grows, so each search ends where it starts."""
    from compact_distributions.cvt.lloyd import final_labels, lloyd
    from compact_distributions.cvt.metrics import compile_sites
    from compact_distributions.cvt.placement import fit as pl
    from compact_distributions.cvt.shapes import element_ball

    p = Problem(Grid(130, 97), 60, make_metric("linf"), seed=8)
    r = lloyd(p, NumpyBackend(), 4)
    for labels, at in ((final_labels(p, NumpyBackend(), r), r.sites), _hostile_labels()):
        angles = np.zeros(len(at))
        gauge = pl._Gauge(compile_sites(element_ball(shape, aspect), at, angles, None), 500.0)
        cells = pl.FitCells(labels, pl._CellSamples(labels, len(at)), gauge, at, shape, aspect)
        centres, sizes = ocl.fit_search(cells)
        assert not sizes.any()
        assert np.array_equal(centres[0], cells.anchor)
        assert np.array_equal(centres[1], cells.inscribed())


def test_no_cell_no_search():
    """A raster without cells places nothing and never calls the search."""
    from compact_distributions.cvt.placement.fit import fit_centres

    def refuse(cells):
        raise AssertionError("searched")

    centres, sizes = fit_centres(
        np.full((9, 9), -1, np.int32), [[4.0, 4.0]], None, "square", 1.0, search=refuse
    )
    assert np.array_equal(centres, [[4.0, 4.0]]) and np.array_equal(sizes, [0.0])


def test_ours_compact_fits_with_its_backends_search():
    """ours-compact and ours-fit hand the fit to their backend's ``fit_search``."""
    from compact_distributions.cvt.placement.fit import search_on_host
    from compact_distributions.cvt.placement.ours import run_ours_compact

    class Counting(NumpyBackend):
        calls = 0

        def fit_search(self, cells):
            Counting.calls += 1
            return search_on_host(cells)

    p = Problem(Grid(64, 48), 30, make_metric("linf"), seed=1)
    compact = run_ours_compact(p, Counting(), iterations=2)
    run_ours(p, Counting(), iterations=2, fit="centre")
    assert Counting.calls == 2 and sum(e is not None for e in compact.elements) > 20


# --- the parts the fit is built from, against plain NumPy ---------------------------------
def test_witness_bounds_never_skip_a_trial_that_would_grow():
    """Searching with witness bounds (a trial evaluated in full only where a few samples
    allow it to grow) gives the sizes and centres of evaluating every trial in full, bit
    for bit, with angles and grout, on polygons and ellipses alike."""
    from compact_distributions.cvt.metrics import compile_sites
    from compact_distributions.cvt.placement import fit as pl
    from compact_distributions.cvt.shapes import element_ball

    grid = Grid(96, 80)
    p = Problem(grid, 40, make_metric("l2"), field=DirectionField.named("circular", 96, 80), seed=4)
    b = NumpyBackend()
    from compact_distributions.cvt.lloyd import final_labels, lloyd

    r = lloyd(p, b, 3)
    lab = final_labels(p, b, r)
    for shape, aspect, gap in (("square", 1.0, 1.0), ("ellipse", 0.5, 1.0), ("triangle", 1.0, 0.0)):
        gauge = pl._Gauge(compile_sites(element_ball(shape, aspect), r.sites, r.angles, None), gap / 2)
        samples = pl._CellSamples(lab, len(r.sites))
        for which, x, y in samples.blocks():
            ids = samples.cells[which]
            terms = gauge.prepare(ids, x, y, r.sites)
            starts = [r.sites[ids], r.sites[ids] + 0.7]
            centres, sizes = pl._fit_search(lab, ids, terms, gauge, starts, r.sites)
            for s, start in enumerate(starts):  # every trial in full, one move at a time
                c, best = _search_in_full(lab, ids, terms, gauge, start.copy(), r.sites)
                assert np.array_equal(sizes[s], best), shape
                assert np.array_equal(centres[s], c), shape


def _search_in_full(labels, ids, terms, gauge, centres, anchor):
    """The pattern search of fit_centres with every trial's size taken over all of its
    cell's samples (the search before witness bounds)."""
    from compact_distributions.cvt.placement import fit as pl

    h, w = labels.shape

    def size(rows, points):
        x, y = points[:, 0], points[:, 1]
        own = (x >= 0) & (x < w) & (y >= 0) & (y < h)
        pix = labels[np.clip(y, 0, h - 1).astype(int), np.clip(x, 0, w - 1).astype(int)]
        least = gauge.least([t[..., rows, :] for t in terms], ids[rows], points, anchor)
        return np.where(own & (pix == ids[rows]), np.maximum(least, 0.0), 0.0)

    every = np.arange(len(ids))
    best = size(every, centres)
    for frac in pl._FIT_STEPS:
        active = every
        for _ in range(pl._FIT_REPEATS):
            if len(active) == 0:
                break
            step = frac * np.maximum(best[active], 1.0)
            grew = np.zeros(len(active), dtype=bool)
            for move in pl._FIT_MOVES:
                trial = centres[active] + step[:, None] * move
                s = size(active, trial)
                better = s > best[active] * (1 + 1e-9)
                centres[active[better]], best[active[better]] = trial[better], s[better]
                grew |= better
            active = active[grew]
    return centres, best


def test_stable_order_is_numpys_stable_argsort():
    from compact_distributions.cvt.placement.fit import _stable_order

    rng = np.random.default_rng(0)
    for n in (1, 7, 1 << 16, (1 << 16) + 1, 300_000, (1 << 31) - 1):
        keys = rng.integers(0, n, 50_000).astype(np.int32)
        assert np.array_equal(_stable_order(keys, n), np.argsort(keys, kind="stable")), n


def test_pick_columns_and_rows_last_reach_match_plain_indexing():
    """The flat gathers pick what two-axis indexing picks, and the size reached from the
    picked samples, laid out with the row last, is the same bit for bit."""
    from compact_distributions.cvt.metrics import compile_sites
    from compact_distributions.cvt.placement import fit as pl
    from compact_distributions.cvt.shapes import element_ball

    rng = np.random.default_rng(1)
    m, width = 30, 11
    sites = rng.uniform(10, 50, (m, 2))
    qx, qy = sites[:, :1] + rng.uniform(-9, 9, (m, width)), sites[:, 1:] + rng.uniform(-9, 9, (m, width))
    rows = rng.permutation(m)[:12]
    cols = rng.integers(0, width, (12, 5))
    for shape in ("triangle", "ellipse"):
        gauge = pl._Gauge(compile_sites(element_ball(shape, 0.5), sites, rng.uniform(0, 3, m), None), 0.4)
        ids = np.arange(m)
        terms = gauge.prepare(ids, qx, qy, sites)
        picked = pl._pick_columns(terms, rows, cols)
        for a, t in zip(picked, terms, strict=True):
            want = t[..., rows, :] if t.shape[-1] == 1 else t[..., rows[:, None], cols]
            assert np.array_equal(a, want)
        points = sites[rows] + rng.uniform(-2, 2, (12, 2))
        coef = gauge.rows(ids[rows], sites)
        full = gauge.reach(pl._pick_rows(terms, rows), coef, points)
        last = gauge.reach([np.ascontiguousarray(np.swapaxes(a, -1, -2)) for a in picked], coef, points, True)
        assert np.array_equal(last.T, np.take_along_axis(full, cols, axis=1))


def _contour_samples_by_hand(labels):
    """The contour samples by their definition, edge by edge: each vertical edge's left
    then right cell (raster order), then each horizontal edge's upper then lower cell."""
    h, w = labels.shape

    def at(i, j):
        return labels[i, j] if 0 <= i < h and 0 <= j < w else -1

    runs = [[], [], [], []]
    for r in range(h):
        for c in range(w + 1):
            a, b = at(r, c - 1), at(r, c)
            if a != b:
                runs[0] += [(a, c, r + 0.5)] if a >= 0 else []
                runs[1] += [(b, c, r + 0.5)] if b >= 0 else []
    for r in range(h + 1):
        for c in range(w):
            a, b = at(r - 1, c), at(r, c)
            if a != b:
                runs[2] += [(a, c + 0.5, r)] if a >= 0 else []
                runs[3] += [(b, c + 0.5, r)] if b >= 0 else []
    rows = np.array([s for run in runs for s in run], dtype=np.float64).reshape(-1, 3)
    return rows[:, 0].astype(np.int32), rows[:, 1], rows[:, 2]


def test_contour_samples_are_the_edges_midpoints_in_order():
    """contour_samples against the samples written out edge by edge, on random label
    rasters with outside pixels (-1), one row or one column among them."""
    rng = np.random.default_rng(4)
    for h, w in ((1, 1), (1, 9), (7, 1), (23, 37), (30, 17)):
        labels = rng.integers(-1, 6, (h, w)).astype(np.int32)
        labels[rng.random((h, w)) < 0.5] = 2  # runs of one cell, as in a real raster
        owner, x, y = contour_samples(labels)
        truth = _contour_samples_by_hand(labels)
        assert owner.dtype == np.int32 and len(owner) > 0
        for got, want in zip((owner, x, y), truth, strict=True):
            assert np.array_equal(got, want)


def test_contour_samples_in_float32_are_exact():
    lab = np.random.default_rng(2).integers(-1, 5, (40, 50)).astype(np.int32)
    o64, x64, y64 = contour_samples(lab)
    o32, x32, y32 = contour_samples(lab, np.float32)
    assert x32.dtype == y32.dtype == np.float32 and x64.dtype == np.float64
    assert np.array_equal(o32, o64) and np.array_equal(x32, x64) and np.array_equal(y32, y64)


@pytest.mark.parametrize("spacing", [(1.0, 1.0), (2.0, 0.5), (1 / 0.3, 0.3)])
def test_squared_depth_is_scipys_euclidean_transform(spacing):
    """The short separable transform gives SciPy's Euclidean distances (squared) on
    random masks, or None (SciPy's then) where a pixel lies too deep."""
    from scipy import ndimage

    from compact_distributions.cvt.placement.fit import _squared_depth

    rng = np.random.default_rng(3)
    done = 0
    for _ in range(25):
        h, w = rng.integers(3, 70, 2)
        inner = rng.random((h, w)) < rng.uniform(0.5, 0.97)
        inner[[0, -1]], inner[:, [0, -1]] = False, False
        got = _squared_depth(inner, *spacing)
        if got is None:
            continue
        done += 1
        want = ndimage.distance_transform_edt(inner, sampling=spacing) ** 2
        assert np.allclose(got, want, rtol=1e-12, atol=1e-9)
    assert done >= 10
    deep = np.ones((200, 200), dtype=bool)
    deep[[0, -1]], deep[:, [0, -1]] = False, False
    assert _squared_depth(deep, *spacing) is None  # 99 rows from the edge
