"""The problem: a raster, a region, N sites, a metric, optional density and field.

Pixel (i, j) (row i, column j) is sampled at its centre (j + 0.5, i + 0.5); x grows
right, y grows down; every coordinate is in pixel units.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .errors import InputError
from .fields import DensityMap, DirectionField
from .metrics import DEFAULT_ELEMENT, ELEMENT_METRIC, Metric, make_metric
from .pixels import pixel_index
from .shapes import check_shape
from .validate import whole_number

MAX_SIDE = 32768
MAX_SEED = 2**63 - 1  # seeds are stored as int64 in reports


def parse_size(text: str | int, name: str = "size") -> tuple[int, int]:
    """'W' or 'WxH' -> (W, H), each in 1..32768 (InputError naming ``name`` otherwise)."""
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
    """The raster the CVT lives on, and the region inside it.

    Pixel (i, j) (row i, column j) is sampled at its centre (j + 0.5, i + 0.5); x grows
    right, y grows down; every coordinate is in pixel units.

    Parameters
    ----------
    width : int
        Raster width in pixels, 1 to 32768.
    height : int
        Raster height in pixels, 1 to 32768.
    mask : numpy.ndarray or None, optional
        The region, an (H, W) bool array, True inside; None (the default) is the whole
        raster.  Stored as a contiguous bool array.

    Attributes
    ----------
    shape : tuple of int
        ``(height, width)``, the shape of the raster's arrays.
    pixel_count : int
        The number of pixels inside the region.

    Raises
    ------
    InputError
        If a side is not a whole number in range, or the mask is not (H, W), not
        booleans, or empty.

    Examples
    --------
    >>> import numpy as np
    >>> from compact_distributions import Grid
    >>> Grid(64, 48).shape
    (48, 64)
    >>> disc = np.hypot(*np.mgrid[-24:24, -32:32] + 0.5) < 20
    >>> Grid(64, 48, disc).pixel_count
    1264
    """

    width: int
    height: int
    mask: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "width", whole_number(self.width, "width", minimum=1, maximum=MAX_SIDE))
        object.__setattr__(self, "height", whole_number(self.height, "height", minimum=1, maximum=MAX_SIDE))
        if self.mask is not None:
            try:
                m = np.ascontiguousarray(self.mask, dtype=bool)
            except (ValueError, TypeError) as exc:
                raise InputError(f"region (its mask) is not an array of booleans: {exc}") from None
            if m.shape != (self.height, self.width):
                raise InputError(
                    f"region (its mask) has shape {m.shape}, the raster is {self.width}x{self.height}: "
                    f"it must be ({self.height}, {self.width})"
                )
            if not m.any():
                raise InputError("region (its mask) is empty: no pixel is inside it")
            object.__setattr__(self, "mask", m)

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)``, the shape of the raster's arrays."""
        return (self.height, self.width)

    @property
    def pixel_count(self) -> int:
        """The number of pixels inside the region."""
        return int(self.mask.sum()) if self.mask is not None else self.width * self.height

    def inside(self) -> np.ndarray:
        """Return the region as an (H, W) bool array.

        Returns
        -------
        numpy.ndarray
            The mask itself, or a new array of True where there is no mask.
        """
        if self.mask is None:
            return np.ones(self.shape, dtype=bool)
        return self.mask


@dataclass
class Problem:
    """Everything that defines one CVT run, independent of the backend and the method.

    :func:`compact_distributions.problem` builds one from names and sizes; build it
    directly for a metric, density or field of your own.

    Parameters
    ----------
    grid : Grid
        The raster and the region.
    n_elements : int
        N, the number of sites (and elements), at least 1 and at most the region's
        pixels; the number of ``init_sites`` where those are given.
    metric : Metric, optional
        The Lloyd distance (:func:`compact_distributions.make_metric`); default ``l2``.
    density : DensityMap or None, optional
        Size from a density image (paper §3.3.1): denser means smaller cells.
    field : DirectionField or None, optional
        Direction of each element from a field (paper §3.3.2).
    seed : int, optional
        Seed of the initial sites (0 to 2**63 - 1).
    init_sites : numpy.ndarray or None, optional
        (N, 2) initial sites in pixel units, inside the raster; they replace the seeding
        and set ``n_elements``.
    walls : numpy.ndarray or None, optional
        (H, W) bool thin walls: pixels outside the region that separate parts of it (a
        picture's strong edges).  Cells stop at them like at any border; a method that
        can (compaction) brings elements up to the walls' centre lines.
    element : str or None, optional
        The element shape its cells hold (a name of the shape table or
        ``polygon:FILE``); None: the metric's own.

    Raises
    ------
    InputError
        If a value has the wrong type or is out of range: N larger than the region, a
        density or field or walls of another size than the raster, walls inside the
        region, an initial site off the raster.

    Examples
    --------
    >>> import compact_distributions as cd
    >>> p = cd.Problem(cd.Grid(64, 64), 16, cd.make_metric("linf"), seed=3)
    >>> p.n_elements, p.metric.name
    (16, 'linf')
    """

    grid: Grid
    n_elements: int
    metric: Metric = field(default_factory=lambda: make_metric(ELEMENT_METRIC[DEFAULT_ELEMENT]))
    density: DensityMap | None = None
    field: DirectionField | None = None
    seed: int = 0
    init_sites: np.ndarray | None = None
    walls: np.ndarray | None = None
    # the element shape its cells hold (a name or ``polygon:FILE``); None: the metric's own
    element: str | None = None

    def __post_init__(self) -> None:
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
        """Return each site's angle, read from the direction field where it stands.

        Parameters
        ----------
        sites : numpy.ndarray
            (N, 2) positions in pixel units.

        Returns
        -------
        numpy.ndarray
            (N,) angles in radians (zeros without a field).
        """
        if self.field is None:
            return np.zeros(len(sites))
        return self.field.angles_at(sites)

    def scales_at(self, sites: np.ndarray) -> np.ndarray:
        """Return each site's size factor, read from the density where it stands.

        Parameters
        ----------
        sites : numpy.ndarray
            (N, 2) positions in pixel units.

        Returns
        -------
        numpy.ndarray
            (N,) size factors (ones without a density).
        """
        if self.density is None:
            return np.ones(len(sites))
        return self.density.scales_at(sites)


def in_own_cell(labels: np.ndarray, points: npt.ArrayLike) -> np.ndarray:
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
