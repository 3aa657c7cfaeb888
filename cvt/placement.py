"""Placing one element in each cell (paper §3.4): the step that turns a CVT into a
compact distribution of discrete elements.

The rule
--------
Each cell is the set of pixels that carry its label in the final label raster.  Its
*contour* is the set of unit pixel edges between one of its pixels and a pixel that is
not (another cell, outside the region, or outside the raster); the contour lies half-way
between the cell's last pixel centres and the first foreign ones.  The element of site i
is the chosen shape's outline (:func:`cvt.shapes.unit_outline`), rotated by the site's
angle θ_i, centred at the site p_i, at the largest size t_i whose element contains no
*contour sample* of its cell in its interior::

    t_i = min over contour samples q of cell i of  ρ(R(-θ_i)(q - p_i))

where ρ is the gauge of the element's own unit ball (``cvt.metrics``; the inscribed
128-gon of a curved outline lies inside that ball, so the polygon obeys the rule too).
The samples are the midpoint of every contour edge, one per pair of 4-neighbour pixels
with different labels.  With them an element follows the raster cell exactly where the
contour is straight (a square in a square cell touches all four sides: coverage 1 on a
lattice whose cell side is a whole number of pixels), and it can cross the contour only
between two samples one pixel apart: by at most half a pixel for a square's corner and
√3/2 px for a triangle's 60° tip, never by a whole pixel (tests check both bounds).  Adding
the edges' end points (pixel corners) as samples would halve the crossing but lose up to
0.7 px of reach on slanted contours: measured on 256 relaxed cells of ~16 px, 0.5 % of
the coverage for squares and rectangles, 3-4 % for ellipses and circles, 6 % for
triangles.  We prefer the coverage.

Grout: ``gap`` G (pixels) is the width of the joint between two neighbouring elements.
Each element keeps G/2 clear of its contour, measured along the normal of its own edge
that faces the sample: polygons use the mitred offset ``max_k (f_k·v − G/2·|f_k|)``
(f_k = R(θ)n_k/h_k, the facets of :func:`cvt.metrics.compile_sites`), so a square or a
rectangle loses exactly G/2 per side in a straight-walled cell; ellipses use the
first-order distance ``ρ(v) − G/2·|∇ρ(v)|`` (exact for circles).  The element stays a
scaled copy of the shape; a cell too small for the gap gets no element.

Skipped sites (``None`` in the returned list): a site whose cell has no pixel, a site
whose own pixel belongs to another cell or lies outside the region (its element would
grow into a foreign cell), and a cell whose contour passes through the site (size 0).
:func:`placement_sizes` returns the sizes, so callers can count them.

Where this departs from the paper
---------------------------------
The paper "extract[s] the contour of every Voronoi region and adjust[s] the size and
direction based on the contour information" (§3.4, Figure 13) without giving the fit.
We keep the direction the field gave the site (so a direction field reads the same in the
elements as in the cells) and the site as the element's centre (a CVT site is its cell's
centroid), and take the largest inscribed scale.  Fitting the angle or moving the centre
per cell might cover more (not measured here); it would also bend the direction field
and loosen the link between a site and its element.  The density's size factor needs no
term of its own: the cell already reflects it.

Cost: one pass over the raster (``np.nonzero`` on neighbour differences), one gauge per
sample and ``np.minimum.at``; no Python loop over pixels or sites.  About 40 ms for
4000 cells on 1024² here.

Which element goes in which CVT: :func:`element_for` gives the metric's own ball
(``NATURAL_ELEMENT``) by default.  The l1 ball is the square turned by 45°, so squares
placed in an l1 CVT (by default or by choice) are turned by 45° to match its diamond
cells; every other shape keeps the site's angle as it is.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import InputError
from .metrics import Metric, compile_sites
from .pixels import pixel_index
from .problem import MAX_SIDE, Grid, in_own_cell
from .shapes import check_shape, element_ball, element_polygons, shape_record
from .validate import one_of, real_number


def parse_gap(value, name: str = "gap") -> float:
    """The grout gap in pixels: a finite number from 0 to the largest raster side."""
    return real_number(value, name, minimum=0.0, maximum=float(MAX_SIDE))


def element_for(metric: Metric, element: str | None = None) -> tuple[str, float]:
    """The element shape for cells of ``metric`` and the turn (radians) to add to every
    site's angle: the metric's own ball unless ``element`` names another shape; squares
    in an l1 CVT are turned by 45° (the l1 ball is a diamond)."""
    shape = metric.natural_element if element is None else check_shape(element)
    turn = math.pi / 4 if (metric.name == "l1" and shape == "square") else 0.0
    return shape, turn


def contour_samples(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Midpoints of the cell contours: ``(owner, x, y)`` with one entry per (cell, edge).

    Every pair of 4-neighbour pixels with different labels shares a unit edge; its
    midpoint is a sample of the contour of each of the two cells (outside labels, -1,
    own nothing).  The raster is padded with -1 so that its border is contour too."""
    h, w = labels.shape
    pad = np.full((h + 2, w + 2), -1, dtype=np.int32)
    pad[1:-1, 1:-1] = labels
    # horizontal pairs: pixels (r-1, c-1) | (r-1, c), shared edge x = c, y in [r-1, r]
    r, c = np.nonzero(pad[:, :-1] != pad[:, 1:])
    left, right = pad[r, c], pad[r, c + 1]
    hx, hy = c.astype(np.float64), r - 0.5
    # vertical pairs: pixels (r-1, c-1) over (r, c-1), shared edge y = r, x in [c-1, c]
    r2, c2 = np.nonzero(pad[:-1, :] != pad[1:, :])
    top, bottom = pad[r2, c2], pad[r2 + 1, c2]
    vx, vy = c2 - 0.5, r2.astype(np.float64)
    owner = np.concatenate([left, right, top, bottom])
    x = np.concatenate([hx, hx, vx, vx])
    y = np.concatenate([hy, hy, vy, vy])
    keep = owner >= 0
    return owner[keep], x[keep], y[keep]


