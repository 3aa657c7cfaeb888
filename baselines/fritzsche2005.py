"""Fritzsche et al. 2005: Lloyd's method extended from points to tiles.

L.-P. Fritzsche, H. Hellwig, S. Hiller, O. Deussen, "Interactive design of authentic
looking mosaics using Voronoi structures", Proc. 2nd International Symposium on Voronoi
Diagrams in Science and Engineering (ISVD 2005), Seoul, pp. 1-11.

Algorithm as implemented
------------------------
The generators of the Voronoi diagram are the tiles themselves (after Hiller, Hellwig
and Deussen, "Beyond stippling", 2003): the region of a tile is the set of points nearer
to the tile (its area) than to any other tile.  Each iteration (20 by default):

1. rasterise the tiles and compute the tiles' Voronoi regions by a Euclidean distance
   transform with nearest-tile indices (``baselines.common.tile_voronoi``): an honest
   distance to the tile, not to its centre;
2. move every tile to the centroid of its region;
3. turn every tile to the principal (major) axis of its region, from the region's
   second central moments, choosing among the tile's symmetric copies the turn of least
   angle.  When the problem has a direction field, the field at the new position gives
   the angle instead (the paper's user-drawn "directional information").

Tiles have a fixed size: all of them the area of a square of side δ·sqrt(area/N),
δ = 0.95 (the budget of ``baselines.common``), times the density's size factor where the
problem has a density.  Nothing keeps two tiles apart: the method relies on the regions
to separate them, tiles can overlap (initially they do, at random seeds), and the overlap
is counted by cvt.evaluate, not hidden.  Tiles are clipped to the region.

Energy per iteration: mean squared distance of the region's pixels to their nearest tile
(0 inside tiles), the quantity the tile Lloyd step lowers.

Where this departs from the paper, and why
------------------------------------------
* Only the abstract of the paper could be read; the details above (centroid, principal
  axis) follow the "Beyond stippling" scheme that the paper extends.  Anything the paper
  adds beyond that is missing.
* The paper's tiles come in several shapes and sizes chosen by the user, and the user
  edits contours interactively; Table 2 compares equal tiles on a plain region, so all
  tiles here have one shape and size and there is no interaction.
* The Voronoi regions are computed on the CPU with a distance transform instead of
  rendering distance meshes on graphics hardware; both are pixel-accurate.
* On a square cell the second moments are isotropic and the principal axis is poorly
  defined, so square tiles may turn erratically; that is the rule, not a bug.
"""

from __future__ import annotations

import numpy as np

from compact_distributions.cvt.distribution import Distribution
from compact_distributions.cvt.problem import Problem

from .common import BUDGET_DELTA, baseline, nearest_equivalent, run_fixed_tiles


def principal_axis_turn(problem: Problem, shape):
    """The turning rule: principal axis of the region (or the problem's field)."""

    def turn(mom, labels, centres, angles, sizes):
        if problem.field is not None:
            target = problem.angles_at(centres)
        else:
            target = mom.principal_angles()
        new = nearest_equivalent(target, angles, shape.symmetry_turn)
        return np.where(mom.empty, angles, new)

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
    """Fritzsche et al. 2005 on ``problem``; ``backend`` is not used (the distance is to
    the tiles, which no point-metric backend computes)."""
    turn = "field" if problem.field is not None else "principal axis of the region"
    return run_fixed_tiles(
        "fritzsche2005",
        problem,
        iterations,
        progress,
        element,
        gap,
        delta,
        principal_axis_turn,
        {"paper": METHOD.paper, "turn": turn},
    )


METHOD = baseline(
    "fritzsche2005",
    run,
    paper="Fritzsche, Hellwig, Hiller, Deussen, Interactive design of authentic looking mosaics using Voronoi structures, ISVD 2005",
    year=2005,
    paper_table2=(0.648, "1 min"),
    fixed_size=True,
    summary="Lloyd's method extended from points to tiles (ISVD 2005)",
)


__all__ = ["principal_axis_turn", "run", "METHOD"]
