"""Compaction (cvt/compaction.py), alternating triangles (cvt/alternate.py) and the
multi-start centre fit (cvt.placement.fit_centres), checked against independent truth:
exact shapely geometry of every round's elements, analytic distances of circles, finer
outlines of curved elements, lattices whose best packing is known by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from compact_distributions.backends.numpy_backend import NumpyBackend
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.evaluate import evaluate, region_polygon
from compact_distributions.cvt.fields import DensityMap
from compact_distributions.cvt.lloyd import final_labels, lloyd
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.placement.alternate import (
    alternate_triangles,
    alternating_turns,
    check_alternate,
)
from compact_distributions.cvt.placement.compaction import (
    CompactionResult,
    _best_pair_directions,
    boundary_segments,
    compact,
)
from compact_distributions.cvt.placement.fit import fit_centres, placement_sizes
from compact_distributions.cvt.problem import Grid, Problem, lattice_sites
from compact_distributions.cvt.shapes import ELEMENT_SHAPES, element_ball, element_polygons, transform

BACKEND = NumpyBackend()
SIZE = 96


# ------------------------------------------------------------------ helpers
def l_mask(size=SIZE):
    m = np.ones((size, size), dtype=bool)
    m[: size // 2, size // 2 :] = False  # an L: one reflex corner
    return m


def annulus_mask(size=SIZE, outer=0.48, inner=0.22):
    yy, xx = np.mgrid[0:size, 0:size] + 0.5
    r = np.hypot(xx - size / 2, yy - size / 2) / size
    return (r < outer) & (r > inner)


REGIONS = {"full": lambda: None, "L": l_mask, "annulus": annulus_mask}


def random_layout(shape, seed, n, region, gap=0.0, field=True):
    """Sites at random in the region, their l2 cells, and each element placed in its cell
    (centred at its site, random angle): a valid, overlap-free start."""
    rng = np.random.default_rng(seed)
    mask = REGIONS[region]()
    grid = Grid(SIZE, SIZE, mask)
    inside = np.flatnonzero(grid.inside().ravel())
    pick = rng.choice(inside, size=n, replace=False)
    i, j = np.divmod(pick, SIZE)
    sites = np.stack([j + rng.random(n), i + rng.random(n)], axis=1)
    labels = BACKEND.label(sites, metric=make_metric("l2"), grid=grid)
    angles = rng.uniform(0, 2 * math.pi, n) if field else np.zeros(n)
    sizes = placement_sizes(labels, sites, angles, shape, 0.5, gap)
    return grid, sites, angles, sizes


def polygons(shape, c, a, s, aspect=0.5, segments=None):
    """Element outlines; ``segments`` > 128 gives curved shapes a finer outline."""
    ok = s > 0
    if segments is None:
        return element_polygons(shape, aspect, c[ok], a[ok], s[ok])
    outline = element_ball(shape, aspect).outline(segments)
    return shapely.polygons(transform(outline, c[ok], a[ok], s[ok]))


def assert_separated(shape, c, a, s, grid, gap, aspect=0.5):
    """No two elements share area; near pairs at least ``gap`` apart, the region's border
    at least gap/2 away; every element inside the region (exact shapely predicates)."""
    region = region_polygon(grid)
    for segments in (None, 2048) if shape in ("circle", "ellipse") else (None,):
        els = polygons(shape, c, a, s, aspect, segments)
        tree = shapely.STRtree(els)
        p, q = tree.query(els, predicate="dwithin", distance=gap + 1.0)
        keep = p < q
        p, q = p[keep], q[keep]
        if len(p):
            assert shapely.area(shapely.intersection(els[p], els[q])).max() == 0.0
            assert shapely.distance(els[p], els[q]).min() >= gap - 1e-6
        assert shapely.covered_by(els, region).all()
        assert shapely.distance(els, region.boundary).min() >= gap / 2 - 1e-6
    if shape == "circle":  # analytic: centre distance >= r_i + r_j + G
        ok = s > 0
        cc, rr = c[ok], s[ok]
        d = np.hypot(*(cc[:, None, :] - cc[None, :, :]).transpose(2, 0, 1))
        need = rr[:, None] + rr[None, :] + gap
        np.fill_diagonal(d, np.inf)
        assert (d >= need - 1e-9).all()


# ------------------------------------------------------------------ the guarantee
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    shape=st.sampled_from(ELEMENT_SHAPES),
    seed=st.integers(0, 10_000),
    n=st.integers(3, 30),
    region=st.sampled_from(sorted(REGIONS)),
    gap=st.sampled_from([0.0, 0.0, 0.7, 2.0]),
    tiles=st.sampled_from([4, 12, 64]),
    field=st.booleans(),
    solver=st.sampled_from(["pdhg", "highs"]),
    iterations=st.sampled_from([3, 20, 100]),
)
def test_every_round_is_overlap_free_and_inside(
    shape, seed, n, region, gap, tiles, field, solver, iterations
):
    grid, sites, angles, sizes = random_layout(shape, seed, n, region, gap, field)
    if not (sizes > 0).any() or gap >= 2 * min(element_ball(shape, 0.5).inradius, 1) * sizes.max():
        return
    states = []
    res = compact(
        sites,
        angles,
        sizes,
        shape,
        0.5,
        grid,
        gap=gap,
        rounds=3,
        tile_elements=tiles,
        solver=solver,
        iterations=iterations,  # PDHG: few steps leave rows short, which shrinking repairs
        on_round=lambda k, c, s: states.append((c, s)),
    )
    assert len(states) == res.rounds >= 1
    for c, s in states:
        assert_separated(shape, c, angles, s, grid, gap)
    assert np.array_equal(res.angles, angles)  # angles are the field's
    assert ((res.sizes > 0) <= (sizes > 0)).all()  # no element appears from nothing


@pytest.mark.parametrize("shape", ELEMENT_SHAPES)
def test_compaction_grows_coverage_in_a_non_convex_region(shape):
    """A Lloyd CVT in an L-shaped region: compaction covers more, nothing leaves the L."""
    grid = Grid(SIZE, SIZE, l_mask())
    from compact_distributions.cvt.shapes import shape_record

    p = Problem(grid, 40, make_metric(shape_record(shape).metric, 0.5), seed=4)
    r = lloyd(p, BACKEND, 6)
    labels = final_labels(p, BACKEND, r)
    c0, s0 = fit_centres(labels, r.sites, r.angles, shape, 0.5)
    res = compact(c0, r.angles, s0, shape, 0.5, grid, rounds=4, tile_elements=16)
    assert_separated(shape, res.centres, r.angles, res.sizes, grid, 0.0)
    before = evaluate(list(polygons(shape, c0, r.angles, s0)), grid).coverage
    after = evaluate(list(polygons(shape, res.centres, r.angles, res.sizes)), grid)
    assert after.coverage > before + 0.05 and after.overlap == 0.0


def test_tiles_solved_in_threads_give_the_same_elements():
    """Tiles are independent programs: solved by two threads side by side (here 30 tiles,
    enough for two workers) or one after another, the elements are the same, and apart."""
    grid, sites, angles, sizes = random_layout("hexagon", 5, 120, "L", gap=0.5)
    runs = [
        compact(
            sites,
            angles,
            sizes,
            "hexagon",
            0.5,
            grid,
            gap=0.5,
            rounds=3,
            tile_elements=4,
            threads=t,
            solver="highs",
        )
        for t in (1, 2)
    ]
    assert np.array_equal(runs[0].centres, runs[1].centres)
    assert np.array_equal(runs[0].sizes, runs[1].sizes)
    assert runs[0].history[-1]["iters"] == runs[1].history[-1]["iters"] > 0
    assert_separated("hexagon", runs[1].centres, angles, runs[1].sizes, grid, 0.5)
    assert (runs[1].sizes ** 2).sum() > 1.05 * (sizes**2).sum()


def round_program(monkeypatch, shape, seed, n, region, gap):
    """The arguments of the first round's program of a random layout (as compaction
    builds it), caught on their way to the PDHG solver."""
    from compact_distributions.cvt.placement import compaction

    grid, sites, angles, sizes = random_layout(shape, seed, n, region, gap)
    caught = []
    real = compaction._solve_pdhg

    def catch(*args):
        caught.append(args)
        return real(*args)

    monkeypatch.setattr(compaction, "_solve_pdhg", catch)
    compact(sites, angles, sizes, shape, 0.5, grid, gap=gap, rounds=1)
    monkeypatch.undo()
    return caught[0]


@pytest.mark.parametrize(
    "shape, seed, region, gap",
    [
        ("square", 1, "full", 0.0),
        ("hexagon", 2, "L", 0.7),
        ("ellipse", 3, "annulus", 0.0),
        ("triangle", 4, "L", 2.0),
    ],
)
def test_pdhg_reaches_the_optimum_highs_finds(monkeypatch, shape, seed, region, gap):
    """PDHG on a round's whole program (no tiles) against HiGHS' dual simplex on the same
    program as one model: run to convergence, the same optimal area gain to 1e-6 and rows
    met to 1e-7 px; after the default steps, within 2 % of it; at any step count the
    moves and growths within their bounds exactly."""
    from compact_distributions.cvt.placement.compaction import (
        _PDHG_ITERATIONS,
        _STEP_RATIO,
        _solve_lp,
        _solve_pdhg,
    )

    args = round_program(monkeypatch, shape, seed, 40, region, gap)
    rows, act, c, r, gap_, delta, lo_dr, hi_dr, weight = args[:9]
    one_tile = np.zeros(len(r), dtype=np.int64)
    _, dr_opt, _, failed = _solve_lp(
        rows, act, c, r, gap_, delta, lo_dr, hi_dr, weight, one_tile, {"presolve": "off"}
    )
    assert failed == 0
    best = float(weight @ dr_opt)
    assert best > 0
    dc, dr, violation, steps = _solve_pdhg(
        rows, act, c, r, gap_, delta, lo_dr, hi_dr, weight, 200_000, _STEP_RATIO
    )
    assert steps < 200_000  # converged, not stopped
    assert violation < 1e-7 and float(weight @ dr) == pytest.approx(best, rel=1e-6)
    for iterations in (1, 7, _PDHG_ITERATIONS):
        dc, dr, violation, _ = _solve_pdhg(
            rows, act, c, r, gap_, delta, lo_dr, hi_dr, weight, iterations, _STEP_RATIO
        )
        assert (np.abs(dc) <= delta[:, None]).all()
        assert ((dr >= lo_dr) & (dr <= hi_dr)).all()
    assert float(weight @ dr) > 0.98 * best


def test_pdhg_rounds_are_reproducible_and_cover_at_least_what_tiles_do():
    """The same input gives the same elements bit for bit; over a few rounds the PDHG
    rounds (one program, no tile walls) cover at least what HiGHS' tiles cover."""
    grid, sites, angles, sizes = random_layout("square", 9, 120, "full")
    runs = [compact(sites, angles, sizes, "square", 0.5, grid, rounds=3, threads=t) for t in (1, 2)]
    assert np.array_equal(runs[0].centres, runs[1].centres) and np.array_equal(runs[0].sizes, runs[1].sizes)
    tiled = compact(sites, angles, sizes, "square", 0.5, grid, rounds=3, tile_elements=16, solver="highs")
    assert np.sum(runs[0].sizes ** 2) >= np.sum(tiled.sizes**2)
    assert_separated("square", runs[0].centres, angles, runs[0].sizes, grid, 0.0)


