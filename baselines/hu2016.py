"""Hu et al. 2016: continuous and combinatorial optimisation of a tile arrangement.

W. Hu, Z. Chen, H. Pan, Y. Yu, E. Grinspun, W. Wang, "Surface mosaic synthesis with
irregular tiles", IEEE Transactions on Visualization and Computer Graphics 22(3),
pp. 1302-1313, 2016.

Algorithm as implemented (2D, on the plane)
-------------------------------------------
Tiles start small (a quarter of the budget size, so that random seeds do not overlap
much) at the common seeds, turned by the problem's field (0 without one).  Each
iteration (20 by default) alternates:

1. Continuous step.  Approximate Voronoi regions of the tiles: every pixel goes to the
   nearest tile, by a Euclidean distance transform of the rasterised tiles with
   nearest-tile indices (``baselines.common.tile_voronoi``).  Then each tile's position,
   orientation and scale are optimised for the tightest fit in its region: the scale is
   the largest that keeps the tile inside the region (its contour samples, the rule of
   ``cvt.placement``), and a compass search over (x, y, θ), started from the better of the
   tile's current pose and its region's centroid, moves or turns the tile while that
   scale grows (steps 2 px / 4° down to 0.25 px / 0.5°, two rounds each).
2. Combinatorial step (``combinatorial_step``).  The smallest tiles (N/50 of them, empty
   ones first) are offered the largest holes (local maxima of the distance to the
   nearest other tile or the region's border; the offered tiles count as holes); the tile is moved there, turned and scaled to
   the largest fit in the hole, and the move is accepted only if the exact coverage
   (shapely, the same quantity cvt.evaluate reports) strictly grows.  The step can
   therefore never lower coverage.

The scale is per tile and free: tiles grow until they touch their regions' borders, so
this method, like ours, does not use the fixed size budget.  ``scales`` reports each
tile's size relative to the budget tile (δ·sqrt(area/N), δ = 0.95).
Energy per iteration: mean squared distance of the region's pixels to their nearest tile.

Where this departs from the paper, and why
------------------------------------------
* Only the abstract of the paper could be read; the pose search is our
  concrete version of "optimise positions and orientations for a tight fit" (the paper
  solves a polygon-containment optimisation per tile).
* The paper works on surfaces with a library of irregular tiles; here the plane and one
  element shape.  Its combinatorial step also *permutes* tiles between regions, which
  changes nothing when every tile has the same shape, so only *replacement* (moving the
  worst tile into the largest hole) is implemented.
* The paper keeps tile sizes from its library and scales them for the fit; without a
  library, the scale is whatever fits.
* A density map does not steer the tile sizes (the scale is whatever fits); the seeds
  still follow it.
* Regions come from a CPU distance transform, not from the paper's restricted Voronoi
  diagram of boundary samples; both approximate the distance to the tile.
"""

from __future__ import annotations

import math
import time

import numpy as np
import shapely

from compact_distributions.cvt.distribution import Distribution
from compact_distributions.cvt.evaluate import region_polygon
from compact_distributions.cvt.lloyd import iterate
from compact_distributions.cvt.placement.fit import parse_gap
from compact_distributions.cvt.problem import Grid, Problem
from compact_distributions.cvt.seeding import initial_sites
from compact_distributions.cvt.shapes import element_polygons

from .common import (
    BUDGET_DELTA,
    Contours,
    baseline,
    budget_size,
    cell_moments,
    make_elements,
    rasterize_tiles,
    tile_pixels,
    tile_shape,
    tile_voronoi,
)

INITIAL_FRACTION = 0.25  # initial tile size, relative to the budget size
SEARCH_SCHEDULE = (
    (2.0, 4.0),
    (2.0, 4.0),
    (1.0, 2.0),
    (1.0, 2.0),
    (0.5, 1.0),
    (0.5, 1.0),
    (0.25, 0.5),
    (0.25, 0.5),
)  # (px, degrees)


def continuous_step(shape, contours: Contours, centres, angles, centroids, gap: float = 0.0):
    """Tightest fit of every tile in its region: returns (centres, angles, sizes)."""
    n = len(centres)
    s_cur = contours.fit(shape, centres, angles, gap)
    s_cen = contours.fit(shape, centroids, angles, gap)
    use_centroid = s_cen > s_cur
    pos = np.where(use_centroid[:, None], centroids, centres)
    ang = angles.copy()
    best = np.maximum(s_cur, s_cen)
    rows = np.arange(n)
    for step_px, step_deg in SEARCH_SCHEDULE:
        da = math.radians(step_deg)
        moves = (
            (step_px, 0.0, 0.0),
            (-step_px, 0.0, 0.0),
            (0.0, step_px, 0.0),
            (0.0, -step_px, 0.0),
            (0.0, 0.0, da),
            (0.0, 0.0, -da),
        )
        sizes = np.empty((n, len(moves)))
        for m, (dx, dy, dt) in enumerate(moves):
            sizes[:, m] = contours.fit(shape, pos + [dx, dy], ang + dt, gap)
        pick = np.argmax(sizes, axis=1)
        gain = sizes[rows, pick] > best + 1e-9
        chosen = np.array(moves)[pick]
        pos = np.where(gain[:, None], pos + chosen[:, :2], pos)
        ang = np.where(gain, ang + chosen[:, 2], ang)
        best = np.where(gain, sizes[rows, pick], best)
    return pos, ang, best