class _Gauge:
    """The reach of contour samples from element centres (the rule of this module), one
    compiled ball per cell, and how far a move of the centre can change it.

    ``lipschitz`` (per cell) bounds |reach(v) - reach(v')| by ``lipschitz``·|v - v'| +
    ``drop``: a polygon's reach is a max of linear functions f_k·v - G/2·|f_k|, so its
    constant is max_k |f_k|; an ellipse's ρ has the square root of Q's larger eigenvalue,
    and its grout term G/2·|∇ρ| lies between 0 and G/2 times that (``drop``)."""

    def __init__(self, coef, half: float):
        self.kind, self.half = coef.kind, half
        if coef.kind == "polygon":
            f = coef.facets  # (N, K, 2): f_k = R(θ) n_k / h_k, |f_k| = 1 / h_k
            self.fx = [np.ascontiguousarray(f[:, k, 0]) for k in range(f.shape[1])]
            self.fy = [np.ascontiguousarray(f[:, k, 1]) for k in range(f.shape[1])]
            self.slack = half * np.hypot(f[0, :, 0], f[0, :, 1])  # same |f_k| for every site
            lip = np.hypot(f[..., 0], f[..., 1]).max(axis=1)
            self.drop = np.zeros(len(lip))
        else:
            q = coef.quad
            self.q = [np.ascontiguousarray(q[:, j]) for j in range(3)]
            lip = np.sqrt(0.5 * (q[:, 0] + q[:, 2]) + np.hypot(0.5 * (q[:, 0] - q[:, 2]), q[:, 1]))
            self.drop = half * lip * (1 + 1e-9)
        self.lipschitz = lip * (1 + 1e-9)  # rounding of the bound itself

    def reach(self, owner, vx, vy):
        """Per sample (``owner`` its ball, v = sample - centre), the element size at which
        the element (grout G/2 kept clear) reaches the sample."""
        if self.kind == "polygon":
            out = None
            for fx, fy, s in zip(self.fx, self.fy, self.slack, strict=True):  # one facet at a time: no (S, K) temporaries
                v = fx[owner]
                v *= vx
                t = fy[owner]
                t *= vy
                v += t
                v -= s
                out = v if out is None else np.maximum(out, v, out=out)
            return out
        q0, q1, q2 = (q[owner] for q in self.q)
        gx = q0 * vx + q1 * vy  # Q v = ρ ∇ρ
        gy = q1 * vx + q2 * vy
        rho = np.sqrt(np.maximum(vx * gx + vy * gy, 0.0))
        if self.half <= 0:
            return rho
        with np.errstate(divide="ignore", invalid="ignore"):
            grad = np.where(rho > 0, np.hypot(gx, gy) / rho, 0.0)
        return rho - self.half * grad