@pytest.mark.parametrize("shape", ["square", "ellipse", "triangle"])
def test_threads_split_the_work_not_the_result(shape, monkeypatch):
    """With pieces small enough that every thread gets some (the near pairs' candidates
    and the PDHG's blocks of rows and columns), a round's elements are those of one
    thread bit for bit: each number is computed by the same operations in the same order."""
    from compact_distributions.cvt.placement import compaction

    grid, sites, angles, sizes = random_layout(shape, 4, 150, "L")
    import threading

    from compact_distributions.cvt.threads import usable_cores

    one = compact(sites, angles, sizes, shape, 0.5, grid, rounds=3, threads=1)
    monkeypatch.setattr(compaction, "_PIECE_ROWS", 50)
    monkeypatch.setattr(compaction, "_PDHG_BLOCK_ENTRIES", 300)
    # where the near pairs and the near pieces are found: side by side with threads
    where: dict = {"pairs": set(), "pieces": set()}
    for name, key in (("_near_pairs", "pairs"), ("_near_segments", "pieces")):
        real = getattr(compaction, name)
        monkeypatch.setattr(
            compaction, name, lambda *a, real=real, key=key: where[key].add(threading.get_ident()) or real(*a)
        )
    for t in (2, 3):
        split = compact(sites, angles, sizes, shape, 0.5, grid, rounds=3, threads=t)
        assert np.array_equal(one.centres, split.centres) and np.array_equal(one.sizes, split.sizes)
    if usable_cores() > 1:
        assert where["pieces"] - where["pairs"]  # the pieces on a thread of the pool
    assert_separated(shape, one.centres, angles, one.sizes, grid, 0.0)


