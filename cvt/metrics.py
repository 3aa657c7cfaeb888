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

import enum
import math
from dataclasses import dataclass, field, replace
from functools import cached_property, lru_cache

import numpy as np

from .errors import InputError
from .validate import one_of, real_number

DEFAULT_ASPECT = 0.5  # the paper's examples use β = 1/2
# β beyond this range makes elements thinner than 1/10000 of their length: no raster
# resolves them, and 1/β overflows long before β reaches the limits of a float
ASPECT_RANGE = (0.01, 100.0)
CURVE_SEGMENTS = 128  # a curved element is drawn as this inscribed polygon: area within 0.04 %


def _regular_normals(angles_deg) -> np.ndarray:
    t = np.radians(np.asarray(angles_deg, dtype=np.float64))
    return np.stack([np.cos(t), np.sin(t)], axis=1)


class Depth(enum.Enum):
    """The distance transform that starts the fit's search in a shape's cells (the
    shape record's ``distance``): chessboard (whole pixels, squares), Euclidean with the
    axes scaled by the aspect β (rectangles, ellipses) or plain Euclidean."""

    CHESSBOARD = "chessboard"
    SCALED = "scaled"
    EUCLIDEAN = "euclidean"


@dataclass(frozen=True)
class Shape:
    """An element shape: every fact about it, in one record (the table :data:`SHAPES`).

    The record holds the element's whole geometry: its unit ball, given once as either
    ``facets`` (a polygon by its edges), ``sides`` and ``phase`` (a regular polygon),
    ``vertices`` (any other convex polygon) or ``semi_axes`` (an ellipse).  The metric of
    the same ball (:func:`make_metric`), the outline of an element, the fit, compaction,
    cutting, the writers and every backend are built from it; nothing branches on a
    shape's name.

    Parameters
    ----------
    name : str
        The element's name (``--element``).
    metric : str
        The name of the metric whose unit ball it is (implied by ``--element``).
    symmetry : int
        Rotational symmetry: turning it by 360°/k maps it onto itself (0: every turn).
    side_period : float
        The turn (radians) after which a side lies along the same line again (a mosaic's
        field is read modulo it).
    packing : float
        The densest packing of its translates, as a share of the plane (compaction's
        size caps under a density).
    facets : tuple of (float, float), optional
        A polygonal ball by its edges: (outward normal's angle in degrees, offset), so
        that the ball is ``{v : n_k·v <= h_k}``.
    semi_axes : tuple of (float, float), optional
        An elliptic ball's semi-axes along x and y (a curved shape).
    axial : bool
        Whether the aspect β stretches it: by 1/β along x and β along y (rectangles,
        ellipses).  Only axis-aligned facets may be stretched.
    unit_aspect_symmetry : int
        An axial shape's symmetry at β = 1 (a rectangle is then a square, 4; an ellipse a
        circle, 0).
    sides : int
        A regular polygon's number of sides (0: not one), with its first vertex at
        ``phase`` degrees; such a shape's ball has circumradius 1.
    phase : float
        The angle (degrees) of a regular polygon's first vertex.
    vertices : tuple of (x, y), optional
        The unit ball of any other convex polygon (the user's), counter-clockwise.
    distance : Depth
        The distance transform that starts the fit's search in its cells.
    compaction_rounds : int
        How many rounds ``ours-compact`` compacts by default.  Hexagons start further
        from their lattice than squares (fitted coverage 0.72 against 0.78, 1024²,
        N = 4000) and gain about a point per two rounds after the fourth: they take 12.
    paper_distance : int
        Where the paper lists the distance of its ball among its six (1 to 6; 0: not one
        of the paper's), which orders :data:`PAPER_METRICS`.
    paper : bool
        Whether it is one of the paper's five element shapes (the tables' default shapes).
    alternates : bool
        Whether ``ours-compact --alternate`` may point it either way (its angle or the
        angle + 180°): a shape that is not its own half turn.
    minkowski_p : float, optional
        The p of the Minkowski norm whose ball it is (what a k-d tree query computes), or
        None.
    reference : bool
        Whether the paper quotes its Table 2 figures on this shape (the tables' headline
        rows stand on it: :data:`REFERENCE_SHAPE`).

    Attributes
    ----------
    curved : bool
        Whether its outline is curved (an ellipse: drawn as a 128-gon, SVG ellipses).

    Examples
    --------
    >>> from compact_distributions.cvt.metrics import SHAPES
    >>> hexagon = SHAPES["hexagon"]
    >>> hexagon.metric, hexagon.symmetry, hexagon.sides, hexagon.phase
    ('hexagon', 6, 6, 90.0)
    >>> SHAPES["circle"].curved, SHAPES["rectangle"].axial
    (True, True)
    >>> SHAPES["rectangle"].ball(0.5).offsets.tolist()  # 2/β wide, 2β high
    [2.0, 0.5, 2.0, 0.5]
    """

    name: str
    metric: str
    symmetry: int
    side_period: float
    packing: float
    facets: tuple[tuple[float, float], ...] | None = None
    semi_axes: tuple[float, float] | None = None
    axial: bool = False
    unit_aspect_symmetry: int = 0
    sides: int = 0
    phase: float = 0.0
    vertices: tuple[tuple[float, float], ...] | None = None  # any convex polygon's unit ball
    distance: Depth = Depth.EUCLIDEAN
    compaction_rounds: int = 4
    paper_distance: int = 0
    paper: bool = False
    alternates: bool = False
    minkowski_p: float | None = None
    reference: bool = False

    def __post_init__(self):
        given = [self.facets is not None, self.semi_axes is not None, self.sides > 0]
        if sum(given) != 1:
            raise ValueError(f"shape {self.name!r}: give its ball once (facets, semi_axes or sides)")
        if self.axial and self.facets is not None:
            n = _regular_normals([a for a, _ in self.facets])
            if not np.all(np.isclose(np.abs(n).max(axis=1), 1.0)):
                raise ValueError(f"shape {self.name!r}: only axis-aligned facets stretch with β")

    @property
    def curved(self) -> bool:
        """Whether the outline is curved (an elliptic ball)."""
        return self.semi_axes is not None

    def ball(self, aspect: float = 1.0, *, name: str | None = None, turn: float = 0.0, scale: float = 1.0):
        """Build the record's unit ball as a :class:`Metric`.

        Parameters
        ----------
        aspect : float
            The β an axial shape is stretched by: 1/β along x, β along y (unchecked here;
            :func:`make_metric` checks it).
        name : str, optional
            The metric's name (default the shape's own metric).
        turn : float
            Degrees the ball is turned by (a metric whose ball is this element's turned,
            like l1's).
        scale : float
            Factor the ball is scaled by.

        Returns
        -------
        Metric
            The ball, with this shape as its element.
        """
        name = self.metric if name is None else name
        beta = aspect if self.axial else 1.0
        common = dict(
            name=name,
            aspect=beta,
            element=self.name,
            symmetry=self.unit_aspect_symmetry if self.axial and np.isclose(beta, 1.0) else self.symmetry,
            turn=math.radians(turn),
            minkowski_p=self.minkowski_p if (turn, scale) == (0.0, 1.0) else None,
        )
        if self.semi_axes is not None:
            a, b = self.semi_axes
            if self.axial:
                a, b = a / beta, b * beta
            return Metric(semi_axes=(a * scale, b * scale), **common)
        if self.facets is not None:
            normals = _regular_normals([angle + turn for angle, _ in self.facets])
            offsets = np.array([h for _, h in self.facets], dtype=np.float64)
            if self.axial:  # an axis-aligned facet moves by the length of S·n, S = diag(1/β, β)
                base = _regular_normals([angle for angle, _ in self.facets])
                offsets = offsets * np.hypot(base[:, 0] / beta, base[:, 1] * beta)
            return Metric(normals=normals, offsets=offsets * scale if scale != 1.0 else offsets, **common)
        vertices = shape_vertices(self)
        edges = np.roll(vertices, -1, axis=0) - vertices
        normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)  # outward for counter-clockwise vertices
        normals /= np.hypot(*normals.T)[:, None]
        offsets = np.einsum("ij,ij->i", normals, vertices)
        return Metric(normals=normals, offsets=offsets, **common)


