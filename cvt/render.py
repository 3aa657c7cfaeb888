"""Drawing placed elements and cells: the one raster renderer, the one SVG writer and the
colour helpers that every picture of the suite uses (``cvtbench run``, the figures, the
sweeps' effect pictures, the mosaics).

Raster: PIL ``ImageDraw.polygon`` at ``supersample`` times the size, reduced with a box
filter: antialiased edges and no ringing (a pixel inside an element keeps its colour).
SVG: ``viewBox="0 0 W H"`` in pixel units (the coordinates of the sites and polygons, y
down), ``width``/``height`` so that it opens at the raster's size, the background, the
region where it is not the whole raster, and one element per placed site: a closed
``<path>``, or an ``<ellipse>`` where the caller gives the exact ellipse.  Plain SVG 1.1,
no scripts or CSS.

Colours: user input goes through :func:`parse_colour` (a name, ``#rrggbb`` or (r, g, b)
in 0..1); fills may be '#rrggbb' strings, float arrays in 0..1 or uint8 arrays.
"""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np
import shapely

from .errors import InputError
from .pixels import pixel_index

DARK = "#202020"  # outside the region, and joints between elements
PAPER = "#f4f1ea"  # inside the region, where no element is
OUTLINE = "#303030"


# ------------------------------------------------------------------ colours
def parse_colour(value, name: str = "colour") -> tuple[float, float, float]:
    """A colour as a CSS name, ``#rrggbb`` or an (r, g, b) sequence in 0..1 -> floats 0..1."""
    if isinstance(value, (tuple, list, np.ndarray)):
        try:
            vals = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            vals = None
        if (
            vals is None
            or vals.shape != (3,)
            or not np.isfinite(vals).all()
            or vals.min() < 0
            or vals.max() > 1
        ):
            raise InputError(f"{name} must be three numbers in 0..1, got {value!r}")
        return tuple(float(v) for v in vals)
    from PIL import ImageColor

    try:
        rgb = ImageColor.getrgb(str(value))
    except ValueError:
        raise InputError(f"unknown {name} {value!r}; use a name like grey or #rrggbb") from None
    return tuple(v / 255.0 for v in rgb[:3])


def rgb8(colour) -> tuple[int, int, int]:
    """(r, g, b) in 0..255 from a '#rrggbb' string or name, a float triple in 0..1, or
    an integer (uint8) triple."""
    if isinstance(colour, str):
        return tuple(int(round(v * 255)) for v in parse_colour(colour))
    arr = np.asarray(colour)
    if np.issubdtype(arr.dtype, np.integer):
        return tuple(int(v) for v in arr[:3])
    return tuple(int(round(float(np.clip(v, 0, 1)) * 255)) for v in arr[:3])


def hex_colour(colour) -> str:
    r, g, b = rgb8(colour)
    return f"#{r:02x}{g:02x}{b:02x}"


def label_colours(n: int, seed: int = 12345) -> np.ndarray:
    """(n + 1, 3) uint8: distinct, well-spread colours per label; the last one (for -1,
    outside the region) is black."""
    import matplotlib.colors as mcolors

    rng = np.random.default_rng(seed)
    hue = (np.arange(n) * 0.618033988749895) % 1.0
    sat = 0.45 + 0.35 * rng.random(n)
    val = 0.70 + 0.30 * rng.random(n)
    out = np.zeros((n + 1, 3), dtype=np.uint8)
    out[:n] = np.round(mcolors.hsv_to_rgb(np.stack([hue, sat, val], axis=1)) * 255).astype(np.uint8)
    return out


# ------------------------------------------------------------------ rasters
def cells_image(labels: np.ndarray, n_elements: int, sites=None):
    """The cells in distinct colours (PIL image); sites drawn as dark dots if given."""
    from PIL import Image

    rgb = label_colours(n_elements)[np.where(labels >= 0, labels, n_elements)]
    if sites is not None:
        h, w = labels.shape
        rgb[pixel_index(sites, w, h)] = (20, 20, 20)
    return Image.fromarray(rgb, mode="RGB")


def draw_elements(
    elements,
    width: int,
    height: int,
    fills=None,
    *,
    background=DARK,
    region_colour=None,
    region_mask=None,
    scale: float = 1.0,
    supersample: int = 3,
    window=None,
    outline=None,
):
    """The elements as a PIL RGB image of ``scale`` times the raster's size.

    ``fills``: one colour per element (default :func:`label_colours`).  ``background``
    paints everything; where ``region_mask`` ((H, W) bool) is given, its inside is painted
    ``region_colour``; without a mask, ``region_colour`` (if given) paints the whole raster.
    ``window`` (x0, y0, x1, y1) in raster pixels draws only that part of the raster."""
    from PIL import Image, ImageDraw

    x0, y0, x1, y1 = (0.0, 0.0, float(width), float(height)) if window is None else map(float, window)
    ss = max(1, int(supersample))
    k = scale * ss
    big = (max(1, round((x1 - x0) * k)), max(1, round((y1 - y0) * k)))
    inside = rgb8(region_colour) if region_colour is not None else None
    if region_mask is None or inside is None:
        img = Image.new("RGB", big, inside if inside is not None else rgb8(background))
    else:
        m = np.asarray(region_mask, dtype=bool)
        rgb = np.where(m[..., None], np.array(inside, np.uint8), np.array(rgb8(background), np.uint8))
        full = Image.fromarray(rgb.astype(np.uint8), "RGB").resize(
            (max(1, round(width * k)), max(1, round(height * k))), Image.NEAREST
        )
        img = full.crop((round(x0 * k), round(y0 * k), round(x0 * k) + big[0], round(y0 * k) + big[1]))
    if fills is None:
        fills = label_colours(len(elements))
    line = rgb8(outline) if outline is not None else None
    draw = ImageDraw.Draw(img)
    for idx, geom in enumerate(elements):
        if geom is None or geom.is_empty:
            continue
        bx0, by0, bx1, by1 = geom.bounds
        if bx0 > x1 or by0 > y1 or bx1 < x0 or by1 < y0:
            continue
        fill = rgb8(fills[idx])
        for ring in _rings(geom):
            pts = [((float(x) - x0) * k, (float(y) - y0) * k) for x, y in ring]
            if len(pts) >= 3:
                draw.polygon(pts, fill=fill, outline=line)
    if ss > 1:
        img = img.resize((max(1, round((x1 - x0) * scale)), max(1, round((y1 - y0) * scale))), Image.BOX)
    return img


