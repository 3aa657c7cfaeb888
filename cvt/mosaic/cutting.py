"""Tiles cut to fit along walls, as a mosaicist nips a tile to meet a contour.

Compaction keeps every tile whole: a square facing a curved or slanted wall touches it
at a corner and leaves a wedge of grout beside it.  Here each tile near a wall is grown
about its centre (by ``enlarge``) and trimmed back to what is free: at least G/2 from
the walls' centre lines and the picture's border, at least G from every other tile.  The
trimmed tile always holds the whole tile it came from, so cutting only adds area, and it
never moves another tile.  Tiles that could reach one another once grown are cut in
turns (a greedy colouring of the graph of grown tiles less than G apart): within one
turn no two candidates can meet, and later turns see the earlier turns' cuts.

Two styles (:func:`cut_to_walls`; ``"auto"`` takes the exact one up to
:data:`EXACT_TILES` tiles, the straight one above):

*exact*: all that is free, by shapely.  Each turn is one vectorised pass of shapely
over its tiles: the grown tile less each neighbour grown by G with mitred corners (never
closer than G anywhere) plus a margin of ``_MARGIN`` for the rounding of the overlay,
one difference per neighbour rank, then less the walls' G/2-wide margin, grown once in
runs of their merged centre lines with square ends (the lines turn only by right
angles, where such ends meet as a mitred join would).  A cut that would let a tile
straddle a strong edge (its hull reaching round the end of a wall,
:func:`cvt.evaluate.straddling_tiles`) is undone, and so is one where shapely gives up
on the geometry.  The cut tile may bend round its neighbours.  Measured on six
photographs (2000 squares, default gap and edge threshold, OpenCL): cutting the tiles
within one spacing of a wall raised coverage by 2-10 points.

*straight*: straight cuts, convex tiles, whole-array.  Each tile's obstacles (the other
tiles, and the walls' centre lines as their longest straight runs: every piece convex)
are taken most constraining first (the least room between it and the tile).  The plane
kept for it is, of the line through their closest points and that line turned by up to
60 degrees, the one that keeps the most of the tile's outline so far while holding the
whole tile and keeping the obstacle at its distance; every other obstacle beyond that
plane (at its own distance) is then done, and the next one left gives the next plane.
Each obstacle is so cleared by a plane found at its distance, which is the proof of the
guarantees (and a cut tile holds no wall pixel centre: every piece of wall within its
reach is beyond one of its planes).  The outlines are clipped (Sutherland-Hodgman)
whole-array, every tile's first plane at once, then their second, ...  Measured against
the exact cut at 2560 px, 20 000 tiles (coffee, chelsea, astronaut, scene.jpg):
coverage 0.2-1.5 points lower (the tiles no longer bend round their neighbours), colour
error 1.7-4.8 % lower, straddling and overlap 0 both ways; on coffee the cutting takes
0.3x the CPU (2.2 against 7.4 s, one process).  At 2000 tiles it loses 1-4 points of
coverage: there the exact cut is kept.

Where the time goes (coffee, 4096 px, 64 000 tiles, 26 835 cut, 676 000 pairs): some
40 % in GEOS (the distances of the tile pairs, the closest points behind each plane,
the pairs within reach that the disks leave open), the rest the rounds of planes.  Three
things keep the NumPy side quick on a few vertices a row: rows gathered with
``np.take`` (fancy indexing of (n, V, 2) rows was 9-15x slower), least and greatest
folded over the vertex places with ``np.minimum`` (a reduction along that short axis
was 3-4x slower), and the distances to the walls' pieces in GEOS's own arithmetic
(:func:`segment_distances`), which beat GEOS only when so folded.  The pairs' order is
STRtree's where it decides ties (the tiles'); the walls' pairs go piece by piece.
"""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import shapely

from ..errors import InputError
from ..evaluate import exterior_rings, straddling_tiles
from ..placement.compaction import _wall_links, wall_segments
from ..threads import elementwise, side_by_side, usable_cores

CUT_ENLARGE = 1.8  # a cut tile lies within its tile grown by this factor about its centre
CUT_STYLES = ("auto", "exact", "straight")  # cut_to_walls's styles (the docstring)
CUT_REACH = 1.0  # tiles this many element spacings or closer to a wall are cut to fit
_MARGIN = 1e-3  # px kept beyond the gap
_ROWS_PER_PART = 2000  # tiles cut at least, per part cut side by side
_RUN = 64  # most vertices of a wall line in one piece of its margin, exact cut (fewer, smaller differences)


def wall_lines(walls: np.ndarray):
    """The centre lines of thin walls as straight pieces: each longest straight run of
    steps between the centres of 4-connected wall pixels (carried on to the picture's
    border where a wall meets it), and a point for each wall pixel that touches no other.

    Parameters
    ----------
    walls : (H, W) bool ndarray
        Thin walls.

    Returns
    -------
    ndarray of shapely geometries
        Straight lines and points: convex pieces, each of which a half-plane can keep a
        tile clear of.
    """
    return _line_geometries(*_wall_line_ends(walls))


