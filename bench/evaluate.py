"""Coverage and overlap of placed elements: the one definition the suite uses.

    coverage = area(union(elements) ∩ region) / area(region)
    overlap  = (Σ area(element ∩ region) − area(union(elements) ∩ region)) / area(region)

Both with shapely 2's vectorised functions (no Python loop over elements or pairs).
The region is the union of its pixels' squares (the whole raster when there is no mask).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from cvt.problem import Grid


@dataclass
class Evaluation:
    coverage: float
    overlap: float
    elements: int  # elements placed
    skipped: int  # sites without an element (empty or degenerate cells)
    min_area: float  # smallest placed element, px²
    max_area: float  # largest placed element, px²

    def as_dict(self) -> dict:
        return {
            "coverage": self.coverage,
            "overlap": self.overlap,
            "placed": self.elements,
            "skipped": self.skipped,
            "min_element_area": self.min_area,
            "max_element_area": self.max_area,
        }


def region_polygon(grid: Grid):
    """The region as a shapely geometry in pixel units (pixel squares, unioned)."""
    if grid.mask is None:
        return shapely.box(0, 0, grid.width, grid.height)
    # one box per horizontal run of inside pixels, then a coverage union (runs never overlap)
    m = np.zeros((grid.height, grid.width + 2), dtype=np.int8)
    m[:, 1:-1] = grid.mask
    edges = np.diff(m, axis=1)
    rows_s, cols_s = np.nonzero(edges == 1)
    rows_e, cols_e = np.nonzero(edges == -1)
    boxes = shapely.box(cols_s, rows_s, cols_e, rows_s + 1)
    return shapely.coverage_union_all(boxes)


def evaluate(elements, grid: Grid, region=None) -> Evaluation:
    """Coverage and overlap of ``elements`` (shapely polygons; None entries are skipped)."""
    region = region_polygon(grid) if region is None else region
    geoms = np.array([e for e in elements if e is not None and not e.is_empty], dtype=object)
    skipped = len(elements) - len(geoms)
    area = shapely.area(region)
    if len(geoms) == 0:
        return Evaluation(0.0, 0.0, 0, skipped, 0.0, 0.0)
    shapely.prepare(region)
    clipped = shapely.intersection(geoms, region)
    union = shapely.union_all(clipped)
    covered = shapely.area(union)
    total = float(shapely.area(clipped).sum())
    areas = shapely.area(geoms)
    return Evaluation(
        coverage=float(covered / area),
        overlap=float(max(0.0, total - covered) / area),
        elements=len(geoms),
        skipped=skipped,
        min_area=float(areas.min()),
        max_area=float(areas.max()),
    )