def _hole_candidates(free: np.ndarray, count: int) -> list[tuple[float, float, float]]:
    """Up to ``count`` well separated holes (x, y, radius), largest first: local maxima
    of the distance from free pixels to the nearest blocked pixel (or the raster edge)."""
    from scipy import ndimage  # here: the registry imports this module at every start

    h, w = free.shape
    pad = np.zeros((h + 2, w + 2), dtype=bool)
    pad[1:-1, 1:-1] = free
    d = ndimage.distance_transform_edt(pad)[1:-1, 1:-1]
    peaks = (d >= 1.0) & (d == ndimage.maximum_filter(d, size=3))
    ii, jj = np.nonzero(peaks)
    order = np.argsort(-d[ii, jj], kind="stable")
    holes: list[tuple[float, float, float]] = []
    for k in order:
        x, y, r = jj[k] + 0.5, ii[k] + 0.5, float(d[ii[k], jj[k]])
        if all((x - hx) ** 2 + (y - hy) ** 2 > (r + hr) ** 2 for hx, hy, hr in holes):
            holes.append((x, y, r))
            if len(holes) >= count:
                break
    return holes


def _fit_in_hole(
    shape,
    blocked_pad: np.ndarray,
    pad: int,
    x: float,
    y: float,
    radius: float,
    angles: np.ndarray,
    gap: float,
) -> tuple[float, float]:
    """Largest size (and its angle, among ``angles``) of a tile centred at (x, y) whose
    outline stays half a pixel clear of every blocked pixel centre."""
    r = int(math.ceil(radius * shape.circumradius / shape.inradius)) + 2
    r = min(r, pad - 1)
    ci, cj = int(math.floor(y)), int(math.floor(x))
    win = blocked_pad[ci + pad - r : ci + pad + r + 1, cj + pad - r : cj + pad + r + 1]
    bi, bj = np.nonzero(win)
    if len(bi) == 0:
        return 0.0, float(angles[0])
    vx = (bj - r + cj + 0.5 - x)[None, :]
    vy = (bi - r + ci + 0.5 - y)[None, :]
    reach = shape.reach(vx, vy, angles[:, None], gap).min(axis=1) - 0.5 / shape.inradius
    k = int(np.argmax(reach))
    return max(float(reach[k]), 0.0), float(angles[k])


