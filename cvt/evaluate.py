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

from dataclasses import dataclass

import numpy as np
import shapely

from compact_distributions.cvt.problem import Grid


@dataclass
class Evaluation:
    coverage: float
    overlap: float
    elements: int  # elements placed
    skipped: int  # sites without an element (empty or degenerate cells)
    min_area: float  # smallest placed element, px²
    max_area: float  # largest placed element, px²
    empty_cells: int | None = None  # sites whose cell holds no pixel (when labels given)
    overlapping_pairs: int = 0  # pairs of elements that share a positive area

    def as_dict(self) -> dict:
        return {
            "coverage": self.coverage,
            "overlap": self.overlap,
            "placed": self.elements,
            "skipped": self.skipped,
            "min_element_area": self.min_area,
            "max_element_area": self.max_area,
            "empty_cell_count": self.empty_cells,
            "overlapping_pairs": self.overlapping_pairs,
        }


def region_polygon(grid: Grid):
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


def empty_cell_count(labels: np.ndarray, n_sites: int) -> int:
    """Sites whose cell holds no pixel of the label raster."""
    lab = np.asarray(labels).ravel()
    counts = np.bincount(lab[lab >= 0], minlength=n_sites)[:n_sites]
    return int((counts == 0).sum())


UNION_BATCH = 4096  # elements unioned at once: bounds the memory of a union


def _union_area(geoms, a, b) -> float:
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


def evaluate(elements, grid: Grid, region=None, labels=None) -> Evaluation:
    """Coverage and overlap of ``elements`` (shapely polygons; None entries are skipped).

    ``labels`` (the final label raster, optional) adds the number of empty cells."""
    region = region_polygon(grid) if region is None else region
    empty = None if labels is None else empty_cell_count(labels, len(elements))
    geoms = np.array([e for e in elements if e is not None and not e.is_empty], dtype=object)
    skipped = len(elements) - len(geoms)
    area = shapely.area(region)
    if len(geoms) == 0:
        return Evaluation(0.0, 0.0, 0, skipped, 0.0, 0.0, empty)
    shapely.prepare(region)
    # clip only what is not already inside the region (prepared, vectorised test)
    clipped = geoms.copy()
    outside = ~shapely.contains(region, geoms)
    if outside.any():
        clipped[outside] = shapely.intersection(geoms[outside], region)
    clip_areas = shapely.area(clipped)
    total = float(clip_areas.sum())

    tree = shapely.STRtree(clipped)
    a, b = tree.query(clipped, predicate="intersects")
    keep = a < b
    a, b = a[keep], b[keep]
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
