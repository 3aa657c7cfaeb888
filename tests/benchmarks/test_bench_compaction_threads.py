"""Compaction's threads (cvt/placement/compaction.py): the same relaxed and fitted cells
as :mod:`.test_bench_stages` (20 OpenCL linf Lloyd steps, squares, no density), compacted
with one thread and with every core this process may use.

A large program's PDHG steps are worked in blocks of rows and of columns, and the near
pairs' candidates in pieces, side by side (numpy and scipy's kernels let go of the
interpreter); each number is computed the same way whatever the split, so both runs give
the same elements bit for bit, which every run checks.  With --benchmark-enable the
cases are N = 4000, 16 000 and 64 000 (the issue's 4096² case) and ``extra_info`` holds
the speed-up of all cores over one (a figure to read on an otherwise idle machine)::

    pytest tests/benchmarks/test_bench_compaction_threads.py --benchmark-enable
"""

from __future__ import annotations

import numpy as np
import pytest

from compact_distributions.cvt.placement.compaction import compact
from compact_distributions.cvt.threads import usable_cores

from .test_bench_stages import _enabled, _rounds, fitted, pytest_generate_tests, relaxed

TIMES: dict = {}  # (n, threads) -> median seconds
FIRST: dict = {}  # n -> (centres, sizes) of one thread


@pytest.mark.parametrize("threads", ["one", "all"])
def test_bench_compaction_threads(benchmark, relaxed, fitted, threads, request):
    problem, sites, _, _ = relaxed
    centres, sizes = fitted
    n = len(sites)
    count = 1 if threads == "one" else usable_cores()
    benchmark.group = f"compaction threads, squares N={n} {problem.grid.width}²"
    benchmark.extra_info.update(n_elements=n, threads=count)
    res = benchmark.pedantic(
        compact,
        args=(centres, np.zeros(n), sizes, "square", 1.0, problem.grid),
        kwargs={"threads": count},
        rounds=_rounds(request.config, n),
        iterations=1,
    )
    if threads == "one":
        FIRST[n] = res.centres, res.sizes
    else:
        if n not in FIRST:
            pytest.skip("the one-thread case did not run in this session")
        assert np.array_equal(res.centres, FIRST[n][0]) and np.array_equal(res.sizes, FIRST[n][1])
    if _enabled(request.config):
        TIMES[n, threads] = benchmark.stats.stats.median
        if threads == "all":
            benchmark.extra_info["speed_up"] = TIMES[n, "one"] / TIMES[n, "all"]


__all__ = ["fitted", "pytest_generate_tests", "relaxed"]
