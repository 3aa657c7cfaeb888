"""Time per Lloyd iteration (labels + moments) of the GL backend in both modes, beside
the cKDTree step the speed target is stated against (target: >= 3x faster at 1024²,
N = 4000, on llvmpipe).

With the suite's default --benchmark-disable each timed case runs once as a plain test
on 256², N = 500 (a few hundred ms on llvmpipe) and checks its result; with
--benchmark-enable the cases are 1024², N = 4000, and ``test_speedup_over_ckdtree``
times all of them interleaved (the machine is shared: only ratios taken in one run mean
anything) and asserts the 3x target where it is claimed (see reports/gl.md).
"""

import time

import numpy as np
import pytest

from compact_distributions.backends.ckdtree import CKDTreeBackend
from compact_distributions.cvt.errors import BackendUnavailable
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.problem import Grid

try:
    from compact_distributions.backends.gl import GLBackend

    GLBackend.probe()
except BackendUnavailable as exc:
    pytest.skip(f"GL backend unavailable: {exc}", allow_module_level=True)

MODES = ("cone", "exact")


@pytest.fixture(scope="module")
def backends():
    made = {mode: GLBackend(mode=mode) for mode in MODES}
    yield made
    for b in made.values():
        b.close()


def size_and_n(benchmark):
    return (256, 500) if benchmark.disabled else (1024, 4000)


def uniform_sites(n, side, seed=0):
    return np.random.default_rng(seed).random((n, 2)) * side


def relaxed_sites(n, side, steps=10):
    """Sites after a few Lloyd steps: cells close to a CVT, as in most iterations."""
    sites = uniform_sites(n, side)
    for _ in range(steps):
        sites = (
            CKDTreeBackend().moments(sites, metric=make_metric("l2"), grid=Grid(side, side)).centroids(sites)
        )
    return sites


def step(backend, sites, metric, grid):
    return backend.moments(sites, metric=metric, grid=grid).centroids(sites)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", ["l2", "linf", "l2-axial"])
def test_bench_gl_step(benchmark, backends, mode, name):
    side, n = size_and_n(benchmark)
    benchmark.group = f"lloyd step, N={n}, {side}x{side}, uniform sites"
    backend, metric, grid = backends[mode], make_metric(name), Grid(side, side)
    sites = uniform_sites(n, side)
    step(backend, sites, metric, grid)  # shaders compiled outside the timing
    benchmark.extra_info.update(backend="gl", mode=mode, metric=name, n=n, size=side, device=backend.device())
    moved = benchmark(step, backend, sites, metric, grid)
    assert moved.shape == sites.shape and np.isfinite(moved).all()
    assert backend.moments(sites, metric=metric, grid=grid).count.sum() == side * side


@pytest.mark.parametrize("name", ["l2", "linf"])
def test_bench_ckdtree_step(benchmark, name):
    side, n = size_and_n(benchmark)
    benchmark.group = f"lloyd step {name} N={n}, {side}x{side}, uniform sites"
    benchmark.extra_info.update(backend="ckdtree", metric=name, n=n, size=side)
    mom = benchmark(
        CKDTreeBackend().moments, uniform_sites(n, side), metric=make_metric(name), grid=Grid(side, side)
    )
    assert mom.count.sum() == side * side


def test_speedup_over_ckdtree(benchmark, backends):
    """Interleaved medians at 1024², N = 4000; asserts >= 3x for the exact mode (l2,
    linf) and the cone mode's pyramids (linf); curved cones are reported only."""
    if benchmark.disabled:
        pytest.skip("the speed ratio is measured only with --benchmark-enable")
    side, n = 1024, 4000
    grid = Grid(side, side)
    ratios = {}
    for label, sites in (("uniform", uniform_sites(n, side)), ("relaxed", relaxed_sites(n, side))):
        for name in ("l2", "linf"):
            metric = make_metric(name)
            calls = {
                "ckdtree": lambda s=sites, m=metric, t=CKDTreeBackend(): t.moments(s, metric=m, grid=grid)
            }
            for mode, b in backends.items():
                calls[mode] = lambda s=sites, m=metric, b=b: b.moments(s, metric=m, grid=grid)
            times = {k: [] for k in calls}
            for f in calls.values():
                f()
            for _ in range(7):
                for k, f in calls.items():
                    t0 = time.perf_counter()
                    f()
                    times[k].append(time.perf_counter() - t0)
            base = np.median(times["ckdtree"])
            for mode in MODES:
                ratios[f"{label} {name} {mode}"] = float(base / np.median(times[mode]))
    benchmark.extra_info.update(ratios)
    benchmark.pedantic(lambda: None, rounds=1)
    claimed = [k for k in ratios if k.endswith("exact") or k.endswith("linf cone")]
    slow = {k: round(ratios[k], 2) for k in claimed if ratios[k] < 3.0}
    assert not slow, f"below 3x the cKDTree step: {slow} (all: {ratios})"
