"""Shared machinery of the baselines: tile shapes, the size budget, tiles on the raster,
Voronoi regions of *tiles* (not points), cell moments and inscribed sizes.

Conventions are those of the core: pixel (i, j) is sampled at (j + 0.5, i + 0.5), x
right, y down, a positive angle turns clockwise on screen, element size 1 is the unit
ball of ``cvt.shapes`` (square side 2, circle radius 1, ...).

Size budget (the same for every method of Table 2): N tiles in a region of area A share
the area; a fixed-size tile has the area of a square of side ``δ·sqrt(A/N)`` with
Hausner's δ = 0.95 (``BUDGET_DELTA``): coverage could reach δ² = 90 % if the tiles were
perfectly packed, the rest being grout.  Other shapes get the same area.

Distance to a tile: the tiles are rasterised (a pixel belongs to a tile when its centre
is inside the tile's outline; where tiles overlap the lower index keeps the pixel), then
``scipy.ndimage.distance_transform_edt`` gives every other pixel the Euclidean distance
to the nearest tile pixel centre and, with ``return_indices``, *which* tile that is.
That is the Voronoi diagram of the tiles as areas (Hoff et al.'s generalised Voronoi
diagram, which the papers render with distance meshes), up to half a pixel.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import shapely

from compact_distributions.cvt.distribution import Distribution
from compact_distributions.cvt.evaluate import region_polygon
from compact_distributions.cvt.lloyd import iterate
from compact_distributions.cvt.methods import Method, MethodOption, SweepVariant
from compact_distributions.cvt.metrics import REFERENCE_SHAPE, Metric
from compact_distributions.cvt.placement.fit import contour_samples, parse_gap
from compact_distributions.cvt.problem import Grid, Problem, in_own_cell
from compact_distributions.cvt.seeding import initial_sites
from compact_distributions.cvt.shapes import (
    check_shape,
    element_ball,
    element_polygons,
)
from compact_distributions.cvt.threads import prepared_copy
from compact_distributions.cvt.validate import real_number

BUDGET_DELTA = 0.95
# Fixed-size tile baselines also run in the sweeps with smaller tile budgets: their coverage
# at the default δ is bought with overlap, and the paper states neither its tile sizes nor
# how it counts overlap, so the reports show where they stand when tiles barely overlap.
SMALLER_BUDGETS = (0.85, 0.80)


def _delta(value, name: str) -> float:
    return real_number(value, name, above=0.0, maximum=2.0)


DELTA_OPTION = MethodOption(
    "delta",
    float,
    BUDGET_DELTA,
    f"tile budget δ: tiles of the area of a square of side δ·sqrt(area/N) "
    f"(0 < δ <= 2; default {BUDGET_DELTA})",
    check=_delta,
    tag="d",
    label="δ={:g}",
)
SMALLER_BUDGET_VARIANTS = tuple(SweepVariant({"delta": d}, (REFERENCE_SHAPE,)) for d in SMALLER_BUDGETS)


def baseline(
    name: str, run, paper: str, year: int, paper_table2=None, fixed_size: bool = True, summary: str = ""
) -> Method:
    """The record of one of the suite's baselines: a tile budget δ, run on the NumPy
    reference and compared on squares; fixed-size ones also with smaller budgets."""
    return Method(
        name,
        run,
        options=(DELTA_OPTION,),
        fixed_size=fixed_size,
        paper=paper,
        year=year,
        paper_table2=paper_table2,
        role="baseline",
        sweep_backends="reference",
        compared_on=(REFERENCE_SHAPE,),
        sweep_variants=SMALLER_BUDGET_VARIANTS if fixed_size else (),
        summary=summary,
    )


def tile_shape(problem: Problem, element: str | None, default: str | None = None) -> Metric:
    """The element's unit ball (the one unit-element record: gauge, reach, area,
    symmetry): ``element``, else the method's ``default``, else the problem's, else the
    metric's own shape."""
    name = check_shape(element or default or problem.element or problem.metric.natural_element)
    return element_ball(name, problem.metric.aspect)


def budget_size(shape: Metric, grid: Grid, n: int, delta: float = BUDGET_DELTA) -> float:
    """Element size whose area is that of a square of side δ·sqrt(area/N)."""
    return shape.size_for_area(delta * delta * grid.pixel_count / n)


