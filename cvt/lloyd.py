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

Convergence: ``iterations`` is a cap; with a ``tolerance`` the loop stops earlier, once
the lowest energy so far has improved by less than ``tolerance`` (relative) over the
last :data:`TOLERANCE_WINDOW` iterations (:func:`settled`).  The raster Lloyd map does
not settle on a density picture: its energy wanders by a few tenths of a percent from
one iteration to the next for ever, so a test on consecutive iterations would never
stop; the lowest energy of a wandering run stops improving, and the cap bounds the rest.
``accelerate`` chooses the next sites by :mod:`cvt.accelerate` instead of moving each to
its centroid; without it the sites are exactly plain Lloyd's.  The log says why the loop
stopped (:data:`STOPPED_BY`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .accelerate import AcceleratedState, accelerated_step
from .errors import InputError
from .methods import MethodOption
from .metrics import Metric
from .problem import Grid, Problem
from .seeding import initial_sites
from .validate import live_backend, real_number, whole_number

MAX_ITERATIONS = 100_000
# a tolerance looks at this many iterations: the wandering of a density picture's energy
# (+-0.3 % per iteration at 1024², N = 4000) sets new lows for tens of iterations at a time
TOLERANCE_WINDOW = 20
STOPPED_BY = ("iterations", "tolerance")  # the cap was reached / the energy settled
TIGHT_TOLERANCE = 1e-5  # "converged" for :func:`convergence_gap`
TIGHT_CAP = 2000


def parse_tolerance(value, name: str = "tolerance") -> float | None:
    """A tolerance: a finite number in (0, 1), or None (no tolerance)."""
    if value is None:
        return None
    return real_number(value, name, above=0.0, below=1.0)


def settled(lowest: list[float], tolerance: float, window: int = TOLERANCE_WINDOW) -> bool:
    """Whether a loop whose lowest energy after each iteration is ``lowest`` may stop:
    the lowest energy improved by at most ``tolerance`` (relative) over the last
    ``window`` iterations.

    Parameters
    ----------
    lowest : list of float
        The running minimum of the energy, one entry per iteration so far.
    tolerance : float
        The relative improvement below which the energy counts as settled.
    window : int
        The iterations the improvement is measured over.

    Returns
    -------
    bool
    """
    if len(lowest) <= window:
        return False
    before, now = lowest[-window - 1], lowest[-1]
    return bool(before - now <= tolerance * abs(now))


@dataclass
class IterationLog:
    """What :func:`iterate` records, one entry per iteration."""

    energy: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)  # wall time per iteration
    empty: list[int] = field(default_factory=list)  # empty cells per iteration
    empty_sites: list[int] = field(default_factory=list)  # indices empty in the last iteration
    stopped_by: str = "iterations"  # one of STOPPED_BY
    tolerance: float | None = None

    @property
    def iterations(self) -> int:
        return len(self.seconds)


def iterate(
    state,
    step: Callable,
    iterations: int,
    progress=None,
    log: IterationLog | None = None,
    tolerance: float | None = None,
):
    """Run ``step(state) -> (state, energy, empty_mask)`` ``iterations`` times, or
    fewer: with a ``tolerance``, until :func:`settled` says the energy has settled.

    ``progress(k, iterations, energy)`` is called after each step when given.
    Returns the final state and the :class:`IterationLog`, whose ``stopped_by`` says
    why the loop ended."""
    iterations = whole_number(iterations, "iterations", minimum=0, maximum=MAX_ITERATIONS)
    tolerance = parse_tolerance(tolerance)
    log = IterationLog() if log is None else log
    log.tolerance, log.stopped_by = tolerance, "iterations"
    lowest: list[float] = []
    for k in range(iterations):
        t0 = time.perf_counter()
        state, energy, empty = step(state)
        log.seconds.append(time.perf_counter() - t0)
        log.energy.append(float(energy))
        log.empty.append(int(np.count_nonzero(empty)))
        log.empty_sites = np.flatnonzero(empty).tolist()
        if progress is not None:
            progress(k + 1, iterations, energy)
        if tolerance is not None:
            lowest.append(float(np.fmin(energy, lowest[-1])) if lowest else float(energy))
            if settled(lowest, tolerance):
                log.stopped_by = "tolerance"
                break
    return state, log


