"""An accelerated Lloyd step: per-site over-relaxation with an energy safeguard.

Plain Lloyd moves every site to its cell's centroid, ``x <- G(x)``.  The accelerated
step moves site i further along the same direction, ``x_i <- x_i + w_i (G_i(x) - x_i)``,
with a relaxation ``w_i`` of its own: it grows (x1.5, up to 3) while the site's step
keeps its direction from one iteration to the next (a slow, persistent drift, the modes
that make Lloyd slow) and shrinks (x0.7, down to 1, plain Lloyd) when the step turns (an
oscillation, which over-relaxation would amplify).  The new sites' moments give their
energy; if it rose by more than :data:`SLACK` (relative) over the energy of the sites
the iteration started from, the step is refused and the iteration falls back to the
plain step ``G(x)`` and starts the relaxations again at 1 (the safeguard of Peng et al.,
ACM TOG 37(4) 2018); a step whose relaxations are all 1 is the plain step and is never
refused.  A site proposed outside the region takes its plain step.

It needs nothing but each evaluation's centroids and energy, so it runs on every
backend.  Each iteration ends with sites whose energy it has measured and records that
energy (plain Lloyd records the energy of the sites an iteration starts from); it costs
one evaluation, two where the safeguard falls back, and the first iteration one more
(the start's).

Why this and not Anderson acceleration (Zhang, Yao, Peng, Yu & Deng, arXiv 1805.10638)
or one global relaxation ``w`` (measured on OpenCL, 1024² px, N = 4000, seed 0: the
evaluations needed to reach the energy plain Lloyd has after 200 iterations): Anderson
with m = 1, 3 or 8 and the same safeguard reached it on neither triangles nor circles
within 200 evaluations, and on squares in 95 (plain Lloyd first gets there at 57): a
raster's centroids move in whole-pixel sums, so the secant model of the last steps fits
noise.  One global ``w = 1.9`` took 13, 19, 76, 161 and 55 evaluations on squares,
rectangles, ellipses, triangles and circles (it amplifies the sites that oscillate); the
per-site relaxation 12, 16, 30, 137 and 49.  A safeguard without slack refused 40-70 of
about 150 steps on ellipses, triangles and density pictures, whose energy also wanders
under plain Lloyd (scales, cells that are not Euclidean), at two evaluations each; 0.1 %
keeps it for real rises.  ``cvtbench converge`` reports the ratios for every problem.

On a noisy density picture (a photograph: grace_hopper.jpg, skimage's chelsea and
coffee; 1024², N = 4000, OpenCL, seeds 0-7) the energy has no slow mode left to
accelerate after about 60-80 iterations: each site's scale is read from the one pixel it
stands on, so a sub-pixel move can change its cell's size, and plain Lloyd's energy
wanders about a level that depends on the seed (grace_hopper squares: 110.5 ± 1.5 after
200 iterations over 8 seeds, 111.1 after 80).  Plain Lloyd itself first reaches the
mean of its own iterations 151-200 after a median 0.35x (squares) and 0.42x (circles) of
its 200 iterations, and the evaluations this step needs to reach plain's energy after
200 iterations range from 0.09x to never (squares) and 0.12x-0.57x (circles) with the
seed.  Tried and no better: stopping the relaxation after the first refused step
(median over seeds 0-7 0.47x squares, 0.42x circles, against this step's 0.62x and 0.38x),
a safeguard against the highest of the last 10 energies (seeds 0-7: 0.25x squares but
never on 3 seeds, 0.47x circles), pausing the relaxation for 1, 2, 4 ... iterations
after each refusal (seeds 0-3), relaxing only the step averaged over the 12 nearest
sites (seed 0), one global relaxation of 0.5, 0.7 or 1.2 (seed 0: no lower level), and
a strictly descending search (steps of random
relaxation in [0.5, 1.5] from the best sites; seed 0), which stalls: after 200
iterations it is above plain Lloyd on 5 of the 6 picture and shape pairs.  Where plain
Lloyd still converges (Table 2's problems, scene.jpg) the ratios hold over seeds 0-3:
scene.jpg squares 0.06x, circles 0.18-0.28x; Table 2's average 0.18-0.25x (by
evaluations).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .pixels import pixel_index
from .problem import Grid

GROW = 1.5  # a site whose step keeps its direction: relaxation x GROW
SHRINK = 0.7  # a site whose step turned: relaxation x SHRINK
MAX_RELAXATION = 3.0
SLACK = 1e-3  # a rise of the energy the safeguard lets pass (relative)


@dataclass
class AcceleratedState:
    """Where the accelerated loop stands: the sites the last iteration ended with, what
    their evaluation gave (centroids, energy, empty cells), each site's relaxation and
    last step, and the evaluations and fallbacks so far."""

    sites: np.ndarray
    centroids: np.ndarray | None = None  # G(sites); None before the first evaluation
    energy: float = float("nan")
    empty: np.ndarray | None = None
    relaxation: np.ndarray | None = None  # (N,) w_i
    previous: np.ndarray | None = None  # (N, 2) the last step G(x) - x, None after a restart
    evaluations: int = 0
    fallbacks: int = 0


def relaxations(relaxation: np.ndarray | None, step: np.ndarray, previous: np.ndarray | None) -> np.ndarray:
    """Each site's relaxation for ``step`` (N, 2): grown where it keeps the direction of
    ``previous``, shrunk where it turned (or stopped), within [1, MAX_RELAXATION]; all 1
    without a previous step.

    Parameters
    ----------
    relaxation : (N,) float array or None
        The relaxations of the last iteration (None: start).
    step, previous : (N, 2) float arrays
        This iteration's plain step G(x) - x and the last one (None after a restart).

    Returns
    -------
    (N,) float array
    """
    if previous is None or relaxation is None:
        return np.ones(len(step))
    same = np.einsum("ij,ij->i", step, previous) > 0
    return np.clip(np.where(same, relaxation * GROW, relaxation * SHRINK), 1.0, MAX_RELAXATION)


def inside_region(grid: Grid) -> Callable[[np.ndarray], np.ndarray]:
    """``inside(points) -> (N,) bool``: the point lies on the raster in a pixel of the
    region (the region's mask is read once)."""
    mask = grid.mask
    w, h = grid.width, grid.height

    def inside(points: np.ndarray) -> np.ndarray:
        on = (points[:, 0] >= 0) & (points[:, 0] <= w) & (points[:, 1] >= 0) & (points[:, 1] <= h)
        if mask is None:
            return on
        return on & mask[pixel_index(points, w, h)]

    return inside


def accelerated_step(evaluate: Callable, grid: Grid) -> Callable:
    """The accelerated iteration over ``evaluate(sites) -> (centroids, energy, empty
    mask)`` (a Lloyd step, :func:`cvt.lloyd.lloyd_step`): ``step(state) -> (state,
    energy, empty mask)`` with an :class:`AcceleratedState`, the energy and empty cells
    those of the sites the iteration ends with.

    Parameters
    ----------
    evaluate : callable
        One evaluation of the backend at the given sites.
    grid : Grid
        The region the sites must stay in.

    Returns
    -------
    callable
    """
    inside = inside_region(grid)

    def measure(state: AcceleratedState, sites: np.ndarray):
        state.evaluations += 1
        return evaluate(sites)

    def step(state: AcceleratedState):
        x = state.sites
        if state.centroids is None:  # the first iteration measures its start too
            state.centroids, state.energy, state.empty = measure(state, x)
        plain = state.centroids
        move = plain - x
        w = relaxations(state.relaxation, move, state.previous)
        proposed = x + w[:, None] * move
        off = ~inside(proposed)
        proposed[off] = plain[off]
        centroids, energy, empty = measure(state, proposed)
        # the plain step itself (every w_i = 1: after a fallback, at the start) is not refused
        relaxed = bool((w > 1.0).any())
        if relaxed and not energy <= state.energy * (1.0 + SLACK):  # NaN falls back as well
            state.fallbacks += 1
            proposed, w, move = plain, np.ones(len(x)), None
            centroids, energy, empty = measure(state, proposed)
        state.sites, state.centroids, state.energy, state.empty = proposed, centroids, energy, empty
        state.relaxation, state.previous = w, move
        return state, energy, empty

    return step


__all__ = [
    "GROW",
    "SHRINK",
    "MAX_RELAXATION",
    "SLACK",
    "AcceleratedState",
    "relaxations",
    "inside_region",
    "accelerated_step",
]
