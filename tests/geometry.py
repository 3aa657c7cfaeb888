"""Independent geometry the tests hold results to."""

from __future__ import annotations

import numpy as np
import shapely


def largest_overlap(elements) -> float:
    """The largest area two of ``elements`` (shapely polygons) share, by exact shapely
    intersection of every pair whose outlines meet (0.0 when none overlap)."""
    elements = np.asarray(elements, dtype=object)
    a, b = shapely.STRtree(elements).query(elements, predicate="intersects")
    keep = a < b
    return float(shapely.area(shapely.intersection(elements[a[keep]], elements[b[keep]])).max(initial=0.0))
