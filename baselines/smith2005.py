"""Smith, Liu & Klein 2005 ("Animosaics"): area-based centroidal Voronoi diagrams.

K. Smith, Y. Liu, A. Klein, "Animosaics", Proc. ACM SIGGRAPH/Eurographics Symposium on
Computer Animation (SCA 2005), pp. 201-208.

Algorithm as implemented
------------------------
The static part of the paper: an area-based CVD, i.e. Lloyd's method whose generators
are rigid tiles of fixed size; the region of a tile is the set of points nearer to the
tile's area than to any other tile.  Each iteration (20 by default):

1. rasterise the tiles and compute their regions with a Euclidean distance transform and
   nearest-tile indices (``baselines.common.tile_voronoi``);
2. translate every tile to the centroid of its region;
3. rotate every tile to fit its region best: among candidate angles (a coarse sweep over
   the tile's whole symmetry period in 6° steps, then ±3° and ±1.5° around the best), the
   angle at which the tile, centred at the new centroid, covers the most pixels of its own
   region; ties keep the smaller turn.

Tiles have a fixed size: the area of a square of side δ·sqrt(area/N), δ = 0.95 (the
budget of ``baselines.common``), times the density's size factor where there is one.
Tiles may overlap (nothing but the regions keeps them apart); the overlap is counted by
cvt.evaluate.  Tiles are clipped to the region.

Energy per iteration: mean squared distance of the region's pixels to their nearest tile.

Where this departs from the paper, and why
------------------------------------------
* Only the abstract of the paper could be read; the best-fit rotation rule above
  ("rotate the tile to fit its cell") is our concrete reading.  The paper's own rotation rule may differ in detail.
* The animation part (temporal coherence, groups of tiles moving together, tiles
  entering and leaving) is irrelevant to a static Table 2 problem and left out.
* Regions are computed with a CPU distance transform, not with distance meshes on
  graphics hardware; both are pixel-accurate.
* One tile shape and size for all tiles (the Table 2 budget), no user-chosen mix.
"""

from __future__ import annotations

import math

import numpy as np

from compact_distributions.cvt.distribution import Distribution
from compact_distributions.cvt.problem import Problem

from .common import BUDGET_DELTA, baseline, run_fixed_tiles

COARSE_STEP = math.radians(6.0)
FINE_STEPS = (math.radians(3.0), math.radians(1.5))


def region_ring(shape, labels: np.ndarray, centres, sizes):
    """The region pixels whose inclusion in their own tile depends on its angle, and the
    count of those inside at every angle: a pixel nearer than the tile's inradius is
    inside at every angle, one beyond its circumradius outside at every angle (with a
    margin far above rounding).  Returns (own, vx, vy, limit, base) for ``ring_counts``."""
    n = len(centres)
    w = labels.shape[1]
    flat = labels.ravel()
    pixels = np.flatnonzero(flat >= 0)
    own = flat[pixels]  # each region pixel is tested against its own tile only
    vx = (pixels % w + 0.5) - centres[own, 0]
    vy = (pixels // w + 0.5) - centres[own, 1]
    limit = sizes[own]
    dist = np.hypot(vx, vy)
    always = dist < limit * shape.inradius * (1.0 - 1e-9)
    ring = ~always & (dist <= limit * shape.circumradius * (1.0 + 1e-9))
    base = np.bincount(own[always], minlength=n)
    return own[ring], vx[ring], vy[ring], limit[ring], base


def ring_counts(shape, ring, angles) -> np.ndarray:
    """(N, A) pixels of each tile's own region covered by the tile turned by each of
    ``angles`` (N, A), from its ``region_ring``."""
    own, vx, vy, limit, base = ring
    counts = np.empty(angles.shape)
    for a in range(angles.shape[1]):
        c, s = np.cos(angles[:, a]), np.sin(angles[:, a])
        inside = shape.gauge_turned(vx, vy, c[own], s[own]) <= limit
        counts[:, a] = base + np.bincount(own[inside], minlength=len(base))
    return counts


def fit_counts(shape, labels: np.ndarray, centres, sizes, angles) -> np.ndarray:
    """(N, A) number of pixels of each tile's own region covered by the tile centred at
    ``centres`` and turned by each of ``angles`` (N, A)."""
    return ring_counts(shape, region_ring(shape, labels, centres, sizes), angles)


def best_fit_turn(shape):
    """The turning rule: the angle at which the tile covers most of its region."""

    def turn(mom, labels, centres, angles, sizes):
        h, w = labels.shape
        cl = np.clip(
            centres, [0.0, 0.0], [w - 1e-9, h - 1e-9]
        )  # a centre off the raster is measured from its edge
        period = shape.symmetry_turn
        if shape.turns_freely:
            return angles  # a circle has no orientation
        half = period / 2
        k = int(np.floor(half / COARSE_STEP))
        offsets = np.arange(-k, k + 1) * COARSE_STEP
        best = angles.copy()
        ring = region_ring(shape, labels, cl, sizes)  # the same pixels for every pass
        for step_offsets in [offsets] + [np.array([-s, 0.0, s]) for s in FINE_STEPS]:
            cand = best[:, None] + step_offsets[None, :]
            counts = ring_counts(shape, ring, cand)
            # prefer the smaller turn among equal counts
            score = counts - 1e-6 * np.abs(cand - angles[:, None])
            best = cand[np.arange(len(best)), np.argmax(score, axis=1)]
        return np.where(mom.empty, angles, best)

    return turn


def run(
    problem: Problem,
    backend=None,
    *,
    iterations: int = 20,
    progress=None,
    element: str | None = None,
    gap: float = 0.0,
    delta: float = BUDGET_DELTA,
) -> Distribution:
    """Smith et al. 2005 on ``problem``; ``backend`` is not used (the distance is to the
    tiles' areas, which no point-metric backend computes)."""
    return run_fixed_tiles(
        "smith2005",
        problem,
        iterations,
        progress,
        element,
        gap,
        delta,
        lambda problem, shape: best_fit_turn(shape),
        {"paper": METHOD.paper, "turn": "best fit: angle covering most of the tile's own region"},
    )


METHOD = baseline(
    "smith2005",
    run,
    paper="Smith, Liu, Klein, Animosaics, SCA 2005",
    year=2005,
    paper_table2=(0.681, "1 min"),
    fixed_size=True,
    summary="tiles moved and turned to cover their own regions best (SCA 2005)",
)


__all__ = [
    "COARSE_STEP",
    "FINE_STEPS",
    "region_ring",
    "ring_counts",
    "fit_counts",
    "best_fit_turn",
    "run",
    "METHOD",
]
