"""A method and a backend of another distribution: the complete plug-in example of the
Extending guide (tests/test_docs.py runs it through the registry, tests/test_plugins.py
installs it with pip, the gallery draws it)."""

import numpy as np
import shapely

from compact_distributions.backends.base import Backend
from compact_distributions.cvt.methods import Method, MethodOption
from compact_distributions.cvt.metrics import compile_sites
from compact_distributions.cvt.placement.ours import run_ours
from compact_distributions.cvt.validate import real_number


def run(problem, backend, *, iterations=20, progress=None, element=None, gap=0.0, shrink=1.0):
    """Ours, every element then scaled about its centre by ``shrink``."""
    dist = run_ours(problem, backend, iterations=iterations, progress=progress, element=element, gap=gap)
    dist.elements = [
        None if p is None else shapely.affinity.scale(p, shrink, shrink, origin="centroid")
        for p in dist.elements
    ]
    dist.method = "shrunk"
    return dist


METHOD = Method(
    "shrunk",
    run,
    summary="ours with every element shrunk",
    options=(
        MethodOption(
            "shrink",
            float,
            1.0,
            "scale of each element (0 to 1)",
            check=lambda v, name: real_number(v, name, above=0.0, maximum=1.0),
        ),
    ),
)


class BruteBackend(Backend):
    """Every pixel against every site, float64 (ties to the lower index)."""

    name = "brute"

    def device(self):
        return "CPU, brute force (a plug-in)"

    def _label(self, sites, angles, scales, metric, grid):
        coeff = compile_sites(metric, sites, angles, scales)
        ys, xs = np.mgrid[0 : grid.height, 0 : grid.width] + 0.5
        best = np.full(xs.shape, np.inf)
        labels = np.full(xs.shape, -1, dtype=np.int32)
        for i in range(len(sites)):
            d = coeff.distance(np.full(xs.shape, i), xs, ys)
            closer = d < best
            best[closer] = d[closer]
            labels[closer] = i
        labels[~grid.inside()] = -1
        return labels


__all__ = ["run", "METHOD", "BruteBackend"]
