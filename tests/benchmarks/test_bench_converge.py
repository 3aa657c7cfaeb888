"""Accelerated against plain Lloyd on a density picture (samples/scene.jpg), OpenCL:
the time of plain Lloyd's K iterations against the time accelerated Lloyd takes to reach
the energy plain Lloyd has after them (target: at most 0.4x, squares and circles alike,
at 1024², N = 4000, K = 200).

The accelerated run is as long as it needs to be: the module finds, once, the first
accelerated iteration that ends at or below plain's energy after K (a run is a pure
function of its problem on one backend), and each timed call runs that many.  With the
suite's default --benchmark-disable each case runs once as a plain test at 256², N = 250,
K = 40; with --benchmark-enable it is timed at 1024², N = 4000, K = 200.  Compare the
two variants of one group within one run: the machine is shared.  ``cvtbench converge``
reports the same ratio for every problem of Table 2 as well.
"""

import numpy as np
import pytest

from compact_distributions.cvt.errors import BackendUnavailable

try:
    from compact_distributions.backends.opencl import OpenCLBackend

    OpenCLBackend.probe()
except BackendUnavailable as exc:
    pytest.skip(f"OpenCL backend unavailable: {exc}", allow_module_level=True)

from compact_distributions.bench.commands.converge import ConvergeSpec  # noqa: E402
from compact_distributions.cvt.lloyd import lloyd  # noqa: E402


@pytest.fixture(scope="module", params=["square", "circle"])
def case(request, ocl):
    opt = request.config.getoption
    large = opt("benchmark_enable") or not opt("benchmark_disable")  # as pytest-benchmark decides
    size, n, k = (1024, 4000, 200) if large else (256, 250, 40)
    spec = ConvergeSpec(
        "bench", request.param, request.param, size, n, 0, k, k, 1e-4, "opencl", picture="scene.jpg"
    )
    problem = spec.problem()
    target = lloyd(problem, ocl, k + 1).energy[k]  # the energy of the K-th sites
    fast = lloyd(problem, ocl, k, accelerate=True)
    below = np.flatnonzero(np.asarray(fast.energy) <= target)
    reach = int(below[0]) + 1 if len(below) else None
    return problem, k, target, reach, f"{request.param}, scene.jpg density, {size}², N = {n}, K = {k}"


@pytest.mark.parametrize("variant", ["plain, K iterations", "accelerated, to plain's energy after K"])
def test_bench_converge(benchmark, ocl, case, variant):
    problem, k, target, reach, text = case
    benchmark.group = f"time to energy: {text}"
    benchmark.extra_info.update(backend="opencl", device=ocl.device(), variant=variant, iterations=k)
    if variant.startswith("plain"):
        res = benchmark.pedantic(lambda: lloyd(problem, ocl, k), rounds=3, iterations=1)
        assert res.iterations == k
        return
    if reach is None:
        pytest.fail(
            f"accelerated Lloyd did not reach plain's energy after {k} iterations ({target:.4g}) in {k}"
        )
    benchmark.extra_info["reach_iterations"] = reach
    res = benchmark.pedantic(lambda: lloyd(problem, ocl, reach, accelerate=True), rounds=3, iterations=1)
    assert res.energy[-1] <= target
