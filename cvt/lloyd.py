"""The Lloyd loop (paper §3.2, steps 1-5), backend-agnostic, and the one iteration loop
that every method built on Lloyd's idea reuses.

:func:`iterate` is the loop itself: it calls a method's ``step`` a number of times and
records, per iteration, the energy, the wall time and the empty cells, and reports
progress.  :func:`lloyd` is the paper's step on a backend: angles and scales are read at
the sites' current positions; the backend gives the integer moments of the cells; every
site moves to its cell's centroid.  A site whose cell holds no pixel stays where it is
and is counted as empty.  The energy of iteration k is that of the sites *before* the
k-th move, over their own cells.  The baselines' tile Lloyd steps run through
:func:`iterate` as well, and Hausner's point Lloyd step through :func:`lloyd` with its
own metric, region and angles (the hooks below).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .metrics import Metric
from .problem import Grid, Problem
from .seeding import initial_sites
from .validate import live_backend, whole_number

MAX_ITERATIONS = 100_000


@dataclass
class IterationLog:
    """What :func:`iterate` records, one entry per iteration."""

    energy: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)  # wall time per iteration
    empty: list[int] = field(default_factory=list)  # empty cells per iteration
    empty_sites: list[int] = field(default_factory=list)  # indices empty in the last iteration

    @property
    def iterations(self) -> int:
        return len(self.seconds)


def iterate(state, step: Callable, iterations: int, progress=None, log: IterationLog | None = None):
    """Run ``step(state) -> (state, energy, empty_mask)`` ``iterations`` times.

    ``progress(k, iterations, energy)`` is called after each step when given.
    Returns the final state and the :class:`IterationLog`."""
    iterations = whole_number(iterations, "iterations", minimum=0, maximum=MAX_ITERATIONS)
    log = IterationLog() if log is None else log
    for k in range(iterations):
        t0 = time.perf_counter()
        state, energy, empty = step(state)
        log.seconds.append(time.perf_counter() - t0)
        log.energy.append(float(energy))
        log.empty.append(int(np.count_nonzero(empty)))
        log.empty_sites = np.flatnonzero(empty).tolist()
        if progress is not None:
            progress(k + 1, iterations, energy)
    return state, log


@dataclass
class LloydResult(IterationLog):
    initial_sites: np.ndarray | None = None
    sites: np.ndarray | None = None  # final sites (N, 2)
    angles: np.ndarray | None = None  # at the final sites (radians)
    scales: np.ndarray | None = None  # at the final sites


@dataclass(frozen=True)
class LloydSetup:
    """How a Lloyd step reads a problem.  The defaults are the paper's; Hausner 2001 uses
    another metric, a smaller region for the centroid sums and a turn of the angles."""

    metric: Metric
    grid: Grid  # the region whose pixels enter the centroid sums
    angles_at: Callable  # sites -> angles (radians) of the elements
    scales_at: Callable  # sites -> size factors
    turn: float = 0.0  # added to the angles the backend sees (not to the elements')

    @classmethod
    def of(cls, problem: Problem, **changes) -> LloydSetup:
        base = dict(
            metric=problem.metric, grid=problem.grid, angles_at=problem.angles_at, scales_at=problem.scales_at
        )
        return cls(**{**base, **changes})

    def cell_angles(self, sites: np.ndarray) -> np.ndarray:
        return self.angles_at(sites) + self.turn if self.turn else self.angles_at(sites)


def lloyd_step(backend, setup: LloydSetup) -> Callable:
    """One Lloyd iteration of ``setup`` on ``backend``: ``step(sites) -> (next sites,
    energy, empty mask)``.  The one step of the suite: :func:`lloyd` iterates it and the
    speed reports time it."""

    def step(current):
        mom = backend.moments(
            current,
            angles=setup.cell_angles(current),
            scales=setup.scales_at(current),
            metric=setup.metric,
            grid=setup.grid,
        )
        return mom.centroids(current), mom.energy(current), mom.empty

    return step


def lloyd(
    problem: Problem,
    backend,
    iterations: int = 20,
    progress=None,
    sites: np.ndarray | None = None,
    setup: LloydSetup | None = None,
) -> LloydResult:
    """Run ``iterations`` Lloyd steps of ``problem`` on ``backend``.

    ``sites`` overrides the problem's seeding; ``setup`` the metric, region and angles
    of the step (:class:`LloydSetup`, default: the problem's own)."""
    live_backend(backend)
    iterations = whole_number(iterations, "iterations", minimum=0, maximum=MAX_ITERATIONS)
    setup = LloydSetup.of(problem) if setup is None else setup
    start = initial_sites(problem) if sites is None else np.array(sites, dtype=np.float64)
    step = lloyd_step(backend, setup)
    result = LloydResult(initial_sites=start)
    final, _ = iterate(start.copy(), step, iterations, progress, log=result)
    result.sites = final
    result.angles = setup.angles_at(final)
    result.scales = setup.scales_at(final)
    return result


def final_labels(
    problem: Problem, backend, result: LloydResult, setup: LloydSetup | None = None
) -> np.ndarray:
    """The label raster of the final sites over the whole region (for pictures and
    element placement)."""
    setup = LloydSetup.of(problem) if setup is None else setup
    return backend.label(
        result.sites,
        angles=setup.cell_angles(result.sites),
        scales=result.scales,
        metric=setup.metric,
        grid=problem.grid,
    )


__all__ = [
    "MAX_ITERATIONS",
    "IterationLog",
    "iterate",
    "LloydResult",
    "LloydSetup",
    "lloyd_step",
    "lloyd",
    "final_labels",
]
