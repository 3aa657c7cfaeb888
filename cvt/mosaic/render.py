"""Drawing placed elements and cells: the one raster renderer, the one SVG writer and the
colour helpers that every picture of the suite uses (``cvtbench run``, the figures, the
sweeps' effect pictures, the mosaics).

Raster: PIL ``ImageDraw.polygon`` at ``supersample`` times the size, reduced to the mean
of each supersample x supersample block (Pillow's ``reduce``; a box filter where the size
is no whole number of blocks): antialiased edges and no ringing (a pixel inside an
element keeps its colour).
SVG: ``viewBox="0 0 W H"`` in pixel units (the coordinates of the sites and polygons, y
down), ``width``/``height`` so that it opens at the raster's size, the background, the
region where it is not the whole raster, and one element per placed site: a closed
``<path>``, or an ``<ellipse>`` where the caller gives the exact ellipse.  Plain SVG 1.1,
no scripts or CSS.

Colours: user input goes through :func:`parse_colour` (a name, ``#rrggbb`` or (r, g, b)
in 0..1); fills may be '#rrggbb' strings, float arrays in 0..1 or uint8 arrays.
"""

from __future__ import annotations

import functools

import numpy as np
import shapely

from ..errors import InputError
from ..evaluate import exterior_rings
from ..pixels import index_ranges, pixel_index
from ..threads import in_order
from .numbers import ring_texts

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


def hex_colours(fills) -> list[str]:
    """:func:`hex_colour` of every colour of ``fills``, by one format call per block.

    Parameters
    ----------
    fills : (N, 3) array or sequence of colours
        As :func:`fill_rows` reads them.

    Returns
    -------
    list of N '#rrggbb' strings
    """
    rgb = fill_rows(fills, len(fills))
    return [line[:-1] for line in format_rows("#{:02x}{:02x}{:02x}\n", list(rgb.T))]


# per sixth of the hue circle, which of (v, t, p, q) are red, green and blue: HSV to RGB
# as matplotlib.colors.hsv_to_rgb computes it (saturation > 0), without importing matplotlib
_HSV_SECTORS = np.array([[0, 1, 2], [3, 0, 2], [2, 0, 1], [2, 3, 0], [1, 2, 0], [0, 2, 3]])


def label_colours(n: int, seed: int = 12345) -> np.ndarray:
    """(n + 1, 3) uint8: distinct, well-spread colours per label; the last one (for -1,
    outside the region) is black."""
    rng = np.random.default_rng(seed)
    hue = (np.arange(n) * 0.618033988749895) % 1.0
    sat = 0.45 + 0.35 * rng.random(n)
    val = 0.70 + 0.30 * rng.random(n)
    sector = (hue * 6.0).astype(int)
    f = hue * 6.0 - sector
    vtpq = np.stack([val, val * (1.0 - sat * (1.0 - f)), val * (1.0 - sat), val * (1.0 - sat * f)])
    rgb = vtpq[_HSV_SECTORS[sector % 6], np.arange(n)[:, None]]
    out = np.zeros((n + 1, 3), dtype=np.uint8)
    out[:n] = np.round(rgb * 255).astype(np.uint8)
    return out


def fill_rows(fills, n: int) -> np.ndarray:
    """(n, 3) int: the first ``n`` of ``fills`` as :func:`rgb8` reads each one (an array
    of numbers at once, anything else colour by colour)."""
    if isinstance(fills, np.ndarray) and fills.ndim == 2 and fills.shape[1] >= 3 and len(fills) >= n:
        if np.issubdtype(fills.dtype, np.integer):
            return fills[:n, :3].astype(np.int64)
        if np.issubdtype(fills.dtype, np.floating) and np.isfinite(fills[:n, :3]).all():
            return np.round(np.clip(fills[:n, :3].astype(np.float64), 0, 1) * 255).astype(np.int64)
    return np.array([rgb8(fills[k]) for k in range(n)], dtype=np.int64).reshape(n, 3)


def _exteriors(polygons: np.ndarray):
    """The exterior rings of shapely ``polygons`` (not closed): their vertices as one
    (P, 2) array and each ring's vertex count."""
    xy, ring = shapely.get_coordinates(exterior_rings(polygons), return_index=True)
    counts = np.bincount(ring, minlength=len(polygons))
    closing = np.zeros(len(xy), dtype=bool)
    closing[np.cumsum(counts) - 1] = True  # each ring repeats its first vertex last
    return xy[~closing], counts - 1