@pytest.mark.parametrize("shape", ["square", "triangle"])
def test_large_programs_step_in_float32_within_their_bounds(shape, monkeypatch):
    """A program past _PDHG_SINGLE_ENTRIES steps in float32: its moves and growths keep
    their float64 bounds exactly (float32's may round outward), the elements come out
    apart (shapely) and within 1e-4 px and 1e-6 of the area of float64's, and threads
    still split the work, not the result."""
    from compact_distributions.cvt.placement import compaction

    grid, sites, angles, sizes = random_layout(shape, 5, 150, "L", gap=0.5)
    wide = compact(sites, angles, sizes, shape, 0.5, grid, gap=0.5, rounds=3, threads=1)
    caught = []
    real = compaction._solve_pdhg

    def catch(*args):
        out = real(*args)
        caught.append((args, out))
        return out

    monkeypatch.setattr(compaction, "_PDHG_SINGLE_ENTRIES", 0)
    monkeypatch.setattr(compaction, "_solve_pdhg", catch)
    single = compact(sites, angles, sizes, shape, 0.5, grid, gap=0.5, rounds=3, threads=1)
    assert len(caught) == 3
    for args, (dc, dr, _, _) in caught:
        act, delta, lo_dr, hi_dr = args[1], args[5], args[6], args[7]
        assert (np.abs(dc[act]) <= delta[act, None]).all()
        assert ((dr[act] >= lo_dr[act]) & (dr[act] <= hi_dr[act])).all()
    assert not np.array_equal(single.centres, wide.centres)  # float32 did run
    np.testing.assert_allclose(single.centres, wide.centres, atol=1e-4)
    assert np.sum(single.sizes**2) == pytest.approx(np.sum(wide.sizes**2), rel=1e-6)
    assert_separated(shape, single.centres, angles, single.sizes, grid, 0.5)
    monkeypatch.setattr(compaction, "_PDHG_BLOCK_ENTRIES", 300)
    split = compact(sites, angles, sizes, shape, 0.5, grid, gap=0.5, rounds=3, threads=2)
    assert np.array_equal(single.centres, split.centres) and np.array_equal(single.sizes, split.sizes)


def test_large_sets_worked_in_z_order_come_back_in_the_callers_order(monkeypatch):
    """Past _SPATIAL_ORDER_ELEMENTS the elements are worked along a Z-order curve: each
    result (and each round's state given to on_round) is in the caller's order, the
    same elements as in the caller's order to rounding (1e-6 px, area 1e-9), apart
    (shapely), an absent element stays absent, and the angles come back as given."""
    from compact_distributions.cvt.placement import compaction

    grid, sites, angles, sizes = random_layout("hexagon", 6, 150, "annulus", gap=0.5)
    sizes = sizes.copy()
    sizes[7] = 0.0

    def run(states):
        """Three rounds, each round's sizes kept in ``states``."""
        return compact(
            sites,
            angles,
            sizes,
            "hexagon",
            0.5,
            grid,
            gap=0.5,
            rounds=3,
            on_round=lambda k, c, s: states.append(s),
        )

    plain_states, z_states = [], []
    plain = run(plain_states)
    monkeypatch.setattr(compaction, "_SPATIAL_ORDER_ELEMENTS", 0)
    order = compaction._spatial_order(np.asarray(sites, dtype=float))
    assert sorted(order) == list(range(len(sites))) and not np.array_equal(order, np.arange(len(sites)))
    z = run(z_states)
    np.testing.assert_allclose(z.centres, plain.centres, atol=1e-6)
    np.testing.assert_allclose(z.sizes, plain.sizes, atol=1e-6)
    assert np.sum(z.sizes**2) == pytest.approx(np.sum(plain.sizes**2), rel=1e-9)
    for a, b in zip(z_states, plain_states, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)
    assert z.sizes[7] == 0.0 and np.array_equal(z.angles, angles)
    assert_separated("hexagon", z.centres, angles, z.sizes, grid, 0.5)


