"""Drawing placed elements: a vector SVG and a raster PNG.

SVG: ``viewBox="0 0 W H"`` in pixel units (the same coordinates as the sites and the
polygons, y down), ``width``/``height`` attributes so that it opens at the raster's size,
a background rectangle, the region (when it is not the whole raster) as one path, and one
closed ``<path>`` per placed element (skipped elements draw nothing).  Plain SVG 1.1, no
scripts or CSS, so browsers and Inkscape read it alike.

PNG: the same picture rasterised with PIL ``ImageDraw.polygon``, drawn at ``supersample``
times the size and reduced with a Lanczos filter, which smooths the edges.
"""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np
import shapely

BACKGROUND = "#202020"  # outside the region, and the joints between elements
REGION = "#f4f1ea"  # inside the region, where no element is
OUTLINE = "#303030"


def element_colours(n: int) -> np.ndarray:
    """(n, 3) uint8 distinct colours, one per site (the cell picture's palette)."""
    from .outputs import label_colours

    return label_colours(max(n, 1))[:n]


def _hex(rgb) -> str:
    r, g, b = (int(v) for v in rgb[:3])
    return f"#{r:02x}{g:02x}{b:02x}"


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


def elements_svg(elements, width: int, height: int, fills=None, region=None,
                 stroke: str | None = OUTLINE, stroke_width: float = 0.25) -> str:
    """The SVG document (text) of ``elements`` (shapely polygons, None entries skipped).

    ``fills``: one colour per element ((r, g, b) or '#rrggbb'); default: distinct colours.
    ``region``: a shapely geometry painted as the free area; default: the whole raster."""
    n = len(elements)
    if fills is None:
        fills = element_colours(n)
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" version="1.1" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}">',
        f'<rect x="0" y="0" width="{width}" height="{height}" fill="{BACKGROUND}"/>',
    ]
    if region is None:
        out.append(f'<rect x="0" y="0" width="{width}" height="{height}" fill="{REGION}"/>')
    else:
        out.append(f'<path d="{_path_data(region)}" fill="{REGION}" fill-rule="evenodd"/>')
    stroke_attr = "" if stroke is None else f' stroke="{stroke}" stroke-width="{stroke_width:g}"'
    out.append(f'<g id="elements"{stroke_attr} stroke-linejoin="round">')
    for k, geom in enumerate(elements):
        if geom is None or geom.is_empty:
            continue
        fill = fills[k] if isinstance(fills[k], str) else _hex(fills[k])
        out.append(f'<path id="e{k}" d="{_path_data(geom)}" fill={quoteattr(fill)}/>')
    out.append("</g>")
    out.append("</svg>")
    return "\n".join(out) + "\n"


def elements_png(elements, width: int, height: int, fills=None, region_mask=None,
                 scale: float = 1.0, supersample: int = 3, outline: bool = False):
    """The elements as a PIL RGB image of ``scale`` times the raster's size.

    ``region_mask`` ((H, W) bool): pixels outside the region are drawn dark."""
    from PIL import Image, ImageDraw

    n = len(elements)
    if fills is None:
        fills = element_colours(n)
    ss = max(1, int(supersample))
    k = scale * ss
    big_w, big_h = max(1, round(width * k)), max(1, round(height * k))
    region_rgb = tuple(int(REGION[i:i + 2], 16) for i in (1, 3, 5))
    if region_mask is None:
        img = Image.new("RGB", (big_w, big_h), region_rgb)
    else:
        m = np.asarray(region_mask, dtype=bool)
        bg = tuple(int(BACKGROUND[i:i + 2], 16) for i in (1, 3, 5))
        rgb = np.where(m[..., None], np.array(region_rgb, np.uint8), np.array(bg, np.uint8))
        img = Image.fromarray(rgb.astype(np.uint8), "RGB").resize((big_w, big_h), Image.NEAREST)
    draw = ImageDraw.Draw(img)
    line = tuple(int(OUTLINE[i:i + 2], 16) for i in (1, 3, 5)) if outline else None
    for idx, geom in enumerate(elements):
        if geom is None or geom.is_empty:
            continue
        fill = fills[idx]
        fill = tuple(int(fill[i:i + 2], 16) for i in (1, 3, 5)) if isinstance(fill, str) else tuple(
            int(v) for v in fill[:3])
        for ring in _rings(geom):
            pts = [(float(x) * k, float(y) * k) for x, y in ring]
            if len(pts) >= 3:
                draw.polygon(pts, fill=fill, outline=line)
    if ss > 1:
        img = img.resize((max(1, round(width * scale)), max(1, round(height * scale))), Image.LANCZOS)
    return img


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
