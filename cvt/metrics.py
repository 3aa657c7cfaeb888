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

from .validate import one_of, real_number

METRIC_NAMES = ("l2", "l1", "linf", "linf-axial", "l2-axial", "triangle")
AXIAL_METRICS = ("linf-axial", "l2-axial")
DEFAULT_ASPECT = 0.5  # the paper's examples use β = 1/2
# β beyond this range makes elements thinner than 1/10000 of their length: no raster
# resolves them, and 1/β overflows long before β reaches the limits of a float
ASPECT_RANGE = (0.01, 100.0)

# The one element <-> metric table: each element shape is the unit ball of its metric
# (cvt/shapes.py draws the shapes from it).  The reverse, a metric's natural element,
# adds the l1 ball, a diamond, which is drawn as a square turned by 45°.
ELEMENT_METRIC = {
    "square": "linf",
    "rectangle": "linf-axial",
    "ellipse": "l2-axial",
    "triangle": "triangle",
    "circle": "l2",
}
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
        return NATURAL_ELEMENT[self.name]

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
    one_of(name, "metric", METRIC_NAMES)
    beta = 1.0 if aspect is None else real_number(aspect, option, *ASPECT_RANGE)
    if aspect is None and name in AXIAL_METRICS:
        beta = DEFAULT_ASPECT
    if name not in AXIAL_METRICS:
        beta = 1.0
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