def test_rows_no_shrinking_can_meet_put_their_elements_back():
    """An approximate solution that brings two centres closer than the gap (or a centre
    onto the border) would cost an element: both are put back where the round started,
    and a third element whose row with a put-back one then fails follows them; the
    others keep their new state, and the result is apart (shapely)."""
    from compact_distributions.cvt.placement.compaction import _revert_hopeless, _Rows, _shrink_to_fit

    grid = Grid(60, 20)
    c = np.array([[10.0, 10.0], [20.0, 10.0], [30.0, 10.0], [50.0, 10.0]])
    r = np.full(4, 4.0)
    new_c = np.array([[15.0, 10.0], [15.2, 10.0], [20.5, 10.0], [51.0, 10.0]])  # 0, 1 cross
    new_r = np.full(4, 4.5)
    one, zero = np.ones(3), np.zeros(3)
    rows = _Rows(
        np.array([0, 1, 2]),
        np.array([1, 2, 3]),
        one,
        zero,
        one,
        one,  # pairs along x
        *(np.zeros(0, dtype=np.int64),) * 2,
        *(np.zeros(0),) * 4,
    )
    got_c, got_r = new_c.copy(), new_r.copy()
    assert _revert_hopeless(rows, c, r, got_c, got_r, 1.0, 1e-7) == 3
    assert np.array_equal(got_c[:3], c[:3]) and np.array_equal(got_r[:3], r[:3])  # 2 follows 1
    assert np.array_equal(got_c[3], new_c[3]) and got_r[3] == 4.5
    sizes, dropped = _shrink_to_fit(rows, got_c, got_r, 1.0, 1e-7)
    assert dropped == 0 and (sizes > 0).all()
    assert_separated("square", got_c, np.zeros(4), sizes, grid, 1.0)


def test_gap_is_kept_between_pairs_and_to_the_border():
    grid, sites, angles, sizes = random_layout("square", 11, 30, "annulus", gap=1.5)
    res = compact(sites, angles, sizes, "square", 0.5, grid, gap=1.5, rounds=4, tile_elements=8)
    assert_separated("square", res.centres, angles, res.sizes, grid, 1.5)
    els = polygons("square", res.centres, angles, res.sizes)
    # the gap is used, not wasted: some pair is within 1e-3 px of exactly G
    p, q = shapely.STRtree(els).query(els, predicate="dwithin", distance=1.6)
    d = shapely.distance(els[p[p < q]], els[q[p < q]])
    assert abs(d.min() - 1.5) < 1e-3


# ------------------------------------------------------------------ known optima
def test_square_lattice_tiles_exactly():
    """8 x 8 equal squares in a 128 px square, each allowed to grow to 1.6 x its size
    (half-side 8): the best is the 16 px tiling, coverage 1, every size at the cap.
    HiGHS' exact rounds and PDHG run to convergence find it; PDHG's default steps per
    round come within 1e-3.  Without the cap the optimum is still coverage 1 (a local
    method gets close)."""
    grid = Grid(128, 128)
    c = lattice_sites(128, 128, 8)
    for options in ({"solver": "highs"}, {"iterations": 3000}, {}):
        res = compact(
            c, np.zeros(64), np.full(64, 5.0), "square", 1.0, grid, rounds=8, max_growth=0.6, **options
        )
        ev = evaluate(list(polygons("square", res.centres, np.zeros(64), res.sizes)), grid)
        exact = 1e-6 if options else 1e-3
        assert ev.coverage == pytest.approx(1.0, abs=exact) and ev.overlap == 0.0
        assert res.sizes == pytest.approx(np.full(64, 8.0), abs=8 * exact)
    free = compact(c, np.zeros(64), np.full(64, 5.0), "square", 1.0, grid, rounds=8)
    ev = evaluate(list(polygons("square", free.centres, np.zeros(64), free.sizes)), grid)
    assert 0.99 < ev.coverage <= 1.0 and ev.overlap == 0.0


def test_circle_lattice_reaches_pi_over_4():
    """8 x 8 circles in a 128 px square, each allowed to grow to radius 8: the best is to
    fill the 16 px lattice cells, coverage π/4.  With a small price on moves (no drift
    off the lattice) compaction finds it exactly; without, within 1 %.  Free to grow
    further from a lattice shaken by 0.1 px, circles of unequal sizes pack more densely
    than the lattice (from the exact lattice every round's optimum is to stay: growth
    needs moves that gain nothing at first, so a solver that nears the optimum stalls
    there)."""
    grid = Grid(128, 128)
    c = lattice_sites(128, 128, 8)
    res = compact(
        c, np.zeros(64), np.full(64, 5.0), "circle", 1.0, grid, rounds=8, max_growth=0.6, move_cost=1e-3
    )
    assert_separated("circle", res.centres, np.zeros(64), res.sizes, grid, 0.0)
    assert res.sizes == pytest.approx(np.full(64, 8.0), abs=1e-6)
    assert float(np.sum(math.pi * res.sizes**2)) / 128**2 == pytest.approx(math.pi / 4, abs=1e-6)
    drift = compact(c, np.zeros(64), np.full(64, 5.0), "circle", 1.0, grid, rounds=8, max_growth=0.6)
    assert_separated("circle", drift.centres, np.zeros(64), drift.sizes, grid, 0.0)
    cov = float(np.sum(math.pi * drift.sizes**2)) / 128**2
    assert math.pi / 4 * 0.99 < cov <= math.pi / 4 + 1e-9
    shaken = c + np.random.default_rng(1).uniform(-0.1, 0.1, c.shape)
    free = compact(shaken, np.zeros(64), np.full(64, 5.0), "circle", 1.0, grid, rounds=8)
    assert_separated("circle", free.centres, np.zeros(64), free.sizes, grid, 0.0)
    assert float(np.sum(math.pi * free.sizes**2)) / 128**2 > math.pi / 4