@dataclass(frozen=True)
class TurnedBall:
    """A metric whose unit ball is an element's ball turned and scaled (no element of its
    own): its cells hold that element, turned by the same angle.

    Parameters
    ----------
    name : str
        The metric's name.
    element : str
        The element shape whose ball it turns.
    turn : float
        The turn, in degrees.
    scale : float
        The scale of the turned ball.
    paper_distance : int
        Where the paper lists it among its six distances (0: not one of them).
    minkowski_p : float, optional
        The p of the Minkowski norm whose ball it is, or None.
    """

    name: str
    element: str
    turn: float
    scale: float
    paper_distance: int = 0
    minkowski_p: float | None = None


_HEX = math.pi / math.sqrt(12.0)  # circles' densest packing (hexagonal)
# The one table of shapes.  The paper's five pair with its metrics; a hexagon and an
# octagon are regular polygons whose metrics are their own unit balls.  A regular
# octagon's densest lattice packing is (4 + 4√2) / (5 + 4√2) of the plane.
_SQUARE = ((0.0, 1.0), (90.0, 1.0), (180.0, 1.0), (270.0, 1.0))  # max(|x|, |y|) <= 1
SHAPES: dict[str, Shape] = {
    s.name: s
    for s in (
        Shape(
            "square", "linf", 4, math.pi / 2, 1.0, facets=_SQUARE, distance=Depth.CHESSBOARD,
            paper_distance=3, paper=True, minkowski_p=math.inf, reference=True,
        ),
        Shape(
            "rectangle", "linf-axial", 2, math.pi, 1.0, facets=_SQUARE, axial=True,
            unit_aspect_symmetry=4, distance=Depth.SCALED, paper_distance=4, paper=True,
        ),
        Shape(
            "ellipse", "l2-axial", 2, math.pi, _HEX, semi_axes=(1.0, 1.0), axial=True,
            unit_aspect_symmetry=0, distance=Depth.SCALED, paper_distance=5, paper=True,
        ),
        # vertex up on screen (y down) at (0, -1), edges at inradius 1/2: the outward
        # normals point away from each vertex, 90° (down) and 90° ± 120°
        Shape(
            "triangle", "triangle", 3, math.pi / 3, 2.0 / 3.0,
            facets=((90.0, 0.5), (210.0, 0.5), (330.0, 0.5)), paper_distance=6, paper=True,
            alternates=True,
        ),
        Shape(
            "circle", "l2", 0, math.pi / 2, _HEX, semi_axes=(1.0, 1.0), paper_distance=1,
            paper=True, minkowski_p=2.0,
        ),
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
}  # fmt: skip
# The l1 ball, |x| + |y| <= 1, is the square's turned by 45° and scaled by 1/√2: its
# cells hold squares turned by 45°.
TURNED_BALLS: dict[str, TurnedBall] = {
    b.name: b
    for b in (TurnedBall("l1", "square", 45.0, 1 / math.sqrt(2), paper_distance=2, minkowski_p=1.0),)
}
DEFAULT_ELEMENT = "square"  # the element of a problem that names none (the paper's first)
REFERENCE_SHAPE = next(s.name for s in SHAPES.values() if s.reference)
PAPER_SHAPES = tuple(s.name for s in SHAPES.values() if s.paper)  # the paper's five, table order
PAPER_METRICS = tuple(  # the paper's six distances, in its order
    r.metric if isinstance(r, Shape) else r.name
    for r in sorted(
        (r for r in (*SHAPES.values(), *TURNED_BALLS.values()) if r.paper_distance),
        key=lambda r: r.paper_distance,
    )
)
METRIC_NAMES = (*PAPER_METRICS, *(s.metric for s in SHAPES.values() if s.metric not in PAPER_METRICS))
# The element <-> metric table, read from the records: a metric's natural element is
# its own ball's, or the element a turned ball turns.
ELEMENT_METRIC = {s.name: s.metric for s in SHAPES.values()}
NATURAL_ELEMENT = {
    **{m: e for e, m in ELEMENT_METRIC.items()},
    **{b.name: b.element for b in TURNED_BALLS.values()},
}
AXIAL_METRICS = tuple(s.metric for s in SHAPES.values() if s.axial)


@dataclass(frozen=True)
class Metric:
    """A convex unit ball, sized: either polygonal (normals, offsets) or elliptic
    (semi-axes), built from a shape record by :meth:`Shape.ball` (see :func:`make_metric`).

    Attributes
    ----------
    name : str
        The metric's name.
    aspect : float
        The β it was stretched by (1 for a shape that is not axial).
    normals : numpy.ndarray or None
        (K, 2) unit outward normals of a polygonal ball.
    offsets : numpy.ndarray or None
        (K,) support values h_k > 0 of a polygonal ball.
    semi_axes : tuple of (float, float) or None
        An elliptic ball's semi-axes (a along x, b along y).
    element : str
        The element shape its cells hold (its natural element).
    turn : float
        The turn (radians) of that element in its cells (the l1 ball's square: π/4).
    minkowski_p : float or None
        The p of the Minkowski norm it is, or None.
    symmetry : int
        The ball's rotational symmetry at this aspect: turning it by 360°/k maps it onto
        itself (0: every turn; an axial shape at β = 1 has its record's
        ``unit_aspect_symmetry``).

    Notes
    -----
    The same record is the unit element: the element of size s turned by θ is
    ``s·R(θ)·B``.  Its gauge, support function, faces, area and symmetry (what the fit,
    compaction, the baselines and the writers need) are methods of the ball, so an
    element shape is implemented once.
    """

    name: str
    aspect: float = 1.0
    normals: np.ndarray = field(default=None, repr=False)  # (K, 2) unit outward normals
    offsets: np.ndarray = field(default=None, repr=False)  # (K,) support values h_k > 0
    semi_axes: tuple[float, float] | None = None  # (a along x, b along y)
    element: str = ""
    turn: float = 0.0
    minkowski_p: float | None = None
    symmetry: int = 1

    @property
    def curved(self) -> bool:
        """Whether the ball is elliptic (else polygonal)."""
        return self.semi_axes is not None

    # ----------------------------------------------------------------- geometry
    def gauge(self, v: np.ndarray) -> np.ndarray:
        """Gauge of vectors ``v`` of shape (..., 2) in the ball's own frame."""
        v = np.asarray(v, dtype=np.float64)
        if self.curved:
            a, b = self.semi_axes
            return np.hypot(v[..., 0] / a, v[..., 1] / b)
        return np.max((v @ self.normals.T) / self.offsets, axis=-1)

    def outline(self, segments: int = 256) -> np.ndarray:
        """Boundary of the unit ball as polygon vertices (M, 2), counter-clockwise in
        (x, y).  Exact for polygons; ``segments`` points for ellipses."""
        if self.curved:
            a, b = self.semi_axes
            t = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
            return np.stack([a * np.cos(t), b * np.sin(t)], axis=1)
        return _polygon_from_halfplanes(self.normals, self.offsets)

    @cached_property
    def circumradius(self) -> float:
        """max |v| over the unit ball: gauge(v) >= |v| / circumradius."""
        if self.curved:
            return float(max(self.semi_axes))
        return float(np.max(np.hypot(*self.outline().T)))

    @cached_property
    def inradius(self) -> float:
        """min over directions of the ball's extent: gauge(v) <= |v| / inradius."""
        if self.curved:
            return float(min(self.semi_axes))
        return float(np.min(self.offsets / np.hypot(*self.normals.T)))

    @property
    def natural_element(self) -> str:
        """The element shape its cells hold."""
        return self.element or self.name

    # ------------------------------------------------ the element, turned and sized
    @property
    def symmetry_turn(self) -> float:
        """The smallest turn (radians) that maps the ball onto itself (2π for a ball of
        symmetry 0 or 1: a turn that is read modulo it is then read whole)."""
        return 2 * math.pi / self.symmetry if self.symmetry else 2 * math.pi

    @property
    def turns_freely(self) -> bool:
        """Whether every turn maps the ball onto itself (a circle)."""
        return self.symmetry == 0

    @cached_property
    def unit_area(self) -> float:
        """The area of the element of size 1 as it is drawn (curved outlines as the
        :data:`CURVE_SEGMENTS`-gon)."""
        x, y = self.outline(CURVE_SEGMENTS).T
        return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))

    def size_for_area(self, area: float) -> float:
        """The size whose element has ``area``."""
        return math.sqrt(area / self.unit_area)

    @cached_property
    def faces(self) -> Faces:
        """A polygonal ball's outline and its faces as drawn (see :class:`Faces`)."""
        if self.curved:
            raise ValueError(f"{self.name}: an elliptic ball has no faces")
        verts = self.outline()
        normals = self.normals / np.hypot(*self.normals.T)[:, None]
        k = len(verts)
        return Faces(
            vertices=verts,
            normals=normals,
            offsets=(verts @ normals.T).max(axis=0),
            symmetric=bool(
                k % 2 == 0
                and np.allclose(verts[k // 2 :], -verts[: k // 2], rtol=0, atol=1e-12)
                and np.allclose(normals[k // 2 :], -normals[: k // 2], rtol=0, atol=1e-12)
            ),
        )

    def support(self, nx, ny, cos, sin) -> np.ndarray:
        """h(n) = max over the ball of v·n, for the ball turned by θ (``cos``, ``sin``
        broadcast against the directions ``nx``, ``ny``)."""
        ux = cos * nx + sin * ny  # R(−θ) n: n in the ball's own frame
        uy = cos * ny - sin * nx
        if self.curved:
            a, b = self.semi_axes
            ux *= a
            uy *= b
            return np.sqrt(ux * ux + uy * uy)  # |diag(a, b) u|; faster than np.hypot
        faces = self.faces
        v = faces.vertices
        if faces.symmetric:  # max(a, −a, b, −b, ...) = max(|a|, |b|, ...) exactly
            out = np.abs(v[0, 0] * ux + v[0, 1] * uy)
            for k in range(1, len(v) // 2):
                np.maximum(out, np.abs(v[k, 0] * ux + v[k, 1] * uy), out=out)
            return out
        out = v[0, 0] * ux + v[0, 1] * uy
        for k in range(1, len(v)):
            np.maximum(out, v[k, 0] * ux + v[k, 1] * uy, out=out)
        return out

    def face_normal(self, m, cos, sin) -> tuple[np.ndarray, np.ndarray]:
        """x and y of face normal ``m[k]`` of ball k turned by θ_k (``cos``, ``sin``):
        the numbers of :meth:`face_normals`, one per ball."""
        normals = self.faces.normals
        nx, ny = normals[m, 0], normals[m, 1]
        return cos * nx - sin * ny, sin * nx + cos * ny

    def face_normals(self, cos, sin, count=None, faces_first=False) -> tuple[np.ndarray, np.ndarray]:
        """(..., K) x and y of the outward face normals, turned by θ (``count``: the
        first ``count`` of them only; ``faces_first``: (K, ...) instead, the same
        numbers)."""
        normals = self.faces.normals
        nx, ny = normals[:count, 0], normals[:count, 1]
        if faces_first:
            nx, ny = (v.reshape(-1, *([1] * np.ndim(cos))) for v in (nx, ny))
            return cos * nx - sin * ny, sin * nx + cos * ny
        c, s = cos[..., None], sin[..., None]
        return c * nx - s * ny, s * nx + c * ny

    def gauge_turned(self, vx, vy, cos, sin) -> np.ndarray:
        """Gauge of world offsets (``vx``, ``vy``) from the centre of a ball turned by θ
        (``cos``, ``sin``): a point is inside the element of size s iff gauge <= s."""
        ux = cos * vx + sin * vy  # R(-θ) v
        uy = cos * vy - sin * vx
        if self.curved:
            a, b = self.semi_axes
            return np.hypot(ux / a, uy / b)
        n, h = self.normals, self.offsets
        out = (n[0, 0] * ux + n[0, 1] * uy) / h[0]
        for k in range(1, len(h)):
            out = np.maximum(out, (n[k, 0] * ux + n[k, 1] * uy) / h[k])
        return out

    def reach(self, vx, vy, theta, gap: float) -> np.ndarray:
        """The largest size whose element turned by ``theta`` keeps ``gap/2`` clear of
        the point at offset (``vx``, ``vy``) from its centre: the grout rule of the
        placement (a mitred offset for polygons, first order for ellipses)."""
        cos, sin = np.cos(theta), np.sin(theta)
        if gap <= 0:
            return self.gauge_turned(vx, vy, cos, sin)
        if self.curved:
            return self.gauge_turned(vx, vy, cos, sin) - 0.5 * gap / min(self.semi_axes)
        ux, uy = cos * vx + sin * vy, cos * vy - sin * vx
        n, h = self.normals, self.offsets
        out = (n[0, 0] * ux + n[0, 1] * uy - 0.5 * gap) / h[0]
        for k in range(1, len(h)):
            out = np.maximum(out, (n[k, 0] * ux + n[k, 1] * uy - 0.5 * gap) / h[k])
        return out

    def cone(self, height: float) -> dict:
        """Paper Table 1: the cone or pyramid whose height over a base point equals the
        distance of that point from the apex's foot.  The base is the unit ball scaled
        by ``height``; its named dimensions are returned for comparison with Table 1."""
        base = self.outline() * height
        geom = {"height": float(height), "base": base}
        if self.curved:
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


@dataclass(frozen=True)
class Faces:
    """A polygonal ball's outline and faces as drawn.

    Attributes
    ----------
    vertices : numpy.ndarray
        (K, 2) the outline's vertices, counter-clockwise.
    normals : numpy.ndarray
        (K, 2) the faces' outward unit normals.
    offsets : numpy.ndarray
        (K,) the outline's support along each of its own face normals.
    symmetric : bool
        Whether vertices and normals come in opposite pairs k, k + K/2 (a centrally
        symmetric polygon: h(−n) = h(n), so half the vertices give the support).
    """

    vertices: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray
    symmetric: bool


def _polygon_from_halfplanes(normals: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Vertices of {v : n_k·v <= h_k} for normals sorted by angle (convex, bounded)."""
    order = np.argsort(np.arctan2(normals[:, 1], normals[:, 0]))
    n, h = normals[order], offsets[order]
    verts = []
    for k in range(len(n)):
        m = np.array([n[k], n[(k + 1) % len(n)]])
        verts.append(np.linalg.solve(m, [h[k], h[(k + 1) % len(n)]]))
    return np.array(verts)


def make_metric(name: str, aspect: float | None = None, *, option: str = "aspect") -> Metric:
    """Build the metric (the Lloyd distance) of a name: one convex unit ball.

    The ball is that of the shape record whose metric it is (or of ``polygon:FILE``, the
    user's polygon), or a record's ball turned (l1: the square's, by 45°).

    Parameters
    ----------
    name : str
        One of :data:`METRIC_NAMES`, or ``polygon:FILE``.
    aspect : float, optional
        The β of the axial shapes, in :data:`ASPECT_RANGE`, used by them only (default
        :data:`DEFAULT_ASPECT` for them).
    option : str
        How messages name ``aspect`` (``--aspect`` on the command line).

    Returns
    -------
    Metric
        The unit ball, ready for :func:`compile_sites`.

    Raises
    ------
    InputError
        For an unknown name or an aspect out of range.

    Examples
    --------
    >>> make_metric("linf").offsets.tolist()
    [1.0, 1.0, 1.0, 1.0]
    >>> make_metric("l2-axial", 0.5).semi_axes
    (2.0, 0.5)
    """
    if isinstance(name, str) and name.startswith(POLYGON_PREFIX):
        return polygon_shape(name).ball()
    record = next((s for s in SHAPES.values() if s.metric == name), None)
    turned = TURNED_BALLS.get(name) if isinstance(name, str) else None
    if record is None and turned is None:
        one_of(name, "metric", METRIC_NAMES)
    beta = 1.0 if aspect is None else real_number(aspect, option, *ASPECT_RANGE)
    if turned is not None:
        ball = SHAPES[turned.element].ball(1.0, name=name, turn=turned.turn, scale=turned.scale)
        return replace(ball, minkowski_p=turned.minkowski_p)
    if aspect is None and record.axial:
        beta = DEFAULT_ASPECT
    return record.ball(beta)


def polygon_metric(name: str, shape: Shape) -> Metric:
    """The metric of a polygonal record (kept for callers of the old path)."""
    return shape.ball(name=name)


def shape_vertices(shape: Shape) -> np.ndarray:
    """(K, 2) counter-clockwise vertices of a polygonal record's unit ball."""
    if shape.vertices is not None:
        return np.array(shape.vertices, dtype=np.float64)
    t = np.radians(shape.phase + 360.0 * np.arange(shape.sides) / shape.sides)
    return np.stack([np.cos(t), np.sin(t)], axis=1)


# ------------------------------------------------------------------ the user's polygon
POLYGON_PREFIX = "polygon:"


def _ring_as_given(pts: np.ndarray) -> np.ndarray:
    """The ring in the order given, without repeats of a vertex in a row (nor the closing
    one): what a user's file means by it."""
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.any(pts[1:] != pts[:-1], axis=1)
    ring = pts[keep]
    while len(ring) > 1 and np.array_equal(ring[0], ring[-1]):
        ring = ring[:-1]
    return ring


def convex_unit_ball(points, name: str = "polygon") -> np.ndarray:
    """(K, 2) counter-clockwise vertices of the convex polygon ``points`` (a ring in
    either direction, closed or not, at any scale), moved to its area centroid and scaled
    to circumradius 1.  InputError naming ``name`` for fewer than 3 distinct vertices, a
    degenerate polygon, a ring that crosses itself, or one that is not convex (a vertex
    strictly inside the hull of the others)."""
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: its vertices must be [x, y] numbers") from None
    if pts.ndim != 2 or pts.shape[1] != 2 or not np.isfinite(pts).all():
        raise InputError(f"{name}: its vertices must be finite [x, y] pairs, got shape {pts.shape}")
    given = _ring_as_given(pts)
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
    import shapely

    if not shapely.LinearRing(given).is_simple:
        raise InputError(f"{name} crosses itself: its vertices, in the order given, must go round it once")
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
    JSON list of [x, y]); its metric has the same name.  The record is the caller's: it
    is not added to :data:`SHAPES` (a file read once is kept while it is unchanged)."""
    import os

    path = name[len(POLYGON_PREFIX) :]
    try:
        stat = os.stat(path)
        stamp = (stat.st_mtime_ns, stat.st_size)
    except OSError:
        stamp = None  # read_vertices says what is wrong with it
    return _polygon_record(name, stamp)


@lru_cache(maxsize=64)
def _polygon_record(name: str, stamp) -> Shape:
    path = name[len(POLYGON_PREFIX) :]
    vertices = convex_unit_ball(read_vertices(path), f"polygon {path}")
    k = len(vertices)
    return Shape(name, name, 1, math.pi, 1.0, sides=k, vertices=tuple(map(tuple, vertices.tolist())))


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

    polygonal (``curved`` false): ``facets`` (N, K, 2) with d_i(x) = max_k facets[i, k]·(x - p_i);
    elliptic (``curved``): ``quad`` (N, 3) = (qxx, qxy, qyy) with
             d_i(x)^2 = qxx·vx² + 2·qxy·vx·vy + qyy·vy², v = x - p_i.
    """

    curved: bool
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
        if not self.curved:
            return self.facets
        (a, b), c, si, s = self._octagon
        nrm = _regular_normals(np.arange(8) * 45.0)
        nk = nrm / np.hypot(a * nrm[:, 0], b * nrm[:, 1])[:, None]
        return _rotate_scale(nk, c, si, s)

    def distance(self, idx: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """d_idx(x, y), broadcasting idx, x and y (float64)."""
        vx = x - self.sites[idx, 0]
        vy = y - self.sites[idx, 1]
        if self.curved:
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
    if metric.curved:
        a, b = metric.semi_axes
        ia, ib = 1.0 / (a * a), 1.0 / (b * b)
        # Q = R(θ) diag(1/a², 1/b²) R(θ)^T / s²
        qxx = (c * c * ia + si * si * ib) / (s * s)
        qxy = (c * si * (ia - ib)) / (s * s)
        qyy = (si * si * ia + c * c * ib) / (s * s)
        quad = np.stack([qxx, qxy, qyy], axis=1)
        return SiteCoefficients(True, sites, quad=quad, _octagon=((a, b), c, si, s))
    facets = _rotate_scale(metric.normals / metric.offsets[:, None], c, si, s)
    return SiteCoefficients(False, sites, facets=facets)


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
    "Depth",
    "Shape",
    "TurnedBall",
    "TURNED_BALLS",
    "DEFAULT_ELEMENT",
    "REFERENCE_SHAPE",
    "PAPER_SHAPES",
    "SHAPES",
    "METRIC_NAMES",
    "ELEMENT_METRIC",
    "NATURAL_ELEMENT",
    "Metric",
    "Faces",
    "CURVE_SEGMENTS",
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