def _geometries(elements) -> np.ndarray:
    """``elements`` as a 1-D object array (itself if it is one)."""
    if isinstance(elements, np.ndarray) and elements.dtype == object and elements.ndim == 1:
        return elements
    geoms = np.empty(len(elements), dtype=object)
    geoms[:] = list(elements)
    return geoms


def _blocks(geoms: np.ndarray, which: np.ndarray, budget: int = 1 << 16):
    """``which`` cut into consecutive blocks of about ``budget`` vertices (at least one
    element each): what is converted to Python objects at once stays small."""
    ends = np.cumsum(shapely.get_num_coordinates(geoms[which]))
    cuts = np.searchsorted(ends, np.arange(budget, ends[-1], budget), side="right") if len(ends) else []
    edges = np.unique(np.concatenate([[0], cuts, [len(which)]])).astype(int)
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        yield which[lo:hi]


def _ring_table(elements, which=None):
    """The rings of ``elements`` (of those listed in ``which``; default: all that are
    neither None nor empty) as :func:`_rings` gives them, element by element: their
    vertices as one (P, 2) array, and per ring its element and vertex count.  Polygons
    without holes are read at once; other geometries one by one."""
    geoms = _geometries(elements)
    if which is None:
        which = np.flatnonzero(shapely.is_geometry(geoms) & ~shapely.is_empty(geoms))
    simple = (shapely.get_type_id(geoms[which]) == 3) & (shapely.get_num_interior_rings(geoms[which]) == 0)
    xy, count = _exteriors(geoms[which[simple]])
    element = which[simple]
    if simple.all():
        return xy, element, count
    parts = [(element, count, xy)]
    for k in which[~simple]:
        rings = list(_rings(geoms[k]))
        if rings:
            parts.append((np.full(len(rings), k), np.array([len(r) for r in rings]), np.concatenate(rings)))
    element = np.concatenate([p[0] for p in parts])
    count = np.concatenate([p[1] for p in parts])
    xy = np.concatenate([p[2] for p in parts])
    order = np.argsort(element, kind="stable")
    return xy[index_ranges((np.cumsum(count) - count)[order], count[order])], element[order], count[order]