# ------------------------------------------------------------------ SVG
def _rings(geom):
    """Exterior and interior rings of a polygon or multipolygon, as (M, 2) arrays."""
    for poly in getattr(geom, "geoms", [geom]):
        if poly.is_empty:
            continue
        yield np.asarray(poly.exterior.coords)[:-1]
        for hole in poly.interiors:
            yield np.asarray(hole.coords)[:-1]


def _path_data(geom, digits: int = 3) -> str:
    """SVG path data: one closed subpath (M ... Z) per ring."""
    parts = []
    for ring in _rings(geom):
        pts = [f"{x:g},{y:g}" for x, y in np.round(ring, digits)]
        parts.append(f"M{pts[0]} L{' '.join(pts[1:])}Z")
    return "".join(parts)


def svg_document(elements, width: int, height: int, fills=None, **options) -> str:
    """The SVG document (text) of ``elements`` (shapely polygons, None entries skipped);
    the options are those of :func:`svg_lines`."""
    return "".join(svg_lines(elements, width, height, fills, **options))


def svg_lines(
    elements,
    width: int,
    height: int,
    fills=None,
    *,
    background=DARK,
    region_colour=PAPER,
    region=None,
    stroke=OUTLINE,
    stroke_width: float = 0.25,
    ellipses=None,
    digits: int = 3,
):
    """The SVG document of ``elements`` line by line (each ending in a newline), so that
    a large one can be written without being held whole.

    ``region``: a shapely geometry painted ``region_colour`` (default: the whole raster;
    ``region_colour=None`` paints nothing over the background).  ``ellipses``: an (N, 5)
    array (cx, cy, rx, ry, angle in degrees) to draw element k as an exact ``<ellipse>``
    instead of its polygon (a row with NaN keeps the polygon)."""
    if fills is None:
        fills = label_colours(len(elements))
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" version="1.1" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}">',
        f'<rect id="background" x="0" y="0" width="{width}" height="{height}" fill="{hex_colour(background)}"/>',
    ]
    if region_colour is not None:
        if region is None:
            out.append(
                f'<rect x="0" y="0" width="{width}" height="{height}" fill="{hex_colour(region_colour)}"/>'
            )
        else:
            out.append(
                f'<path d="{_path_data(region)}" fill="{hex_colour(region_colour)}" fill-rule="evenodd"/>'
            )
    stroke_attr = (
        ' stroke="none"' if stroke is None else f' stroke="{stroke}" stroke-width="{stroke_width:g}"'
    )
    out.append(f'<g id="elements"{stroke_attr} stroke-linejoin="round">')
    yield from (line + "\n" for line in out)
    fmt = f"{{:.{digits}f}}"
    for k, geom in enumerate(elements):
        if geom is None or geom.is_empty:
            continue
        fill = quoteattr(hex_colour(fills[k]))
        if ellipses is not None and np.isfinite(ellipses[k]).all():
            cx, cy, rx, ry, deg = (fmt.format(v) for v in ellipses[k])
            yield (
                f'<ellipse id="e{k}" cx="{cx}" cy="{cy}" rx="{rx}" ry="{ry}" '
                f'transform="rotate({deg} {cx} {cy})" fill={fill}/>\n'
            )
        else:
            yield f'<path id="e{k}" d="{_path_data(geom, digits)}" fill={fill}/>\n'
    yield "</g>\n</svg>\n"


def ellipse_parameters(centres, angles, sizes, semi_axes) -> np.ndarray:
    """(N, 5) (cx, cy, rx, ry, degrees) of elliptic elements of ``sizes`` whose unit
    ball has ``semi_axes`` (a, b)."""
    a, b = semi_axes
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    sizes = np.asarray(sizes, dtype=np.float64)
    return np.column_stack([centres, a * sizes, b * sizes, np.degrees(np.asarray(angles, dtype=np.float64))])


def element_coordinates(elements, digits: int = 3) -> list:
    """JSON-ready element outlines: per site a list of [x, y] vertices (the exterior ring,
    not closed), or None where the site has no element."""
    out = []
    for geom in elements:
        if geom is None or geom.is_empty:
            out.append(None)
            continue
        ring = shapely.get_coordinates(geom.exterior if hasattr(geom, "exterior") else geom)
        out.append(np.round(ring[:-1], digits).tolist())
    return out


__all__ = [
    "parse_colour",
    "rgb8",
    "hex_colour",
    "label_colours",
    "cells_image",
    "draw_elements",
    "svg_document",
    "svg_lines",
    "ellipse_parameters",
    "element_coordinates",
]
