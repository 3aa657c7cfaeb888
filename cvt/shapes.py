"""Element shapes, defined from the same unit balls as the metrics.

``square`` is the linf ball, ``rectangle`` the linf-axial ball (2/β wide, 2β high),
``circle`` the l2 ball, ``ellipse`` the l2-axial ball (semi-axes 1/β and β),
``triangle`` the triangle ball (circumradius 1, vertex up on screen).  An element of
``size`` s is the outline scaled by s, rotated by the site's angle (clockwise on screen
for positive angles, as the metrics) and centred on the site.  Curved outlines use
enough vertices that the polygon's area is within 0.1 % of the true one.
"""

from __future__ import annotations

import numpy as np
import shapely

from .metrics import (
    CURVE_SEGMENTS,
    DEFAULT_ELEMENT,
    METRIC_NAMES,
    NATURAL_ELEMENT,
    PAPER_SHAPES,
    POLYGON_PREFIX,
    SHAPES,
    Metric,
    Shape,
    make_metric,
    polygon_shape,
)
from .validate import one_of

ELEMENT_SHAPES = tuple(SHAPES)  # the built-in shapes; the user's polygon is "polygon:FILE"


def shape_record(shape, name: str = "element") -> Shape:
    """The record of element ``shape`` (a name, ``polygon:FILE``, or a record); an
    unknown name is InputError naming ``name``."""
    if isinstance(shape, Shape):
        return shape
    if isinstance(shape, str) and shape.startswith(POLYGON_PREFIX):
        return polygon_shape(shape)
    return SHAPES[one_of(shape, name, list(SHAPES))]


def packing_density(shape: str) -> float:
    """The densest packing of the shape's translates (share of the plane)."""
    return shape_record(shape).packing


def rotational_symmetry(shape: str, aspect: float = 0.5) -> int:
    """k such that turning the element by 360°/k maps it onto itself (0 for a circle, or
    an ellipse of β = 1: the ball's :attr:`~.metrics.Metric.symmetry`)."""
    return element_ball(shape, aspect).symmetry


def unit_outline(shape: str, aspect: float = 0.5) -> np.ndarray:
    """(M, 2) vertices of the element at size 1, centred at the origin, angle 0."""
    return element_ball(shape, aspect).outline(CURVE_SEGMENTS)


def check_shape(shape) -> str:
    """``shape`` if it names an element shape (or a readable convex ``polygon:FILE``),
    else InputError naming it."""
    return shape_record(shape).name


def resolve_shapes(
    metric: str | None,
    element: str | None,
    default: str = DEFAULT_ELEMENT,
    names: tuple[str, str] = ("metric", "element"),
) -> tuple[str, str]:
    """(metric, element): either one implies the other (an element's metric is the one
    whose unit ball it is; a metric's element is its own ball); neither means the element
    ``default``.  ``names`` name the two in messages (``--metric``, ``--element``)."""
    if element is not None:
        element = shape_record(element, names[1]).name
    if metric is not None and not str(metric).startswith(POLYGON_PREFIX):
        one_of(metric, names[0], [*METRIC_NAMES, *(s.metric for s in SHAPES.values())])
    if metric is None and element is None:
        element = default
    if metric is None:
        metric = shape_record(element).metric
    if element is None:
        own = [s.name for s in SHAPES.values() if s.metric == metric]
        element = NATURAL_ELEMENT.get(metric) or (own[0] if own else metric)
    return metric, element


def element_ball(shape: str, aspect: float | None = 0.5) -> Metric:
    """The unit ball (as a metric) whose outline is the element ``shape``."""
    return make_metric(shape_record(shape).metric, aspect)


def transform(outline: np.ndarray, centres, angles, sizes) -> np.ndarray:
    """(N, M, 2) outlines scaled by ``sizes``, rotated by ``angles``, moved to ``centres``."""
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    n = len(centres)
    angles = np.broadcast_to(np.asarray(angles, dtype=np.float64), (n,))
    sizes = np.broadcast_to(np.asarray(sizes, dtype=np.float64), (n,))
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
    ox, oy = outline[None, :, 0] * sizes[:, None], outline[None, :, 1] * sizes[:, None]
    x = c * ox - s * oy + centres[:, 0:1]
    y = s * ox + c * oy + centres[:, 1:2]
    return np.stack([x, y], axis=-1)


CHUNK = 4096  # elements whose vertices are computed at once: bounds the temporaries


def element_polygons(shape: str, aspect: float, centres, angles, sizes) -> np.ndarray:
    """Shapely polygons (object array) of N elements."""
    outline = unit_outline(shape, aspect)
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    n = len(centres)
    angles = np.broadcast_to(np.asarray(angles, dtype=np.float64), (n,))
    sizes = np.broadcast_to(np.asarray(sizes, dtype=np.float64), (n,))
    out = np.empty(n, dtype=object)
    for a in range(0, n, CHUNK):
        b = min(n, a + CHUNK)
        out[a:b] = shapely.polygons(transform(outline, centres[a:b], angles[a:b], sizes[a:b]))
    return out


__all__ = [
    "ELEMENT_SHAPES",
    "PAPER_SHAPES",
    "DEFAULT_ELEMENT",
    "CURVE_SEGMENTS",
    "shape_record",
    "packing_density",
    "rotational_symmetry",
    "unit_outline",
    "check_shape",
    "resolve_shapes",
    "element_ball",
    "transform",
    "CHUNK",
    "element_polygons",
]
