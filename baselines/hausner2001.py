"""Hausner 2001: Lloyd relaxation under a Manhattan metric turned by a direction field.

A. Hausner, "Simulating decorative mosaics", Proc. SIGGRAPH 2001 (ACM), pp. 573-580.

Algorithm as implemented
------------------------
1. Direction field: the problem's ``--field`` when it has one; otherwise Hausner's own
   construction from the "edges", which on a plain problem are the region's border: the
   angle of the gradient of the distance transform to the edges (tiles turn their sides
   parallel to the nearest edge; on a square region that is 0° modulo 90°).
2. Lloyd iterations (20 by default) with the L1 (Manhattan) metric turned at each site by
   the field angle + 45°: Lloyd under L1 drives the cells towards copies of the L1 ball, a
   diamond, so the extra 45° makes them squares whose sides follow the field (measured
   here: without it, neighbour directions cluster at 45° to the field and tiles aligned
   with the field overlap more, 10.0 % against 8.0 % at 512², N = 1000).  The Voronoi
   step runs on the chosen backend (it is a point metric: Hausner's square pyramids in
   the z-buffer are exactly this).
3. Edge avoidance: pixels closer to an edge than half a tile side are "overwritten" (kept
   out of the centroid sums), so the centroid of a cell touching an edge lies inside, and
   tile centres drift at least half a tile away from it.  Implemented by giving the
   backend a region mask without that band, which labels the interior pixels exactly as
   the full region would.
4. Tiles: equal squares (or the ``element`` shape with the same area) of side
   δ·sqrt(area/N), δ = 0.95 (Hausner's tile size rule; ``baselines.common``), centred at
   the sites, turned by the field angle at each site.  Tiles are never resized or moved
   to avoid each other: overlap is allowed and counted by cvt.evaluate.  Tiles are
   clipped to the region (the clipped area is reported in ``extra``).

Energy per iteration: mean squared Euclidean distance of the counted pixels to their
site (``Moments.energy``), i.e. not the L1 energy Lloyd decreases here; reported for
comparison with ``ours``.

Where this departs from the paper, and why
------------------------------------------
* No picture: the suite's Table 2 problems have none, so the only edges are the region
  border; the picture's colours (tile colours) are not part of the comparison.
* The paper's field comes from user-drawn edge curves; a problem's ``--field`` replaces it
  when given (so that the same field drives every method).
* The edge band width (half a tile side) is our choice; the paper overwrites the edge
  lines with a thickness that it leaves to the user.
* Hausner's pyramids have finite resolution in a hardware z-buffer; here the backend's
  labels are exact at pixel centres.
* ``gap`` (grout) shrinks every tile by gap/2 on each side; the paper's δ is the grout.
"""

from __future__ import annotations

import math
import time

import numpy as np

from compact_distributions.cvt.distribution import Distribution
from compact_distributions.cvt.lloyd import LloydSetup, final_labels, lloyd
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.pixels import pixel_index
from compact_distributions.cvt.placement.fit import parse_gap
from compact_distributions.cvt.problem import Grid, Problem

from .common import BUDGET_DELTA, baseline, budget_size, make_elements, tile_shape

# The L1 ball is a diamond, and Lloyd under L1 drives the cells towards copies of it: a
# lattice of squares turned 45° from the metric's axes.  Turning the metric by the field
# angle + 45° makes the cells squares whose sides follow the field, as Hausner intends.
DIAMOND_TURN = math.pi / 4


def border_distance(grid: Grid) -> np.ndarray:
    """(H, W) Euclidean distance of each pixel centre to the region's border (the
    nearest pixel outside the region or the raster), in pixels."""
    from scipy import ndimage  # here: the registry imports this module at every start

    h, w = grid.shape
    pad = np.zeros((h + 2, w + 2), dtype=bool)
    pad[1:-1, 1:-1] = grid.inside()
    # distance to the nearest outside pixel centre minus half a pixel: to its edge
    return ndimage.distance_transform_edt(pad)[1:-1, 1:-1] - 0.5


class EdgeField:
    """Hausner's direction field from edges: the direction of the gradient of the
    distance to the nearest edge, sampled at a site's pixel."""

    def __init__(self, distance: np.ndarray):
        gy, gx = np.gradient(distance)
        self.angles = np.arctan2(gy, gx)

    def angles_at(self, sites: np.ndarray) -> np.ndarray:
        h, w = self.angles.shape
        return self.angles[pixel_index(sites, w, h)]


def run(
    problem: Problem,
    backend,
    *,
    iterations: int = 20,
    progress=None,
    element: str | None = None,
    gap: float = 0.0,
    delta: float = BUDGET_DELTA,
) -> Distribution:
    """Hausner 2001 on ``problem`` (see the module docstring)."""
    t_setup = time.perf_counter()
    gap = parse_gap(gap)
    shape = tile_shape(problem, element, default="square")
    grid = problem.grid
    n = problem.n_elements
    size = budget_size(shape, grid, n, delta)
    tile_side = math.sqrt(shape.unit_area) * size  # side of the square of the same area
    dist = border_distance(grid)
    band = 0.5 * tile_side
    interior = (dist >= band) & grid.inside()
    if not interior.any():  # region thinner than a tile: keep every pixel
        interior = grid.inside()
    field = problem.field if problem.field is not None else EdgeField(dist)
    setup_l1 = LloydSetup.of(
        problem,
        metric=make_metric("l1"),
        grid=Grid(grid.width, grid.height, interior),
        angles_at=field.angles_at,
        turn=DIAMOND_TURN,
    )
    setup = time.perf_counter() - t_setup

    t0 = time.perf_counter()
    res = lloyd(problem, backend, iterations, progress=progress, setup=setup_l1)
    sites, angles, scales = res.sites, res.angles, res.scales
    labels = final_labels(problem, backend, res, setup=setup_l1)
    tile_sizes = size * scales
    if gap > 0:
        tile_sizes = np.maximum(tile_sizes - 0.5 * gap * _gap_factor(shape), 0.0)
    elements, clipped = make_elements(shape, sites, angles, tile_sizes, grid)
    total = time.perf_counter() - t0
    return Distribution(
        method="hausner2001",
        sites=sites,
        angles=angles,
        scales=scales,
        elements=elements,
        energy=res.energy,
        seconds=res.seconds,
        setup_seconds=setup,
        lloyd_seconds=total,
        empty=res.empty,
        empty_sites=res.empty_sites,
        labels=labels,
        extra={
            "paper": METHOD.paper,
            "element": shape.element,
            "delta": delta,
            "tile_size": size,
            "tile_side_px": tile_side,
            "edge_band_px": band,
            "field": getattr(problem.field, "spec", None)
            or "edges (gradient of the distance to the region border)",
            "voronoi": f"L1 metric turned by the field + 45°, backend {getattr(backend, 'name', '?')}",
            "energy": "mean squared Euclidean distance of counted pixels to their site (px²)",
            "clipped_area_fraction": clipped,
        },
    )


def _gap_factor(shape) -> float:
    """Size units per pixel of offset along an edge normal (1/inradius of the unit ball)."""
    return 1.0 / shape.inradius


METHOD = baseline(
    "hausner2001",
    run,
    paper="Hausner, Simulating decorative mosaics, SIGGRAPH 2001",
    year=2001,
    paper_table2=None,
    fixed_size=True,
    summary="Lloyd under a turned Manhattan metric, equal squares centred at the sites (SIGGRAPH 2001)",
)


__all__ = ["DIAMOND_TURN", "border_distance", "EdgeField", "run", "METHOD"]
