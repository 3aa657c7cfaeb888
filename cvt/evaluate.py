"""Coverage and overlap of placed elements: the one definition the suite uses.

    coverage = area(union(elements) ∩ region) / area(region)
    overlap  = (Σ area(element ∩ region) − area(union(elements) ∩ region)) / area(region)

Both with shapely 2's vectorised functions (no Python loop over elements or pairs).
The region is the union of its pixels' squares (the whole raster when there is no mask).

How the union is computed without its full cost: an STRtree gives every pair of clipped
elements whose bounds meet, one vectorised ``intersection`` keeps the pairs that share
area, and only the elements of those pairs go through ``union_all``, group of
overlapping elements by group, in batches (memory stays linear even when most
elements overlap a neighbour); every other element adds its own area.  The result is the same union area (to rounding), and a
placement with little overlap (ours: a few pairs) is evaluated several times faster
than by ``union_all`` of everything (4000 circles on 1024²: ~0.03 s instead of ~0.8-1.0 s).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import shapely

from compact_distributions.cvt.pixels import PIXEL_BAND, index_ranges
from compact_distributions.cvt.problem import Grid
from compact_distributions.cvt.threads import elementwise, prepared_copy

if TYPE_CHECKING:
    from compact_distributions.cvt.problem import Problem


@dataclass
class Evaluation:
    """The suite's measures of placed elements: what :func:`evaluate` returns.

    Parameters
    ----------
    coverage : float
        Area of the union of the elements inside the region / area of the region.
    overlap : float
        Summed area of the elements inside the region less the union's, / area of the
        region: the share covered more than once.
    elements : int
        The number of elements placed.
    skipped : int
        Sites without an element (empty or degenerate cells).
    min_area : float
        The smallest placed element's area, px² (0 with none placed).
    max_area : float
        The largest placed element's area, px² (0 with none placed).
    empty_cells : int or None, optional
        Sites whose cell holds no pixel of the label raster; None when no labels were
        given.
    overlapping_pairs : int, optional
        Pairs of elements that share a positive area.
    """

    coverage: float
    overlap: float
    elements: int
    skipped: int
    min_area: float
    max_area: float
    empty_cells: int | None = None
    overlapping_pairs: int = 0

    def as_dict(self) -> dict[str, Any]:
        """Return the measures under the names result.json gives them.

        Returns
        -------
        dict of str to float or int or None
            ``coverage``, ``overlap``, ``placed``, ``skipped``, ``min_element_area``,
            ``max_element_area``, ``empty_cells``, ``overlapping_pairs``.
        """
        return {
            "coverage": self.coverage,
            "overlap": self.overlap,
            "placed": self.elements,
            "skipped": self.skipped,
            "min_element_area": self.min_area,
            "max_element_area": self.max_area,
            "empty_cells": self.empty_cells,
            "overlapping_pairs": self.overlapping_pairs,
        }


def region_polygon(grid: Grid) -> Any:
    """The region as a shapely geometry in pixel units (pixel squares, unioned)."""
    if grid.mask is None:
        return shapely.box(0, 0, grid.width, grid.height)
    # one box per horizontal run of inside pixels, then their union.  (A coverage union
    # leaves runs of neighbouring rows as separate polygons that share parts of edges: an
    # invalid MultiPolygon, on which shapely's predicates are unreliable; union_all
    # dissolves them into one valid polygon, ~45 ms for a 1024² disc.)
    m = np.zeros((grid.height, grid.width + 2), dtype=np.int8)
    m[:, 1:-1] = grid.mask
    edges = np.diff(m, axis=1)
    rows_s, cols_s = np.nonzero(edges == 1)
    rows_e, cols_e = np.nonzero(edges == -1)
    boxes = shapely.box(cols_s, rows_s, cols_e, rows_s + 1)
    return shapely.union_all(boxes)


EMPTY_BAND = PIXEL_BAND  # pixels read at once by empty_cells: no raster-sized temporaries


def empty_cells(labels: np.ndarray, n_elements: int) -> int:
    """Sites whose cell holds no pixel of the label raster (labels outside 0 .. N - 1
    count for no site); read a band of pixels at a time."""
    lab = np.asarray(labels).reshape(-1)
    seen = np.zeros(n_elements, dtype=bool)
    for lo in range(0, lab.size, EMPTY_BAND):
        part = lab[lo : lo + EMPTY_BAND]
        # every label of the band begins one of its runs: only those are read
        part = np.concatenate([part[:1], part[1:][part[1:] != part[:-1]]])
        seen[part[(part >= 0) & (part < n_elements)]] = True
    return int(n_elements - np.count_nonzero(seen))


UNION_BATCH = 4096  # elements unioned at once: bounds the memory of a union


def _union_area(geoms: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Area of the union of the elements that share area with another (pairs a, b).

    Elements of different groups of overlapping elements (connected components of the
    pairs) share no area, so the union's area is the sum over the groups; the groups
    are unioned in batches of whole groups, which keeps the memory of one union small
    however many elements overlap."""
    if len(a) == 0:
        return 0.0
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(geoms)
    _, group = connected_components(coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n)), directed=False)
    members = np.unique(np.concatenate([a, b]))
    members = members[np.argsort(group[members], kind="stable")]
    starts = np.flatnonzero(np.diff(group[members], prepend=-1))  # where each group begins
    total, begin = 0.0, 0
    while begin < len(members):
        # the last group start that keeps the batch at most UNION_BATCH long (one group at least)
        k = np.searchsorted(starts, begin + UNION_BATCH, side="right") - 1
        if begin + UNION_BATCH >= len(members):
            end = len(members)
        elif starts[k] > begin:
            end = starts[k]
        else:
            end = starts[k + 1] if k + 1 < len(starts) else len(members)
        total += float(shapely.area(shapely.union_all(geoms[members[begin:end]])))
        begin = end
    return total


