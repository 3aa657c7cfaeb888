"""The six distances of the paper, each defined once as a convex unit ball.

A metric is the gauge (Minkowski functional) of a convex, centrally placed unit ball B:
``gauge(v) = min{t >= 0 : v in t·B}``.

* Polygonal balls (``l1`` diamond, ``linf`` square, ``linf-axial`` rectangle,
  ``triangle``) are a list of edge normals ``n_k`` and offsets ``h_k`` (the ball is
  ``{v : n_k·v <= h_k}``), so ``gauge(v) = max_k n_k·v / h_k``.
* Elliptic balls (``l2`` circle, ``l2-axial`` ellipse) are two semi-axes ``a`` (along x)
  and ``b`` (along y): ``gauge(v) = sqrt((v_x/a)^2 + (v_y/b)^2)``.

Per site i, with angle θ_i and size factor s_i (paper §3.3), the distance from pixel
position x is ``d_i(x) = gauge(R(-θ_i)(x - p_i)) / s_i``.  :func:`compile_sites`
folds rotation and scale into per-site coefficients (rotated, scaled facet normals,
or a quadratic form) that every backend evaluates: NumPy directly, the OpenCL kernel as
buffers, the GL backend as the faces of its pyramids and cones.  No backend re-types a
shape of its own.

Coordinates are pixel units, x right, y down.  A positive angle turns the ball from +x
towards +y, i.e. clockwise on screen (the same sense as SVG's ``rotate()``).

Axial scale β (``aspect``), after the paper's §3.1.2-3.1.3:
``linf-axial``: ``max(β|x|, |y|/β)``, a rectangle 2/β wide and 2β high;
``l2-axial``: ``sqrt(β²x² + y²/β²)``, an ellipse with semi-axes 1/β and β.
``triangle`` (§3.1.4, the "equidistant line" distance): an equilateral triangle with its
centroid at the origin, one vertex pointing up on screen, where the distance of a point
on the triangle equals the centroid-to-vertex length (circumradius 1, side √3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .errors import InputError
from .validate import one_of, real_number

PAPER_METRICS = ("l2", "l1", "linf", "linf-axial", "l2-axial", "triangle")  # the paper's six
AXIAL_METRICS = ("linf-axial", "l2-axial")
DEFAULT_ASPECT = 0.5  # the paper's examples use β = 1/2
# β beyond this range makes elements thinner than 1/10000 of their length: no raster
# resolves them, and 1/β overflows long before β reaches the limits of a float
ASPECT_RANGE = (0.01, 100.0)


@dataclass(frozen=True)
class Shape:
    """An element shape: every fact about it, in one record (the table :data:`SHAPES`).

    Parameters
    ----------
    name : str
        The element's name (``--element``).
    metric : str
        The metric whose unit ball it is (implied by ``--element``).
    symmetry : int
        Rotational symmetry: turning it by 360°/k maps it onto itself (0: every turn).
    side_period : float
        The turn (radians) after which a side lies along the same line again (a mosaic's
        field is read modulo it).
    packing : float
        The densest packing of its translates, as a share of the plane (compaction's
        size caps under a density).
    curved : bool
        Whether its outline is curved (drawn as a 128-gon; SVG ellipses).
    axial : bool
        Whether the aspect β stretches it (rectangles, ellipses).
    sides : int
        A regular polygon's number of sides (0: not one), with its first vertex at
        ``phase`` degrees; such a shape's metric is built from it (circumradius 1).
    distance : str
        The distance transform that starts the fit's search in its cells:
        ``chessboard``, ``scaled`` (Euclidean with the axes scaled by β) or ``euclidean``.
    vertices : tuple of (x, y) or None
        The unit ball of any other convex polygon (the user's), counter-clockwise.
    compaction_rounds : int
        How many rounds ``ours-compact`` compacts by default.  Hexagons start further
        from their lattice than squares (fitted coverage 0.72 against 0.78, 1024²,
        N = 4000) and gain about a point per two rounds after the fourth: they take 12.
    """

    name: str
    metric: str
    symmetry: int
    side_period: float
    packing: float
    curved: bool = False
    axial: bool = False
    sides: int = 0
    phase: float = 0.0
    distance: str = "euclidean"
    vertices: tuple[tuple[float, float], ...] | None = None  # any convex polygon's unit ball
    compaction_rounds: int = 4


_HEX = math.pi / math.sqrt(12.0)  # circles' densest packing (hexagonal)
# The one table of shapes.  The paper's five pair with its metrics; a hexagon and an
# octagon are regular polygons whose metrics are their own unit balls.  A regular
# octagon's densest lattice packing is (4 + 4√2) / (5 + 4√2) of the plane.
SHAPES: dict[str, Shape] = {
    s.name: s
    for s in (
        Shape("square", "linf", 4, math.pi / 2, 1.0, distance="chessboard"),
        Shape("rectangle", "linf-axial", 2, math.pi, 1.0, axial=True, distance="scaled"),
        Shape("ellipse", "l2-axial", 2, math.pi, _HEX, curved=True, axial=True, distance="scaled"),
        Shape("triangle", "triangle", 3, math.pi / 3, 2.0 / 3.0),
        Shape("circle", "l2", 0, math.pi / 2, _HEX, curved=True),
        Shape("hexagon", "hexagon", 6, math.pi / 3, 1.0, sides=6, phase=90.0, compaction_rounds=12),
        Shape(
            "octagon",
            "octagon",
            8,
            math.pi / 4,
            (4 + 4 * math.sqrt(2)) / (5 + 4 * math.sqrt(2)),
            sides=8,
            phase=22.5,
        ),
    )
}
METRIC_NAMES = (*PAPER_METRICS, *(s.metric for s in SHAPES.values() if s.metric not in PAPER_METRICS))
# The element <-> metric table, read from the records.  The reverse, a metric's natural
# element, adds the l1 ball, a diamond, which is drawn as a square turned by 45°.
ELEMENT_METRIC = {s.name: s.metric for s in SHAPES.values()}
NATURAL_ELEMENT = {**{m: e for e, m in ELEMENT_METRIC.items()}, "l1": "square"}


@dataclass(frozen=True)
class Metric:
    """A convex unit ball: either polygonal (normals, offsets) or elliptic (semi-axes)."""

    name: str
    aspect: float
    kind: str  # "polygon" or "ellipse"
    normals: np.ndarray = field(default=None, repr=False)  # (K, 2) unit outward normals
    offsets: np.ndarray = field(default=None, repr=False)  # (K,) support values h_k > 0
    semi_axes: tuple[float, float] | None = None  # (a along x, b along y)

    # ----------------------------------------------------------------- geometry
    def gauge(self, v: np.ndarray) -> np.ndarray:
        """Gauge of vectors ``v`` of shape (..., 2) in the ball's own frame."""
        v = np.asarray(v, dtype=np.float64)
        if self.kind == "ellipse":
            a, b = self.semi_axes
            return np.hypot(v[..., 0] / a, v[..., 1] / b)
        return np.max((v @ self.normals.T) / self.offsets, axis=-1)

    def outline(self, segments: int = 256) -> np.ndarray:
        """Boundary of the unit ball as polygon vertices (M, 2), counter-clockwise in
        (x, y).  Exact for polygons; ``segments`` points for ellipses."""
        if self.kind == "ellipse":
            a, b = self.semi_axes
            t = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
            return np.stack([a * np.cos(t), b * np.sin(t)], axis=1)
        return _polygon_from_halfplanes(self.normals, self.offsets)

    @property
    def circumradius(self) -> float:
        """max |v| over the unit ball: gauge(v) >= |v| / circumradius."""
        if self.kind == "ellipse":
            return float(max(self.semi_axes))
        return float(np.max(np.hypot(*self.outline().T)))

    @property
    def inradius(self) -> float:
        """min over directions of the ball's extent: gauge(v) <= |v| / inradius."""
        if self.kind == "ellipse":
            return float(min(self.semi_axes))
        return float(np.min(self.offsets / np.hypot(*self.normals.T)))

    @property
    def natural_element(self) -> str:
        return NATURAL_ELEMENT.get(self.name, self.name)  # the user's polygon is its own element

    def cone(self, height: float) -> dict:
        """Paper Table 1: the cone or pyramid whose height over a base point equals the
        distance of that point from the apex's foot.  The base is the unit ball scaled
        by ``height``; its named dimensions are returned for comparison with Table 1."""
        base = self.outline() * height
        geom = {"height": float(height), "base": base}
        if self.kind == "ellipse":
            a, b = self.semi_axes
            geom.update(
                geometry="circular cone" if a == b else "elliptic cone",
                axis_x=2 * a * height,
                axis_y=2 * b * height,
            )
        else:
            sides = np.hypot(*(np.roll(base, -1, axis=0) - base).T)
            geom.update(
                geometry={3: "triangular pyramid"}.get(len(base), "pyramid"),
                sides=sides,
                width=float(np.ptp(base[:, 0])),
                depth=float(np.ptp(base[:, 1])),
            )
        return geom


def _polygon_from_halfplanes(normals: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Vertices of {v : n_k·v <= h_k} for normals sorted by angle (convex, bounded)."""
    order = np.argsort(np.arctan2(normals[:, 1], normals[:, 0]))
    n, h = normals[order], offsets[order]
    verts = []
    for k in range(len(n)):
        m = np.array([n[k], n[(k + 1) % len(n)]])
        verts.append(np.linalg.solve(m, [h[k], h[(k + 1) % len(n)]]))
    return np.array(verts)


def _regular_normals(angles_deg) -> np.ndarray:
    t = np.radians(np.asarray(angles_deg, dtype=np.float64))
    return np.stack([np.cos(t), np.sin(t)], axis=1)


def make_metric(name: str, aspect: float | None = None, *, option: str = "aspect") -> Metric:
    """Build one of the six metrics; ``aspect`` (β, in :data:`ASPECT_RANGE`) is used by
    the axial ones only; ``option`` names it in messages (``--aspect`` on the command line)."""
    if isinstance(name, str) and name.startswith(POLYGON_PREFIX):
        shape = polygon_shape(name)
    else:  # a polygonal record of the table (a new shape is one record there)
        shape = next((s for s in SHAPES.values() if s.metric == name and s.sides), None)
    if shape is None:
        one_of(name, "metric", METRIC_NAMES)
    beta = 1.0 if aspect is None else real_number(aspect, option, *ASPECT_RANGE)
    if aspect is None and name in AXIAL_METRICS:
        beta = DEFAULT_ASPECT
    if name not in AXIAL_METRICS:
        beta = 1.0
    if shape is not None:
        return polygon_metric(name, shape)
    if name == "l2":
        return Metric(name, beta, "ellipse", semi_axes=(1.0, 1.0))
    if name == "l2-axial":
        return Metric(name, beta, "ellipse", semi_axes=(1.0 / beta, beta))
    if name == "l1":  # |x| + |y| <= 1: normals (±1, ±1)/√2, offset 1/√2
        n = _regular_normals([45, 135, 225, 315])
        return Metric(name, beta, "polygon", n, np.full(4, 1 / math.sqrt(2)))
    if name == "linf":
        return Metric(name, beta, "polygon", _regular_normals([0, 90, 180, 270]), np.ones(4))
    if name == "linf-axial":  # β|x| <= 1 and |y|/β <= 1
        n = _regular_normals([0, 90, 180, 270])
        return Metric(name, beta, "polygon", n, np.array([1 / beta, beta, 1 / beta, beta]))
    # triangle: vertex up on screen (y down) at (0, -1); edges at inradius 1/2.
    # Outward normals point away from each vertex: 90° (down) and 90° ± 120°.
    return Metric(name, beta, "polygon", _regular_normals([90, 210, 330]), np.full(3, 0.5))


def polygon_metric(name: str, shape: Shape) -> Metric:
    """The metric of a polygonal record: a regular polygon of ``shape.sides`` sides
    (circumradius 1, a vertex at ``shape.phase`` degrees), or a user's polygon."""
    vertices = shape_vertices(shape)
    edges = np.roll(vertices, -1, axis=0) - vertices
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)  # outward for counter-clockwise vertices
    normals /= np.hypot(*normals.T)[:, None]
    offsets = np.einsum("ij,ij->i", normals, vertices)
    return Metric(name, 1.0, "polygon", normals, offsets)


def shape_vertices(shape: Shape) -> np.ndarray:
    """(K, 2) counter-clockwise vertices of a polygonal record's unit ball."""
    if shape.vertices is not None:
        return np.array(shape.vertices, dtype=np.float64)
    t = np.radians(shape.phase + 360.0 * np.arange(shape.sides) / shape.sides)
    return np.stack([np.cos(t), np.sin(t)], axis=1)


# ------------------------------------------------------------------ the user's polygon
POLYGON_PREFIX = "polygon:"


def convex_unit_ball(points, name: str = "polygon") -> np.ndarray:
    """(K, 2) counter-clockwise vertices of the convex polygon ``points`` (any order and
    scale), moved to its area centroid and scaled to circumradius 1.  InputError naming
    ``name`` for fewer than 3 distinct vertices, a degenerate polygon or one that is not
    convex (a vertex strictly inside the hull of the others)."""
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: its vertices must be [x, y] numbers") from None
    if pts.ndim != 2 or pts.shape[1] != 2 or not np.isfinite(pts).all():
        raise InputError(f"{name}: its vertices must be finite [x, y] pairs, got shape {pts.shape}")
    pts = np.unique(pts, axis=0)
    if len(pts) < 3:
        raise InputError(f"{name} has {len(pts)} distinct vertices; a polygon needs at least 3")
    centre = pts.mean(axis=0)
    order = np.argsort(np.arctan2(pts[:, 1] - centre[1], pts[:, 0] - centre[0]))
    ring = pts[order]
    scale = np.ptp(pts, axis=0).max()
    area2 = np.sum(ring[:, 0] * np.roll(ring[:, 1], -1) - np.roll(ring[:, 0], -1) * ring[:, 1])
    if scale == 0 or abs(area2) < 1e-9 * scale * scale:
        raise InputError(f"{name} is degenerate: its vertices lie on one line")
    # the turn at each vertex: negative where the outline bends inwards
    before, after = ring - np.roll(ring, 1, axis=0), np.roll(ring, -1, axis=0) - ring
    turn = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    if np.any(turn < -1e-9 * scale * scale):
        raise InputError(f"{name} is not convex: a vertex lies inside the others' outline")
    ring = ring[turn > 1e-9 * scale * scale]  # a vertex in the middle of a side is no corner
    if len(ring) < 3:
        raise InputError(f"{name} is degenerate: fewer than 3 corners")
    # area centroid of the polygon (shoelace)
    x, y = ring[:, 0], ring[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    c = x * yn - xn * y
    a = c.sum() / 2.0
    cx, cy = ((x + xn) * c).sum() / (6 * a), ((y + yn) * c).sum() / (6 * a)
    ring = ring - [cx, cy]
    return ring / np.hypot(*ring.T).max()


def polygon_shape(name: str) -> Shape:
    """The record of the user's polygon ``polygon:FILE`` (a CSV with columns x, y, or a
    JSON list of [x, y]), read once and kept by its name; its metric has the same name."""
    if name in SHAPES:
        return SHAPES[name]
    path = name[len(POLYGON_PREFIX) :]
    vertices = convex_unit_ball(read_vertices(path), f"polygon {path}")
    k = len(vertices)
    shape = Shape(name, name, 1, math.pi, 1.0, sides=k, vertices=tuple(map(tuple, vertices.tolist())))
    SHAPES[name] = shape
    return shape


def read_vertices(path: str) -> np.ndarray:
    """[x, y] rows of a polygon file: JSON (a list of [x, y]) or CSV (columns x, y)."""
    import json
    import os

    if not os.path.isfile(path):
        raise InputError(
            f"polygon file {path} does not exist"
            if not os.path.exists(path)
            else f"polygon file {path} is not a file"
        )
    if os.path.getsize(path) > 1 << 20:
        raise InputError(f"polygon file {path} is over 1 MiB: no polygon of an element needs that")
    try:
        with open(path, encoding="utf-8-sig") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read polygon file {path}: {exc}") from None
    if text.lstrip().startswith("["):
        try:
            data = json.loads(text)
        except ValueError as exc:
            raise InputError(f"polygon file {path} is not valid json: {exc}") from None
        return data
    rows = [line.split(",") for line in text.splitlines() if line.strip()]
    head = [c.strip() for c in rows[0]] if rows else []
    if "x" not in head or "y" not in head:
        raise InputError(
            f"polygon file {path} needs columns x and y (or a JSON list of [x, y]), found {head}"
        )
    ix, iy = head.index("x"), head.index("y")
    try:
        return [[float(r[ix]), float(r[iy])] for r in rows[1:]]
    except (ValueError, IndexError):
        raise InputError(f"polygon file {path}: x and y must be numbers on every line") from None


# --------------------------------------------------------------------- per site
@dataclass(frozen=True)
class SiteCoefficients:
    """Per-site evaluation coefficients, shared by every backend.

    polygon: ``facets`` (N, K, 2) with d_i(x) = max_k facets[i, k]·(x - p_i);
    ellipse: ``quad`` (N, 3) = (qxx, qxy, qyy) with
             d_i(x)^2 = qxx·vx² + 2·qxy·vx·vy + qyy·vy², v = x - p_i.
    """

    kind: str
    sites: np.ndarray
    facets: np.ndarray | None = None
    quad: np.ndarray | None = None
    # For ellipses, what the pruning octagon needs (semi-axes, cos θ, sin θ, s); computed
    # only when a backend asks for ``bounds`` (it costs ms at 16 000 sites).
    _octagon: tuple | None = field(default=None, repr=False)

    @cached_property
    def bounds(self) -> np.ndarray:
        """(N, F, 2) facets of a polygon that contains each scaled, rotated ball:
        ``max_k bounds·v <= d``.  A polygon's own facets; for an ellipse the circumscribed
        octagon (support of the ellipse in direction n is |diag(a, b) n|).  For pruning."""
        if self.kind == "polygon":
            return self.facets
        (a, b), c, si, s = self._octagon
        nrm = _regular_normals(np.arange(8) * 45.0)
        nk = nrm / np.hypot(a * nrm[:, 0], b * nrm[:, 1])[:, None]
        return _rotate_scale(nk, c, si, s)

    def distance(self, idx: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """d_idx(x, y), broadcasting idx, x and y (float64)."""
        vx = x - self.sites[idx, 0]
        vy = y - self.sites[idx, 1]
        if self.kind == "ellipse":
            q = self.quad[idx]
            return np.sqrt(q[..., 0] * vx * vx + 2 * q[..., 1] * vx * vy + q[..., 2] * vy * vy)
        f = self.facets[idx]
        out = f[..., 0, 0] * vx + f[..., 0, 1] * vy
        for k in range(1, f.shape[-2]):
            np.maximum(out, f[..., k, 0] * vx + f[..., k, 1] * vy, out=out)
        return out


def compile_sites(metric: Metric, sites, angles=None, scales=None) -> SiteCoefficients:
    """Fold each site's rotation θ_i and size factor s_i into evaluation coefficients."""
    sites = np.asarray(sites, dtype=np.float64).reshape(-1, 2)
    n = len(sites)
    theta = np.zeros(n) if angles is None else np.asarray(angles, dtype=np.float64)
    s = np.ones(n) if scales is None else np.asarray(scales, dtype=np.float64)
    c, si = np.cos(theta), np.sin(theta)
    if metric.kind == "ellipse":
        a, b = metric.semi_axes
        ia, ib = 1.0 / (a * a), 1.0 / (b * b)
        # Q = R(θ) diag(1/a², 1/b²) R(θ)^T / s²
        qxx = (c * c * ia + si * si * ib) / (s * s)
        qxy = (c * si * (ia - ib)) / (s * s)
        qyy = (si * si * ia + c * c * ib) / (s * s)
        quad = np.stack([qxx, qxy, qyy], axis=1)
        return SiteCoefficients("ellipse", sites, quad=quad, _octagon=((a, b), c, si, s))
    facets = _rotate_scale(metric.normals / metric.offsets[:, None], c, si, s)
    return SiteCoefficients("polygon", sites, facets=facets)


def _rotate_scale(nk: np.ndarray, c: np.ndarray, si: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Per-site facets R(θ_i)·n_k / s_i, shape (N, K, 2): n·R(-θ)v = (R(θ)n)·v."""
    fx = c[:, None] * nk[None, :, 0] - si[:, None] * nk[None, :, 1]
    fy = si[:, None] * nk[None, :, 0] + c[:, None] * nk[None, :, 1]
    return np.stack([fx, fy], axis=-1) / s[:, None, None]


__all__ = [
    "PAPER_METRICS",
    "AXIAL_METRICS",
    "DEFAULT_ASPECT",
    "ASPECT_RANGE",
    "Shape",
    "SHAPES",
    "METRIC_NAMES",
    "ELEMENT_METRIC",
    "NATURAL_ELEMENT",
    "Metric",
    "make_metric",
    "polygon_metric",
    "shape_vertices",
    "POLYGON_PREFIX",
    "convex_unit_ball",
    "polygon_shape",
    "read_vertices",
    "SiteCoefficients",
    "compile_sites",
]