def triangle_tiling(width, side):
    """Labels of a raster cut into up and down triangles of ``side`` px (rows of height
    side·√3/2, every other row shifted by side/2), their centroids and which point down."""
    h = side * math.sqrt(3) / 2
    rows = int(width / h)
    height = int(rows * h)
    yy, xx = np.mgrid[0:height, 0:width] + 0.5
    rho = np.floor(yy / h).astype(int)
    t = yy / h - rho  # 0 at the row's top, 1 at its bottom
    u = (xx - (rho % 2) * side / 2) / side
    k = np.floor(u).astype(int)
    f = u - k
    up_left, up_right = f <= t / 2, f >= 1 - t / 2
    kind = np.where(up_left | up_right, 0, 1)  # 0 up, 1 down
    k = np.where(up_right, k + 1, k)
    kmin = k.min()
    ncol = k.max() - kmin + 1
    key = (rho * ncol + (k - kmin)) * 2 + kind
    uniq, labels = np.unique(key, return_inverse=True)
    labels = labels.reshape(key.shape).astype(np.int32)
    r_, rest = np.divmod(uniq, 2 * ncol)
    kk, kd = np.divmod(rest, 2)
    kk = kk + kmin
    off = (r_ % 2) * side / 2
    cx = np.where(kd == 0, kk * side + off, (kk + 0.5) * side + off)
    cy = np.where(kd == 0, r_ * h + 2 * h / 3, r_ * h + h / 3)
    return labels, np.stack([cx, cy], axis=1), kd == 1, height


def test_alternating_triangles_follow_a_triangle_tiling():
    """Cells that are up and down triangles: each cell gets the triangle pointing its
    cell's way, and compaction fills the tiling (coverage of the inner window -> 1)."""
    labels, centres, down, height = triangle_tiling(200, 40)
    grid = Grid(200, height)
    n = len(centres)
    own = np.bincount(labels.ravel(), minlength=n)
    inner = (
        (centres[:, 0] > 30)
        & (centres[:, 0] < 170)
        & (centres[:, 1] > 30)
        & (centres[:, 1] < height - 30)
        & (own > 0)
    )
    angles, c, s = alternate_triangles(labels, centres, np.zeros(n), fit="site")
    turned = np.abs(np.angle(np.exp(1j * angles))) > 1  # π, not 0
    assert np.array_equal(turned[inner], down[inner])
    res = compact(c, angles, s, "triangle", None, grid, rounds=8)
    assert_separated("triangle", res.centres, angles, res.sizes, grid, 0.0)
    window = shapely.box(40, 40, 160, height - 40)
    ev = evaluate(list(polygons("triangle", res.centres, angles, res.sizes)), grid, region=window)
    assert ev.coverage > 0.97 and ev.overlap == 0.0


def test_alternating_turns_are_half_and_half_and_seeded():
    t = alternating_turns(101, seed=3)
    assert set(np.unique(t)) == {0.0, math.pi}
    assert abs((t > 0).sum() - 50.5) <= 0.5
    assert np.array_equal(t, alternating_turns(101, seed=3))
    assert not np.array_equal(t, alternating_turns(101, seed=4))


# ------------------------------------------------------------------ sizes and density
def test_density_contrast_survives():
    """Left half 4x denser: cells and elements half the size.  Compaction grows both
    halves alike (median size ratio kept within 10 %)."""
    s = 192
    yy, xx = np.mgrid[0:s, 0:s]
    dens = DensityMap(np.where(xx < s / 2, 4.0, 1.0))
    p = Problem(Grid(s, s), 150, make_metric("linf"), density=dens, seed=2)
    r = lloyd(p, BACKEND, 8)
    labels = final_labels(p, BACKEND, r)
    c0, s0 = fit_centres(labels, r.sites, r.angles, "square", 1.0)
    res = compact(c0, r.angles, s0, "square", 1.0, p.grid, tile_elements=16)

    def ratio(c, z):
        left, right = (c[:, 0] < s / 2 - 12) & (z > 0), (c[:, 0] > s / 2 + 12) & (z > 0)
        return np.median(z[right]) / np.median(z[left])

    assert ratio(c0, s0) > 1.6
    assert ratio(res.centres, res.sizes) == pytest.approx(ratio(c0, s0), rel=0.1)
    assert np.sum(res.sizes**2) > 1.1 * np.sum(s0**2)


def test_max_growth_caps_each_size():
    grid, sites, angles, sizes = random_layout("circle", 5, 20, "full")
    res = compact(sites, angles, sizes, "circle", 1.0, grid, rounds=4, max_growth=0.05)
    assert (res.sizes <= sizes * 1.05 + 1e-9).all()