APART_MARGIN = 1e-9  # relative to the largest coordinate: projections' rounding is far below
APART_VERTICES = 1 << 18  # vertex projections _surely_apart works at once (bounded memory)


def _surely_apart(geoms: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(P,) bool: the pairs (a, b) of ``geoms`` that cannot meet, because their vertices'
    projections on the line between their bounding boxes' centres are apart by more than
    a rounding margin (a shape lies within its vertices' projection interval on any line:
    two apart intervals separate the shapes).  False leaves a pair to shapely; an empty
    geometry meets nothing.  The pairs are worked in blocks of about
    :data:`APART_VERTICES` vertices, each block reading only its own geometries'."""
    count = shapely.get_num_coordinates(geoms)
    apart = (count[a] == 0) | (count[b] == 0)
    live = np.flatnonzero(~apart)
    if len(live) == 0:
        return apart
    box = shapely.bounds(geoms)
    mid = 0.5 * (box[:, :2] + box[:, 2:])
    scale = APART_MARGIN * max(1.0, float(np.abs(box).max()))
    ends = np.cumsum(count[a[live]] + count[b[live]])
    cuts = np.searchsorted(ends, np.arange(APART_VERTICES, ends[-1], APART_VERTICES), side="right")
    for lo, hi in itertools.pairwise(np.unique(np.concatenate([[0], cuts, [len(live)]])).tolist()):
        pairs = live[lo:hi]
        used, local = np.unique(np.concatenate([a[pairs], b[pairs]]), return_inverse=True)
        coords = shapely.get_coordinates(geoms[used])
        n = count[used]
        start = np.cumsum(n) - n
        ia, ib = local[: len(pairs)], local[len(pairs) :]
        line = (mid[used[ib], 0] - mid[used[ia], 0], mid[used[ib], 1] - mid[used[ia], 1])
        low_b = _projected_extreme(coords, start[ib], n[ib], line, np.minimum)
        high_a = _projected_extreme(coords, start[ia], n[ia], line, np.maximum)
        apart[pairs] = low_b - high_a > scale * np.hypot(*line)
    return apart


def _projected_extreme(
    coords: np.ndarray, start: np.ndarray, n: np.ndarray, line: tuple, reduce: np.ufunc
) -> np.ndarray:
    """Per pair, ``reduce`` (np.maximum or np.minimum) of the projections on the pair's
    ``line`` (ux, uy) of its geometry's vertices, ``coords[start : start + n]``."""
    at = index_ranges(start, n)
    pair = np.repeat(np.arange(len(n)), n)
    projected = coords[at, 0] * line[0][pair] + coords[at, 1] * line[1][pair]
    return reduce.reduceat(projected, np.cumsum(n) - n)


def evaluate(
    elements: Sequence[Any], grid: Grid, region: Any = None, labels: np.ndarray | None = None
) -> Evaluation:
    """Measure the coverage and overlap of placed elements in a region.

    ``coverage = area(union(elements) ∩ region) / area(region)`` and ``overlap =
    (Σ area(element ∩ region) − area(union(elements) ∩ region)) / area(region)``,
    with shapely's vectorised functions (no Python loop over elements or pairs).

    Parameters
    ----------
    elements : sequence of shapely.Geometry or None
        One per site; None and empty entries are sites without an element.
    grid : Grid
        The raster and its region (the union of its pixels' squares).
    region : shapely.Geometry or None, optional
        The region as a geometry, when the caller has it already
        (``region_polygon(grid)``); None: made from ``grid``.
    labels : numpy.ndarray or None, optional
        The final (H, W) label raster, to count the empty cells.

    Returns
    -------
    Evaluation
        Coverage, overlap, counts and the smallest and largest element's area.

    Examples
    --------
    Two unit-overlapping squares on a 10 x 10 raster:

    >>> import shapely
    >>> import compact_distributions as cd
    >>> squares = [shapely.box(0, 0, 5, 5), shapely.box(4, 0, 9, 5), None]
    >>> ev = cd.evaluate(squares, cd.Grid(10, 10))
    >>> ev.coverage, ev.overlap, ev.elements, ev.skipped
    (0.45, 0.05, 2, 1)
    """
    region = region_polygon(grid) if region is None else region
    empty = None if labels is None else empty_cells(labels, len(elements))
    _, geoms = _present(elements)
    skipped = len(elements) - len(geoms)
    area = shapely.area(region)
    if len(geoms) == 0:
        return Evaluation(0.0, 0.0, 0, skipped, 0.0, 0.0, empty)
    # clip only what is not already inside the region (prepared, vectorised test)
    clipped = geoms.copy()
    outside = ~shapely.contains(prepared_copy(region), geoms)
    if outside.any():
        clipped[outside] = shapely.intersection(geoms[outside], region)
    clip_areas = shapely.area(clipped)
    total = float(clip_areas.sum())

    # the pairs whose bounding boxes meet, less those surely apart, tested by shapely
    a, b = shapely.STRtree(clipped).query(clipped)
    keep = a < b
    a, b = a[keep], b[keep]
    keep = ~_surely_apart(clipped, a, b)
    a, b = a[keep], b[keep]
    meet = elementwise(shapely.intersects, clipped[a], clipped[b])
    a, b = a[meet], b[meet]
    shared = shapely.area(shapely.intersection(clipped[a], clipped[b])) > 0
    a, b = a[shared], b[shared]
    involved = np.zeros(len(clipped), dtype=bool)
    involved[a] = involved[b] = True
    covered = float(clip_areas[~involved].sum()) + _union_area(clipped, a, b)

    areas = shapely.area(geoms)
    return Evaluation(
        coverage=float(covered / area),
        overlap=float(max(0.0, total - covered) / area),
        elements=len(geoms),
        skipped=skipped,
        min_area=float(areas.min()),
        max_area=float(areas.max()),
        empty_cells=empty,
        overlapping_pairs=int(len(a)),
    )


# ----------------------------------------------------------------- mosaic measures
#
#   fill of tile k     = the geometric median, in CIELAB, of the picture's pixels whose
#                        centres lie inside or on the outline of tile k (the colour with
#                        the least mean ΔE*ab to them; cvt.mosaic.tile_colours)
#   colour_error       = mean over every (tile, pixel centre inside or on the tile) pair of
#                        ΔE*ab (CIE76) between the pixel and the tile's fill as written
#                        (8-bit sRGB): the mean perceived difference over the tiled area
#   straddling         = share of placed tiles that hold a strong-edge pixel centre at
#                        least 1 px inside their outline (tile eroded by 1 px): the edge runs
#                        through the tile with at least 1 px of the tile on each side.  A
#                        tile that a method clipped (to a region with walls) is taken as its
#                        convex hull: its pieces on both sides of a wall still straddle it


# ------------------------------------------------------------------ equal-overlap comparison
SCALE_FACTORS = (0.80, 0.85, 0.90, 0.95, 1.00, 1.05, 1.10, 1.15, 1.20)


def scaled(elements: Sequence[Any], factor: float) -> list[Any]:
    """Every element scaled by ``factor`` about its own centre (its centroid: the centre of
    every element shape, and of a clipped tile near enough)."""
    present = [k for k, e in enumerate(elements) if e is not None and not e.is_empty]
    out = [None] * len(elements)
    if not present:
        return out
    geoms = np.array([elements[k] for k in present], dtype=object)
    centres = shapely.get_coordinates(shapely.centroid(geoms))
    coords, owner = shapely.get_coordinates(geoms, return_index=True)
    moved = shapely.set_coordinates(geoms.copy(), (coords - centres[owner]) * factor + centres[owner])
    for k, g in zip(present, moved, strict=True):
        out[k] = g
    return out


def coverage_overlap_curve(
    elements: Sequence[Any], grid: Grid, factors: Iterable[float] = SCALE_FACTORS, region: Any = None
) -> list[list[float]]:
    """[[factor, coverage, overlap], ...]: :func:`evaluate` of the elements scaled by each
    factor.  Compares methods at equal overlap: a method that overlaps can shrink its
    elements, one that does not can grow them."""
    region = region_polygon(grid) if region is None else region
    out = []
    for f in factors:
        ev = evaluate(scaled(elements, f), grid, region=region)
        out.append([float(f), ev.coverage, ev.overlap])
    return out


def coverage_at_overlap(curve: Iterable[Sequence[float]], limit: float = 0.01) -> float:
    """The largest coverage on the curve with overlap at most ``limit``, interpolating
    linearly between the two factors where the overlap crosses it (NaN when even the
    smallest factor overlaps more)."""
    pts = sorted((float(f), float(c), float(o)) for f, c, o in curve)
    candidates = [c for _, c, o in pts if o <= limit]
    for (_, c0, o0), (_, c1, o1) in zip(pts, pts[1:], strict=False):
        if o0 <= limit < o1:
            candidates.append(c0 + (limit - o0) / (o1 - o0) * (c1 - c0))
    return max(candidates) if candidates else float("nan")


def coverage_at_overlap_limit(
    elements: Sequence[Any],
    grid: Grid,
    limit: float = 0.01,
    factors: Iterable[float] = SCALE_FACTORS,
    region: Any = None,
) -> float:
    """:func:`coverage_at_overlap` of :func:`coverage_overlap_curve`, evaluating the factors
    in increasing order only up to the first whose overlap passes ``limit``: the overlap
    grows with the factor (every element grows about its own centre), so the larger
    factors cannot change the answer, and they are the costly ones (every pair overlaps)."""
    region = region_polygon(grid) if region is None else region
    curve = []
    for f in sorted(float(f) for f in factors):
        ev = evaluate(scaled(elements, f), grid, region=region)
        curve.append([f, ev.coverage, ev.overlap])
        if ev.overlap > limit:
            break
    return coverage_at_overlap(curve, limit)


# pixels_under decides with shapely only where a pixel centre lies within this many px of
# a crossing of the tile's outline with the pixel's row, or on a row through a vertex or
# along a nearly horizontal edge; elsewhere the row's crossings decide (they are computed
# to far better than this)
CHORD_MARGIN = 1e-5
_FLAT_EDGE = 1e-3  # px of height below which an edge's crossings are not trusted


def pixels_under(elements: Sequence[Any], width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Every pixel of a raster whose centre lies inside or on the outline of a tile.

    Polygonal tiles are read row by row: the crossings of the row through the pixel
    centres with the tile's rings, in order along the row, bound the spans inside it
    (even-odd); the centres within a span less :data:`CHORD_MARGIN` are in the tile, those
    farther than the margin from every span are not, and shapely decides the rest (and
    every pixel of the bounding box of other tiles).

    Parameters
    ----------
    elements : list of shapely geometries
        The tiles (None and empty tiles hold no pixel).
    width, height : int
        The raster.

    Returns
    -------
    tiles, pixels : (P,) int64 arrays
        (tile index, flat pixel index i·width + j) pairs, by tile, then pixel;
        overlapping tiles each hold the pixel.
    """
    idx = np.array([k for k, e in enumerate(elements) if e is not None and not e.is_empty], dtype=np.int64)
    if len(idx) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    geoms = np.array([elements[k] for k in idx], dtype=object)
    b = shapely.bounds(geoms)
    j0 = np.clip(np.ceil(b[:, 0] - 0.5), 0, width).astype(np.int64)
    i0 = np.clip(np.ceil(b[:, 1] - 0.5), 0, height).astype(np.int64)
    j1 = np.clip(np.floor(b[:, 2] - 0.5), -1, width - 1).astype(np.int64)
    i1 = np.clip(np.floor(b[:, 3] - 0.5), -1, height - 1).astype(np.int64)
    # the tiles are the caller's, so not prepared (cvt.threads)
    # even-odd spans are shapely's inside for one ring (crossing parity), and for holes
    # and parts when they neither overlap nor leave the shell (a valid geometry)
    kind = shapely.get_type_id(geoms)
    spans = (kind == 3) & (shapely.get_num_interior_rings(geoms) == 0)
    several = np.flatnonzero(((kind == 3) & ~spans) | (kind == 6))
    spans[several] = shapely.is_valid(geoms[several])
    segments = [_span_segments(geoms, np.flatnonzero(spans), i0, i1, j0, j1, width)]
    other = np.flatnonzero(~spans)
    if len(other):
        # prepared copies: prepared, GEOS reads the parts of an invalid tile by parity
        # too (a point where two overlap is outside, as shapely has always said here)
        own = geoms.copy()
        own[other] = prepared_copy(geoms[other])
        segments.append(_box_segments(own, other, i0, i1, j0, j1, width))
    tile, first, length = (np.concatenate(parts) for parts in zip(*segments, strict=True))
    # by tile, then pixel (a tile's segments never overlap); they come in a few sorted
    # runs, which a stable sort merges
    order = np.argsort(tile * (width * height) + first, kind="stable")
    tile, first, length = tile[order], first[order], length[order]
    tiles, pixels = idx[np.repeat(tile, length)], index_ranges(first, length)
    if np.any((tile[1:] == tile[:-1]) & (first[1:] < first[:-1] + length[:-1])):
        # two crossings of a row at one point can leave a pixel both sure and a candidate
        pair = np.unique(tiles * (width * height) + pixels)
        tiles, pixels = pair // (width * height), pair % (width * height)
    return tiles, pixels


def _box_segments(
    geoms: np.ndarray,
    tiles: np.ndarray,
    i0: np.ndarray,
    i1: np.ndarray,
    j0: np.ndarray,
    j1: np.ndarray,
    width: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tile, flat pixel, 1) of the pixels of each tile's bounding box that shapely finds in it."""
    nx = np.maximum(j1[tiles] - j0[tiles] + 1, 0)
    ny = np.maximum(i1[tiles] - i0[tiles] + 1, 0)
    counts = nx * ny
    tile = np.repeat(tiles, counts)
    offset = index_ranges(np.zeros(len(tiles), dtype=np.int64), counts)
    k = np.repeat(np.arange(len(tiles)), counts)
    jj = j0[tile] + offset % nx[k]
    ii = i0[tile] + offset // nx[k]
    inside = shapely.intersects_xy(geoms[tile], jj + 0.5, ii + 0.5)
    return tile[inside], ii[inside] * width + jj[inside], np.ones(int(inside.sum()), dtype=np.int64)


def _span_segments(
    geoms: np.ndarray,
    tiles: np.ndarray,
    i0: np.ndarray,
    i1: np.ndarray,
    j0: np.ndarray,
    j1: np.ndarray,
    width: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tile, first flat pixel, length) of the pixels of each row inside each polygonal
    tile: the sure part of every span between crossings, and the pixels near a crossing
    or on an unsure row that shapely finds in the tile."""
    rows = np.maximum(i1[tiles] - i0[tiles] + 1, 0)
    base = np.cumsum(rows) - rows  # a (tile, row) pair's key: base[tile] + row - i0
    n_keys = int(rows.sum())
    key_tile = np.repeat(tiles, rows)
    key_row = i0[key_tile] + index_ranges(np.zeros(len(tiles), dtype=np.int64), rows)
    # every ring: exteriors, holes, the polygons of a multipolygon
    parts, part_of = shapely.get_parts(geoms[tiles], return_index=True)
    rings, ring_of = shapely.get_rings(parts, return_index=True)
    coords, ci = shapely.get_coordinates(rings, return_index=True)
    owner = part_of[ring_of[ci]]  # each vertex's place in ``tiles``
    unsure = np.zeros(n_keys, dtype=bool)
    # a row through a vertex (within the margin) is left to shapely
    yv = coords[:, 1]
    iv = np.round(yv - 0.5).astype(np.int64)
    hit = (np.abs(iv + 0.5 - yv) < CHORD_MARGIN) & (iv >= i0[tiles[owner]]) & (iv <= i1[tiles[owner]])
    unsure[base[owner[hit]] + iv[hit] - i0[tiles[owner[hit]]]] = True
    # each edge's crossing with the rows it spans (a ring repeats its first vertex)
    same = ci[1:] == ci[:-1]
    a, c = coords[:-1][same], coords[1:][same]
    t = owner[:-1][same]
    lo, hi = np.minimum(a[:, 1], c[:, 1]), np.maximum(a[:, 1], c[:, 1])
    e_i0 = np.maximum(np.ceil(lo - 0.5).astype(np.int64), i0[tiles[t]])
    e_i1 = np.minimum(np.floor(hi - 0.5).astype(np.int64), i1[tiles[t]])
    n_cross = np.maximum(e_i1 - e_i0 + 1, 0)
    edge = np.repeat(np.arange(len(t)), n_cross)
    row = e_i0[edge] + index_ranges(np.zeros(len(t), dtype=np.int64), n_cross)
    key = base[t[edge]] + row - i0[tiles[t[edge]]]
    dy = c[edge, 1] - a[edge, 1]
    flat = np.abs(dy) < _FLAT_EDGE
    unsure[key[flat]] = True
    steady = ~flat
    frac = (row[steady] + 0.5 - a[edge[steady], 1]) / dy[steady]
    x = a[edge[steady], 0] + frac * (c[edge[steady], 0] - a[edge[steady], 0])
    key = key[steady]
    count = np.bincount(key, minlength=n_keys)
    unsure |= (count == 0) | (count % 2 == 1)
    # a row with two crossings (every row of a convex tile) holds one span, between the
    # two; the crossings of a row with more are sorted along it and paired in turn
    left = np.full(n_keys, np.inf)
    right = np.full(n_keys, -np.inf)
    two = (count == 2) & ~unsure
    pick = two[key]
    np.minimum.at(left, key[pick], x[pick])
    np.maximum.at(right, key[pick], x[pick])
    pick = ~pick & ~unsure[key]
    order = np.lexsort((x[pick], key[pick]))
    more_x, more_key = x[pick][order], key[pick][order]
    span_key = np.concatenate([np.flatnonzero(two), more_key[0::2]])
    lo_x = np.concatenate([left[two], more_x[0::2]])
    hi_x = np.concatenate([right[two], more_x[1::2]])
    # sure: centres within the span less the margin; candidates: within the margin of an end
    lo_sure = np.clip(np.ceil(lo_x + CHORD_MARGIN - 0.5), 0, width).astype(np.int64)
    hi_sure = np.clip(np.floor(hi_x - CHORD_MARGIN - 0.5), -1, width - 1).astype(np.int64)
    lo_cand = np.clip(np.ceil(lo_x - CHORD_MARGIN - 0.5), 0, width).astype(np.int64)
    hi_cand = np.clip(np.floor(hi_x + CHORD_MARGIN - 0.5), -1, width - 1).astype(np.int64)
    left_n = np.maximum(np.minimum(lo_sure, hi_cand + 1) - lo_cand, 0)
    right_n = np.maximum(hi_cand - np.maximum(hi_sure, lo_cand - 1), 0)
    doubt = np.flatnonzero(unsure)  # every pixel of these rows
    row_n = np.maximum(j1[key_tile[doubt]] - j0[key_tile[doubt]] + 1, 0)
    test_key = np.concatenate(
        [np.repeat(span_key, left_n), np.repeat(span_key, right_n), np.repeat(doubt, row_n)]
    )
    jj = np.concatenate(
        [
            index_ranges(lo_cand, left_n),
            index_ranges(np.maximum(hi_sure, lo_cand - 1) + 1, right_n),
            index_ranges(j0[key_tile[doubt]], row_n),
        ]
    )
    if len(jj):  # each once: the ends of two spans can share a candidate
        pair = np.unique(test_key * (width + 1) + jj)
        test_key, jj = pair // (width + 1), pair % (width + 1)
    ok = shapely.intersects_xy(geoms[key_tile[test_key]], jj + 0.5, key_row[test_key] + 0.5)
    full = lo_sure <= hi_sure
    return (
        np.concatenate([key_tile[span_key[full]], key_tile[test_key[ok]]]),
        np.concatenate(
            [key_row[span_key[full]] * width + lo_sure[full], key_row[test_key[ok]] * width + jj[ok]]
        ),
        np.concatenate([hi_sure[full] - lo_sure[full] + 1, np.ones(int(ok.sum()), dtype=np.int64)]),
    )


ERROR_BAND = 1 << 15  # (tile, pixel) pairs read at once by colour_error: its temporaries stay in cache


def colour_error(
    picture_lab: np.ndarray, fills_lab: np.ndarray, tiles: np.ndarray, pixels: np.ndarray
) -> float:
    """Mean ΔE*ab between each pixel and the fill of the tile it lies under, over the
    (tile, pixel) pairs of :func:`pixels_under`; NaN when no tile holds a pixel."""
    if len(tiles) == 0:
        return float("nan")
    flat = picture_lab.reshape(-1, 3)
    fills = np.asarray(fills_lab)
    dist = np.empty(len(tiles))
    for lo in range(0, len(tiles), ERROR_BAND):
        diff = flat[pixels[lo : lo + ERROR_BAND]]
        diff -= fills[tiles[lo : lo + ERROR_BAND]]
        diff *= diff
        np.sqrt(diff.sum(axis=1), out=dist[lo : lo + ERROR_BAND])
    return float(dist.mean())


STRADDLE_DEPTH = 1.0  # px of tile on each side of an edge for the tile to straddle it
STRADDLE_PIXELS = 1 << 18  # edge pixels straddling_tiles looks up at once (bounded memory)


def straddling_tiles(elements: Sequence[Any], edges: np.ndarray, depth: float = STRADDLE_DEPTH) -> np.ndarray:
    """(N,) bool: tile k straddles a strong edge, i.e. its outline (convex hull) eroded
    by ``depth`` px holds (inside or on it) the centre of a pixel of ``edges`` ((H, W)
    bool).

    Only the edge pixels are looked at, :data:`STRADDLE_PIXELS` at a time: those within a
    tile's bounding box (which holds its eroded hull) are found by the tiles' STRtree,
    and shapely tests each against the eroded hull of the tiles that have any (the others
    are never eroded)."""
    out = np.zeros(len(elements), dtype=bool)
    placed, geoms = _present(elements)
    ei, ej = np.nonzero(edges)
    if len(placed) == 0 or len(ei) == 0:
        return out
    tree = shapely.STRtree(geoms)
    for lo in range(0, len(ei), STRADDLE_PIXELS):
        x, y = ej[lo : lo + STRADDLE_PIXELS] + 0.5, ei[lo : lo + STRADDLE_PIXELS] + 0.5
        at, tile = tree.query(shapely.points(x, y))  # within the bounding box
        near, tile = np.unique(tile, return_inverse=True)
        eroded = shapely.buffer(shapely.convex_hull(geoms[near]), -depth, join_style="mitre")
        inside = shapely.intersects_xy(eroded[tile], x[at], y[at])
        out[placed[near[np.unique(tile[inside])]]] = True
    return out


# ----------------------------------------------------------------- fidelity measures
#
# How well placed elements follow the problem's density, its direction field, and how
# even their joints are; each computed from the elements and the problem alone (so a
# stored run can be measured again), vectorised over the elements.
#
#   size_fidelity      = sqrt(mean_i (log2(a_i / t_i) − m)²), m = mean_i log2(a_i / t_i):
#                        the RMS of log2(area / target) with the target's scale fitted
#                        (least squares in log2), a_i the element's area, t_i ∝ 1/density
#                        at its centre (t_i = s_i², s_i the problem's size factor there,
#                        cvt.fields.DensityMap.scales_at; 1 without a density).  0: every
#                        area follows the density exactly; 1: off by a factor 2 (RMS)
#   direction_fidelity = mean_i |wrap(φ_i − θ_i)| in degrees, wrap to (−180°/k, 180°/k]:
#                        φ_i the element's orientation, θ_i the field at its centre (0
#                        without a field), k the shape's rotational symmetry (square 4,
#                        rectangle and ellipse 2, triangle 3).  φ_i from the outline
#                        alone: arg(Σ_edges L·e^{ikψ})/k (L, ψ: an edge's length and
#                        direction), less the same of the unit element at angle 0.  NaN
#                        for circles (no direction)
#   grout_mean, grout_cv = mean and coefficient of variation (sd / mean, population sd)
#                        of the exact distances (shapely) between neighbouring elements;
#                        0 where two touch or overlap.  Neighbours: the Urquhart graph of
#                        the element centres (Delaunay edges less each triangle's strictly
#                        longest edge): on a square lattice Delaunay's diagonals join
#                        elements that meet only at corners, which are no joint
#   coverage_at_1pct_overlap: coverage_at_overlap(coverage_overlap_curve(...), 0.01)

# measure name -> (what it says, its unit): the one list of the measures a run reports
MEASURES = {
    "coverage": ("area of the union of the elements inside the region / area of the region", "share"),
    "overlap": ("summed element area minus the union's, / area of the region", "share"),
    "coverage_at_1pct_overlap": (
        "the largest coverage of the elements scaled about their centres "
        "(0.80-1.20) with overlap at most 1 %",
        "share",
    ),
    "size_fidelity": (
        "RMS of log2(area / target), target ∝ 1/density at the element's centre, scale fitted; 0 is perfect",
        "log2",
    ),
    "direction_fidelity": (
        "mean angle between element and field at its centre, modulo the shape's symmetry",
        "degrees",
    ),
    "grout_mean": ("mean distance between neighbouring elements (Urquhart graph of the centres)", "px"),
    "grout_cv": ("coefficient of variation of those distances; 0 is even grout", "share"),
}
FIDELITY_TIE = 1e-9  # relative: a triangle's longest edge must beat the next by this to go


def _present(elements: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """(indices, geometries) of the elements that are placed (not None, not empty)."""
    geoms = np.empty(len(elements), dtype=object)
    geoms[:] = list(elements)
    idx = np.flatnonzero(shapely.is_geometry(geoms) & ~shapely.is_empty(geoms))
    return idx, geoms[idx]


def size_fidelity(areas: npt.ArrayLike, targets: npt.ArrayLike) -> float:
    """RMS of log2(areas / targets) about its mean (the targets' scale fitted); NaN for
    no element.  ``targets`` need only be proportional to the wanted areas."""
    q = np.log2(np.asarray(areas, dtype=np.float64) / np.asarray(targets, dtype=np.float64))
    return float(np.sqrt(np.mean((q - q.mean()) ** 2))) if len(q) else float("nan")


def exterior_rings(polygons: np.ndarray) -> np.ndarray:
    """What ``shapely.get_coordinates`` reads for the exterior rings of ``polygons``: the
    polygons themselves where all are Polygons without a hole (their coordinates are
    then their exterior's, in order, and no ring is copied), else their exterior rings.

    Parameters
    ----------
    polygons : (N,) object array of shapely geometries

    Returns
    -------
    (N,) object array of geometries
    """
    plain = (shapely.get_type_id(polygons) == 3).all() and not shapely.get_num_interior_rings(polygons).any()
    return polygons if plain else shapely.get_exterior_ring(polygons)


def orientations(geoms: np.ndarray, k: int) -> np.ndarray:
    """(N,) the phase arg(Σ_edges L·e^{ikψ}) of each polygon's exterior (radians; divide
    by k for an angle): the direction of its edges modulo 360°/k, weighted by length."""
    coords, owner = shapely.get_coordinates(exterior_rings(geoms), return_index=True)
    d = np.diff(coords, axis=0)
    same = owner[1:] == owner[:-1]  # consecutive vertices of one ring (rings are closed)
    d, own = d[same], owner[1:][same]
    length = np.hypot(d[:, 0], d[:, 1])
    psi = np.arctan2(d[:, 1], d[:, 0])
    re = np.bincount(own, weights=length * np.cos(k * psi), minlength=len(geoms))
    im = np.bincount(own, weights=length * np.sin(k * psi), minlength=len(geoms))
    return np.arctan2(im, re)


def direction_errors(geoms: np.ndarray, field_angles: npt.ArrayLike, shape: str, aspect: float) -> np.ndarray:
    """(N,) |angle between each element and the field angle at it| in degrees, modulo the
    shape's rotational symmetry (in [0, 180/k]); NaN for shapes without a direction."""
    from .shapes import rotational_symmetry, unit_outline

    k = rotational_symmetry(shape, aspect)
    if k == 0:
        return np.full(len(geoms), np.nan)
    ref = orientations(np.array([shapely.Polygon(unit_outline(shape, aspect))], dtype=object), k)[0]
    phase = orientations(geoms, k) - ref - k * np.asarray(field_angles, dtype=np.float64)
    return np.degrees(np.abs(np.angle(np.exp(1j * phase)))) / k


def neighbour_pairs(points: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(a, b) with a < b: the edges of the Urquhart graph of ``points`` (Delaunay edges
    less each triangle's strictly longest edge).  Fewer than 3 points, or all on a line:
    consecutive points in sorted order."""
    from scipy.spatial import Delaunay, QhullError

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = len(pts)
    try:
        tri = Delaunay(pts).simplices if n >= 3 else None
    except QhullError:
        tri = None
    if tri is None:
        order = np.lexsort((pts[:, 1], pts[:, 0]))
        a, b = order[:-1], order[1:]
        return np.minimum(a, b), np.maximum(a, b)
    tri = tri.astype(np.int64)  # qhull's int32 indices: a·n + b overflows past 46 340 points
    turn = np.roll(tri, -1, axis=1)  # edge k of a triangle joins its vertices k and k + 1
    lo, hi = np.minimum(tri, turn), np.maximum(tri, turn)  # (T, 3)
    d = pts[lo] - pts[hi]
    length = np.sqrt(np.sum(d * d, axis=2))  # (T, 3)
    srt = np.sort(length, axis=1)
    longest = np.argmax(length, axis=1)
    strict = srt[:, 2] > srt[:, 1] * (1 + FIDELITY_TIE)
    # one sort of the edges: each distinct edge once, dropped if any of its triangles drops it
    edges, where = np.unique((lo * n + hi).ravel(), return_inverse=True)
    dropped = np.zeros(len(edges), dtype=bool)
    dropped[where.reshape(-1, 3)[strict, longest[strict]]] = True
    keep = edges[~dropped]
    return keep // n, keep % n


def grout(geoms: np.ndarray, centres: np.ndarray | None = None) -> tuple[float, float]:
    """(mean, coefficient of variation) of the exact distances between neighbouring
    elements (:func:`neighbour_pairs` of their centroids, ``centres`` when the caller
    has them); NaN with fewer than 2."""
    if len(geoms) < 2:
        return float("nan"), float("nan")
    if centres is None:
        centres = shapely.get_coordinates(shapely.centroid(geoms))
    a, b = neighbour_pairs(centres)
    d = shapely.distance(geoms[a], geoms[b])
    mean = float(d.mean())
    return mean, (float(d.std() / mean) if mean > 0 else float("nan"))


def fidelity(
    elements: Sequence[Any], problem: Problem, shape: str, aspect: float | None = None
) -> dict[str, float]:
    """size_fidelity, direction_fidelity, grout_mean and grout_cv (formulas above) of the
    placed ``elements`` of ``shape`` (a ``cvt.shapes`` name; ``aspect`` β of rectangles
    and ellipses, default the problem metric's) on ``problem`` (its density and field)."""
    aspect = problem.metric.aspect if aspect is None else aspect
    _, geoms = _present(elements)
    if len(geoms) == 0:
        nan = float("nan")
        return {"size_fidelity": nan, "direction_fidelity": nan, "grout_mean": nan, "grout_cv": nan}
    centres = shapely.get_coordinates(shapely.centroid(geoms))
    targets = problem.scales_at(centres) ** 2
    errors = direction_errors(geoms, problem.angles_at(centres), shape, aspect)
    mean, cv = grout(geoms, centres)
    return {
        "size_fidelity": size_fidelity(shapely.area(geoms), targets),
        "direction_fidelity": float(np.mean(errors)) if len(errors) else float("nan"),
        "grout_mean": mean,
        "grout_cv": cv,
    }


def timed_fidelity(elements: Sequence[Any], problem: Problem, shape: str) -> tuple[dict[str, float], float]:
    """:func:`fidelity` of ``elements`` and the seconds it took (for a command that takes
    it on a thread of its own, beside other work, and reports it as a stage).

    Parameters
    ----------
    elements : sequence of shapely geometries or None
        The placed elements.
    problem : Problem
        The problem they were placed on (its density and field).
    shape : str
        Their shape (a ``cvt.shapes`` name).

    Returns
    -------
    measures : dict of str to float
        As :func:`fidelity` gives them.
    seconds : float
        Wall time of the call.
    """
    t0 = time.perf_counter()
    measured = fidelity(elements, problem, shape)
    return measured, time.perf_counter() - t0


def measures(
    elements: Sequence[Any], problem: Problem, shape: str, aspect: float | None = None, region: Any = None
) -> dict[str, float]:
    """Every measure of :data:`MEASURES` of the placed ``elements`` on ``problem``."""
    region = region_polygon(problem.grid) if region is None else region
    ev = evaluate(elements, problem.grid, region=region)
    out = {
        "coverage": ev.coverage,
        "overlap": ev.overlap,
        "coverage_at_1pct_overlap": coverage_at_overlap_limit(elements, problem.grid, 0.01, region=region),
        **fidelity(elements, problem, shape, aspect),
    }
    return {name: out[name] for name in MEASURES}


__all__ = [
    "Evaluation",
    "region_polygon",
    "EMPTY_BAND",
    "empty_cells",
    "UNION_BATCH",
    "evaluate",
    "SCALE_FACTORS",
    "scaled",
    "coverage_overlap_curve",
    "coverage_at_overlap",
    "coverage_at_overlap_limit",
    "pixels_under",
    "ERROR_BAND",
    "colour_error",
    "STRADDLE_DEPTH",
    "STRADDLE_PIXELS",
    "straddling_tiles",
    "MEASURES",
    "FIDELITY_TIE",
    "size_fidelity",
    "timed_fidelity",
    "exterior_rings",
    "orientations",
    "direction_errors",
    "neighbour_pairs",
    "grout",
    "fidelity",
    "measures",
]