# ------------------------------------------------------------------ tiles on the raster
def rasterize_tiles(
    shape: Metric, centres, angles, sizes, grid: Grid, budget_entries: int = 2_000_000
) -> np.ndarray:
    """(H, W) int32: the tile whose outline contains each pixel centre, -1 for none.
    Where tiles overlap the lower index keeps the pixel.  Tiles of size <= 0 are absent."""
    h, w = grid.shape
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    n = len(centres)
    angles = np.broadcast_to(np.asarray(angles, dtype=np.float64), (n,))
    sizes = np.broadcast_to(np.asarray(sizes, dtype=np.float64), (n,))
    best = np.full(h * w, n, dtype=np.int64)
    ok = np.flatnonzero(np.isfinite(sizes) & (sizes > 0) & np.isfinite(centres).all(axis=1))
    if len(ok):
        reach = np.ceil(sizes[ok] * shape.circumradius + 1.0).astype(np.int64)
        order = ok[np.argsort(reach, kind="stable")]
        reach = np.sort(reach, kind="stable")
        start = 0
        while start < len(order):
            side = 2 * reach[start] + 1
            count = max(1, budget_entries // (side * side))
            stop = min(len(order), start + count)
            r = int(reach[stop - 1])  # windows grow with the chunk's largest tile
            ids = order[start:stop]
            flat, who = _window_hits(shape, centres[ids], angles[ids], sizes[ids], r, h, w)
            np.minimum.at(best, flat, ids[who])
            start = stop
    best[best == n] = -1
    return best.reshape(h, w).astype(np.int32)


def tile_pixels(shape: Metric, centre, angle: float, size: float, grid: Grid):
    """(rows, columns) of the pixels whose centres one tile's outline contains: the
    pixels ``rasterize_tiles`` gives that tile when it is alone."""
    if not (math.isfinite(size) and size > 0):
        return np.empty(0, np.int64), np.empty(0, np.int64)
    r = int(math.ceil(size * shape.circumradius + 1.0))
    flat, _ = _window_hits(
        shape,
        np.asarray(centre, np.float64).reshape(1, 2),
        np.array([angle], np.float64),
        np.array([size], np.float64),
        r,
        *grid.shape,
    )
    return np.divmod(flat, grid.shape[1])


def _window_hits(shape: Metric, centres, angles, sizes, r: int, h: int, w: int):
    """Flat raster indices of the pixel centres inside each tile, within the (2r+1)²
    window around it, and the tile's position in the arguments for each index."""
    offs = np.arange(-r, r + 1)
    ci = np.floor(centres[:, 1]).astype(np.int64)
    cj = np.floor(centres[:, 0]).astype(np.int64)
    ii = ci[:, None, None] + offs[None, :, None]
    jj = cj[:, None, None] + offs[None, None, :]
    vx = jj + 0.5 - centres[:, 0][:, None, None]
    vy = ii + 0.5 - centres[:, 1][:, None, None]
    g = shape.gauge_turned(vx, vy, np.cos(angles)[:, None, None], np.sin(angles)[:, None, None])
    hit = (g <= sizes[:, None, None]) & (ii >= 0) & (ii < h) & (jj >= 0) & (jj < w)
    flat = (ii * w + jj)[hit]
    who = np.broadcast_to(np.arange(len(centres))[:, None, None], hit.shape)[hit]
    return flat, who


def tile_voronoi(tile_labels: np.ndarray, inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Voronoi regions of the tiles: every pixel goes to the tile nearest to it
    (distance to the tile's pixels, 0 inside a tile).  Returns (labels, distance), both
    (H, W); labels -1 outside the region (and everywhere when there is no tile)."""
    from scipy import ndimage  # here: the registry imports this module at every start

    empty = tile_labels < 0
    if empty.all():
        return np.full(tile_labels.shape, -1, np.int32), np.full(tile_labels.shape, np.inf)
    dist, (ii, jj) = ndimage.distance_transform_edt(empty, return_indices=True)
    labels = tile_labels[ii, jj]
    labels[~inside] = -1
    return labels.astype(np.int32), dist


@dataclass
class CellMoments:
    count: np.ndarray  # pixels per cell (N,)
    centroids: np.ndarray  # (N, 2); the old position where the cell is empty
    mxx: np.ndarray  # central second moments per pixel (N,)
    mxy: np.ndarray
    myy: np.ndarray

    @property
    def empty(self) -> np.ndarray:
        return self.count == 0

    def principal_angles(self) -> np.ndarray:
        """Direction of each cell's major axis (radians, modulo π)."""
        return 0.5 * np.arctan2(2 * self.mxy, self.mxx - self.myy)


def cell_moments(labels: np.ndarray, n: int, old: np.ndarray) -> CellMoments:
    """Centroids and central second moments of each label's pixels (pixel centres)."""
    flat = labels.ravel()
    keep = flat >= 0
    idx = np.flatnonzero(keep)
    lab = flat[idx]
    h, w = labels.shape
    y = (idx // w).astype(np.float64) + 0.5
    x = (idx % w).astype(np.float64) + 0.5
    cnt = np.bincount(lab, minlength=n).astype(np.float64)
    sx = np.bincount(lab, x, n)
    sy = np.bincount(lab, y, n)
    full = cnt > 0
    cen = np.array(old, dtype=np.float64, copy=True)
    cen[full, 0] = sx[full] / cnt[full]
    cen[full, 1] = sy[full] / cnt[full]
    dx = x - cen[lab, 0]
    dy = y - cen[lab, 1]
    safe = np.where(full, cnt, 1.0)
    mxx = np.bincount(lab, dx * dx, n) / safe
    mxy = np.bincount(lab, dx * dy, n) / safe
    myy = np.bincount(lab, dy * dy, n) / safe
    return CellMoments(cnt.astype(np.int64), cen, mxx, mxy, myy)


def nearest_equivalent(target: np.ndarray, current: np.ndarray, period: float) -> np.ndarray:
    """The angle equal to ``target`` modulo ``period`` that is closest to ``current``
    (so that a symmetric tile turns by the least amount)."""
    return current + (target - current + period / 2) % period - period / 2


def angle_residual(a: np.ndarray, b: np.ndarray, period: float) -> np.ndarray:
    """|a - b| modulo ``period``, in [0, period/2]."""
    d = (np.asarray(a) - np.asarray(b)) % period
    return np.minimum(d, period - d)


# ------------------------------------------------------------------ inscribed sizes
@dataclass
class Contours:
    """Contour samples of every cell (``cvt.placement`` convention: midpoints of the
    unit pixel edges between a cell and anything else), plus the label raster."""

    owner: np.ndarray
    x: np.ndarray
    y: np.ndarray
    labels: np.ndarray

    @classmethod
    def of(cls, labels: np.ndarray) -> Contours:
        owner, x, y = contour_samples(labels)
        return cls(owner, x, y, labels)

    def fit(self, shape: Metric, centres, angles, gap: float = 0.0) -> np.ndarray:
        """Largest size of each tile, at the given centre and angle, that stays inside
        its own cell; 0 where the centre's pixel is not in the cell."""
        n = len(centres)
        o = self.owner
        r = shape.reach(self.x - centres[o, 0], self.y - centres[o, 1], angles[o], gap)
        sizes = np.full(n, np.inf)
        np.minimum.at(sizes, o, r)
        own = in_own_cell(self.labels, centres)
        return np.where(own & np.isfinite(sizes) & (sizes > 0), sizes, 0.0)


# ------------------------------------------------------------------ output
def make_elements(shape: Metric, centres, angles, sizes, grid: Grid, region=None):
    """Shapely polygons of the tiles, clipped to the region (None for absent tiles), and
    the area cut off by the clipping as a fraction of the region's area."""
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    n = len(centres)
    sizes = np.broadcast_to(np.asarray(sizes, dtype=np.float64), (n,))
    angles = np.broadcast_to(np.asarray(angles, dtype=np.float64), (n,))
    region = region_polygon(grid) if region is None else region
    out: list = [None] * n
    placed = np.flatnonzero(np.isfinite(sizes) & (sizes > 0))
    if len(placed) == 0:
        return out, 0.0
    polys = element_polygons(shape.element, shape.aspect, centres[placed], angles[placed], sizes[placed])
    inside = shapely.contains(prepared_copy(region), polys)
    clipped_area = 0.0
    if not inside.all():
        cut = np.flatnonzero(~inside)
        parts = shapely.intersection(polys[cut], region)
        clipped_area = float((shapely.area(polys[cut]) - shapely.area(parts)).sum())
        polys = polys.copy()
        polys[cut] = parts
    for k, poly in zip(placed.tolist(), polys, strict=True):
        if poly is not None and not poly.is_empty:
            out[k] = poly
    return out, clipped_area / float(shapely.area(region))


# ------------------------------------------------------------------ Lloyd over tiles
def fixed_sizes(problem: Problem, shape: Metric, base: float, centres, gap: float) -> np.ndarray:
    """Fixed tile sizes: the budget size times the density's size factor at the tile,
    less the grout (gap/2 along each edge normal)."""
    sizes = base * problem.scales_at(centres)
    if gap > 0:
        sizes = np.maximum(sizes - 0.5 * gap / shape.inradius, 0.0)
    return sizes


def tile_lloyd(
    problem: Problem,
    shape: Metric,
    base_size: float,
    iterations: int,
    turn,
    progress=None,
    gap: float = 0.0,
):
    """Lloyd's method extended from points to fixed-size tiles.

    Each iteration: rasterise the tiles, give every pixel to its nearest tile
    (``tile_voronoi``), move each tile to its region's centroid, and turn it with
    ``turn(moments, labels, new_centers, old_angles, sizes) -> angles``.  A tile whose
    region is empty (covered entirely by lower-index tiles) stays where it is.

    Returns (centres, angles, sizes, labels, log) where the log's energy is the mean
    squared distance of the region's pixels to their tile."""
    grid = problem.grid
    inside = grid.inside()
    centres = initial_sites(problem)
    n = len(centres)

    def step(state):
        centres, angles = state
        sizes = fixed_sizes(problem, shape, base_size, centres, gap)
        tiles = rasterize_tiles(shape, centres, angles, sizes, grid)
        labels, dist = tile_voronoi(tiles, inside)
        mom = cell_moments(labels, n, centres)
        angles = turn(mom, labels, mom.centroids, angles, sizes)
        return (mom.centroids, angles), float(np.mean(dist[inside] ** 2)), mom.empty

    (centres, angles), log = iterate((centres, problem.angles_at(centres)), step, iterations, progress)
    sizes = fixed_sizes(problem, shape, base_size, centres, gap)
    tiles = rasterize_tiles(shape, centres, angles, sizes, grid)
    labels, _ = tile_voronoi(tiles, inside)
    return centres, angles, sizes, labels, log


def run_fixed_tiles(
    method: str,
    problem: Problem,
    iterations: int,
    progress,
    element,
    gap,
    delta: float,
    make_turn,
    extra: dict,
):
    """The frame shared by the fixed-size tile methods (Fritzsche, Smith): set up the tile
    shape and budget size (timed apart), run :func:`tile_lloyd` with the method's turning
    rule ``make_turn(problem, shape)``, and package the result as a Distribution."""
    t_setup = time.perf_counter()
    gap = parse_gap(gap)
    shape = tile_shape(problem, element)
    base = budget_size(shape, problem.grid, problem.n_elements, delta)
    setup = time.perf_counter() - t_setup

    t0 = time.perf_counter()
    centres, angles, sizes, labels, log = tile_lloyd(
        problem, shape, base, iterations, make_turn(problem, shape), progress, gap
    )
    elements, clipped = make_elements(shape, centres, angles, sizes, problem.grid)
    total = time.perf_counter() - t0
    return Distribution(
        method=method,
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
            **extra,
            "element": shape.element,
            "delta": delta,
            "tile_size": base,
            "scales": "tile size / budget tile size",
            "voronoi": "distance transform of the rasterised tiles (scipy.ndimage)",
            "energy": "mean squared distance of region pixels to their nearest tile (px²)",
            "clipped_area_fraction": clipped,
        },
    )


__all__ = [
    "BUDGET_DELTA",
    "SMALLER_BUDGETS",
    "DELTA_OPTION",
    "SMALLER_BUDGET_VARIANTS",
    "baseline",
    "tile_shape",
    "budget_size",
    "rasterize_tiles",
    "tile_pixels",
    "tile_voronoi",
    "CellMoments",
    "cell_moments",
    "nearest_equivalent",
    "angle_residual",
    "Contours",
    "make_elements",
    "fixed_sizes",
    "tile_lloyd",
    "run_fixed_tiles",
]
