"""Label and Lloyd-step benchmarks of every backend, side by side.

Each case is (backend variant, metric, N, raster side); the benchmark group is
"<kind> <metric> N=<N> <side>²" so that pytest-benchmark's table puts the backends of
one problem next to each other.  ``extra_info`` carries backend, metric, n_elements, size
and kind, which is what `cvtbench backends --from-benchmark-json FILE` reads.

Sizes: in normal CI (``--benchmark-disable`` from pyproject) each case runs once as a
plain test on a small problem (l2 and linf, N = 500, 128²) and checks its result
against the NumPy reference.  With ``--benchmark-enable`` the set grows to the six
metrics, N in {1000, 4000, 16000} and 512²/1024²; with ``CVT_BENCH_FULL=1`` it is the whole
grid of the backends report (N up to 16000, rasters up to 2048²).  For example::

    pytest tests/benchmarks/test_bench_lloyd.py --benchmark-enable --benchmark-json bench.json
    cvtbench backends --from-benchmark-json bench.json --out reports/pytest-bench

A backend that cannot start here is skipped with the reason.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from compact_distributions.backends import variant_metrics, variant_status
from compact_distributions.backends.numpy_backend import NumpyBackend
from compact_distributions.bench.sweep import BackendCache
from compact_distributions.cvt.metrics import METRIC_NAMES, make_metric
from compact_distributions.cvt.problem import Grid

SMALL = {"metrics": ["l2", "linf"], "sites": [500], "sizes": [128]}
ENABLED = {"metrics": list(METRIC_NAMES), "sites": [1000, 4000, 16000], "sizes": [512, 1024]}
FULL = {"metrics": list(METRIC_NAMES), "sites": [1000, 4000, 16000], "sizes": [512, 1024, 2048]}

VARIANTS = variant_status()  # variant -> (available, device or reason)


def _grid_of_cases(config) -> list:
    if os.environ.get("CVT_BENCH_FULL"):
        cfg = FULL
    elif config.getoption("benchmark_enable", False) or not config.getoption("benchmark_disable", True):
        cfg = ENABLED
    else:
        cfg = SMALL
    # backend-major order: consecutive cases share one backend instance (see _cache)
    return [
        pytest.param(v, m, n, s, id=f"{v}-{m}-N{n}-{s}")
        for v in VARIANTS
        for m in cfg["metrics"]
        for n in cfg["sites"]
        for s in cfg["sizes"]
        if variant_metrics(v) is None or m in variant_metrics(v)
    ]


def pytest_generate_tests(metafunc):
    if {"variant", "metric", "n_elements", "size"} <= set(metafunc.fixturenames):
        metafunc.parametrize("variant,metric,n_elements,size", _grid_of_cases(metafunc.config))


@pytest.fixture(scope="module")
def _cache():
    cache = BackendCache()  # one live backend at a time (moderngl contexts interfere)
    yield cache
    cache.close()


@pytest.fixture
def backend(_cache, variant):
    ok, text = VARIANTS[variant]
    if not ok:
        pytest.skip(f"backend {variant} unavailable: {text}")
    return _cache.get(variant)


def _problem(metric_name: str, n: int, size: int):
    sites = np.random.default_rng(n + size).random((n, 2)) * size
    return sites, np.ones(n), np.zeros(n), make_metric(metric_name), Grid(size, size)


def _step(backend, sites, scales, angles, metric, grid):
    mom = backend.moments(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    return mom, mom.centroids(sites)


def _reference(metric_name, n, size):
    sites, scales, angles, metric, grid = _problem(metric_name, n, size)
    return NumpyBackend().label(sites, angles=angles, scales=scales, metric=metric, grid=grid)


def test_bench_label(benchmark, backend, variant, metric, n_elements, size):
    sites, scales, angles, metric_obj, grid = _problem(metric, n_elements, size)
    backend.label(
        sites, angles=angles, scales=scales, metric=metric_obj, grid=grid
    )  # warm-up: kernel builds, buffers
    benchmark.group = f"label {metric} N={n_elements} {size}²"
    benchmark.extra_info.update(
        kind="label",
        backend=variant,
        metric=metric,
        n_elements=n_elements,
        size=size,
        device=backend.device(),
    )
    labels = benchmark(backend.label, sites, angles=angles, scales=scales, metric=metric_obj, grid=grid)
    assert labels.shape == (size, size) and labels.dtype == np.int32
    assert labels.min() >= 0 and labels.max() < n_elements
    # against the float64 reference: only ties and the cones' facets may differ
    wrong = float(np.mean(labels != _reference(metric, n_elements, size)))
    assert wrong < 0.01, f"{variant} {metric}: {100 * wrong:.2f} % of pixels differ from numpy"


def test_bench_lloyd_step(benchmark, backend, variant, metric, n_elements, size):
    sites, scales, angles, metric_obj, grid = _problem(metric, n_elements, size)
    _step(backend, sites, scales, angles, metric_obj, grid)  # warm-up
    benchmark.group = f"lloyd-step {metric} N={n_elements} {size}²"
    benchmark.extra_info.update(
        kind="lloyd-step",
        backend=variant,
        metric=metric,
        n_elements=n_elements,
        size=size,
        device=backend.device(),
    )
    mom, moved = benchmark(_step, backend, sites, scales, angles, metric_obj, grid)
    assert int(mom.count.sum()) == size * size  # every pixel belongs to exactly one cell
    assert np.isfinite(moved).all() and (moved >= 0).all() and (moved <= size).all()
    _, ref = _step(NumpyBackend(), sites, scales, angles, metric_obj, grid)
    shift = np.hypot(*(moved - ref).T)
    assert float(np.mean(shift)) < 0.1, (
        f"{variant} {metric}: centroids {np.mean(shift):.3f} px off numpy on average"
    )
