"""The Lloyd loop, backend-agnostic (paper §3.2, steps 1-5).

Each iteration: angles and scales are read at the sites' current positions; the backend
gives the integer moments of the cells; every site moves to its cell's centroid.  A site
whose cell holds no pixel stays where it is and is counted as empty.  The energy of
iteration k is that of the sites *before* the k-th move, over their own cells.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .problem import Problem
from .seeding import initial_sites


@dataclass
class LloydResult:
    initial_sites: np.ndarray
    sites: np.ndarray  # final sites (N, 2)
    angles: np.ndarray  # at the final sites (radians)
    scales: np.ndarray  # at the final sites
    energy: list[float] = field(default_factory=list)  # per iteration
    seconds: list[float] = field(default_factory=list)  # wall time per iteration
    empty: list[int] = field(default_factory=list)  # empty cells per iteration
    empty_sites: list[int] = field(default_factory=list)  # indices empty in the last iteration

    @property
    def iterations(self) -> int:
        return len(self.energy)


def lloyd(problem: Problem, backend, iterations: int = 20, progress=None,
          sites: np.ndarray | None = None) -> LloydResult:
    """Run ``iterations`` Lloyd steps of ``problem`` on ``backend``.

    ``progress(k, iterations, energy)`` is called after each step when given.
    ``sites`` overrides the problem's seeding (used by baselines and tests)."""
    if iterations < 0:
        raise ValueError(f"iterations must be >= 0, got {iterations}")
    start = initial_sites(problem) if sites is None else np.array(sites, dtype=np.float64)
    sites = start.copy()
    metric, grid = problem.metric, problem.grid
    result = LloydResult(start, sites, problem.angles_at(sites), problem.scales_at(sites))
    for k in range(iterations):
        t0 = time.perf_counter()
        angles, scales = problem.angles_at(sites), problem.scales_at(sites)
        mom = backend.moments(sites, scales, angles, metric, grid)
        energy = mom.energy(sites)
        sites = mom.centroids(sites)
        result.seconds.append(time.perf_counter() - t0)
        result.energy.append(energy)
        result.empty.append(int(mom.empty.sum()))
        result.empty_sites = np.flatnonzero(mom.empty).tolist()
        if progress is not None:
            progress(k + 1, iterations, energy)
    result.sites = sites
    result.angles = problem.angles_at(sites)
    result.scales = problem.scales_at(sites)
    return result


def final_labels(problem: Problem, backend, result: LloydResult) -> np.ndarray:
    """The label raster of the final sites (for pictures and element placement)."""
    return backend.label(result.sites, result.scales, result.angles, problem.metric, problem.grid)