def test_max_sizes_caps_each_size_absolutely():
    grid, sites, angles, sizes = random_layout("circle", 5, 20, "full")
    caps = sizes * np.linspace(0.9, 1.3, len(sizes))  # some below the start: those only shrink
    res = compact(sites, angles, np.minimum(sizes, caps), "circle", 1.0, grid, rounds=4, max_sizes=caps)
    assert (res.sizes <= caps + 1e-9).all()
    free = compact(sites, angles, np.minimum(sizes, caps), "circle", 1.0, grid, rounds=4)
    assert (free.sizes > caps + 1e-6).any()  # the caps did bind
    with pytest.raises(InputError, match="max_sizes"):
        compact(sites, angles, sizes, "circle", 1.0, grid, max_sizes=np.zeros(len(sizes)))


def test_overlapping_start_is_repaired():
    """Two squares that overlap at the start (as placement may leave a corner half a
    pixel over its contour) come out apart; a centre closer than the gap is dropped."""
    grid = Grid(40, 40)
    c = np.array([[10.0, 10.0], [19.5, 10.0], [30.0, 30.0], [30.3, 30.0]])
    res = compact(c, np.zeros(4), np.array([5.0, 5.0, 3.0, 3.0]), "square", 1.0, grid, gap=1.0, rounds=0)
    assert res.dropped == 1 and (res.sizes > 0).sum() == 3
    assert_separated("square", res.centres, np.zeros(4), res.sizes, grid, 1.0)


# ------------------------------------------------------------------ separating directions
@pytest.mark.parametrize("shape", [s for s in ELEMENT_SHAPES if not element_ball(s, 0.5).curved])
def test_pair_gaps_along_face_normals_match_the_outlines(shape):
    """The gap a pair is given (along the direction chosen) is the gap of the two exact
    outlines along it, and no face normal of either outline separates them more: the
    outlines' vertices (shapely) against the support functions and the shortcuts for
    a shape's own faces and for centrally symmetric shapes (half the pairs turned alike,
    where j's faces are i's and are not evaluated)."""
    rng = np.random.default_rng(7)
    n = 400
    c = rng.uniform(0, 60, (n, 2))
    th = rng.uniform(0, 2 * math.pi, n)
    r = rng.uniform(1, 4, n)
    i, j = np.arange(0, n, 2), np.arange(1, n, 2)
    th[j[::2]] = th[i[::2]]
    unit = element_ball(shape, 0.5)
    prev = np.full((len(i), 2), np.nan)
    nx, ny, g = _best_pair_directions(unit, c, r, np.cos(th), np.sin(th), i, j, prev)
    xy = [np.asarray(shapely.get_coordinates(p)).reshape(-1, 2) for p in polygons(shape, c, th, r)]

    def outline_gap(a, b, ux, uy):  # min over b's vertices − max over a's, along u
        return (xy[b] @ [ux, uy]).min() - (xy[a] @ [ux, uy]).max()

    def normals(a):  # outward unit normals of a's outline edges
        e = np.diff(xy[a], axis=0)
        m = np.stack([e[:, 1], -e[:, 0]], axis=1)
        m = m[np.hypot(*m.T) > 1e-12]
        m /= np.hypot(*m.T)[:, None]
        inside = xy[a].mean(axis=0)
        flip = np.einsum("ij,ij->i", m, xy[a][:-1][: len(m)] - inside) < 0
        return np.where(flip[:, None], -m, m)

    for k, (a, b) in enumerate(zip(i, j, strict=True)):
        assert math.hypot(nx[k], ny[k]) == pytest.approx(1.0)
        assert g[k] == pytest.approx(outline_gap(a, b, nx[k], ny[k]), abs=1e-9)
        best = max([outline_gap(a, b, *m) for m in normals(a)] + [outline_gap(a, b, *-m) for m in normals(b)])
        assert g[k] >= best - 1e-9


# ------------------------------------------------------------------ region pieces
def test_boundary_segments_cover_the_region_border_exactly():
    mask = annulus_mask(64)
    segs = boundary_segments(mask, length=5)
    lines = shapely.linestrings(segs.reshape(-1, 2, 2))
    border = region_polygon(Grid(64, 64, mask)).boundary
    assert np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1]).max() <= 5
    assert shapely.union_all(lines).symmetric_difference(border).length == pytest.approx(0.0, abs=1e-9)
    assert shapely.length(lines).sum() == pytest.approx(border.length)


def test_boundary_segments_of_a_whole_raster_are_its_sides():
    """A mask with every pixel inside (a Grid's) gives its four sides cut into pieces of
    at most ``length`` px, in the order of the pass over the pixels (a hand-written list;
    the same sides as the mask with one pixel taken out, less that pixel's edges)."""
    segs = boundary_segments(np.ones((40, 70), dtype=bool))
    expected = [
        *([x0, y, x1, y] for y in (0, 40) for x0, x1 in ((0, 32), (32, 64), (64, 70))),
        *([x, y0, x, y1] for x in (0, 70) for y0, y1 in ((0, 32), (32, 40))),
    ]
    assert segs.dtype == np.float64 and np.array_equal(segs, np.array(expected, dtype=np.float64))
    holed = np.ones((40, 70), dtype=bool)
    holed[20, 30] = False  # the general pass: the sides, and the hole's four edges
    other = boundary_segments(holed)
    hole = np.array(
        [[30, 20, 31, 20], [30, 21, 31, 21], [30, 20, 30, 21], [31, 20, 31, 21]], dtype=np.float64
    )
    assert np.array_equal(np.unique(other, axis=0), np.unique(np.concatenate([segs, hole]), axis=0))


