"""Picture to mosaic (paper §4.1, Figures 16-19): the Python API.

    >>> from compact_distributions.backends import create_backend
    >>> from compact_distributions.cvt.mosaic import make_mosaic
    >>> with create_backend("numpy") as backend:
    ...     m = make_mosaic("samples/shapes.png", backend, n_elements=1500, element="square")
    >>> m.coverage, len(m.sites), m.colours.shape
    >>> open("mosaic.svg", "w").write(m.svg())
    >>> m.render().save("mosaic.png")

Steps: the picture is read (any format Pillow reads, or a numpy array) and resampled to
the raster size; :mod:`cvt.image_fields` extracts a density map (smaller elements where
there is detail) and a direction field (element sides along the nearby edges); Lloyd
relaxation under the element's metric runs on the chosen backend with both fields;
:func:`cvt.placement.place_elements` puts one element in each cell; each element gets
the mean colour of the picture's pixels whose centres lie inside it; coverage comes from
:func:`compact_distributions.cvt.evaluate.evaluate`, the suite's one definition.

Colours are RGB floats in 0..1.  A numpy picture is (H, W) grey, (H, W, 3) RGB or
(H, W, 4) RGBA (composited on white, as :func:`cvt.images.load_rgb` does for files);
integer arrays are scaled by their type's full range (uint8 255, uint16 65535), float
arrays must already be in 0..1.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .evaluate import evaluate
from .image_fields import CONTRAST_RANGE, DEFAULT_CONTRAST, PictureFields, picture_fields
from .lloyd import final_labels, lloyd
from .metrics import AXIAL_METRICS, ELEMENT_METRIC, METRIC_NAMES, NATURAL_ELEMENT, compile_sites, make_metric
from .placement import parse_gap, place_elements
from .problem import Grid, Problem, parse_size, pixel_index
from .render import draw_elements, ellipse_parameters, parse_colour, svg_lines
from .resources import mosaic_estimate
from .shapes import ELEMENT_SHAPES, check_shape, element_ball, unit_outline
from .validate import live_backend, real_number, whole_number

DEFAULT_ELEMENTS = 2000
MAX_DEFAULT_SIDE = 1024  # the picture's own size, capped at this on the long side
AUTO_GAP = 0.05  # default grout: this share of the mean element spacing
DEFAULT_GROUT = (0.22, 0.22, 0.22)


# --------------------------------------------------------------------------- picture

def picture_array(image, at_least: tuple[int, int] | None = None, memory_limit=None,
                  name: str = "image") -> tuple[np.ndarray, str]:
    """(H, W, 3) float64 RGB in 0..1 and a short description of where it came from.

    A file is read by :func:`cvt.images.read_picture` (EXIF orientation applied, bombs
    refused, decoded at a reduced size no smaller than ``at_least`` when that is smaller
    than the picture, its decoding checked against ``memory_limit``)."""
    if isinstance(image, (str, os.PathLike)):
        from .images import load_rgb

        return load_rgb(image, at_least, name=name, memory_limit=memory_limit), os.fspath(image)
    arr = np.asarray(image)
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (1, 3, 4)):
        raise InputError(f"picture array must be (H, W), (H, W, 3) or (H, W, 4), got shape {arr.shape}")
    if arr.size == 0:
        raise InputError(f"picture array has no pixels (shape {arr.shape})")
    if arr.dtype == bool:
        arr = arr.astype(np.float64)
    elif np.issubdtype(arr.dtype, np.integer):
        info = np.iinfo(arr.dtype)
        if arr.min() < 0:
            raise InputError("integer picture arrays must not hold negative values")
        arr = arr.astype(np.float64) / float(info.max)
    elif np.issubdtype(arr.dtype, np.floating):
        arr = arr.astype(np.float64)
        if not np.isfinite(arr).all():
            raise InputError("picture array contains NaN or infinite values")
        if arr.min() < 0 or arr.max() > 1:
            raise InputError(f"float picture arrays must lie in 0..1, got {arr.min():g}..{arr.max():g}")
    else:
        raise InputError(f"picture array of dtype {arr.dtype} is not a numeric image")
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.shape[2] == 4:
        alpha = arr[..., 3:4]
        arr = arr[..., :3] * alpha + (1.0 - alpha)  # composite on white
    if arr.shape[2] == 1:
        arr = np.repeat(arr, 3, axis=2)
    return np.ascontiguousarray(arr), f"array {arr.shape[1]}x{arr.shape[0]}"


def raster_size(width: int, height: int, size=None, name: str = "size") -> tuple[int, int]:
    """The mosaic's raster for a ``width`` x ``height`` picture.

    ``None``: the picture's own size, shrunk (aspect kept) so that the long side is at
    most 1024 px.  A single number (``512`` or ``"512"``): the long side, aspect kept.
    ``"WxH"`` or ``(W, H)``: exactly that (the picture is stretched if its aspect
    differs)."""
    if size is None:
        long_side = min(max(width, height), MAX_DEFAULT_SIDE)
    elif isinstance(size, (tuple, list)):
        if len(size) != 2:
            raise InputError(f"{name} must be (W, H), got {size!r}")
        return parse_size(f"{size[0]}x{size[1]}", name)
    elif "x" in str(size).lower():
        return parse_size(size, name)
    else:
        long_side = parse_size(size, name)[0]
    k = long_side / max(width, height)
    return max(1, round(width * k)), max(1, round(height * k))


def resample(rgb: np.ndarray, width: int, height: int) -> np.ndarray:
    """The picture at (height, width): Lanczos (antialiased when shrinking), clipped to 0..1."""
    if rgb.shape[:2] == (height, width):
        return rgb
    from PIL import Image

    out = np.empty((height, width, 3))
    for c in range(3):
        img = Image.fromarray(np.ascontiguousarray(rgb[..., c], dtype=np.float32), mode="F")
        out[..., c] = np.asarray(img.resize((width, height), Image.Resampling.LANCZOS))
    return np.clip(out, 0.0, 1.0)


def resolve_shapes(metric: str | None, element: str | None) -> tuple[str, str]:
    """(metric, element): either one implies the other; neither means square tiles."""
    if element is not None:
        check_shape(element)
    if metric is not None and metric not in METRIC_NAMES:
        raise InputError(f"unknown metric {metric!r}; choose one of {', '.join(METRIC_NAMES)}")
    if metric is None and element is None:
        element = "square"
    if metric is None:
        metric = ELEMENT_METRIC[element]
    if element is None:
        element = NATURAL_ELEMENT[metric]
    return metric, element


# --------------------------------------------------------------------------- colours

def element_sizes(polygons, element: str, aspect: float) -> np.ndarray:
    """(N,) size of each placed element (0 where skipped), from its area: an element is a
    scaled copy of the unit outline, so size = sqrt(area / unit area)."""
    import shapely

    unit = shapely.area(shapely.polygons(unit_outline(element, aspect)))
    areas = np.array([0.0 if p is None else p.area for p in polygons])
    return np.sqrt(areas / unit)


def element_colours(picture: np.ndarray, labels: np.ndarray, sites, angles, sizes,
                    element: str, aspect: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean colour of the picture under each element, and the pixel count it came from.

    A pixel is under element k when it lies in cell k and its centre is inside the
    element (the element's own gauge <= its size, evaluated exactly).  An element that
    covers no pixel centre (tiny) or a skipped site takes the mean colour of its cell,
    and a site with an empty cell the colour of the pixel it sits on."""
    h, w = labels.shape
    n = len(sites)
    ball = element_ball(element, aspect)
    safe = np.where(sizes > 0, sizes, 1.0)
    coef = compile_sites(ball, sites, angles, safe)
    flat = labels.ravel()
    inside = np.flatnonzero(flat >= 0)
    owner = flat[inside]
    ys, xs = np.divmod(inside, w)
    d = coef.distance(owner, xs + 0.5, ys + 0.5)
    under = (d <= 1.0 + 1e-9) & (sizes[owner] > 0)
    pix = picture.reshape(-1, 3)

    def mean_over(idx, who):
        count = np.bincount(who, minlength=n).astype(np.float64)
        sums = np.stack([np.bincount(who, weights=pix[idx, c], minlength=n) for c in range(3)], axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return sums / count[:, None], count

    colours, count = mean_over(inside[under], owner[under])
    cell_colours, cell_count = mean_over(inside, owner)
    use_cell = count == 0
    colours[use_cell] = cell_colours[use_cell]
    none = use_cell & (cell_count == 0)
    if none.any():
        colours[none] = picture[pixel_index(sites[none], w, h)]
    return colours, count.astype(np.int64)


# --------------------------------------------------------------------------- result

@dataclass
class MosaicResult:
    """A picture turned into a mosaic: one element per site (``polygons[k]`` is None
    where the cell was empty or too small for an element)."""

    sites: np.ndarray  # (N, 2) pixel units of the mosaic raster
    angles: np.ndarray  # (N,) radians, positive = clockwise on screen
    scales: np.ndarray  # (N,) size factor from the density (1 without density)
    polygons: list  # shapely polygons, one per site, None where skipped
    colours: np.ndarray  # (N, 3) RGB in 0..1: the picture's mean colour under each element
    sizes: np.ndarray  # (N,) element size (1 = the unit ball: square side 2), 0 where skipped
    coverage: float  # cvt.evaluate: area(union of elements) / area(raster)
    overlap: float
    width: int
    height: int
    metric: str
    element: str
    aspect: float
    gap: float
    contrast: float = DEFAULT_CONTRAST
    grout: tuple = DEFAULT_GROUT
    picture: np.ndarray | None = field(default=None, repr=False)  # (H, W, 3) resampled input
    labels: np.ndarray | None = field(default=None, repr=False)  # final cells (H, W) int32
    fields: PictureFields | None = field(default=None, repr=False)
    problem: Problem | None = field(default=None, repr=False)
    energy: list = field(default_factory=list)
    seconds: list = field(default_factory=list)
    empty: list = field(default_factory=list)
    empty_sites: list = field(default_factory=list)
    backend: str = "numpy"
    device: str = ""
    source: str = ""
    total_seconds: float = 0.0

    @property
    def placed(self) -> int:
        return sum(p is not None for p in self.polygons)

    def svg(self, grout=None, precision: int = 2) -> str:
        """The mosaic as SVG text: a grout-coloured background and one filled element per
        placed site, in pixel units (viewBox = the raster).  Squares, rectangles and
        triangles are paths with their exact corners; circles and ellipses are
        ``<ellipse>``s rotated by the site's angle."""
        return "".join(self.svg_lines(grout, precision))

    def svg_lines(self, grout=None, precision: int = 2):
        """:meth:`svg` line by line (to write a large mosaic without holding its text)."""
        grout = self.grout if grout is None else parse_colour(grout, "grout")
        ellipses = None
        if self.element in ("circle", "ellipse"):
            ellipses = ellipse_parameters(self.sites, self.angles, self.sizes,
                                          element_ball(self.element, self.aspect).semi_axes)
        return svg_lines(self.polygons, self.width, self.height, self.colours, background=grout,
                         region_colour=None, stroke=None, ellipses=ellipses, digits=precision)

    def render(self, scale: float = 1.0, grout=None, supersample: int = 3):
        """The mosaic as a PIL RGB image ``scale`` times the raster size (antialiased)."""
        grout = self.grout if grout is None else parse_colour(grout, "grout")
        return draw_elements(self.polygons, self.width, self.height, self.colours, background=grout,
                             scale=scale, supersample=supersample)

    def to_distribution(self):
        """The run as a :class:`cvt.distribution.Distribution` (what bench/ reports)."""
        from .distribution import Distribution

        return Distribution(method="ours", sites=self.sites, angles=self.angles, scales=self.scales,
                            elements=self.polygons, energy=list(self.energy), seconds=list(self.seconds),
                            total_seconds=self.total_seconds, empty=list(self.empty),
                            empty_sites=list(self.empty_sites), labels=self.labels)


# --------------------------------------------------------------------------- the API

def make_mosaic(image, backend, *, n_elements: int = DEFAULT_ELEMENTS, metric: str | None = None,
                element: str | None = None, size=None, gap: float | None = None,
                use_field: bool = True, use_density: bool = True, iterations: int = 20,
                seed: int = 0, aspect: float | None = None, contrast: float = DEFAULT_CONTRAST,
                grout=DEFAULT_GROUT, progress=None, memory_limit=None) -> MosaicResult:
    """Turn ``image`` (a file path or a numpy array) into a mosaic of ``n_elements``.

    ``metric``/``element``: the Lloyd distance and the placed shape; give either (the
    other follows: square <-> linf, rectangle <-> linf-axial, ellipse <-> l2-axial,
    triangle <-> triangle, circle <-> l2), both, or neither (squares).  ``aspect``: β of
    rectangles and ellipses (default 0.5).  ``size``: raster (see :func:`raster_size`;
    default the picture's size, long side capped at 1024).  ``backend``: a live
    backend (``compact_distributions.backends.create_backend``), left open.  ``gap``: grout width in
    pixels (default ``None``: 5 % of the mean element spacing sqrt(W·H/N), e.g. 1 px for
    2000 elements on 1024x768).  ``use_field``: align element sides with the picture's edges; ``use_density``:
    smaller elements where the picture has detail (``contrast`` = densest / sparsest
    cell area, 1 to 100).  ``progress(k, iterations, energy)`` is called after each Lloyd
    step.  ``memory_limit`` (bytes or a size such as ``"8G"``; default what the machine
    has available) refuses, before any work, a mosaic estimated to need more
    (:mod:`cvt.resources`)."""
    t_start = time.perf_counter()
    live_backend(backend)
    n_elements = whole_number(n_elements, "n_elements", minimum=1)
    iterations = whole_number(iterations, "iterations", minimum=0)
    seed = whole_number(seed, "seed", minimum=0)
    contrast = real_number(contrast, "contrast", *CONTRAST_RANGE)
    grout = parse_colour(grout, "grout")
    metric_name, element = resolve_shapes(metric, element)
    metric_obj = make_metric(metric_name, aspect)
    # β of the placed shape: the metric's own for the axial metrics, else the one given
    # (validated like the metric's), default 0.5 for rectangles and ellipses
    shape_aspect = (metric_obj.aspect if metric_name in AXIAL_METRICS
                    else make_metric("linf-axial", aspect).aspect)

    if isinstance(image, (str, os.PathLike)):
        from .images import open_picture, upright_size

        with open_picture(image, "image") as header:
            pw, ph = upright_size(header)
        rgb = None
    else:
        rgb, source = picture_array(image)
        ph, pw = rgb.shape[:2]
    w, h = raster_size(pw, ph, size)
    if n_elements > w * h:
        raise InputError(f"{n_elements} elements do not fit in a {w}x{h} raster "
                         f"(from a {pw}x{ph} picture); "
                         f"use fewer elements or a larger size (--size)")
    mosaic_estimate(w, h, n_elements, type(backend), element=element).check(
        memory_limit, lower="use a smaller size or fewer elements", name="memory_limit")
    if rgb is None:
        rgb, source = picture_array(image, at_least=(w, h), memory_limit=memory_limit)
    picture = resample(rgb, w, h)
    del rgb
    spacing = math.sqrt(w * h / n_elements)
    gap = AUTO_GAP * spacing if gap is None else parse_gap(gap)
    fields = picture_fields(picture, spacing, element, contrast=contrast)
    problem = Problem(Grid(w, h), n_elements, metric_obj,
                      density=fields.density if use_density else None,
                      field=fields.field if use_field else None, seed=seed)

    res = lloyd(problem, backend, iterations, progress=progress)
    labels = final_labels(problem, backend, res)
    grid = problem.grid
    polygons = place_elements(labels, res.sites, res.angles, element, shape_aspect, grid, gap)
    sizes = element_sizes(polygons, element, shape_aspect)
    colours, _ = element_colours(picture, labels, res.sites, res.angles, sizes, element, shape_aspect)
    ev = evaluate(polygons, grid)
    return MosaicResult(
        sites=res.sites, angles=res.angles, scales=res.scales, polygons=polygons,
        colours=colours, sizes=sizes, coverage=ev.coverage, overlap=ev.overlap,
        width=w, height=h, metric=metric_name, element=element, aspect=shape_aspect, gap=gap, contrast=contrast,
        grout=grout, picture=picture, labels=labels, fields=fields, problem=problem, energy=res.energy,
        seconds=res.seconds, empty=res.empty, empty_sites=list(res.empty_sites),
        backend=backend.variant, device=backend.device(), source=source,
        total_seconds=time.perf_counter() - t_start,
    )


__all__ = ["make_mosaic", "MosaicResult", "picture_array", "raster_size", "resample",
           "resolve_shapes", "element_colours", "ELEMENT_SHAPES"]