def _line_geometries(segs: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Shapely lines of ends ``segs`` (n, 2, 2), then points ``points`` (m, 2)."""
    if len(segs) + len(points) == 0:
        return np.zeros(0, dtype=object)
    return np.concatenate([shapely.linestrings(segs), shapely.points(points)])


def _wall_line_ends(walls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`wall_lines` as coordinates: each straight line's ends, (n, 2, 2), and each
    point, (m, 2)."""
    walls = np.asarray(walls, dtype=bool)
    h, w = walls.shape
    i, j, right, down, left, up = _wall_links(walls)
    if len(i) == 0:
        return np.zeros((0, 2, 2)), np.zeros((0, 2))
    # runs along rows: row-major, a run's pixels come one after another
    row, col, length = _runs(i, j, right, left)
    x0, y0 = col + 0.5, row + 0.5
    pieces = [np.stack([x0, y0, x0 + length, y0], axis=1)]
    # runs along columns: the pixels taken column by column
    by_column = np.lexsort((i, j))
    # column-major, a pixel's lower neighbour comes next
    col, row, length = _runs(j[by_column], i[by_column], down[by_column], up[by_column])
    x0, y0 = col + 0.5, row + 0.5
    pieces.append(np.stack([x0, y0, x0, y0 + length], axis=1))
    # a wall that meets the picture's border is carried on to it: a cut tile, unlike a
    # whole one, could otherwise bend round the wall's end in the half pixel left there
    for r, to_y in ((0, 0.0), (h - 1, float(h))):
        x = np.flatnonzero(walls[r]) + 0.5
        pieces.append(np.stack([x, np.full_like(x, r + 0.5), x, np.full_like(x, to_y)], axis=1))
    for c, to_x in ((0, 0.0), (w - 1, float(w))):
        y = np.flatnonzero(walls[:, c]) + 0.5
        pieces.append(np.stack([np.full_like(y, c + 0.5), y, np.full_like(y, to_x), y], axis=1))
    segs = np.concatenate(pieces)
    lone = ~(right | down | left | up)
    return segs.reshape(-1, 2, 2), np.stack([j[lone] + 0.5, i[lone] + 0.5], axis=1)


def _runs(line, pos, on, before) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The runs of links between wall pixels along lines (rows, or columns): ``line``,
    ``pos`` the line and place of each pixel, taken line by line in order of place;
    ``on``: each pixel is linked to the next one, ``before``: the one before to it.
    Returns each run's line, first place and length (links), in the pixels' order."""
    start = np.flatnonzero(on & ~before)
    last = on.copy()
    last[:-1] &= ~on[1:]  # a run's last link: the next pixel has none onward
    end = np.flatnonzero(last)
    return line[start], pos[start], end - start + 1


def _merged_lines(walls: np.ndarray):
    """The centre lines of thin walls as the exact cut reads them: merged lines, plus a
    point for each wall pixel that touches no other."""
    steps, points = _wall_pieces(walls)
    parts = []
    if len(steps):
        # the steps meet only at their ends: they are merged as they are, with no noding union
        merged = shapely.line_merge(shapely.multilinestrings(steps))
        # less the vertices where a line runs straight on: the same lines, fewer to test
        parts.append(shapely.get_parts(shapely.simplify(merged, 0.0, preserve_topology=False)))
    if len(points):
        parts.append(points)
    return np.concatenate(parts) if parts else np.zeros(0, dtype=object)


def _wall_pieces(walls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The walls' centre lines in pieces: unit steps between the centres of 4-connected
    wall pixels and on to the border (lines), and lone wall pixels (points)."""
    segs = wall_segments(walls)
    if len(segs) == 0:
        return np.zeros(0, dtype=object), np.zeros(0, dtype=object)
    # a wall that meets the picture's border is carried on to it: a cut tile, unlike a
    # whole one, could otherwise bend round the wall's end in the half pixel left there
    h, w = walls.shape
    ends = []
    for row, to_y in ((0, 0.0), (h - 1, float(h))):
        x = np.flatnonzero(walls[row]) + 0.5
        ends.append(np.stack([x, np.full_like(x, row + 0.5), x, np.full_like(x, to_y)], axis=1))
    for col, to_x in ((0, 0.0), (w - 1, float(w))):
        y = np.flatnonzero(walls[:, col]) + 0.5
        ends.append(np.stack([np.full_like(y, col + 0.5), y, np.full_like(y, to_x), y], axis=1))
    segs = np.concatenate([segs, *ends])
    long = segs[:, 0] != segs[:, 2]
    long |= segs[:, 1] != segs[:, 3]
    return shapely.linestrings(segs[long].reshape(-1, 2, 2)), shapely.points(segs[~long, :2])


def _grown(polygons: np.ndarray, factor: float) -> np.ndarray:
    """Each polygon scaled by ``factor`` about its centroid (vectorised)."""
    centres = shapely.get_coordinates(shapely.centroid(polygons))
    coords, index = shapely.get_coordinates(polygons, return_index=True)
    at = np.take(centres, index, axis=0)
    out = shapely.set_coordinates(polygons.copy(), at + factor * (coords - at))
    return out


def _turns(pairs: np.ndarray, n: int) -> np.ndarray:
    """A turn per node such that no pair shares one: greedy colouring, the nodes taken
    by degree, largest first (ties by index), each given the least turn none of its
    neighbours taken before it has.  Worked in rounds: a round turns every node whose
    neighbours taken before it all have theirs, the same turns as one node at a time."""
    turn = np.full(n, -1, dtype=np.int64)
    if n == 0:
        return turn
    pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    # each pair once, in order (one key per pair sorts as the pairs do, and far quicker)
    key = np.unique(pairs[:, 0] * n + pairs[:, 1])
    pairs = np.stack([key // n, key % n], axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    degree = np.bincount(pairs.ravel(), minlength=n)
    rank = np.empty(n, dtype=np.int64)
    rank[np.argsort(-degree, kind="stable")] = np.arange(n)
    # each edge from the node taken first to the one taken later
    u, v = pairs[:, 0], pairs[:, 1]
    swap = rank[u] > rank[v]
    early = np.where(swap, v, u)
    late = np.where(swap, u, v)
    order = np.argsort(late, kind="stable")
    early, late = early[order], late[order]
    waiting = np.bincount(late, minlength=n)
    by_early = np.argsort(early, kind="stable")
    first_out = np.searchsorted(early[by_early], np.arange(n + 1))
    ready = np.flatnonzero(waiting == 0)
    while len(ready):
        # the turns of each ready node's earlier neighbours, all known now
        lo, hi = np.searchsorted(late, ready), np.searchsorted(late, ready, side="right")
        counts = hi - lo
        seen = np.repeat(np.arange(len(ready)), counts)
        nb = early[np.repeat(lo - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())]
        used = np.zeros((len(ready), int(counts.max(initial=0)) + 2), dtype=bool)
        t = turn[nb]
        fits = t < used.shape[1]
        used[seen[fits], t[fits]] = True
        turn[ready] = np.argmin(used, axis=1)  # the least turn not used
        # their later neighbours wait on one fewer
        lo, hi = first_out[ready], first_out[ready + 1]
        counts = hi - lo
        later = late[by_early[np.repeat(lo - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())]]
        np.subtract.at(waiting, later, 1)
        touched = np.unique(later)
        ready = touched[(waiting[touched] == 0) & (turn[touched] < 0)]
    return turn


# up to this many tiles cut_to_walls cuts exactly (shapely differences: the cut tiles may
# bend round their neighbours); above it with straight cuts (convex tiles), several
# times cheaper (module docstring)
EXACT_TILES = 10_000


def cut_to_walls(
    polygons,
    walls: np.ndarray,
    gap: float,
    spacing: float,
    enlarge: float = CUT_ENLARGE,
    reach: float = CUT_REACH,
    style: str = "auto",
) -> tuple[list, int]:
    """The tiles within ``reach`` spacings of a wall cut to fit (module docstring).

    Parameters
    ----------
    polygons : sequence of shapely Polygon or None
        The tiles (None where there is none): convex, pairwise at least ``gap`` apart and
        at least gap/2 from the walls' centre lines and the raster's border.
    walls : (H, W) bool ndarray
        Thin walls.
    gap : float
        G, in pixels.
    spacing : float
        The element spacing, in pixels.
    enlarge : float
        A cut tile lies within its tile grown by this factor about its centre.
    reach : float
        Tiles this many spacings or closer to a wall's centre line are cut.
    style : str
        ``"exact"`` (what is free, by shapely differences), ``"straight"`` (convex tiles,
        straight cuts) or ``"auto"``: exact up to :data:`EXACT_TILES` tiles, else straight.

    Returns
    -------
    list
        The tiles, cut ones replaced.
    int
        How many tiles grew.
    """
    if style not in CUT_STYLES:
        raise InputError(f"style must be 'auto', 'exact' or 'straight', got {style!r}")
    if style == "auto":
        style = "exact" if len(polygons) <= EXACT_TILES else "straight"
    cut = _cut_exact if style == "exact" else _cut_straight
    return cut(polygons, walls, gap, spacing, enlarge, reach)


def _tile_array(polygons) -> tuple[list, np.ndarray, np.ndarray]:
    """The tiles as a list, as an object array (an empty polygon where there is none),
    and the indices of those present."""
    out = list(polygons)
    geoms = np.array([shapely.Polygon() if p is None else p for p in out], dtype=object)
    return out, geoms, np.flatnonzero(~shapely.is_empty(geoms))


def _cut_straight(
    polygons,
    walls: np.ndarray,
    gap: float,
    spacing: float,
    enlarge: float = CUT_ENLARGE,
    reach: float = CUT_REACH,
) -> tuple[list, int]:
    """:func:`cut_to_walls` by straight cuts (module docstring; the arguments and the
    answer are :func:`cut_to_walls`'s)."""
    out, geoms, present = _tile_array(polygons)
    h, w = walls.shape
    segs, points = _wall_line_ends(walls)
    pieces = _line_geometries(segs, points)
    if len(pieces) == 0 or len(present) == 0:
        return out, 0
    near = present[_near_walls(pieces, geoms[present], reach * spacing, walls)]
    if len(near) == 0:
        return out, 0
    full = gap + _MARGIN  # kept from every other tile
    half = 0.5 * gap + _MARGIN  # kept from the walls' centre lines
    grown = _grown(geoms[near], enlarge)
    grown_xy = _vertex_arrays(grown)
    piece_xy = np.concatenate([segs, np.repeat(points[:, None, :], 2, axis=1)])
    (ci, oi), (wi, wc) = _obstacles(geoms, near, (grown, _disks(*grown_xy)), (pieces, piece_xy), full, half)
    # cut in turns: two tiles whose grown outlines come within the gap never share one
    cand = np.flatnonzero(np.isin(oi, near))
    slot = np.searchsorted(near, oi[cand])
    turn = _turns(np.stack([ci[cand], slot], axis=1), len(near))
    # the vertices of every tile that is cut or in the way and of every piece, padded
    # (a tile's row follows its cuts); most have at most ``narrow`` (the whole tiles,
    # the pieces), read at that width
    involved = np.union1d(near, oi)
    row_of = np.full(len(geoms), -1)
    row_of[involved] = np.arange(len(involved))
    tile_xy = _padded(*_vertex_arrays(geoms[involved]))
    narrow = max(tile_xy.shape[1], 2)
    tile_xy, piece_xy = _widened(tile_xy, narrow), _widened(piece_xy, narrow)
    tile_count = np.full(len(involved), narrow)
    # the rows of the obstacles (the tiles', then the pieces') and their first
    # ``narrow`` vertices (all of most)
    pool_row = np.concatenate([row_of, len(involved) + np.arange(len(pieces))])
    pool_xy = np.concatenate([tile_xy, piece_xy])
    plans = _turn_plans(turn, near, (ci, oi), (wc, wi), len(geoms), (full, half))
    pool = np.concatenate([geoms, pieces])
    whole = geoms[near]  # a candidate is whole until its own turn
    whole_xy = np.take(pool_xy, pool_row[near], axis=0)  # (all their vertices: narrow)
    piece_ends = piece_xy[:, :2]
    grew = 0
    # the distances of the pairs whose obstacle no turn before theirs moves are found
    # while the turns before run (GEOS lets go of the GIL): one thread beside this one
    with ThreadPoolExecutor(1) as beside:
        fixed = [
            beside.submit(
                _distances, (whole, whole_xy), (pool, piece_ends), pair_tile[~moved], obstacle[~moved]
            )
            for _, pair_tile, obstacle, _, moved in plans[1:]
        ]
        for t, (rows, pair_tile, obstacle, keep, moved) in enumerate(plans):
            pool = np.concatenate([geoms, pieces])
            d = np.empty(len(obstacle))
            if t == 0:
                d[:] = _distances((whole, whole_xy), (pool, piece_ends), pair_tile, obstacle, elementwise)
            else:
                d[~moved] = fixed[t - 1].result()
                d[moved] = elementwise(shapely.distance, whole[pair_tile[moved]], pool[obstacle[moved]])
            wide = np.flatnonzero(tile_count > narrow)
            by_row = np.concatenate([geoms[involved], pieces])
            vertices = (pool_row, pool_xy, by_row, wide, tile_xy[wide])
            cut, ok, poly, count = _cut_convex_in_parts(
                whole, grown_xy, rows, (pair_tile, pool, obstacle, keep, d), (w, h), gap, (near, vertices)
            )
            good = rows[ok]
            # each cut outline begun at its vertex nearest the whole tile's first one
            # (as _started_as does, here on the arrays)
            at = row_of[near[good]]
            poly, count = _started_at(poly[ok], count[ok], tile_xy[at, 0])
            geoms[near[good]] = _polygons(poly, count)
            cut_xy = _padded(poly, count)
            tile_xy = _widened(tile_xy, cut_xy.shape[1])
            tile_xy[at] = _widened(cut_xy, tile_xy.shape[1])
            pool_xy[at] = tile_xy[at, :narrow]
            tile_count[at] = count
            grew += len(good)
    result = np.empty(len(out), dtype=object)
    result[:] = out
    result[near] = geoms[near]  # every candidate is a tile (not None)
    return list(result), grew


def _obstacles(geoms, near, grown: tuple, pieces: tuple, full: float, half: float) -> tuple:
    """Each candidate's obstacles (a cut tile lies within its grown outline): ((candidate,
    tile) pairs of the other tiles whose outline, grown where it is a candidate, comes
    within ``full`` of its grown outline; (piece, candidate) pairs of the pieces of the
    walls' centre lines within ``half`` of it).  ``grown``: the candidates' grown outlines
    and their :func:`_disks`; ``pieces``: the pieces and their ends."""
    outlines, disks = grown
    outer = geoms.copy()
    outer[near] = outlines
    twin = np.full(len(geoms), -1)
    twin[near] = np.arange(len(near))  # outer[near[k]] is outlines[k]
    # the two searches side by side (GEOS and the trees let go of the GIL)
    (ci, oi), by_piece = side_by_side(
        functools.partial(_within, outer, outlines, full, _tile_bounds(disks, outer), twin),
        functools.partial(_within, outlines, pieces[0], half, _piece_bounds(disks, pieces[1])),
    )
    other = oi != near[ci]
    return (ci[other], oi[other]), by_piece


def _distances(tiles: tuple, obstacles: tuple, pair_tile, obstacle, run=None) -> np.ndarray:
    """``shapely.distance(tiles[pair_tile], pool[obstacle])``: the pairs of a tile and a
    piece of wall by :func:`segment_distances` (the same numbers, quicker), the others
    and the few it leaves open by GEOS (through ``run(shapely.distance, ...)`` if given).
    ``tiles``: the tiles and their padded vertices; ``obstacles``: the pool (the tiles
    then the pieces) and the pieces' ends."""
    whole, whole_xy = tiles
    pool, ends = obstacles
    n_tiles = len(pool) - len(ends)
    d = np.full(len(obstacle), np.nan)
    wall = np.flatnonzero(obstacle >= n_tiles)
    d[wall] = segment_distances(
        np.take(whole_xy, pair_tile[wall], axis=0), np.take(ends, obstacle[wall] - n_tiles, axis=0)
    )
    ask = np.flatnonzero(np.isnan(d))
    if len(ask):
        a, b = whole[pair_tile[ask]], pool[obstacle[ask]]
        d[ask] = run(shapely.distance, a, b) if run is not None else shapely.distance(a, b)
    return d


_HAIR_APART = 1e-9  # px: a pair nearer than this to meeting is left to GEOS
_BLOCK_PAIRS = 8192  # pairs per block of segment_distances (its arrays stay in cache)


def segment_distances(poly: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Distances between convex polygons and segments, as GEOS computes them, whole-array.

    GEOS's distance between a polygon and a line that do not meet is the least, over each
    pair of a polygon edge and the segment, of four point-to-segment distances (each end
    of one to the other); over all the edges, that is the least distance of each vertex
    to the segment and of each end of the segment to each edge, each here computed in
    GEOS's own arithmetic (``Distance::pointToSegment``), so the least is the same number
    bit for bit.  Only pairs surely apart are so computed: the segment's line, or a line
    through a polygon edge, has the other wholly beyond it by more than a hair.

    Parameters
    ----------
    poly : (n, V, 2) float ndarray
        Each convex polygon's vertices in ring order (either way round), the places past
        its own vertices holding its first one.
    segs : (n, 2, 2) float ndarray
        Each segment's ends (a point: both the same).

    Returns
    -------
    (n,) float ndarray
        ``shapely.distance(polygon, segment)``, NaN where the pair is not surely apart (ask
        GEOS).
    """
    out = np.empty(len(poly))
    for s in range(0, len(poly), _BLOCK_PAIRS):
        out[s : s + _BLOCK_PAIRS] = _segment_block(poly[s : s + _BLOCK_PAIRS], segs[s : s + _BLOCK_PAIRS])
    return out


def _point_segment(px, py, ax, ay, bx, by):
    """GEOS's ``Distance::pointToSegment``, element by element, in its arithmetic."""
    dx, dy = bx - ax, by - ay
    len2 = dx * dx + dy * dy
    ex, ey = px - ax, py - ay
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (ex * dx + ey * dy) / len2
        s = ((ay - py) * dx - (ax - px) * dy) / len2
        mid = np.abs(s) * np.sqrt(len2)
    fx, fy = px - bx, py - by
    out = np.where(r >= 1.0, np.sqrt(fx * fx + fy * fy), mid)
    # the first end where A = B (r is then not a number) or r <= 0
    return np.where(~(r > 0.0), np.sqrt(ex * ex + ey * ey), out)


def _segment_block(poly: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """:func:`segment_distances` of one block: folded vertex by vertex (a reduction along
    the short vertex axis is several times slower)."""
    cx, cy, dx, dy = segs[:, 0, 0], segs[:, 0, 1], segs[:, 1, 0], segs[:, 1, 1]
    sx, sy = dx - cx, dy - cy
    margin = _HAIR_APART * np.sqrt(sx * sx + sy * sy)
    v = poly.shape[1]
    area = np.zeros(len(poly))
    for k in range(v):  # twice the signed area: which way round the ring goes
        a, b = poly[:, k], poly[:, (k + 1) % v]
        area += a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]
    turn = np.sign(area)
    least = np.full(len(poly), np.inf)
    above = np.ones(len(poly), dtype=bool)
    below = np.ones(len(poly), dtype=bool)
    apart = np.zeros(len(poly), dtype=bool)
    for k in range(v):
        a, b = poly[:, k], poly[:, (k + 1) % v]
        ax, ay, bx, by = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
        np.minimum(least, _point_segment(ax, ay, cx, cy, dx, dy), out=least)
        np.minimum(least, _point_segment(cx, cy, ax, ay, bx, by), out=least)
        np.minimum(least, _point_segment(dx, dy, ax, ay, bx, by), out=least)
        # apart: every vertex beyond the segment's line (one side), or both ends beyond
        # this edge's line (outward)
        side = sx * (ay - cy) - sy * (ax - cx)
        above &= side > margin
        below &= side < -margin
        ex, ey = bx - ax, by - ay
        edge = _HAIR_APART * np.sqrt(ex * ex + ey * ey)
        out_c = turn * (ex * (cy - ay) - ey * (cx - ax)) < -edge
        out_d = turn * (ex * (dy - ay) - ey * (dx - ax)) < -edge
        apart |= out_c & out_d
    return np.where(apart | above | below, least, np.nan)


def _turn_plans(turn, near, tile_pairs, wall_pairs, n_tiles, keeps) -> list:
    """Each turn's candidates (indices into ``near``) and pairs: (candidate, obstacle)
    with the obstacle as an index into the tiles (as they are when the turn comes) then
    the pieces (``wall_pairs``' second indices, after ``n_tiles``), the distance to keep
    (``keeps``: from tiles, from pieces), and whether the obstacle is a tile cut in an
    earlier turn."""
    (ci, oi), (wc, wi) = tile_pairs, wall_pairs
    when = np.full(n_tiles, -1)
    when[near] = turn
    plans = []
    for t in range(turn.max() + 1):
        members = turn == t
        tile_pair, wall_pair = members[ci], members[wc]
        pair_tile = np.concatenate([ci[tile_pair], wc[wall_pair]])
        obstacle = np.concatenate([oi[tile_pair], n_tiles + wi[wall_pair]])
        keep = np.concatenate([np.full(tile_pair.sum(), keeps[0]), np.full(wall_pair.sum(), keeps[1])])
        moved = np.zeros(len(obstacle), dtype=bool)
        moved[: tile_pair.sum()] = (when[oi[tile_pair]] >= 0) & (when[oi[tile_pair]] < t)
        plans.append((np.flatnonzero(members), pair_tile, obstacle, keep, moved))
    return plans


_BLOCK = 24  # px: the pieces of wall are gathered by the square of this side their centre lies in


def _near_walls(pieces: np.ndarray, tiles: np.ndarray, distance: float, walls: np.ndarray) -> np.ndarray:
    """Indices (sorted) of the convex ``tiles`` within ``distance`` of a piece of wall.

    Most tiles are settled by the nearest wall pixel centre to a point inside each (its
    vertices' mean): the centre lines pass through every wall pixel centre and come no
    farther than half a pixel from one, so a tile whose inner disk about that point is
    within reach of a centre is near, and one whose outer disk is beyond reach of them
    all by half a pixel is not.  The few others (some 3 %) are looked up exactly."""
    from scipy.spatial import cKDTree  # here: importing this module (the parser does) stays cheap

    i, j = np.nonzero(walls)
    inner, inner_r, outer_r = _disks(*_vertex_arrays(tiles))
    # (a tree built plainly is quicker to build and query here; beyond the reach that
    # could matter a tile is far: infinity)
    centres = cKDTree(np.stack([j + 0.5, i + 0.5], axis=1), balanced_tree=False, compact_nodes=False)
    rho = centres.query(inner, distance_upper_bound=distance + 0.5 + float(outer_r.max()) + 1.0)[0]
    sure = rho - inner_r <= distance - 1e-9
    unsure = np.flatnonzero(~sure & (rho - 0.5 - outer_r <= distance + 1e-9))
    found = np.zeros(0, dtype=np.int64)
    if len(unsure):  # each looked up among the pieces (GEOS prepares the tile once)
        predicate = "dwithin" if distance > 0 else "intersects"
        hit = shapely.STRtree(pieces).query(tiles[unsure], predicate=predicate, distance=distance)[0]
        found = unsure[hit]
    return np.union1d(np.flatnonzero(sure), found)


def _disks(poly: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of convex polygons (padded vertex arrays, :func:`_vertex_arrays`): a point inside
    each (its vertices' mean), the radius of the disk about it that the polygon holds
    (the least distance to its edges' lines) and of the one that holds the polygon."""
    v = np.arange(poly.shape[1])[None, :]
    real = v < count[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        inner = (poly * real[:, :, None]).sum(axis=1) / count[:, None]
    off = poly - inner[:, None, :]
    outer_r = np.sqrt(np.where(real, (off**2).sum(axis=2), 0.0).max(axis=1, initial=0.0))
    nxt = np.where(v + 1 < count[:, None], v + 1, 0)
    edge = np.take_along_axis(poly, nxt[:, :, None], axis=1) - poly
    length = np.hypot(edge[..., 0], edge[..., 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        across = np.abs(edge[..., 0] * off[..., 1] - edge[..., 1] * off[..., 0]) / length
    inner_r = np.where(real & (length > 0), across, np.inf).min(axis=1, initial=np.inf)
    return inner, inner_r, outer_r


def _within(
    geoms: np.ndarray, query: np.ndarray, distance: float, bounds, twin: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (query index, geoms index) less than ``distance`` apart: the boxes grown by
    it looked up in a tree, then the exact distances (cheaper than the tree's own
    ``dwithin``).  ``bounds(qi, gi, low, high)`` tells which pairs are surely nearer
    than ``low`` and which surely farther than ``high``: GEOS is asked only about the
    rest.  ``twin``: per geometry, the query that is the same geometry (-1 if none);
    GEOS's distance is the same either way round, so of each two such pairs (a, b),
    (b, a) it is asked once."""
    qi, gi = _boxes_within(geoms, query, distance)
    close, far = bounds(qi, gi, distance - _HAIR, distance + _HAIR)
    ask = np.flatnonzero(~close & ~far)
    if twin is not None:
        other = twin[gi[ask]]
        both = other >= 0
        pairs, ask = ask[both], ask[~both]
        a, b = qi[pairs], other[both]
        _, once, back = np.unique(
            np.minimum(a, b) * len(query) + np.maximum(a, b), return_index=True, return_inverse=True
        )
        found = elementwise(
            shapely.dwithin, query[qi[pairs[once]]], geoms[gi[pairs[once]]], distance=distance
        )
        close[pairs] = found[back]
    close[ask] = elementwise(shapely.dwithin, query[qi[ask]], geoms[gi[ask]], distance=distance)
    return qi[close], gi[close]


def _boxes_within(geoms: np.ndarray, query: np.ndarray, distance: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (query index, geoms index) whose boxes come within ``distance``, the query
    indices in order: the boxes of the fewer grown by it, in a tree or as the query
    (each query's pairs then come in another order)."""
    few = query if len(query) <= len(geoms) else geoms
    lo_x, lo_y, hi_x, hi_y = shapely.bounds(few).T
    boxes = shapely.box(lo_x - distance, lo_y - distance, hi_x + distance, hi_y + distance)
    if len(query) <= len(geoms):
        return shapely.STRtree(geoms).query(boxes)
    return shapely.STRtree(boxes).query(query)


_HAIR = 1e-9  # px: a bound nearer than this to the threshold leaves the pair to GEOS


def _tile_bounds(a: tuple, polygons: np.ndarray):
    """``bounds`` for :func:`_within` of convex polygons (the query's :func:`_disks`
    ``a``, and ``polygons``): apart by at most the room between their inner disks, at
    least that between their outer ones (compared squared)."""

    def bounds(qi, gi, low, high):
        used, gi = np.unique(gi, return_inverse=True)
        b = _disks(*_vertex_arrays(polygons[used]))
        apart = np.take(a[0], qi, axis=0) - np.take(b[0], gi, axis=0)
        return _nearer(apart, a[1][qi] + b[1][gi], low, high, a[2][qi] + b[2][gi])

    return bounds


def _piece_bounds(disks: tuple, segs: np.ndarray):
    """``bounds`` for :func:`_within` of the wall pieces (their ends ``segs``, (n, 2, 2);
    the query) and convex polygons (their :func:`_disks`): the distance from the inner
    point to the piece less the inner radius, less the outer one."""

    def bounds(qi, gi, low, high):
        p = np.take(disks[0], gi, axis=0)
        ends = np.take(segs, qi, axis=0)
        a, b = ends[:, 0], ends[:, 1]
        ab = b - a
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.clip(((p - a) * ab).sum(axis=1) / (ab * ab).sum(axis=1), 0.0, 1.0)
        t = np.where(np.isfinite(t), t, 0.0)  # a point: its one end
        return _nearer(a + t[:, None] * ab - p, disks[1][gi], low, high, disks[2][gi])

    return bounds


def _nearer(apart, inner, low, high, outer):
    """Where the vector ``apart`` (k, 2) between two disks' centres (or a centre and its
    nearest point of a piece) is no longer than ``low`` plus the ``inner`` radii, and
    where it is longer than ``high`` plus the ``outer`` ones: squared, no roots."""
    length2 = apart[:, 0] * apart[:, 0] + apart[:, 1] * apart[:, 1]
    reach = low + inner
    return (reach >= 0) & (length2 <= reach * reach), length2 > (high + outer) ** 2


def _cut_convex_in_parts(whole, grown, rows, pairs, size, gap, padded):
    """:func:`_cut_convex` of ``rows`` (the same arguments and answer), the rows cut in
    consecutive parts side by side (whole-array NumPy and GEOS let go of the GIL): a
    tile's cut reads only its own pairs, which keep their order within its part."""
    parts = min(usable_cores(), len(rows) // _ROWS_PER_PART)
    if parts < 2:
        return _cut_convex(whole, grown, rows, pairs, size, gap, padded)
    pair_tile, pool, obstacle, keep, d = pairs
    slot = np.full(len(whole), -1)
    slot[rows] = np.arange(len(rows))
    at = slot[pair_tile]
    # runs of rows holding about equal numbers of pairs
    ordered = np.sort(at)
    edges = np.unique(np.r_[0, ordered[len(at) * np.arange(1, parts) // parts], len(rows)])
    part_of = np.searchsorted(edges, at, side="right") - 1

    def part(k):
        mine = part_of == k
        own = (pair_tile[mine], pool, obstacle[mine], keep[mine], d[mine])
        return _cut_convex(whole, grown, rows[edges[k] : edges[k + 1]], own, size, gap, padded)

    done = side_by_side(*(functools.partial(part, k) for k in range(len(edges) - 1)))
    width = max(poly.shape[1] for _, _, poly, _ in done)  # padded rows: zeros past the count
    return (
        np.concatenate([cut for cut, _, _, _ in done]),
        np.concatenate([ok for _, ok, _, _ in done]),
        np.concatenate(
            [np.pad(poly, ((0, 0), (0, width - poly.shape[1]), (0, 0))) for _, _, poly, _ in done]
        ),
        np.concatenate([count for _, _, _, count in done]),
    )


def _cut_convex(whole, grown, rows, pairs, size, gap, padded):
    """The candidates ``rows`` cut as convex polygons: each one's grown outline within
    the frame, less a half-plane for each group of obstacles (module docstring).
    ``grown``: the grown outlines' vertex arrays and counts (:func:`_vertex_arrays`).

    ``pairs``: ``pair_tile``, ``pool``, ``obstacle``, ``keep``, ``d``: per (candidate,
    obstacle) pair, the candidate (an index into ``whole``/``grown``), the obstacle (an
    index into ``pool``, convex geometries), the distance to keep from it and the
    distance between them.  ``padded``: ``near`` (the tiles of ``whole``) and
    (``pool_row``, ``pool_xy``, ``by_row``, ``wide``, ``wide_xy``): each obstacle's row
    (-1 where it is never read), the rows' first vertices (:func:`_padded`, at the
    narrow width that the whole tiles and the pieces fit) and geometries, and the rows
    with more vertices and all of theirs.  Returns the cut outlines of ``rows``, whether
    each is one polygon that grew and keeps every distance (else the tile stays whole),
    and their vertex arrays and counts."""
    nr = len(rows)
    slot = np.full(len(whole), -1)
    slot[rows] = np.arange(nr)
    pair_tile, pool, obstacle, keep, d = pairs
    # the most constraining obstacle first: the least room between it and the tile
    order = np.argsort(d - keep, kind="stable")
    # then by candidate, stable (as np.lexsort; a key of 16 bits sorts by radix)
    key = pair_tile[order].astype(np.uint16 if len(whole) <= 1 << 16 else np.int64)
    order = order[np.argsort(key, kind="stable")]
    pair_tile, obstacle, keep, d = (x[order] for x in (pair_tile, obstacle, keep, d))
    count = grown[1][rows]
    poly = grown[0][rows, : int(count.max(initial=0))]
    w, h = size
    frame_n = np.array([[-1.0, 0.0], [0.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
    frame_c = np.array([-0.5 * gap, -0.5 * gap, w - 0.5 * gap, h - 0.5 * gap])
    for k in range(4):
        # only the outlines that reach beyond this side (the others it leaves as they are)
        s = poly[..., 0] * frame_n[k, 0] + poly[..., 1] * frame_n[k, 1] - frame_c[k]
        sub = np.flatnonzero(((s > 0) & (np.arange(poly.shape[1]) < count[:, None])).any(axis=1))
        if len(sub):
            poly, count = _clip_rows(
                poly, count, sub, np.tile(frame_n[k], (len(sub), 1)), np.full(len(sub), frame_c[k])
            )
    near, (pool_row, pool_xy, by_row, wide, wide_xy) = padded
    tiles = _Padded(pool_xy[pool_row[near[rows]]], whole[rows])
    obstacles = _Padded(pool_xy, by_row, pool_row[obstacle], wide, wide_xy)
    pt = slot[pair_tile]
    left = np.ones(len(pt), dtype=bool)
    while left.any():
        idx = np.flatnonzero(left)
        # each tile's first pair left (the pairs go tile by tile)
        of = pt[idx]
        first = idx[np.flatnonzero(np.concatenate([[True], of[1:] != of[:-1]]))]
        r = pt[first]
        normal, offset = _best_plane(poly, count, r, first, tiles, obstacles, (d, keep))
        poly, count = _clip_rows(poly, count, r, normal, offset)
        # every obstacle of these tiles that the plane keeps clear of is done
        row = np.full(nr, -1)
        row[r] = np.arange(len(r))
        along = row[pt[idx]]
        least = obstacles.least(idx, np.take(normal, along, axis=0))
        clear = least - keep[idx] >= offset[along] - 1e-12
        left[idx[clear]] = False
        left[first] = False
    cut = _polygons(poly, count)
    ok = shapely.area(cut) > shapely.area(whole[rows]) * (1 + 1e-9)
    # each obstacle lies beyond a plane at its distance (or the room there was) from the
    # cut, found as it was cleared; one that touched the tile already is checked here:
    # the cut may touch it, not overlap it
    touching = np.flatnonzero(d <= 1e-9)
    if len(touching):
        bad = shapely.relate_pattern(cut[pt[touching]], pool[obstacle[touching]], "T********")
        ok[pt[touching[bad]]] = False
    return cut, ok, poly, count


class _Padded:
    """Convex geometries and their vertices, padded (:func:`_padded`), each read however
    many items (``ref``: the geometry of each item; default one item per geometry)
    share one.  ``xy``: every geometry's first ``narrow`` vertices (all of most);
    ``wide``: those with more (their indices), and ``wide_xy`` all of theirs."""

    def __init__(self, xy, geoms, ref=None, wide=None, wide_xy=None):
        self.ref = np.arange(len(geoms)) if ref is None else ref
        self.geoms = geoms
        self.xy = xy
        self.wide_xy = wide_xy
        self.slot = None
        if wide is not None and len(wide):
            self.slot = np.full(len(geoms), -1)
            self.slot[wide] = np.arange(len(wide))

    def geometry(self, which):
        """The geometries of items ``which``."""
        return self.geoms[self.ref[which]]

    def centre(self, which):
        """Centroids of items ``which``, (k, 2)."""
        return shapely.get_coordinates(shapely.centroid(self.geometry(which)))

    def least(self, which, normal):
        """Per item ``which[k]``, the least of normal[k]·vertex over its vertices
        (``normal`` (k, 2), or (k, K, 2): K candidates each)."""
        rows = self.ref[which]
        out = _least(np.take(self.xy, rows, axis=0), normal)  # (take: far quicker than [rows])
        if self.slot is not None:
            slot = self.slot[rows]
            wide = np.flatnonzero(slot >= 0)
            if len(wide):
                out[wide] = _least(self.wide_xy[slot[wide]], normal[wide])
        return out


def _least(p, normal):
    """Per row, the least of normal·vertex over the padded vertices ``p`` (k, V, 2), for
    ``normal`` (k, 2) or (k, K, 2)."""
    if normal.ndim == 2:
        proj = p[..., 0] * normal[:, None, 0] + p[..., 1] * normal[:, None, 1]
    else:
        proj = p[:, :, None, 0] * normal[:, None, :, 0] + p[:, :, None, 1] * normal[:, None, :, 1]
    # the least folded over the few vertex places (several times quicker than a
    # reduction along that short axis)
    out = proj[:, 0].copy()
    for v in range(1, proj.shape[1]):
        np.minimum(out, proj[:, v], out=out)
    return out


def _padded(poly, count):
    """Padded vertex arrays (as :func:`_vertex_arrays` gives them) with each row's spare
    places holding its first vertex: a least or greatest over a row is its vertices'."""
    spare = np.arange(poly.shape[1])[None, :] >= count[:, None]
    return np.where(spare[:, :, None], poly[:, :1], poly)


def _widened(xy, width):
    """Padded vertex arrays (:func:`_padded`) widened to ``width`` places."""
    if xy.shape[1] >= width:
        return xy
    return np.concatenate([xy, np.repeat(xy[:, :1], width - xy.shape[1], axis=1)], axis=1)


# turns of the line between a tile's and an obstacle's closest points tried as the
# normal of the plane between them (radians)
_TURNS = np.radians([0.0, -15.0, 15.0, -30.0, 30.0, -45.0, 45.0, -60.0, 60.0])


def _best_plane(poly, count, r, first, tiles, obstacles, pairs):
    """For each tile ``r`` and its most constraining obstacle left (pair ``first``), the
    plane that keeps the most of the tile's outline so far, among those that hold the
    whole tile and keep the obstacle at its distance: normal to the line between their
    closest points, or turned from it by up to 60 degrees."""
    d, keep = pairs
    # the closest points of each pair: the tile's a, the obstacle's b
    ends = shapely.get_coordinates(
        elementwise(shapely.shortest_line, tiles.geometry(r), obstacles.geometry(first))
    )
    a, b = ends[0::2], ends[1::2]
    direction = b - a
    # touching (no gap): the direction between the centres, the plane the tile's own
    # support line that way (a square's shared side)
    flat = d[first] <= 1e-9
    if flat.any():
        f = np.flatnonzero(flat)
        direction[f] = obstacles.centre(first[f]) - tiles.centre(r[f])
    base = direction / np.maximum(np.hypot(*direction.T), 1e-300)[:, None]
    c, s = np.cos(_TURNS), np.sin(_TURNS)
    normal = np.stack(
        [base[:, None, 0] * c - base[:, None, 1] * s, base[:, None, 0] * s + base[:, None, 1] * c], axis=-1
    )
    # each candidate at the obstacle's distance, kept if the whole tile is on its side
    offset = obstacles.least(first, normal) - keep[first, None]
    high = -tiles.least(r, -normal)
    usable = high <= offset + 1e-12
    # the line between the closest points always holds (at the room there is)
    offset[:, 0] = np.einsum("ij,ij->i", base, b) - np.minimum(keep[first], d[first])
    offset[flat, 0] = high[flat, 0]
    usable[:, 0] = True
    # the area each usable candidate keeps (the first always: it wins ties)
    row, k = np.nonzero(usable)
    flat = row * normal.shape[1] + k
    p, n = _clip_arrays(
        np.take(poly, r[row], axis=0),
        count[r[row]],
        np.take(normal.reshape(-1, 2), flat, axis=0),
        offset[row, k],
    )
    area = np.full(usable.shape, -np.inf)
    area[row, k] = _area(p, n)
    best = np.argmax(area, axis=1)
    pick = np.arange(len(r))
    return np.take(normal.reshape(-1, 2), pick * normal.shape[1] + best, axis=0), offset[pick, best]


def _vertex_arrays(polygons):
    """(n, V, 2) vertices of each polygon's exterior (less the closing one), padded, and
    their counts."""
    coords, index = shapely.get_coordinates(exterior_rings(polygons), return_index=True)
    begin = np.searchsorted(index, np.arange(len(polygons)))
    count = np.diff(np.append(begin, len(index))) - 1
    poly = np.zeros((len(polygons), int(count.max()) if len(polygons) else 0, 2))
    pos = np.arange(len(index)) - begin[index]
    open_ = pos < count[index]
    flat = (index * poly.shape[1] + pos)[open_]  # placed through flat indices (quicker)
    poly.reshape(-1, 2)[:, 0][flat] = coords[open_, 0]
    poly.reshape(-1, 2)[:, 1][flat] = coords[open_, 1]
    return poly, count


def _polygons(poly, count):
    """Shapely polygons of padded vertex arrays (empty where fewer than 3 vertices)."""
    out = np.array([shapely.Polygon()] * len(poly), dtype=object)
    k = np.flatnonzero(count >= 3)
    if len(k):
        ring = np.concatenate([poly[k], np.zeros((len(k), 1, 2))], axis=1)
        ring[np.arange(len(k)), count[k]] = poly[k, 0]  # closed
        closed = np.arange(ring.shape[1])[None, :] <= count[k, None]
        idx = np.broadcast_to(np.arange(len(k))[:, None], closed.shape)[closed]
        out[k] = shapely.polygons(shapely.linearrings(ring[closed], indices=idx))
    return out


def _area(poly, count):
    """Areas of padded vertex arrays (shoelace)."""
    v = poly.shape[1]
    j = np.arange(v)[None, :]
    nxt = np.where(j + 1 < count[:, None], j + 1, 0)
    q = np.take_along_axis(poly, nxt[:, :, None], axis=1)
    cross = poly[..., 0] * q[..., 1] - q[..., 0] * poly[..., 1]
    return 0.5 * np.abs(np.where(j < count[:, None], cross, 0.0).sum(axis=1))


def _clip_arrays(p, c, normal, offset):
    """Padded vertex arrays ``p`` (``c`` vertices each) clipped to normal·x <= offset
    (Sutherland-Hodgman): the clipped arrays and their counts."""
    v = p.shape[1]
    j = np.arange(v)[None, :]
    valid = j < c[:, None]
    # each vertex's next one round its ring (the rows with spare places closed by hand)
    short = np.flatnonzero((c < v) & (c > 0))
    q = np.roll(p, -1, axis=1)
    q[short, c[short] - 1] = p[short, 0]
    s = p[..., 0] * normal[:, None, 0] + p[..., 1] * normal[:, None, 1] - offset[:, None]
    sn = np.roll(s, -1, axis=1)
    sn[short, c[short] - 1] = s[short, 0]
    inside = valid & (s <= 0)
    cross = valid & (((s < 0) & (sn > 0)) | ((s > 0) & (sn < 0)))
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(cross, s / (s - sn), 0.0)
    x = p + t[:, :, None] * (q - p)
    # each edge gives its first vertex where inside, then its crossing where it crosses
    use = np.stack([inside, cross], axis=2).reshape(len(p), 2 * v)
    place = np.cumsum(use, axis=1)
    new_count = place[:, -1] if v else np.zeros(len(p), dtype=np.int64)
    width = int(new_count.max()) if len(p) else 0
    # gathered and placed through flat indices (quicker than fancy indexing by pairs)
    at = np.flatnonzero(use)
    edge = at // 2  # the edge (row * v + vertex) each comes from
    vals = np.where(
        (at % 2 == 0)[:, None],
        np.take(p.reshape(-1, 2), edge, axis=0),
        np.take(x.reshape(-1, 2), edge, axis=0),
    )
    dest = (at // (2 * v)) * width + np.take(place, at) - 1
    out = np.zeros(len(p) * width * 2)
    out[2 * dest] = vals[:, 0]
    out[2 * dest + 1] = vals[:, 1]
    return out.reshape(len(p), width, 2), new_count


def _clip_rows(poly, count, sub, normal, offset):
    """Rows ``sub`` of ``poly`` (each ``count`` vertices) clipped to normal·x <= offset."""
    packed, new_count = _clip_arrays(np.take(poly, sub, axis=0), count[sub], normal, offset)
    width = max(packed.shape[1], poly.shape[1])
    if width > poly.shape[1]:
        poly = np.concatenate([poly, np.zeros((len(poly), width - poly.shape[1], 2))], axis=1)
    poly[sub] = 0.0
    poly[sub, : packed.shape[1]] = packed
    count = count.copy()
    count[sub] = new_count
    return poly, count


def _cut_exact(
    polygons,
    walls: np.ndarray,
    gap: float,
    spacing: float,
    enlarge: float = CUT_ENLARGE,
    reach: float = CUT_REACH,
) -> tuple[list, int]:
    """:func:`cut_to_walls` by shapely differences (module docstring; the arguments and
    the answer are :func:`cut_to_walls`'s)."""
    out, geoms_all, present = _tile_array(polygons)
    h, w = walls.shape
    lines = _merged_lines(walls)
    if len(lines) == 0 or len(present) == 0:
        return out, 0
    geoms = geoms_all[present]
    # the lines query the tiles rather than the other way round: GEOS then prepares each
    # long line once instead of walking it for every tile
    near = np.unique(shapely.STRtree(geoms).query(lines, predicate="dwithin", distance=reach * spacing)[1])
    if len(near) == 0:
        return out, 0
    grown = _grown(geoms[near], enlarge)
    # the margin also keeps a hair's width between tiles when the gap is 0 (shapely's
    # overlay was measured up to 6e-5 px off without it)
    full = gap + _MARGIN
    half = 0.5 * gap + _MARGIN
    # cut in turns: two tiles whose grown outlines come within the gap never share one
    grown_tree = shapely.STRtree(grown)
    a, b = grown_tree.query(grown, predicate="dwithin", distance=full)
    turn = _turns(np.stack([a[a < b], b[a < b]], axis=1), len(near))
    # a cut tile lies within its grown outline, so only a tile with a later partner in
    # that graph can reach a later turn's tiles
    later = np.zeros(len(near), dtype=bool)
    later[a[turn[b] > turn[a]]] = True
    wall_margin = _margin_pieces(lines, half)
    frame = shapely.box(0.5 * gap, 0.5 * gap, w - 0.5 * gap, h - 0.5 * gap)
    padded = elementwise(
        shapely.buffer, geoms_all, distance=full, join_style="mitre"
    )  # each tile's G-wide margin
    tile_tree = shapely.STRtree(padded)
    grew = 0
    for t in range(turn.max() + 1):
        members = np.flatnonzero(turn == t)
        tiles = present[near[members]]
        whole = np.array([out[k] for k in tiles], dtype=object)
        cand = shapely.intersection(grown[members], frame)
        # less each other tile near it grown by G (one vectorised difference per neighbour
        # rank), then the walls near it: taken in this order each difference meets a
        # simpler outline
        ci, oi = tile_tree.query(cand, predicate="intersects")
        other = oi != tiles[ci]
        _subtract_by_rank(cand, ci[other], padded[oi[other]])
        # the walls: the pieces of their G/2-wide margin that reach each tile
        wi, wt = shapely.STRtree(cand).query(wall_margin, predicate="intersects")
        _subtract_by_rank(cand, wt, wall_margin[wi])
        cut = _robust(shapely.union, _piece_holding(cand, whole), whole)
        bigger = shapely.area(cut) > shapely.area(whole) * (1 + 1e-9)
        bigger &= shapely.get_type_id(cut) == 3  # one polygon (a failed step gives none)
        keep = np.flatnonzero(bigger)
        keep = keep[~straddling_tiles(list(cut[keep]), walls)]
        cut[keep] = _started_as(cut[keep], whole[keep])
        for k, g in zip(tiles[keep], cut[keep], strict=True):
            out[k] = g
        seen = keep[later[members[keep]]]
        if len(seen):  # a cut tile's margin grows with it
            padded[tiles[seen]] = elementwise(shapely.buffer, cut[seen], distance=full, join_style="mitre")
            tile_tree = shapely.STRtree(padded)
        grew += len(keep)
    return out, grew


def _subtract_by_rank(cand: np.ndarray, target: np.ndarray, parts: np.ndarray) -> None:
    """cand[target[k]] less parts[k] for every k, in place: one vectorised difference per
    rank (a target's first part, its second, ...), each target's parts in the order given."""
    order = np.argsort(target, kind="stable")
    target, parts = target[order], parts[order]
    rank = np.arange(len(target)) - np.searchsorted(target, target)
    for r in range(rank.max() + 1 if len(target) else 0):
        at = rank == r
        cand[target[at]] = _robust(shapely.difference, cand[target[at]], parts[at])


def _robust(operation, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``operation(a, b)`` element by element; where GEOS gives up on a pair (a topology
    exception from nearly coincident edges) the result is an empty geometry, so that
    tile stays whole."""
    try:
        return elementwise(operation, a, b)
    except shapely.errors.GEOSException:
        out = np.empty(len(a), dtype=object)
        for k in range(len(a)):
            try:
                out[k] = operation(a[k], b[k])
            except shapely.errors.GEOSException:
                out[k] = shapely.Polygon()
        return out


def _margin_pieces(lines: np.ndarray, distance: float, length: int = _RUN) -> np.ndarray:
    """The lines' margin of ``distance`` in pieces: each line cut into runs of at most
    ``length`` vertices (straight stretches between turns), each run grown by ``distance`` (mitred joins, square caps).  The
    lines turn only by right angles, where a square cap meets the next run as a mitred
    join would, so the pieces cover the same ground as the whole lines grown."""
    is_point = shapely.get_type_id(lines) == 0
    coords, line = shapely.get_coordinates(lines[~is_point], return_index=True)
    pos = np.arange(len(line)) - np.searchsorted(line, line)  # each vertex's place on its line
    end = np.append(line[1:] != line[:-1], True)
    run = pos // length
    joint = (pos % length == 0) & (pos > 0)  # a vertex that ends one run and starts the next
    first = ~(joint & end)  # a line's last vertex starts no run
    key = np.concatenate([line[first] * len(line) + run[first], line[joint] * len(line) + run[joint] - 1])
    at = np.concatenate([np.flatnonzero(first), np.flatnonzero(joint)])
    order = np.lexsort((at, key))
    _, runs = np.unique(key[order], return_inverse=True)
    pieces = shapely.linestrings(coords[at[order]], indices=runs)
    pieces = np.concatenate([pieces, lines[is_point]])
    return elementwise(shapely.buffer, pieces, distance=distance, join_style="mitre", cap_style="square")


def _started_as(cut: np.ndarray, whole: np.ndarray) -> np.ndarray:
    """Each cut tile's outline begun at its vertex nearest the whole tile's first one, so
    that where it starts follows the tile rather than the order of the overlays (tiles
    with holes are left as they are)."""
    out = cut.copy()
    plain = np.flatnonzero(shapely.get_num_interior_rings(cut) == 0)
    if len(plain) == 0:
        return out
    first = shapely.get_coordinates(shapely.get_point(shapely.get_exterior_ring(whole[plain]), 0))
    out[plain] = _polygons(*_started_at(*_vertex_arrays(cut[plain]), first))
    return out


def _started_at(poly: np.ndarray, count: np.ndarray, first: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Padded vertex arrays (:func:`_vertex_arrays`) each rolled to begin at its vertex
    nearest the point ``first`` (k, 2), the first such where several are."""
    spare = np.arange(poly.shape[1])[None, :] >= count[:, None]
    d = ((poly - first[:, None, :]) ** 2).sum(axis=2)
    d[spare] = np.inf
    start = np.argmin(d, axis=1)
    pos = np.arange(poly.shape[1])[None, :]
    src = (pos + start[:, None]) % np.maximum(count, 1)[:, None]
    out = np.take_along_axis(poly, src[:, :, None], axis=1)
    out[spare] = 0.0
    return out, count


def _piece_holding(cand: np.ndarray, whole: np.ndarray) -> np.ndarray:
    """Of each candidate, the piece that holds a point inside the whole tile: what was
    taken away comes at most ``_MARGIN`` into the whole tile, so one piece holds all of
    it but that margin."""
    parts, index = shapely.get_parts(cand, return_index=True)
    out = np.array([shapely.Polygon()] * len(cand), dtype=object)
    if len(parts) == 0:
        return out
    inside = shapely.get_coordinates(shapely.point_on_surface(whole))
    hit = shapely.contains_xy(parts, inside[index, 0], inside[index, 1])
    out[index[hit]] = parts[hit]
    return out


__all__ = ["CUT_ENLARGE", "CUT_REACH", "EXACT_TILES", "wall_lines", "cut_to_walls"]