def test_product_is_the_sparse_product():
    """The PDHG steps' products into a given array equal scipy's m @ v and m.T @ w
    exactly, and m.T @ w equals the product by the transposed copy (m.T.tocsr()) that
    the steps used before, bit for bit."""
    import scipy.sparse as sp

    from compact_distributions.cvt.placement.compaction import _product

    m = sp.random(300, 200, density=0.03, format="csr", random_state=4)
    v = np.random.default_rng(4).normal(size=200)
    w = np.random.default_rng(5).normal(size=300)
    out = np.full(300, np.nan)  # whatever was there is overwritten
    assert _product(m, v, out) is out and np.array_equal(out, m @ v)
    out_t = np.full(200, np.nan)
    assert _product(m, w, out_t, transpose=True) is out_t
    assert np.array_equal(out_t, m.T @ w) and np.array_equal(out_t, m.T.tocsr() @ w)


def test_product_falls_back_when_scipys_kernel_is_gone(monkeypatch):
    """A scipy without the private CSR kernel (or with a changed one) gives the public
    product, not an error."""
    import sys

    import scipy.sparse as sp

    from compact_distributions.cvt.placement import compaction

    compaction._csr_matvec.cache_clear()
    monkeypatch.setitem(sys.modules, "scipy.sparse._sparsetools", None)  # import fails
    try:
        assert compaction._csr_matvec() is None
        m = sp.random(50, 40, density=0.1, format="csr", random_state=5)
        v = np.random.default_rng(5).normal(size=40)
        out = np.full(50, np.nan)
        assert np.array_equal(compaction._product(m, v, out), m @ v)
        w = np.random.default_rng(6).normal(size=50)
        assert np.array_equal(compaction._product(m, w, np.full(40, np.nan), transpose=True), m.T @ w)
    finally:
        compaction._csr_matvec.cache_clear()


# ------------------------------------------------------------------ the better fit
def test_fit_finds_the_largest_square_from_a_bad_site():
    """One 40 px square cell with its site in a corner: the largest square has half-side
    20 at the centre; the distance-transform start finds it."""
    labels = np.zeros((40, 40), dtype=np.int32)
    c, s = fit_centres(labels, [[2.5, 3.5]], [0.0], "square", 1.0)
    assert s[0] == pytest.approx(20.0, abs=0.5)
    assert np.allclose(c[0], [20.0, 20.0], atol=0.5)


# ------------------------------------------------------------------ bad input
def test_bad_input_names_the_value():
    grid = Grid(40, 40)
    c, a, s = np.array([[10.0, 10.0], [30.0, 30.0]]), np.zeros(2), np.array([4.0, 4.0])
    with pytest.raises(InputError, match="gap 9 px"):
        compact(c, a, s, "square", 1.0, grid, gap=9)
    with pytest.raises(InputError, match="'heptagon'"):
        compact(c, a, s, "heptagon", 1.0, grid)
    with pytest.raises(InputError, match="'square'"):
        check_alternate("square", True)
    check_alternate("triangle", True)
    check_alternate("square", False)
    with pytest.raises(InputError, match="gap"):
        compact(c, a, s, "square", 1.0, grid, gap=-1)
    with pytest.raises(InputError, match="sizes"):
        compact(c, a, np.array([4.0, -1.0]), "square", 1.0, grid)
    with pytest.raises(InputError, match="one entry per element"):
        compact(c, a, np.array([4.0]), "square", 1.0, grid)
    with pytest.raises(InputError, match="rounds"):
        compact(c, a, s, "square", 1.0, grid, rounds=-2)
    with pytest.raises(InputError, match="growth"):
        compact(c, a, s, "square", 1.0, grid, growth=0)
    with pytest.raises(InputError, match="empty"):
        compact(c, a, s, "square", 1.0, np.zeros((40, 40), dtype=bool))
    with pytest.raises(InputError, match="'simplex'"):
        compact(c, a, s, "square", 1.0, grid, solver="simplex")
    with pytest.raises(InputError, match="iterations"):
        compact(c, a, s, "square", 1.0, grid, iterations=0)
    with pytest.raises(InputError, match="unknown fit 'best'"):
        alternate_triangles(np.zeros((8, 8), np.int32), [[4.0, 4.0]], [0.0], fit="best")


def test_lloyd_turns_act_like_a_turned_field():
    """Angles turned by π for every site (as alternating triangles turn half of them) give
    the same CVT as a constant field of 180°."""
    from compact_distributions.cvt.fields import DirectionField
    from compact_distributions.cvt.lloyd import LloydSetup

    grid = Grid(64, 64)
    base = Problem(grid, 12, make_metric("triangle"), seed=5)
    turned = Problem(
        grid, 12, make_metric("triangle"), field=DirectionField.named("constant:180", 64, 64), seed=5
    )
    a = lloyd(base, BACKEND, 4, setup=LloydSetup.of(base, angles_at=lambda p: base.angles_at(p) + math.pi))
    b = lloyd(turned, BACKEND, 4)
    assert np.allclose(a.sites, b.sites) and np.allclose(a.angles, b.angles)
    c = lloyd(base, BACKEND, 4)
    assert not np.allclose(a.sites, c.sites)


@pytest.mark.parametrize("shape,full", [("square", 20.0), ("circle", 20.0), ("rectangle", 20.0 * 0.5)])
def test_a_lone_element_fills_its_square_region(shape, full):
    """One element off-centre in a 40 px square: it moves to the middle and grows to the
    largest that fits (square half-side 20, circle radius 20, a 2:1 rectangle 80/β wide
    capped by the width: size 20·β with β = 0.5)."""
    grid = Grid(40, 40)
    res = compact([[12.0, 27.0]], [0.0], [3.0], shape, 0.5, grid, rounds=30, growth=0.5, move=2.0)
    assert res.sizes[0] == pytest.approx(full, abs=1e-4)
    if shape != "rectangle":
        assert np.allclose(res.centres[0], [20.0, 20.0], atol=1e-4)
    assert_separated(shape, res.centres, np.zeros(1), res.sizes, grid, 0.0)