def placement_sizes(labels, sites, angles, shape: str, aspect, gap: float = 0.0) -> np.ndarray:
    """(N,) element size per site by the rule of this module; 0 where the site is skipped.

    Size 1 is the element's unit ball (``cvt.shapes``: square side 2, circle radius 1,
    ...)."""
    check_shape(shape)
    gap = parse_gap(gap)
    labels = np.asarray(labels)
    sites = np.asarray(sites, dtype=np.float64).reshape(-1, 2)
    n = len(sites)
    angles = np.zeros(n) if angles is None else np.broadcast_to(np.asarray(angles, np.float64), (n,))
    if n == 0:
        return np.zeros(0)
    ball = element_ball(shape, aspect)
    coef = compile_sites(ball, sites, angles, None)
    owner, qx, qy = contour_samples(labels)
    reach = _Gauge(coef, 0.5 * gap).reach(owner, qx - sites[owner, 0], qy - sites[owner, 1])
    sizes = np.full(n, np.inf)
    np.minimum.at(sizes, owner, reach)

    # a site must sit in a pixel of its own cell, or its element would grow into another
    ok = in_own_cell(labels, sites) & np.isfinite(sizes) & (sizes > 0)
    return np.where(ok, sizes, 0.0)


FITS = ("site", "centre")
_FIT_STEPS = (0.3, 0.15, 0.075, 0.0375)  # pattern-search steps, as fractions of the size
_FIT_MOVES = np.array(
    [[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]], dtype=np.float64
)
_FIT_REPEATS = 3  # tries of the 8 moves per step, while the cell still grows
# Which contour samples stay in play: those whose reach is within this many steps (times
# the gauge's Lipschitz constant) of their cell's smallest, per step size and per repeat.
# Only the speed depends on them: a trial that the samples in play cannot vouch for is
# evaluated over all of its cell's samples.
_KEEP_STEPS_LEVEL, _KEEP_STEPS_REPEAT = 6.0, 2.5


class _SampleSet:
    """Contour samples grouped by cell: coordinates ``x``, ``y``; ``cell``, the index of
    the sample's cell in the fit's list of cells (non-decreasing); ``pos``, the index of
    that cell in ``cells``, the cells the set serves (each holds at least one sample)."""

    def __init__(self, x, y, cell, cells, pos=None):
        self.x, self.y, self.cell, self.cells = x, y, cell, cells
        self.pos = cell if pos is None else pos
        self.counts = np.bincount(self.pos, minlength=len(cells))
        self.offsets = np.cumsum(self.counts) - self.counts

    def take(self, keep, cells=None) -> _SampleSet:
        """The samples where ``keep``, serving ``cells`` (default: the same cells)."""
        if cells is None:
            return _SampleSet(self.x[keep], self.y[keep], self.cell[keep], self.cells, self.pos[keep])
        rank = np.full(len(self.cells), -1)
        rank[cells] = np.arange(len(cells))
        cell = self.cell[keep]
        return _SampleSet(self.x[keep], self.y[keep], cell, cells, rank[cell])

    def cells_at(self, ids) -> _SampleSet:
        """All samples of cells ``ids`` (indices into ``cells``), serving those."""
        cnt = self.counts[ids]
        offs = np.cumsum(cnt) - cnt
        idx = np.repeat(self.offsets[ids] - offs, cnt) + np.arange(int(cnt.sum()))
        pos = np.repeat(np.arange(len(ids)), cnt)
        return _SampleSet(self.x[idx], self.y[idx], self.cell[idx], ids, pos)

    def reach(self, gauge: _Gauge, centres):
        """Per sample its reach from its cell's centre (``centres``: one per served cell),
        and per served cell the smallest."""
        r = gauge.reach(self.cell, self.x - centres[self.pos, 0], self.y - centres[self.pos, 1])
        return np.minimum.reduceat(r, self.offsets), r

    def prune(self, r, limit):
        """The samples whose reach ``r`` is at most ``limit`` (per served cell) with their
        reaches, and per served cell the smallest reach of those dropped (inf: none)."""
        keep = r <= limit[self.pos]
        dropped = np.minimum.reduceat(np.where(keep, np.inf, r), self.offsets)
        return self.take(keep), r[keep], dropped


