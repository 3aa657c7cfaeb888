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

from .metrics import ELEMENT_METRIC, METRIC_NAMES, NATURAL_ELEMENT, Metric, make_metric
from .validate import one_of

ELEMENT_SHAPES = tuple(ELEMENT_METRIC)
CURVE_SEGMENTS = 128  # inscribed 128-gon: area within 0.04 % of the ellipse
# rotational symmetry of each shape (turns by 360°/k map it onto itself; 0: every turn)
SYMMETRY = {"square": 4, "rectangle": 2, "ellipse": 2, "triangle": 3, "circle": 0}
# densest packing of translates of each shape (share of the plane): squares and rectangles
# tile it; circles, and ellipses as their affine images, π/√12 (hexagonal); a triangle
# that keeps its direction 2/3 (its densest lattice packing)
PACKING_DENSITY = {"square": 1.0, "rectangle": 1.0, "ellipse": np.pi / np.sqrt(12.0), "triangle": 2.0 / 3.0,
                   "circle": np.pi / np.sqrt(12.0)}


def rotational_symmetry(shape: str, aspect: float = 0.5) -> int:
    """k such that turning the element by 360°/k maps it onto itself (0 for a circle, or
    an ellipse of β = 1; a rectangle of β = 1 is a square: 4)."""
    k = SYMMETRY[check_shape(shape)]
    if aspect is not None and np.isclose(aspect, 1.0) and k == 2:
        return 4 if shape == "rectangle" else 0
    return k


def unit_outline(shape: str, aspect: float = 0.5) -> np.ndarray:
    """(M, 2) vertices of the element at size 1, centred at the origin, angle 0."""
    return element_ball(shape, aspect).outline(CURVE_SEGMENTS)


def check_shape(shape) -> str:
    """``shape`` if it names an element shape, else InputError naming it."""
    return one_of(shape, "element", ELEMENT_SHAPES)


def resolve_shapes(metric: str | None, element: str | None, default: str = "square",
                   names: tuple[str, str] = ("metric", "element")) -> tuple[str, str]:
    """(metric, element): either one implies the other (an element's metric is the one
    whose unit ball it is; a metric's element is its own ball); neither means the element
    ``default``.  ``names`` name the two in messages (``--metric``, ``--element``)."""
    if element is not None:
        one_of(element, names[1], ELEMENT_SHAPES)
    if metric is not None:
        one_of(metric, names[0], METRIC_NAMES)
    if metric is None and element is None:
        element = default
    if metric is None:
        metric = ELEMENT_METRIC[element]
    if element is None:
        element = NATURAL_ELEMENT[metric]
    return metric, element


def element_ball(shape: str, aspect: float | None = 0.5) -> Metric:
    """The unit ball (as a metric) whose outline is the element ``shape``."""
    return make_metric(ELEMENT_METRIC[check_shape(shape)], aspect)


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
