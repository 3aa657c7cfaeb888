"""Time of one walled Lloyd step (cells cut at a picture's strong edges) against the
unwalled step on the same sites, OpenCL (target: walled at most 1.5x unwalled on a
20 000-tile mosaic of a 2560 px photograph).  Three paths: the unwalled step, the walled
step with the device listing the runs of the cells that may be in pieces, and the walled
step split on the host from the whole label raster (the path of every other backend).

The sites are those of a few Lloyd iterations of a mosaic of samples/scene.jpg, then of
STEPS walled Lloyd steps from there: each timed call takes the next of these, as a Lloyd
run does (the same sites called again would flatter a backend that carries state from
one call to the next, as the label kernel's seeds do).  With the suite's default
--benchmark-disable each path runs once as a plain test at 512 px and 2000 tiles; with
--benchmark-enable it is timed at 2560 px and 20 000 tiles.  Compare the paths within
one run: the machine is shared.
"""

import dataclasses
import itertools

import numpy as np
import pytest

from compact_distributions.cvt.errors import BackendUnavailable
from compact_distributions.cvt.mosaic.pipeline import WalledBackend, make_mosaic, split_moments

try:
    from compact_distributions.backends.opencl import OpenCLBackend

    OpenCLBackend.probe()
except BackendUnavailable as exc:
    pytest.skip(f"OpenCL backend unavailable: {exc}", allow_module_level=True)

from compact_distributions.bench.commands.mosaic import SAMPLES_DIR  # noqa: E402

PATHS = {
    "unwalled": lambda ocl, sites, args: ocl.moments(
        sites, **{**args, "grid": dataclasses.replace(args["grid"], mask=None)}
    ),
    "walled, on the device": lambda ocl, sites, args: WalledBackend(ocl).moments(sites, **args),
    "walled, host split": lambda ocl, sites, args: split_moments(ocl.label(sites, **args), sites),
}


STEPS = 6  # successive site sets the timed calls go through


@pytest.fixture(scope="module")
def walled_steps(request, ocl):
    opt = request.config.getoption
    large = opt("benchmark_enable") or not opt("benchmark_disable")  # as pytest-benchmark decides
    size, n = (2560, 20000) if large else (512, 2000)
    m = make_mosaic(SAMPLES_DIR / "scene.jpg", ocl, n_elements=n, size=size, iterations=3, method="ours")
    p = m.problem
    assert p.grid.mask is not None and not p.grid.mask.all()
    steps, sites = [], m.sites
    for _ in range(STEPS):
        args = dict(angles=p.angles_at(sites), scales=p.scales_at(sites), metric=p.metric, grid=p.grid)
        steps.append((sites, args))
        sites = WalledBackend(ocl).moments(sites, **args).centroids(sites)
    return steps, f"{m.width}x{m.height}, {n} tiles"


@pytest.mark.parametrize("path", PATHS)
def test_bench_walled_step(benchmark, ocl, walled_steps, path):
    steps, case = walled_steps
    benchmark.group = f"walled lloyd step, scene.jpg {case}"
    benchmark.extra_info.update(backend="opencl", device=ocl.device(), path=path, steps=STEPS)
    for sites, args in steps:  # buffers and kernels made outside the timing
        PATHS[path](ocl, sites, args)
    order = itertools.cycle(steps)

    def step():
        sites, args = next(order)
        return sites, args, PATHS[path](ocl, sites, args)

    sites, args, mom = benchmark(step)
    area = args["grid"].width * args["grid"].height
    walls = int((~args["grid"].mask).sum())
    assert mom.count.sum() == area if path == "unwalled" else 0 < mom.count.sum() < area - walls
    assert np.isfinite(mom.centroids(sites)).all()