def format_rows(template: str, columns) -> list[str]:
    """``template`` (one line: a newline at its end, none before) filled with row i of
    ``columns`` (equal-length sequences) for every i: one line per row, made by one
    ``str.format`` call per block of rows (bounded memory)."""
    rows = len(columns[0]) if columns else 0
    step = max(1, (1 << 16) // max(1, len(columns)))
    out: list[str] = []
    for lo in range(0, rows, step):
        part = [c[lo : lo + step] for c in columns]
        table = np.empty((len(part[0]), len(part)), dtype=object)
        for j, column in enumerate(part):  # Python numbers: {!r} as json writes them
            table[:, j] = column.tolist() if isinstance(column, np.ndarray) else list(column)
        text = (template * len(table)).format(*table.ravel().tolist())
        out += [line + "\n" for line in text.split("\n")[:-1]]
    return out


def _ring_texts(xy, count, template_of, digits: int | None = None) -> np.ndarray:
    """Per ring (``count`` vertices each, ``xy`` one ring after another) the text
    ``template_of(V)`` (V vertices) filled with its x0, y0, x1, y1, ...: one format
    call per distinct vertex count.  The JSON and SVG rings of ``xy`` rounded to
    ``digits`` decimals are built whole-array (:func:`numbers.ring_texts`) where it can."""
    style = {_svg_ring: "svg", _json_ring: "json"}.get(template_of)
    if digits is not None and style is not None:
        built = ring_texts(xy, count, digits, style)
        if built is not None:
            out = np.empty(len(built), dtype=object)
            out[:] = built
            return out
    starts = np.cumsum(count) - count
    out = np.empty(len(count), dtype=object)
    for v in np.unique(count).tolist():
        rings = np.flatnonzero(count == v)
        pts = xy[index_ranges(starts[rings], count[rings])].reshape(len(rings), 2 * v)
        out[rings] = [t[:-1] for t in format_rows(template_of(v) + "\n", list(pts.T))]
    return out


def _svg_ring(v: int) -> str:
    return "M{:g},{:g} L" + " ".join(["{:g},{:g}"] * (v - 1)) + "Z"


def _json_ring(v: int) -> str:
    return "[" + ", ".join(["[{!r}, {!r}]"] * v) + "]"


# ------------------------------------------------------------------ rasters
class CellRows:
    """The pixels of :func:`cells_image` a band of rows at a time, for a writer that
    streams them (``bench.outputs.write_png``) without the whole picture in memory.

    Parameters
    ----------
    labels : (H, W) int array
        The label raster (-1 outside the region).
    n_elements : int
        The number of sites (labels 0 .. N - 1).
    sites : (N, 2) array or None, optional
        Drawn as dark dots where given.

    Attributes
    ----------
    size : tuple of int
        (W, H).
    """

    def __init__(self, labels: np.ndarray, n_elements: int, sites=None):
        self.labels, self.n_elements = labels, n_elements
        h, w = labels.shape
        self.size = (w, h)
        rgb = label_colours(n_elements).astype("<u4")
        self._packed = (
            rgb[:, 0] | rgb[:, 1] << 8 | rgb[:, 2] << 16
        )  # one 4-byte gather per pixel: R, G, B, pad
        self._dark = None if sites is None else pixel_index(sites, w, h)

    def packed(self, lo: int, hi: int) -> np.ndarray:
        """(hi - lo, W) uint32: rows lo .. hi - 1 as R | G << 8 | B << 16."""
        part = self.labels[lo:hi]
        # label -1 (outside) takes the last colour by numpy's own negative indexing
        pixels = self._packed[
            part if part.min(initial=0) >= -1 else np.where(part >= 0, part, self.n_elements)
        ]
        if self._dark is not None:
            i, j = self._dark
            at = (i >= lo) & (i < hi)
            pixels[i[at] - lo, j[at]] = 20 | 20 << 8 | 20 << 16
        return pixels

    def rows(self, lo: int, hi: int) -> np.ndarray:
        """(hi - lo, W, 3) uint8: rows lo .. hi - 1 in RGB."""
        return self.packed(lo, hi).view(np.uint8).reshape(hi - lo, self.size[0], 4)[:, :, :3]


def cells_image(labels: np.ndarray, n_elements: int, sites=None):
    """The cells in distinct colours (PIL image); sites drawn as dark dots if given."""
    from PIL import Image

    h, w = labels.shape
    pixels = CellRows(labels, n_elements, sites).packed(0, h)
    return Image.frombuffer("RGBX", (w, h), np.ascontiguousarray(pixels), "raw", "RGBX", 0, 1).convert("RGB")


BAND_BYTES = 8 << 20  # a supersampled picture is drawn in bands of about this size


class RowStream:
    """A row source (``size``, ``rows(lo, hi)``: what :func:`bench.outputs.png_chunks`
    reads) over bands of rows made in order: rows are asked for in increasing order, and
    a band is dropped once it is read past, so the picture is never whole in memory.

    Parameters
    ----------
    size : tuple of int
        (W, H) of the picture.
    bands : iterable
        (first row, (n, W, 3) uint8 array) pairs, consecutive, from row 0.
    """

    def __init__(self, size, bands):
        self.size = tuple(size)
        self._bands = iter(bands)
        self._buffer = np.empty((0, self.size[0], 3), dtype=np.uint8)
        self._start = 0

    def rows(self, lo: int, hi: int) -> np.ndarray:
        """(hi - lo, W, 3) uint8: rows lo .. hi - 1 (lo never below an earlier call's)."""
        if lo < self._start:
            raise ValueError(f"rows {lo}..{hi} were already passed (at {self._start})")
        self._buffer, self._start = self._buffer[lo - self._start :], lo
        parts, have = [self._buffer], lo + len(self._buffer)
        while have < hi:
            first, band = next(self._bands)
            if first != have:
                raise ValueError(f"a band starts at row {first}, not {have}")
            parts.append(band)
            have += len(band)
        if len(parts) > 1:
            self._buffer = np.concatenate(parts)
        return self._buffer[: hi - lo]


class _Painter:
    """Draws elements on a band of the supersampled picture: ``paint(img, top, which)``
    draws elements ``which`` on ``img``, rows top .. top + height of the picture, their
    vertices read a block of elements at a time (bounded memory)."""

    def __init__(self, elements, fills, origin, k: float, line):
        self.geoms = _geometries(elements)
        self.rgb = fill_rows(fills, len(elements))
        self.origin, self.k, self.line = origin, k, line

    def paint(self, img, top: int, which) -> None:
        from PIL import ImageDraw

        draw = ImageDraw.Draw(img)
        # without an outline, ImageDraw.polygon is its core's fill call: made directly
        core, ink = draw.draw, draw.draw.draw_ink
        (x0, y0), k, geoms = self.origin, self.k, self.geoms
        for block in _blocks(geoms, which):
            xy, element, count = _ring_table(geoms, block)
            px, py = (xy[:, 0] - x0) * k, (xy[:, 1] - y0) * k - top  # whole-pixel move: exact
            pts, at = np.stack([px, py], axis=1).ravel().tolist(), 0
            for colour, n in zip(map(tuple, self.rgb[element].tolist()), count.tolist(), strict=True):
                if n >= 3 and self.line is None:
                    core.draw_polygon(pts[at : at + 2 * n], ink(colour), 1)
                elif n >= 3:
                    draw.polygon(pts[at : at + 2 * n], fill=colour, outline=self.line)
                at += 2 * n


def _reduce(img, ss: int, size, box=None):
    """``img`` (its ``box``) reduced to ``size`` by Pillow's BOX resize (kept rather than
    ``reduce``, which is faster but rounds once instead of twice: pictures would move by
    one level wherever a block is not one colour)."""
    from PIL import Image

    return img.resize(size, Image.BOX, box=box)


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
    as_rows: bool = False,
):
    """The elements as a PIL RGB image of ``scale`` times the raster's size (``as_rows``:
    a :class:`RowStream` of its rows instead, drawn as they are read, where the picture
    is drawn in bands).

    ``fills``: one colour per element (default :func:`label_colours`).  ``background``
    paints everything; where ``region_mask`` ((H, W) bool) is given, its inside is painted
    ``region_colour``; without a mask, ``region_colour`` (if given) paints the whole raster.
    ``window`` (x0, y0, x1, y1) in raster pixels draws only that part of the raster.

    A supersampled picture of the whole raster is drawn and reduced band by band (rows
    in whole boxes of the reduction, each polygon moved by whole pixels): the same image
    as one drawn at once, in a fixed amount of memory."""
    from PIL import Image

    x0, y0, x1, y1 = (0.0, 0.0, float(width), float(height)) if window is None else map(float, window)
    ss = max(1, int(supersample))
    k = scale * ss
    big = (max(1, round((x1 - x0) * k)), max(1, round((y1 - y0) * k)))
    small = (max(1, round((x1 - x0) * scale)), max(1, round((y1 - y0) * scale)))
    inside = rgb8(region_colour) if region_colour is not None else None
    masked = region_mask is not None and inside is not None
    if fills is None:
        fills = label_colours(len(elements))
    line = rgb8(outline) if outline is not None else None

    # the elements that reach the window; their vertical extent in the picture's pixels
    painter = _Painter(elements, fills, (x0, y0), k, line)
    b = shapely.bounds(painter.geoms)
    with np.errstate(invalid="ignore"):
        shown = np.isfinite(b[:, 0]) & ~((b[:, 0] > x1) | (b[:, 1] > y1) | (b[:, 2] < x0) | (b[:, 3] < y0))
    shown = np.flatnonzero(shown)
    top_y, bottom_y = (b[shown, 1] - y0) * k, (b[shown, 3] - y0) * k
    paint = painter.paint

    banded = ss > 1 and window is None and big == (small[0] * ss, small[1] * ss)
    if masked:
        banded = banded and float(k).is_integer()
        m = np.asarray(region_mask, dtype=bool)
        colours = np.array([rgb8(background), inside], dtype=np.uint8)
    if not banded:
        if not masked:
            img = Image.new("RGB", big, inside if inside is not None else rgb8(background))
        else:
            full = Image.fromarray(colours[m.astype(np.uint8)], "RGB").resize(
                (max(1, round(width * k)), max(1, round(height * k))), Image.NEAREST
            )
            img = full.crop((round(x0 * k), round(y0 * k), round(x0 * k) + big[0], round(y0 * k) + big[1]))
        paint(img, 0, shown)
        if ss > 1:
            img = _reduce(img, ss, small)
        return img
    step = int(np.lcm(int(k), ss)) if masked else ss
    rows = max(step, BAND_BYTES // (3 * big[0]) // step * step)

    def draw_band(top):
        # PIL fills a polygon that crosses an image's edge differently from one that
        # does not: each band is drawn tall enough to hold whole every polygon it shows
        n_rows = min(rows, big[1] - top)
        near = (bottom_y >= top - 2) & (top_y <= top + n_rows + 2)
        lo = int(np.floor(min(top, top_y[near].min(initial=top)))) - 2
        hi = int(np.ceil(max(top + n_rows, bottom_y[near].max(initial=top)))) + 2
        lo, hi = max(0, lo // step * step), min(big[1], -(-hi // step) * step)
        if masked:  # the mask's rows, each pixel repeated k times (what NEAREST gives)
            part = m[lo // int(k) : hi // int(k)].astype(np.uint8)
            img = Image.fromarray(np.repeat(np.repeat(colours[part], int(k), axis=0), int(k), axis=1), "RGB")
        else:
            img = Image.new("RGB", (big[0], hi - lo), inside if inside is not None else rgb8(background))
        paint(img, lo, shown[near])
        box = (0, top - lo, big[0], top - lo + n_rows)  # the band's own rows, no cropped copy
        return top // ss, _reduce(img, ss, (small[0], n_rows // ss), box)

    def bands():
        # the bands drawn on the pool, a core's worth at once, taken in order (Pillow's
        # reduction lets go of the GIL while the next band's polygons are drawn)
        return in_order(functools.partial(draw_band, top) for top in range(0, big[1], rows))

    if as_rows:
        return RowStream(small, ((first, np.asarray(band)) for first, band in bands()))
    out = Image.new("RGB", small)
    for first, band in bands():
        out.paste(band, (0, first))
    return out


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
    yield from _svg_elements(elements, fills, ellipses, digits)
    yield "</g>\n</svg>\n"


def _svg_elements(elements, fills, ellipses, digits: int):
    """The ``<path>`` or ``<ellipse>`` line of every element that is neither None nor
    empty, in order, a block of elements at a time: the text of each kind built by one
    format call per vertex count."""
    geoms = _geometries(elements)
    present = np.flatnonzero(shapely.is_geometry(geoms) & ~shapely.is_empty(geoms))
    rgb = fill_rows(fills, len(elements))
    exact = np.zeros(len(elements), dtype=bool)
    if ellipses is not None:
        ellipses = np.asarray(ellipses, dtype=np.float64)
        exact[present] = np.isfinite(ellipses[present]).all(axis=1)
    for which in _blocks(geoms, present):
        lines = np.empty(len(which), dtype=object)
        paths = np.flatnonzero(~exact[which])
        if len(paths):
            xy, element, count = _ring_table(geoms, which[paths])
            rings = _ring_texts(np.round(xy, digits), count, _svg_ring, digits)
            firsts = np.flatnonzero(np.r_[True, element[1:] != element[:-1]])
            data = rings if len(firsts) == len(rings) else np.add.reduceat(rings, firsts)
            ids = element[firsts]
            lines[np.searchsorted(which, ids)] = format_rows(
                '<path id="e{}" d="{}" fill="#{:02x}{:02x}{:02x}"/>\n', [ids, data, *rgb[ids].T]
            )
        shapes = which[exact[which]]
        if len(shapes):
            cx, cy, rx, ry, deg = ellipses[shapes].T
            f = f"{{:.{digits}f}}"
            lines[np.searchsorted(which, shapes)] = format_rows(
                f'<ellipse id="e{{}}" cx="{f}" cy="{f}" rx="{f}" ry="{f}" transform="rotate({f} {f} {f})" '
                'fill="#{:02x}{:02x}{:02x}"/>\n',
                [shapes, cx, cy, rx, ry, deg, cx, cy, *rgb[shapes].T],
            )
        yield from lines.tolist()


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


def element_coordinates_json(elements, digits: int = 3) -> list[str]:
    """The JSON text of each outline of :func:`element_coordinates` ("null" for none),
    the polygons' built by one format call per vertex count."""
    import json

    geoms = _geometries(elements)
    out = np.full(len(elements), "null", dtype=object)
    present = shapely.is_geometry(geoms) & ~shapely.is_empty(geoms)
    polygons = np.flatnonzero(present & (shapely.get_type_id(geoms) == 3))
    xy, count = _exteriors(geoms[polygons])
    out[polygons] = _ring_texts(np.round(xy, digits), count, _json_ring, digits)
    for k in np.flatnonzero(present & (shapely.get_type_id(geoms) != 3)).tolist():
        out[k] = json.dumps(element_coordinates([geoms[k]], digits)[0])
    return out.tolist()


__all__ = [
    "RowStream",
    "parse_colour",
    "rgb8",
    "hex_colour",
    "hex_colours",
    "label_colours",
    "CellRows",
    "cells_image",
    "draw_elements",
    "svg_document",
    "svg_lines",
    "ellipse_parameters",
    "element_coordinates",
    "element_coordinates_json",
    "fill_rows",
    "format_rows",
    "BAND_BYTES",
]
