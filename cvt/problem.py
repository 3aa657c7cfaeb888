"""The problem: a raster, a region, N sites, a metric, optional density and field.

Pixel (i, j) (row i, column j) is sampled at its centre (j + 0.5, i + 0.5); x grows
right, y grows down; every coordinate is in pixel units.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .fields import DensityMap, DirectionField
from .metrics import DEFAULT_ELEMENT, ELEMENT_METRIC, Metric, make_metric
from .pixels import pixel_index
from .shapes import check_shape
from .validate import whole_number

MAX_SIDE = 32768
MAX_SEED = 2**63 - 1  # seeds are stored as int64 in reports


def parse_size(text, name: str = "size") -> tuple[int, int]:
    """'W' or 'WxH' -> (W, H), each in 1..32768."""
    raw = str(text).strip().lower()
    parts = raw.split("x")
    try:
        if len(parts) == 1:
            w = h = int(parts[0])
        elif len(parts) == 2:
            w, h = int(parts[0]), int(parts[1])
        else:
            raise ValueError
    except ValueError:
        raise InputError(f"{name} must be W or WxH with whole numbers, got {text!r}") from None
    for side in (w, h):
        if side < 1 or side > MAX_SIDE:
            raise InputError(f"{name} {text!r}: each side must be between 1 and {MAX_SIDE} pixels")
    return w, h


@dataclass(frozen=True)
class Grid:
    """The raster the CVT lives on, and the region inside it (``mask`` True = inside)."""

    width: int
    height: int
    mask: np.ndarray | None = None  # (H, W) bool, None means the whole raster

    def __post_init__(self):
        object.__setattr__(self, "width", whole_number(self.width, "width", minimum=1, maximum=MAX_SIDE))
        object.__setattr__(self, "height", whole_number(self.height, "height", minimum=1, maximum=MAX_SIDE))
        if self.mask is not None:
            try:
                m = np.ascontiguousarray(self.mask, dtype=bool)
            except (ValueError, TypeError) as exc:
                raise InputError(f"mask is not an array of booleans: {exc}") from None
            if m.shape != (self.height, self.width):
                raise InputError(
                    f"mask (the region) has shape {m.shape}, the raster is {self.width}x{self.height}: "
                    f"it must be ({self.height}, {self.width})"
                )
            if not m.any():
                raise InputError("mask (the region) is empty: no pixel is inside the region")
            object.__setattr__(self, "mask", m)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    @property
    def pixel_count(self) -> int:
        return int(self.mask.sum()) if self.mask is not None else self.width * self.height

    def inside(self) -> np.ndarray:
        """The region as a (H, W) bool array (allocated when mask is None)."""
        if self.mask is None:
            return np.ones(self.shape, dtype=bool)
        return self.mask


@dataclass
class Problem:
    """Everything that defines one CVT run, independent of the backend."""

    grid: Grid
    n_elements: int
    metric: Metric = field(default_factory=lambda: make_metric(ELEMENT_METRIC[DEFAULT_ELEMENT]))
    density: DensityMap | None = None
    field: DirectionField | None = None
    seed: int = 0
    init_sites: np.ndarray | None = None  # (N, 2) pixel units; overrides seeding
    # (H, W) bool: thin walls, pixels outside the region that separate parts of it (a
    # picture's strong edges).  Cells stop at them like at any border; a method that can
    # (compaction) brings elements up to the walls' centre lines instead of their sides.
    walls: np.ndarray | None = None
    # the element shape its cells hold (a name or ``polygon:FILE``); None: the metric's own
    element: str | None = None

    def __post_init__(self):
        if not isinstance(self.grid, Grid):
            raise InputError(f"grid must be a Grid, got {self.grid!r}")
        if not isinstance(self.metric, Metric):
            raise InputError(f"metric must be a Metric (cvt.metrics.make_metric), got {self.metric!r}")
        for name, value, kind in (
            ("density", self.density, DensityMap),
            ("field", self.field, DirectionField),
        ):
            if value is not None and not isinstance(value, kind):
                raise InputError(f"{name} must be a {kind.__name__} or None, got {value!r}")
        self.seed = whole_number(self.seed, "seed", minimum=0, maximum=MAX_SEED)
        if self.element is not None:
            self.element = check_shape(self.element)
        if self.walls is not None:
            walls = np.ascontiguousarray(self.walls, dtype=bool)
            if walls.shape != self.grid.shape:
                raise InputError(
                    f"walls are {walls.shape[1]}x{walls.shape[0]}, raster is "
                    f"{self.grid.width}x{self.grid.height}"
                )
            if (walls & self.grid.inside()).any():
                raise InputError("walls must lie outside the region")
            self.walls = walls
        if self.init_sites is not None:
            pts = np.asarray(self.init_sites, dtype=np.float64)
            if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) == 0:
                raise InputError("initial sites must be a non-empty list of (x, y) pairs")
            if not np.isfinite(pts).all():
                raise InputError("initial sites contain NaN or infinite coordinates")
            w, h = self.grid.width, self.grid.height
            bad = (pts[:, 0] < 0) | (pts[:, 0] > w) | (pts[:, 1] < 0) | (pts[:, 1] > h)
            if bad.any():
                k = int(np.argmax(bad))
                raise InputError(
                    f"initial site {k} at ({float(pts[k, 0])!r}, {float(pts[k, 1])!r}) is outside the "
                    f"{w}x{h} raster (0 <= x <= {w}, 0 <= y <= {h})"
                )
            self.init_sites = pts
            self.n_elements = len(pts)
        self.n_elements = whole_number(self.n_elements, "n_elements", minimum=1)
        if self.n_elements > self.grid.pixel_count:
            raise InputError(
                f"{self.n_elements} elements do not fit in a region of {self.grid.pixel_count} pixels"
            )
        for name, img in (("density", self.density), ("field", self.field)):
            if img is not None and img.shape is not None and img.shape != self.grid.shape:
                raise InputError(f"{name} map is {img.shape[::-1]}, raster is {self.grid.shape[::-1]}")

    def angles_at(self, sites: np.ndarray) -> np.ndarray:
        if self.field is None:
            return np.zeros(len(sites))
        return self.field.angles_at(sites)

    def scales_at(self, sites: np.ndarray) -> np.ndarray:
        if self.density is None:
            return np.ones(len(sites))
        return self.density.scales_at(sites)


def in_own_cell(labels: np.ndarray, points) -> np.ndarray:
    """(N,) True where point k lies on the raster in a pixel labelled k."""
    h, w = labels.shape
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    on_raster = (points[:, 0] >= 0) & (points[:, 0] < w) & (points[:, 1] >= 0) & (points[:, 1] < h)
    i, j = pixel_index(points, w, h)
    return on_raster & (labels[i, j] == np.arange(len(points)))


def lattice_sites(width: int, height: int, k: int) -> np.ndarray:
    """k x k sites at the centres of a regular lattice of cells (for tests and figures)."""
    xs = (np.arange(k) + 0.5) * (width / k)
    ys = (np.arange(k) + 0.5) * (height / k)
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


__all__ = ["MAX_SIDE", "MAX_SEED", "parse_size", "Grid", "Problem", "in_own_cell", "lattice_sites"]
