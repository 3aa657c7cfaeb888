"""Speed of placement and of coverage/overlap evaluation at 1024 x 1024 with 4000
elements (target: each under a second).

Run the timings with ``pytest tests/benchmarks/test_bench_coverage.py --benchmark-enable``;
in the default run (benchmarks disabled) each case runs once and checks its result only.
"""

import numpy as np
import pytest

from compact_distributions.backends.ckdtree import CKDTreeBackend
from compact_distributions.cvt.evaluate import evaluate, region_polygon
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.placement.fit import place_elements
from compact_distributions.cvt.problem import Grid

SIZE, N = 1024, 4000


@pytest.fixture(scope="module")
def relaxed():
    """4000 sites after 5 cKDTree Lloyd steps (cells close to a CVT), and their labels."""
    rng = np.random.default_rng(7)
    sites = rng.random((N, 2)) * SIZE
    grid, l2, tree = Grid(SIZE, SIZE), make_metric("l2"), CKDTreeBackend()
    for _ in range(5):
        sites = tree.moments(sites, metric=l2, grid=grid).centroids(sites)
    return sites, tree.label(sites, metric=l2, grid=grid), grid


@pytest.mark.parametrize("shape", ["circle", "square"])
def test_bench_evaluate_4000_elements(benchmark, relaxed, shape):
    sites, labels, grid = relaxed
    angles = np.random.default_rng(1).uniform(0, np.pi, N)
    elements = place_elements(labels, sites, angles, shape, 1.0, grid)
    region = region_polygon(grid)
    ev = benchmark(evaluate, elements, grid, region)
    assert ev.elements > 0.99 * N
    assert 0.4 < ev.coverage < 0.95 and ev.overlap < 0.005
    if benchmark.stats:
        assert benchmark.stats.stats.median < 1.0


def test_bench_place_4000_elements(benchmark, relaxed):
    sites, labels, grid = relaxed
    elements = benchmark(place_elements, labels, sites, None, "circle", 1.0, grid)
    assert sum(e is not None for e in elements) > 0.99 * N
    if benchmark.stats:
        assert benchmark.stats.stats.median < 1.0