def test_nothing_placed_and_zero_rounds():
    grid = Grid(30, 30)
    res = compact(np.zeros((0, 2)), np.zeros(0), np.zeros(0), "circle", 1.0, grid)
    assert res.sizes.shape == (0,) and res.rounds == 0
    res = compact([[5.0, 5.0], [20.0, 20.0]], [0.0, 0.0], [0.0, 0.0], "circle", 1.0, grid)
    assert (res.sizes == 0).all() and res.rounds == 0
    c = np.array([[8.0, 8.0], [22.0, 22.0]])
    res = compact(c, [0.0, 0.0], [3.0, 3.0], "square", 1.0, grid, rounds=0)
    assert np.array_equal(res.centres, c) and np.array_equal(res.sizes, [3.0, 3.0])


def test_tightest_pieces_keep_the_same_constraints():
    """Piece rows of one element along one direction differ only in min(n·p, n·q): the
    rows kept are one per (element, direction), each the least of its group (brute force
    over the groups), and at random states every element's tightest piece slack is the
    same with all rows as with those kept."""
    from compact_distributions.cvt.placement.compaction import _Rows

    rng = np.random.default_rng(3)
    m = 400
    e = rng.integers(0, 30, m)
    turn = rng.integers(0, 3, m) * (math.pi / 3)
    sx, sy = np.cos(turn), np.sin(turn)
    he, sm = 1.0 + 0.1 * e, rng.normal(0.0, 5.0, m)
    empty_i, empty_f = np.zeros(0, dtype=np.int64), np.zeros(0)
    rows = _Rows(empty_i, empty_i, *(empty_f,) * 4, e, np.arange(m), sx, sy, he, sm)
    kept = rows.tightest_pieces()
    groups = {}
    for k in range(m):  # brute force: the least sm of each (element, direction)
        key = (e[k], sx[k], sy[k])
        groups[key] = min(groups.get(key, np.inf), sm[k])
    assert len(kept.e) == len(groups)
    assert np.all(np.diff(kept.s) > 0)  # rows stay in their order
    for k in range(len(kept.e)):
        assert kept.sm[k] == groups[(kept.e[k], kept.sx[k], kept.sy[k])]
    for _ in range(5):
        c, r = rng.normal(0.0, 3.0, (30, 2)), rng.random(30)
        every, tight = rows.seg_slack(c, r, 0.5), kept.seg_slack(c, r, 0.5)
        least_every, least_tight = np.full(30, np.inf), np.full(30, np.inf)
        np.minimum.at(least_every, e, every)
        np.minimum.at(least_tight, kept.e, tight)
        assert np.array_equal(least_every, least_tight)
    nan = _Rows(
        empty_i, empty_i, *(empty_f,) * 4, e[:2], np.arange(2), np.full(2, np.nan), sy[:2], he[:2], sm[:2]
    )
    assert len(nan.tightest_pieces().e) == 2  # NaN directions are never equal: nothing merged
    two, signed = np.zeros(2, dtype=np.int64), np.array([-0.0, 0.0])
    zero = _Rows(empty_i, empty_i, *(empty_f,) * 4, two, np.arange(2), signed, np.ones(2), np.ones(2), sm[:2])
    assert len(zero.tightest_pieces().e) == 1  # −0.0 and 0.0: one direction


def test_sorted_pairs_are_lexicographic():
    """_sorted_pairs sorts index pairs as np.lexsort does (by the first, then the
    second), equal pairs included."""
    from compact_distributions.cvt.placement.compaction import _sorted_pairs

    rng = np.random.default_rng(5)
    ab = np.unique(rng.integers(0, 1000, (5000, 2)), axis=0)[rng.permutation(4000)]
    ab = np.concatenate([ab, ab[:50]])  # some twice
    a, b = ab[:, 0], ab[:, 1]
    order = np.lexsort((b, a))
    sa, sb = _sorted_pairs(a, b, 1000)
    assert np.array_equal(sa, a[order]) and np.array_equal(sb, b[order])
    empty = np.zeros(0, np.int64)
    assert all(len(v) == 0 for v in _sorted_pairs(empty, empty, 1))


def test_a_later_pass_continues_a_result():
    # hand-made passes: the later one's elements, both passes' counts (or only the
    # elements it dropped, where its rounds belong to another step)
    first = CompactionResult(np.zeros((2, 2)), np.ones(2), np.zeros(2), 3, 1.5, 0.5, 1, [{"round": 1}])
    later = CompactionResult(
        np.ones((2, 2)), np.array([2.0, 0.0]), np.zeros(2), 2, 0.25, 0.125, 1, [{"round": 2}]
    )
    both = first.followed_by(later)
    assert (both.rounds, both.seconds, both.lp_seconds, both.dropped) == (5, 1.75, 0.625, 2)
    assert both.history == [{"round": 1}, {"round": 2}]
    assert np.array_equal(both.centres, np.ones((2, 2))) and np.array_equal(both.sizes, [2.0, 0.0])
    turned = first.followed_by(later, counted=False)
    assert (turned.rounds, turned.seconds, turned.lp_seconds, turned.dropped) == (3, 1.5, 0.5, 2)
    assert turned.history == [{"round": 1}] and np.array_equal(turned.sizes, [2.0, 0.0])
    assert first.rounds == 3 and np.array_equal(first.sizes, [1.0, 1.0])  # the first is left as it was