@dataclass
class LloydResult(IterationLog):
    initial_sites: np.ndarray | None = None
    sites: np.ndarray | None = None  # final sites (N, 2)
    angles: np.ndarray | None = None  # at the final sites (radians)
    scales: np.ndarray | None = None  # at the final sites
    accelerated: bool = False
    evaluations: int = 0  # backend evaluations (moments) the loop made
    fallbacks: int = 0  # accelerated steps the safeguard refused

    def convergence(self) -> dict:
        """How the loop ran, for a method's ``extra`` (and result.json): why it stopped,
        its tolerance, whether it was accelerated, its evaluations and fallbacks."""
        return {
            "stopped_by": self.stopped_by,
            "tolerance": self.tolerance,
            "accelerate": self.accelerated,
            "lloyd_evaluations": self.evaluations,
            "accelerate_fallbacks": self.fallbacks,
        }


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
    *,
    tolerance: float | None = None,
    accelerate: bool = False,
) -> LloydResult:
    """Run ``iterations`` Lloyd steps of ``problem`` on ``backend`` (fewer where a
    ``tolerance`` finds the energy settled, :func:`settled`).

    Parameters
    ----------
    problem : Problem
        The raster, sites, metric, density and field.
    backend : Backend
        A live backend (its moments).
    iterations : int
        The iterations, or their cap with a ``tolerance``.
    progress : callable, optional
        ``progress(k, iterations, energy)`` after each iteration.
    sites : (N, 2) array, optional
        The start, instead of the problem's seeding.
    setup : LloydSetup, optional
        The metric, region and angles of the step (default: the problem's own).
    tolerance : float, optional
        Stop once the lowest energy improved by less than this (relative) over the last
        :data:`TOLERANCE_WINDOW` iterations.
    accelerate : bool
        Choose the next sites by :func:`cvt.accelerate.accelerated_step` (each
        iteration's energy is then that of the sites it ends with); False: plain Lloyd.

    Returns
    -------
    LloydResult
    """
    live_backend(backend)
    iterations = whole_number(iterations, "iterations", minimum=0, maximum=MAX_ITERATIONS)
    tolerance = parse_tolerance(tolerance)
    accelerate = parse_accelerate(accelerate)
    setup = LloydSetup.of(problem) if setup is None else setup
    start = initial_sites(problem) if sites is None else np.array(sites, dtype=np.float64)
    step = lloyd_step(backend, setup)
    result = LloydResult(initial_sites=start, accelerated=accelerate)
    if accelerate:
        state, _ = iterate(
            AcceleratedState(start.copy()),
            accelerated_step(step, setup.grid),
            iterations,
            progress,
            log=result,
            tolerance=tolerance,
        )
        final, result.evaluations, result.fallbacks = state.sites, state.evaluations, state.fallbacks
    else:
        final, _ = iterate(start.copy(), step, iterations, progress, log=result, tolerance=tolerance)
        result.evaluations = result.iterations
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


def parse_accelerate(value, name: str = "accelerate") -> bool:
    """A yes/no: True or False (numpy's bools too)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise InputError(f"{name} must be true or false, got {value!r}")


def final_energy(backend, setup: LloydSetup, sites: np.ndarray) -> float:
    """The energy of ``sites`` over their own cells (one more evaluation: plain Lloyd's
    log holds the energy of the sites each iteration starts from, not of its last move's).

    Parameters
    ----------
    backend : Backend
        A live backend.
    setup : LloydSetup
        The step's metric, region, angles and scales.
    sites : (N, 2) array
        The sites.

    Returns
    -------
    float
    """
    return float(lloyd_step(backend, setup)(np.asarray(sites, dtype=np.float64))[1])


def convergence_gap(
    problem: Problem,
    backend,
    iterations: int = 20,
    *,
    setup: LloydSetup | None = None,
    accelerate: bool = False,
    tolerance: float = TIGHT_TOLERANCE,
    cap: int = TIGHT_CAP,
) -> dict:
    """How far a run of ``iterations`` is from converged: the energy of its final sites
    against the lowest energy of accelerated Lloyd run from the same start to a tight
    ``tolerance`` (at most ``cap`` iterations): a table's "how far from converged".

    Parameters
    ----------
    problem : Problem
        The run's problem (its seeding is the start of both runs).
    backend : Backend
        A live backend.
    iterations : int
        The run's Lloyd iterations.
    setup : LloydSetup, optional
        The run's step, where its method changes it (default: the problem's own).
    accelerate : bool
        Whether the run itself is accelerated.
    tolerance, cap : float, int
        The tight tolerance and its cap.

    Returns
    -------
    dict
        ``energy`` (after the run's iterations), ``converged_energy``, ``excess`` (their
        relative difference: 0.05 is 5 % above converged; negative where the run ended
        lower than the tight one), and the tight run's ``converged_iterations`` and
        ``stopped_by``.
    """
    setup = LloydSetup.of(problem) if setup is None else setup
    run = lloyd(problem, backend, iterations, setup=setup, accelerate=accelerate)
    energy = run.energy[-1] if accelerate and run.energy else final_energy(backend, setup, run.sites)
    tight = lloyd(problem, backend, cap, setup=setup, tolerance=tolerance, accelerate=True)
    converged = min(tight.energy) if tight.energy else energy
    return {
        "energy": float(energy),
        "converged_energy": float(converged),
        "excess": float(energy / converged - 1.0),
        "converged_iterations": tight.iterations,
        "stopped_by": tight.stopped_by,
    }


# the options of a method whose loop is :func:`lloyd` (its record declares them)
TOLERANCE_OPTION = MethodOption(
    "tolerance",
    float,
    None,
    "stop Lloyd once its lowest energy improved by less than TOLERANCE (relative) over the last "
    f"{TOLERANCE_WINDOW} iterations, with --iterations as the cap (default 20: raise it, "
    "e.g. --iterations 2000); result.json's stopped_by says which ended the loop",
    check=parse_tolerance,
    tag="tol",
    label="tol={:g}",
)
ACCELERATE_OPTION = MethodOption(
    "accelerate",
    bool,
    False,
    "accelerated Lloyd: each site over-relaxed along its step while the step keeps its "
    "direction, with an energy safeguard that falls back to the plain step (any backend)",
    check=parse_accelerate,
    tag="acc",
    label="accelerated",
)
LLOYD_OPTIONS = (TOLERANCE_OPTION, ACCELERATE_OPTION)


__all__ = [
    "MAX_ITERATIONS",
    "TOLERANCE_WINDOW",
    "STOPPED_BY",
    "TIGHT_TOLERANCE",
    "TIGHT_CAP",
    "parse_tolerance",
    "parse_accelerate",
    "settled",
    "final_energy",
    "convergence_gap",
    "TOLERANCE_OPTION",
    "ACCELERATE_OPTION",
    "LLOYD_OPTIONS",
    "IterationLog",
    "iterate",
    "LloydResult",
    "LloydSetup",
    "lloyd_step",
    "lloyd",
    "final_labels",
]
