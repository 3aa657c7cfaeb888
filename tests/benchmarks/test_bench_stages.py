"""Speed of the stages of ``ours-compact`` after the Lloyd step, at growing N: the fit
(``cvt.placement.fit_centres``, with the OpenCL kernel's search as ours-compact runs it
on that backend, and with the host's) and compaction (``cvt.compaction.compact``), each timed
alone on the same relaxed cells, beside the 20 Lloyd iterations that made them.

The cells come from 20 OpenCL linf Lloyd steps (squares, no density, no field; raster
about 16 px per element: 1024² for N = 4000 ... 4096² for N = 64 000).  With the suite's
default --benchmark-disable each case runs once on a small problem (N = 300, 256²) and
checks only its result; with --benchmark-enable it runs N = 4000, 16 000 and 64 000 and
reports the medians (``extra_info`` holds the Lloyd time of the same cells)::

    pytest tests/benchmarks/test_bench_stages.py --benchmark-enable

At N = 4000 the issue's target is that the stages after Lloyd take at most twice the
Lloyd time of the same run; ``test_stages_after_lloyd`` says whether it holds and
asserts it only when timing is enabled.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from compact_distributions.cvt.lloyd import final_labels, lloyd
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.placement.compaction import compact
from compact_distributions.cvt.placement.fit import fit_centres
from compact_distributions.cvt.problem import Grid, Problem
from compact_distributions.cvt.shapes import element_polygons

from ..geometry import largest_overlap

SMALL = [(300, 256)]
LARGE = [(4000, 1024), (16000, 2048), (64000, 4096)]
TIMES: dict = {}  # (n, stage) -> median seconds, filled by the benchmarks of one run


def _enabled(config) -> bool:
    return bool(config.getoption("benchmark_enable", False)) or not config.getoption(
        "benchmark_disable", True
    )


def pytest_generate_tests(metafunc):
    if "case" in metafunc.fixturenames:
        cases = LARGE if _enabled(metafunc.config) else SMALL
        metafunc.parametrize("case", cases, ids=[f"N{n}_{s}" for n, s in cases], scope="module")


@pytest.fixture(scope="module")
def relaxed(case, ocl):
    """(problem, sites, labels, Lloyd seconds) of 20 OpenCL linf iterations."""
    n, size = case
    problem = Problem(Grid(size, size), n, make_metric("linf"), None, None, 0)
    t0 = time.perf_counter()
    res = lloyd(problem, ocl, 20)
    seconds = time.perf_counter() - t0
    return problem, res.sites, final_labels(problem, ocl, res), seconds


@pytest.fixture(scope="module")
def fitted(relaxed):
    problem, sites, labels, _ = relaxed
    return fit_centres(labels, sites, np.zeros(len(sites)), "square", 1.0)


def _rounds(config, n) -> int:
    return (3 if n <= 16000 else 1) if _enabled(config) else 1


@pytest.mark.parametrize("where", ["opencl", "host"])
def test_bench_fit(benchmark, relaxed, ocl, where, fitted, request):
    """The fit as ours-compact runs it on OpenCL (its kernel's search: ``fit``), and with
    the host's search (``fit-host``); the same centres and sizes bit for bit.  The
    kernel is built before the timing (a first call builds it once per process)."""
    problem, sites, labels, lloyd_s = relaxed
    n = len(sites)
    search = ocl.fit_search if where == "opencl" else None
    stage = "fit" if where == "opencl" else "fit-host"
    benchmark.group = f"stages after Lloyd, squares N={n} {problem.grid.width}²"
    benchmark.extra_info.update(stage=stage, n_elements=n, lloyd_seconds=lloyd_s)
    if search is not None:
        fit_centres(labels, sites, np.zeros(n), "square", 1.0, search=search)  # builds the kernel
    centres, sizes = benchmark.pedantic(
        fit_centres,
        args=(labels, sites, np.zeros(n), "square", 1.0),
        kwargs={"search": search},
        rounds=_rounds(request.config, n),
        iterations=1,
    )
    assert np.array_equal(centres, fitted[0]) and np.array_equal(sizes, fitted[1])
    # every fitted square lies in its own cell up to the half pixel of the placement rule
    assert np.isfinite(centres).all() and (sizes > 0).mean() > 0.99
    coverage = 4 * float(np.sum(sizes**2)) / problem.grid.pixel_count
    assert 0.7 < coverage < 1.0
    if _enabled(request.config):
        TIMES[n, stage] = benchmark.stats.stats.median
        TIMES[n, "lloyd"] = lloyd_s


def test_bench_compaction(benchmark, relaxed, fitted, request):
    problem, sites, _, _ = relaxed
    centres, sizes = fitted
    n = len(sites)
    benchmark.group = f"stages after Lloyd, squares N={n} {problem.grid.width}²"
    benchmark.extra_info.update(stage="compaction", n_elements=n)
    res = benchmark.pedantic(
        compact,
        args=(centres, np.zeros(n), sizes, "square", 1.0, problem.grid),
        rounds=_rounds(request.config, n),
        iterations=1,
    )
    before = 4 * float(np.sum(sizes**2)) / problem.grid.pixel_count
    after = 4 * float(np.sum(res.sizes**2)) / problem.grid.pixel_count  # disjoint squares
    benchmark.extra_info.update(coverage_before=before, coverage_after=after)
    assert after > before + 0.1
    ok = res.sizes > 0
    els = element_polygons("square", 1.0, res.centres[ok], np.zeros(ok.sum()), res.sizes[ok])
    assert largest_overlap(els) == 0.0
    if _enabled(request.config):
        TIMES[n, "compaction"] = benchmark.stats.stats.median


def test_stages_after_lloyd(request):
    """N = 4000, 1024²: fit + compaction at most twice the 20 Lloyd iterations."""
    if not _enabled(request.config):
        pytest.skip("a timing target: run with --benchmark-enable")
    stages = [TIMES.get((4000, s)) for s in ("lloyd", "fit", "compaction")]
    if None in stages:
        pytest.skip("the N = 4000 stage benchmarks did not run in this session")
    lloyd_s, fit_s, compaction_s = stages
    ratio = (fit_s + compaction_s) / lloyd_s
    assert ratio <= 2.0, (
        f"fit {fit_s:.2f} s + compaction {compaction_s:.2f} s = {ratio:.1f}x Lloyd {lloyd_s:.2f} s"
    )