def combinatorial_step(
    shape, centres, angles, sizes, grid: Grid, moves: int | None = None, gap: float = 0.0, region=None
):
    """Replace the smallest tiles by tiles fitted into the largest holes, one at a time,
    accepting a replacement only if the coverage (area of the union of the tiles within
    the region, exactly as cvt.evaluate measures it) strictly grows.

    Returns (centres, angles, sizes, info) as new arrays; info counts tried and accepted
    moves and the coverage gained (fraction of the region)."""
    centres = np.array(centres, dtype=np.float64, copy=True)
    angles = np.array(angles, dtype=np.float64, copy=True)
    sizes = np.array(sizes, dtype=np.float64, copy=True)
    n = len(centres)
    moves = max(1, n // 50) if moves is None else int(moves)
    info = {"tried": 0, "accepted": 0, "gain": 0.0}
    if moves <= 0 or n == 0:
        return centres, angles, sizes, info
    region = region_polygon(grid) if region is None else region
    area = float(shapely.area(region))
    inside = grid.inside()
    # the tiles offered for replacement are the smallest (absent ones first); their own
    # pixels count as free, so that the hole a tiny tile sits in is found whole
    order = np.lexsort((np.arange(n), sizes))[:moves]
    owner = rasterize_tiles(shape, centres, angles, sizes, grid)
    offered = np.zeros(n + 1, dtype=bool)
    offered[order] = True
    free = inside & ((owner < 0) | offered[owner])  # owner -1 reads offered[n], False
    holes = _hole_candidates(free, moves)
    if not holes:
        return centres, angles, sizes, info
    pad = int(math.ceil(max(r for _, _, r in holes) * shape.circumradius / shape.inradius)) + 4
    h, w = free.shape
    blocked = np.ones((h + 2 * pad, w + 2 * pad), dtype=bool)
    blocked[pad : pad + h, pad : pad + w] = ~free

    geoms = np.full(n, None, dtype=object)
    live = np.flatnonzero(sizes > 0)
    geoms[live] = shapely.intersection(
        element_polygons(shape.element, shape.aspect, centres[live], angles[live], sizes[live]), region
    )
    present = ~shapely.is_missing(geoms) & ~shapely.is_empty(geoms)
    tree_ids = np.flatnonzero(present)
    tree = shapely.STRtree(geoms[tree_ids])

    def exclusive(poly, skip):
        """Area of ``poly`` that no other tile covers."""
        if poly is None or poly.is_empty:
            return 0.0
        near = tree_ids[tree.query(poly)]
        near = near[near != skip]
        if len(near) == 0:
            return float(shapely.area(poly))
        others = shapely.union_all(geoms[near])
        return float(shapely.area(shapely.difference(poly, others)))

    for (x, y, r), k in zip(holes, order[: len(holes)], strict=True):
        info["tried"] += 1
        # candidate angles: the tile's own, and a sweep over the shape's symmetry period
        sweep = np.arange(0.0, shape.symmetry_turn, math.radians(7.5))[:12]
        cand = np.concatenate([[angles[k]], angles[k] + sweep[1:]])
        size, ang = _fit_in_hole(shape, blocked, pad, x, y, r, cand, gap)
        if size <= sizes[k] or size <= 0:
            continue
        new_poly = shapely.intersection(
            element_polygons(shape.element, shape.aspect, (x, y), ang, size)[0], region
        )
        delta = exclusive(new_poly, k) - exclusive(geoms[k] if present[k] else None, k)
        if delta <= 1e-9:
            continue
        centres[k] = (x, y)
        angles[k] = ang
        sizes[k] = size
        geoms[k] = new_poly
        present[k] = True
        ii, jj = tile_pixels(shape, centres[k], angles[k], sizes[k], grid)
        blocked[ii + pad, jj + pad] = True  # later moves must fit around the new tile
        tree_ids = np.flatnonzero(present)
        tree = shapely.STRtree(geoms[tree_ids])
        info["accepted"] += 1
        info["gain"] += delta / area
    return centres, angles, sizes, info


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
    """Hu et al. 2016 on ``problem`` (2D); ``backend`` is not used (the distance is to
    the tiles, which no point-metric backend computes)."""
    t_setup = time.perf_counter()
    gap = parse_gap(gap)
    shape = tile_shape(problem, element)
    grid = problem.grid
    n = problem.n_elements
    base = budget_size(shape, grid, n, delta)
    inside = grid.inside()
    region = region_polygon(grid)
    centres = initial_sites(problem)
    angles = problem.angles_at(centres)
    sizes = np.full(n, INITIAL_FRACTION * base)
    setup = time.perf_counter() - t_setup

    t0 = time.perf_counter()
    raster_cov, accepted, gained = [], [], []

    def step(state):
        centres, angles, sizes = state
        tiles = rasterize_tiles(shape, centres, angles, sizes, grid)
        labels, dist = tile_voronoi(tiles, inside)
        mom = cell_moments(labels, n, centres)
        centres, angles, sizes = continuous_step(
            shape, Contours.of(labels), centres, angles, mom.centroids, gap
        )
        centres, angles, sizes, info = combinatorial_step(
            shape, centres, angles, sizes, grid, gap=gap, region=region
        )
        accepted.append(info["accepted"])
        gained.append(info["gain"])
        raster_cov.append(float((tiles[inside] >= 0).mean()))
        return (centres, angles, sizes), float(np.mean(dist[inside] ** 2)), mom.empty

    (centres, angles, sizes), log = iterate((centres, angles, sizes), step, iterations, progress)
    tiles = rasterize_tiles(shape, centres, angles, sizes, grid)
    labels, _ = tile_voronoi(tiles, inside)
    elements, clipped = make_elements(shape, centres, angles, sizes, grid, region)
    total = time.perf_counter() - t0
    return Distribution(
        method="hu2016",
        sites=centres,
        angles=angles,
        scales=sizes / base,
        elements=elements,
        energy=log.energy,
        seconds=log.seconds,
        setup_seconds=setup,
        lloyd_seconds=total,
        empty=log.empty,
        empty_sites=log.empty_sites,
        labels=labels,
        extra={
            "paper": METHOD.paper,
            "element": shape.element,
            "delta": delta,
            "budget_tile_size": base,
            "scales": "tile size / budget tile size (free per tile)",
            "replacements_accepted": accepted,
            "coverage_gained_by_replacements": gained,
            "raster_coverage_before_step": raster_cov,
            "voronoi": "distance transform of the rasterised tiles (scipy.ndimage)",
            "energy": "mean squared distance of region pixels to their nearest tile (px²)",
            "clipped_area_fraction": clipped,
        },
    )


METHOD = baseline(
    "hu2016",
    run,
    paper="Hu, Chen, Pan, Yu, Grinspun, Wang, Surface mosaic synthesis with irregular tiles, IEEE TVCG 22(3) 2016",
    year=2016,
    paper_table2=(0.843, "10 min"),
    fixed_size=False,
    summary="tiles grown and moved into the gaps (IEEE TVCG 2016)",
)


__all__ = ["INITIAL_FRACTION", "SEARCH_SCHEDULE", "continuous_step", "combinatorial_step", "run", "METHOD"]
