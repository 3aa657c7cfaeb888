"""The common CPU tool as a backend: scipy's cKDTree labels every pixel centre (Minkowski
p = 2, 1 or ∞), then ``np.bincount`` sums the moments.  It is the comparison point of the
speed targets.

It supports what a k-d tree query can express: ``l2`` with any angles (a circle does not
turn) and ``l1`` / ``linf`` with every angle 0, all with one size factor for every site
(a common factor does not change the nearest site).  Anything else is refused with the
reason.  Exact ties (equidistant sites, common under l1 and linf on the pixel lattice)
go to whichever site cKDTree returns, not always the lower index, so where labels
differ from the NumPy reference they differ only at ties.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.spatial import cKDTree

from compact_distributions.cvt.metrics import METRIC_NAMES, make_metric

from .base import Backend

# the metrics a k-d tree query computes: the balls of a Minkowski norm, by the records
P_OF_METRIC = {
    name: ball.minkowski_p for name in METRIC_NAMES if (ball := make_metric(name)).minkowski_p is not None
}


@lru_cache(maxsize=2)
def _pixel_centres(width: int, height: int) -> np.ndarray:
    ys, xs = np.mgrid[0:height, 0:width]
    return np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], axis=1)


class CKDTreeBackend(Backend):
    name = "ckdtree"
    contained = True  # NumPy/SciPy only: a sweep runs it in its own process
    runtime_bytes = 0  # numpy and scipy: loaded by the program itself
    bytes_per_pixel = 64  # pixel centres (float64 x, y, cached), the query's distances and indices
    bytes_per_site = 1000
    metrics = tuple(P_OF_METRIC)

    def device(self) -> str:
        return "CPU, scipy cKDTree (all cores) + np.bincount"

    def supports(self, metric, angles, scales) -> str | None:
        if (reason := super().supports(metric, angles, scales)) is not None:
            return reason
        if metric.minkowski_p != 2 and np.any(angles != 0):  # only the circle does not turn
            return f"metric {metric.name!r} with turned sites (a direction field) is not supported"
        if np.ptp(scales) > 0:
            return "sites of different sizes (a density) are not supported"
        return None

    def _label(self, sites, angles, scales, metric, grid) -> np.ndarray:
        tree = cKDTree(sites)
        centres = _pixel_centres(grid.width, grid.height)
        labels = np.full(grid.width * grid.height, -1, dtype=np.int32)
        if grid.mask is None:
            _, idx = tree.query(centres, k=1, p=metric.minkowski_p, workers=-1)
            labels[:] = idx
        else:
            inside = np.flatnonzero(grid.mask.ravel())
            _, idx = tree.query(centres[inside], k=1, p=metric.minkowski_p, workers=-1)
            labels[inside] = idx
        return labels.reshape(grid.height, grid.width)


__all__ = ["P_OF_METRIC", "CKDTreeBackend"]