def _fit_search(labels, cells, full: _SampleSet, gauge: _Gauge, centres):
    """The pattern search of :func:`fit_centres` from ``centres`` (one per cell of
    ``cells``, ``full`` their samples): the centres and sizes it ends at.

    Each trial needs the smallest reach over its cell's samples, but far samples cannot
    be the smallest: the reach changes by at most ``gauge.lipschitz``·|move| +
    ``gauge.drop``, so a sample dropped at centre c with reach T reaches at least
    T - L·|x - c| - drop from any x.  The search keeps in play the samples near the
    smallest (chosen per step size, then per repeat) and, per cell, that bound on the
    others.  A trial that would be accepted while the smallest reach in play is above the
    bound is evaluated over all of its cell's samples; a rejected trial needs no check
    (the smallest over all samples is no larger).  Sizes and centres are therefore those
    of a search over all samples, bit for bit."""
    h, w = labels.shape
    every = np.arange(len(cells))
    lip, drop = gauge.lipschitz, gauge.drop

    def sizes(ids, points, least):
        """Sizes at ``points`` in cells ``ids`` whose smallest reach there is ``least``."""
        x, y = points[:, 0], points[:, 1]
        own = (x >= 0) & (x < w) & (y >= 0) & (y < h) & (labels[pixel_index(points, w, h)] == cells[ids])
        return np.where(own, np.maximum(least, 0.0), 0.0)

    def bound(ids, points, floor_t, floor_c):
        """Least reach from ``points`` of samples dropped where ``floor_t`` was the least."""
        return floor_t - lip[ids] * np.hypot(points[:, 0] - floor_c[:, 0], points[:, 1] - floor_c[:, 1])

    least, r = full.reach(gauge, centres)
    best = sizes(every, centres, least)
    level = full  # the samples in play for this step size
    level_t, level_c = np.full(len(cells), np.inf), centres.copy()  # bound on the others
    for frac in _FIT_STEPS:
        active = every
        for rep in range(_FIT_REPEATS):
            if len(active) == 0:
                break
            step = frac * np.maximum(best[active], 1.0)
            if rep == 0:  # every cell: choose this step size's samples
                if level is not full:
                    least, r = level.reach(gauge, centres)
                outside = bound(every, centres, level_t, level_c)
                level, r, dropped = level.prune(r, least + lip * (_KEEP_STEPS_LEVEL * step))
                level_t, level_c = np.minimum(dropped, outside), centres.copy()
                here = level
            else:
                on = np.zeros(len(cells), dtype=bool)
                on[active] = True
                here = level.take(on[level.cell], active)
                least, r = here.reach(gauge, centres[active])
            here, _, rep_t = here.prune(r, least + lip[active] * (_KEEP_STEPS_REPEAT * step))
            rep_c = centres[active]
            grew = np.zeros(len(active), dtype=bool)
            for move in _FIT_MOVES:
                trial = centres[active] + step[:, None] * move
                least_t = here.reach(gauge, trial)[0]
                size = sizes(active, trial, least_t)
                better = size > best[active] * (1 + 1e-9)
                if not better.any():
                    continue
                b = np.flatnonzero(better)
                a, pts = active[b], trial[b]
                vouched = np.minimum(
                    bound(a, pts, level_t[a], level_c[a]), bound(a, pts, rep_t[b], rep_c[b])
                ) - drop[a]
                unsure = b[least_t[b] > vouched - 1e-9 * (1.0 + np.abs(least_t[b]))]
                if len(unsure):
                    ids = active[unsure]
                    size[unsure] = sizes(ids, trial[unsure], full.cells_at(ids).reach(gauge, trial[unsure])[0])
                    better[unsure] = size[unsure] > best[ids] * (1 + 1e-9)
                a = active[better]
                centres[a], best[a] = trial[better], size[better]
                grew |= better
            active = active[grew]
    return centres, best


def _inscribed_centres(labels, shape: str, aspect, n: int) -> np.ndarray:
    """(n, 2) per cell, the centre of the pixel farthest from the cell's contour, by a
    distance transform in the element's own metric (chessboard for squares, Euclidean
    with the axes scaled by β for rectangles and ellipses, Euclidean otherwise; the
    site's angle is ignored: this is only a start for the search).  NaN for empty cells."""
    from scipy import ndimage

    h, w = labels.shape
    pad = np.pad(labels, 1, constant_values=-1)
    inner = (
        (labels >= 0)
        & (pad[:-2, 1:-1] == labels)
        & (pad[2:, 1:-1] == labels)
        & (pad[1:-1, :-2] == labels)
        & (pad[1:-1, 2:] == labels)
    )
    kind = shape_record(shape).distance
    if kind == "chessboard":
        dt = ndimage.distance_transform_cdt(inner, metric="chessboard").astype(np.float64)
    elif kind == "scaled":
        beta = element_ball(shape, aspect).aspect  # gauge ~ hypot(β·dx, dy/β)
        dt = ndimage.distance_transform_edt(inner, sampling=(1.0 / beta, beta))
    else:
        dt = ndimage.distance_transform_edt(inner)
    lab, d = labels.ravel(), dt.ravel()
    inside = np.flatnonzero(lab >= 0)
    best = np.full(n, -1.0)
    np.maximum.at(best, lab[inside], d[inside])
    top = inside[d[inside] == best[lab[inside]]]
    cells, first = np.unique(lab[top], return_index=True)
    out = np.full((n, 2), np.nan)
    i, j = np.divmod(top[first], w)
    out[cells] = np.stack([j + 0.5, i + 0.5], axis=1)
    return out


