"""Speed of compaction (cvt/compaction.py): 4000 squares at 1024² after 20 Lloyd
iterations (issue 12: at most 3 s on the project's 2-core machine), and squares among
thin walls, as in a picture mosaic (many 1-px pieces of wall beside each element).

The cells come from 20 cKDTree linf Lloyd steps (scipy only, so every machine times the
same input) and the multi-start centre fit; the benchmark times ``compact`` alone, with
its defaults, and with HiGHS' tiles (``solver="highs"``) beside it.  In the default run
(--benchmark-disable from pyproject) each case runs once on a small problem (N = 500,
384²) and checks only the result; with --benchmark-enable it is the 4000-square problem
(walled: 8000 squares at 1536² among rings of wall), timed over several rounds, and the
unwalled median must stay under 3 s::

    pytest tests/benchmarks/test_bench_compaction.py --benchmark-enable
"""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from compact_distributions.backends.ckdtree import CKDTreeBackend
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.placement.compaction import compact, wall_segments
from compact_distributions.cvt.placement.fit import fit_centres
from compact_distributions.cvt.problem import Grid
from compact_distributions.cvt.shapes import element_polygons

from ..geometry import largest_overlap

LIMIT_S = 3.0


def _enabled(config) -> bool:
    return bool(config.getoption("benchmark_enable", False)) or not config.getoption(
        "benchmark_disable", True
    )


@pytest.fixture(scope="module")
def squares(request):
    """Relaxed linf cells and their fitted squares: (centres, sizes, grid, n)."""
    n, size = (4000, 1024) if _enabled(request.config) else (500, 384)
    sites = np.random.default_rng(12).random((n, 2)) * size
    tree, linf, grid = CKDTreeBackend(), make_metric("linf"), Grid(size, size)
    for _ in range(20):
        sites = tree.moments(sites, metric=linf, grid=grid).centroids(sites)
    labels = tree.label(sites, metric=linf, grid=grid)
    centres, sizes = fit_centres(labels, sites, np.zeros(n), "square", 1.0)
    return centres, sizes, Grid(size, size), n


def _checked(benchmark, res, sizes, grid):
    """Coverage before and after (disjoint squares: area = coverage), recorded with the
    rounds; the compacted squares as polygons, checked to overlap nowhere."""
    before = 4 * float(np.sum(sizes**2)) / grid.pixel_count
    after = 4 * float(np.sum(res.sizes**2)) / grid.pixel_count
    benchmark.extra_info.update(coverage_before=before, coverage_after=after, rounds=res.rounds)
    ok = res.sizes > 0
    els = element_polygons("square", 1.0, res.centres[ok], np.zeros(ok.sum()), res.sizes[ok])
    assert largest_overlap(els) == 0.0
    return before, after, els


def _compacted(benchmark, request, group, rounds, centres, sizes, grid, **options):
    """``compact`` of the squares timed by the benchmark (``rounds`` rounds where
    benchmarks are enabled, once otherwise), its options in the benchmark's record (an
    array one as True)."""
    n = len(sizes)
    benchmark.group = group
    benchmark.extra_info.update(
        kind="compaction",
        shape="square",
        n_elements=n,
        size=grid.width,
        **{k: v if isinstance(v, str) else True for k, v in options.items()},
    )
    return benchmark.pedantic(
        compact,
        args=(centres, np.zeros(n), sizes, "square", 1.0, grid),
        kwargs=options,
        rounds=rounds if _enabled(request.config) else 1,
        iterations=1,
    )


@pytest.mark.parametrize("solver", ["pdhg", "highs"])
def test_bench_compaction_squares(benchmark, squares, request, solver):
    centres, sizes, grid, n = squares
    res = _compacted(
        benchmark, request, f"compaction square N={n} {grid.width}²", 5, centres, sizes, grid, solver=solver
    )
    before, after, _ = _checked(benchmark, res, sizes, grid)
    assert before > 0.7 and after > before + 0.1
    if _enabled(request.config):
        median = benchmark.stats.stats.median
        assert median < LIMIT_S, f"compaction of {n} squares took {median:.2f} s (median)"


def _rings(size: int) -> np.ndarray:
    """Thin walls: 1-px rings about a few centres (staircases in every direction)."""
    yy, xx = np.mgrid[0:size, 0:size] + 0.5
    walls = np.zeros((size, size), dtype=bool)
    rng = np.random.default_rng(3)
    for cx, cy, radius in rng.uniform([0, 0, 0.1], [size, size, 0.4], (6, 3)) * [1, 1, size]:
        walls |= np.abs(np.hypot(xx - cx, yy - cy) - radius) < 0.5
    return walls


@pytest.fixture(scope="module")
def walled(request):
    """Relaxed linf cells in a region cut by thin walls, their fitted squares, the grid
    and the walls: (centres, sizes, grid, walls, n)."""
    n, size = (8000, 1536) if _enabled(request.config) else (500, 384)
    walls = _rings(size)
    grid = Grid(size, size, ~walls)
    tree, linf = CKDTreeBackend(), make_metric("linf")
    inside = np.argwhere(~walls)[np.random.default_rng(12).choice(int((~walls).sum()), n, replace=False)]
    sites = inside[:, ::-1] + 0.5
    for _ in range(20):
        sites = tree.moments(sites, metric=linf, grid=grid).centroids(sites)
    labels = tree.label(sites, metric=linf, grid=grid)
    centres, sizes = fit_centres(labels, sites, np.zeros(n), "square", 1.0)
    return centres, sizes, grid, walls, n


def test_bench_compaction_among_walls(benchmark, walled, request):
    centres, sizes, grid, walls, n = walled
    group = f"compaction square among walls N={n} {grid.width}²"
    res = _compacted(benchmark, request, group, 3, centres, sizes, grid, walls=walls)
    before, after, els = _checked(benchmark, res, sizes, grid)
    assert after > before + 0.05
    # no element reaches over a wall's centre line (compaction keeps half the gap, 0, off it)
    lines = shapely.multilinestrings(wall_segments(walls).reshape(-1, 2, 2))
    assert not shapely.intersects(shapely.union_all(shapely.buffer(els, -1e-6)), lines)
