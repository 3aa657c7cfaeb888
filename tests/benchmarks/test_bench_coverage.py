"""Speed of placement and of coverage/overlap evaluation at 1024 x 1024 with 4000
elements (issue 3: evaluated in under a second).

Run the timings with ``pytest tests/benchmarks/test_bench_coverage.py --benchmark-enable``;
in the default run (benchmarks disabled) each test still runs once and checks the bound
with its own clock, so a slowdown past one second fails either way.
"""

import time

import numpy as np
import pytest

from compact_distributions.bench.ckdtree_step import ckdtree_labels, ckdtree_step
from compact_distributions.bench.evaluate import evaluate, region_polygon
from compact_distributions.cvt.placement import place_elements
from compact_distributions.cvt.problem import Grid

SIZE, N = 1024, 4000


@pytest.fixture(scope="module")
def relaxed():
    """4000 sites after 5 cKDTree Lloyd steps (cells close to a CVT), and their labels."""
    rng = np.random.default_rng(7)
    sites = rng.random((N, 2)) * SIZE
    for _ in range(5):
        sites = ckdtree_step(sites, SIZE, SIZE, "l2").centroids(sites)
    return sites, ckdtree_labels(sites, SIZE, SIZE, "l2"), Grid(SIZE, SIZE)


@pytest.mark.parametrize("shape", ["circle", "square"])
def test_bench_evaluate_4000_elements(benchmark, relaxed, shape):
    sites, labels, grid = relaxed
    angles = np.random.default_rng(1).uniform(0, np.pi, N)
    elements = place_elements(labels, sites, angles, None, shape, 1.0, grid)
    region = region_polygon(grid)
    t0 = time.perf_counter()
    ev = benchmark(evaluate, elements, grid, region)
    once = time.perf_counter() - t0
    assert ev.elements > 0.99 * N
    assert 0.4 < ev.coverage < 0.95 and ev.overlap < 0.005
    seconds = benchmark.stats.stats.median if benchmark.stats else once
    assert seconds < 1.0, f"evaluate took {seconds:.3f} s"


def test_bench_place_4000_elements(benchmark, relaxed):
    sites, labels, grid = relaxed
    t0 = time.perf_counter()
    elements = benchmark(place_elements, labels, sites, None, None, "circle", 1.0, grid)
    once = time.perf_counter() - t0
    assert sum(e is not None for e in elements) > 0.99 * N
    seconds = benchmark.stats.stats.median if benchmark.stats else once
    assert seconds < 1.0, f"placement took {seconds:.3f} s"