def fit_centres(labels, sites, angles, shape: str, aspect, gap: float = 0.0):
    """``fit="centre"``: move each element's centre inside its cell to the position
    where the same rule allows the largest size.

    A compass (pattern) search per cell, all cells at once, from two starts: the site, and
    the centre of the largest inscribed element found by a distance transform of the cell
    (:func:`_inscribed_centres`); each cell keeps the larger result.  The search tries 8
    moves of a step proportional to the element's size, keeps any that grows it, repeats
    while the cell grows (up to 3 times per step), then halves the step (0.3, 0.15,
    0.075, 0.0375 of the size); only the cells still growing are evaluated.  The centre
    must stay in a pixel of its own cell.  The angle is kept (the field's direction).
    Returns the centres (N, 2) and sizes (N,), 0 where skipped.  Relaxed linf CVT at
    1024², N = 4000, seed 1: square coverage 0.769 searching from the site alone, 0.780
    from both starts (circles 0.723 / 0.728, triangles 0.516 / 0.522), about 1-1.5 s CPU."""
    labels = np.asarray(labels)
    sites = np.asarray(sites, dtype=np.float64).reshape(-1, 2)
    n = len(sites)
    angles = np.zeros(n) if angles is None else np.broadcast_to(np.asarray(angles, np.float64), (n,))
    gap = parse_gap(gap)
    ball = element_ball(shape, aspect)
    owner, qx, qy = contour_samples(labels)
    order = np.argsort(owner, kind="stable")
    owner, qx, qy = owner[order], qx[order], qy[order]
    counts = np.bincount(owner, minlength=n)[:n]
    cells = np.flatnonzero(counts > 0)
    out_c, out_s = sites.copy(), np.zeros(n)
    if len(cells) == 0:
        return out_c, out_s
    full = _SampleSet(qx, qy, np.repeat(np.arange(len(cells)), counts[cells]), np.arange(len(cells)))
    del owner, order
    gauge = _Gauge(compile_sites(ball, sites[cells], angles[cells], None), 0.5 * gap)

    def search(start):
        return _fit_search(labels, cells, full, gauge, start[cells].copy())

    c1, s1 = search(sites)
    start2 = _inscribed_centres(labels, shape, aspect, n)
    start2[~np.isfinite(start2).all(axis=1)] = sites[~np.isfinite(start2).all(axis=1)]
    c2, s2 = search(start2)
    second = s2 > s1
    out_c[cells] = np.where(second[:, None], c2, c1)
    out_s[cells] = np.where(second, s2, s1)
    return out_c, out_s


def place_elements(
    labels, sites, angles, shape: str, aspect, grid: Grid, gap: float = 0.0, fit: str = "site"
) -> list:
    """One shapely Polygon per site (``None`` where the cell is empty or too small):
    the ``shape`` element, rotated by the site's angle, centred at the site, at the
    largest size that keeps it in its cell (see the module docstring for the rule).

    ``labels`` is the final (H, W) int32 label raster of these sites (-1 outside the
    region); ``aspect`` is β of rectangles and ellipses; ``gap`` the grout width in px;
    ``fit`` "site" (centred at the site, the default) or "centre" (:func:`fit_centres`)."""
    one_of(fit, "fit", FITS)
    labels = np.asarray(labels)
    if labels.shape != grid.shape:
        raise InputError(
            f"label raster is {labels.shape[1]}x{labels.shape[0]}, grid is {grid.width}x{grid.height}"
        )
    sites = np.asarray(sites, dtype=np.float64).reshape(-1, 2)
    n = len(sites)
    angles = np.zeros(n) if angles is None else np.broadcast_to(np.asarray(angles, np.float64), (n,))
    if fit == "centre":
        centres, sizes = fit_centres(labels, sites, angles, shape, aspect, gap)
    else:
        centres, sizes = sites, placement_sizes(labels, sites, angles, shape, aspect, gap)
    placed = np.flatnonzero(sizes > 0)
    out = np.full(n, None, dtype=object)
    if len(placed):
        out[placed] = element_polygons(shape, aspect, centres[placed], angles[placed], sizes[placed])
    return out.tolist()


__all__ = [
    "parse_gap",
    "element_for",
    "contour_samples",
    "placement_sizes",
    "FITS",
    "fit_centres",
    "place_elements",
]
