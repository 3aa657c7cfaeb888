"""Picture to mosaic (paper §4.1, Figures 16-19): the Python API.

    >>> from compact_distributions.backends import create_backend
    >>> from compact_distributions.cvt.mosaic.pipeline import make_mosaic
    >>> with create_backend("numpy") as backend:
    ...     m = make_mosaic("samples/shapes.png", backend, n_elements=1500, element="square")
    >>> m.coverage, len(m.sites), m.colours.shape
    >>> open("mosaic.svg", "w").write(m.svg())
    >>> m.render().save("mosaic.png")

Steps: the picture is read (any format Pillow reads, or a numpy array) and resampled to
the raster size; :mod:`cvt.image_fields` extracts a density map (smaller tiles where
there is detail), a direction field (tile sides along the nearby edges) and the strong
edges, which become walls: their pixels are taken out of the problem's region.  A method
(the method interface of :mod:`cvt.methods`: Lloyd relaxation under the tile's metric on
the chosen backend, then one tile per cell, and for ``ours-compact`` tiles that share
their walls) places the tiles inside that region, so no tile crosses a wall; the tiles of
``ours-compact`` beside a wall are then cut to fit it (:mod:`cvt.cutting`).  Each tile
is then filled with the geometric median, in CIELAB, of the picture's pixels whose
centres lie in its final polygon.  Coverage and overlap come from
:func:`compact_distributions.cvt.evaluate.evaluate` over the whole picture; the colour
error and the share of tiles that straddle a strong edge from the same module.

Colours are RGB floats in 0..1.  A numpy picture is (H, W) grey, (H, W, 3) RGB or
(H, W, 4) RGBA (composited on white, as :func:`cvt.images.load_rgb` does for files);
integer arrays are scaled by their type's full range (uint8 255, uint16 65535), float
arrays must already be in 0..1.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..distribution import Distribution
from ..errors import InputError
from ..evaluate import Evaluation, colour_error, evaluate, pixels_under, straddling_tiles
from ..metrics import make_metric
from ..moments import Moments, moments_from_runs
from ..pixels import index_ranges, pixel_index
from ..placement.fit import parse_gap
from ..problem import Grid, Problem, parse_size
from ..registry import resolve_method
from ..resources import mosaic_estimate
from ..shapes import ELEMENT_SHAPES, element_ball, resolve_shapes, shape_record, unit_outline
from ..threads import in_order, on_its_own_thread, side_by_side
from ..validate import live_backend, real_number, whole_number
from .colour import lab_to_srgb, quantised, srgb_to_lab
from .cutting import CUT_STYLES, cut_to_walls
from .image_fields import (
    CONTRAST_RANGE,
    DEFAULT_CONTRAST,
    DEFAULT_EDGE_THRESHOLD,
    PictureFields,
    picture_fields,
    picture_fields_later,
    strong_edges,
)
from .render import draw_elements, ellipse_parameters, parse_colour, svg_lines

# The method that places the tiles when none is named: compaction, whose tiles share their
# walls with the grout asked for.
DEFAULT_METHOD = "ours-compact"
DEFAULT_ELEMENTS = 2000
MAX_DEFAULT_SIDE = 1024  # the picture's own size, capped at this on the long side
AUTO_GAP = 0.05  # default grout: this share of the mean element spacing
DEFAULT_GROUT = (0.22, 0.22, 0.22)
# strong edges shorter than this many element spacings are no walls: no tile row can
# line up along them, and each would only cut a tile or two
EDGE_MIN_LENGTH = 2.0


# --------------------------------------------------------------------------- picture


def picture_array(
    image, at_least: tuple[int, int] | None = None, memory_limit=None, name: str = "image"
) -> tuple[np.ndarray, str]:
    """(H, W, 3) RGB in 0..1 and a short description of where it came from: float32 for a
    float32 array (a picture :func:`resample` made), float64 otherwise.

    A file is read by :func:`cvt.images.read_picture` (EXIF orientation applied, bombs
    refused, decoded at a reduced size no smaller than ``at_least`` when that is smaller
    than the picture, its decoding checked against ``memory_limit``)."""
    if isinstance(image, (str, os.PathLike)):
        from .images import load_rgb

        return load_rgb(image, at_least, name=name, memory_limit=memory_limit), os.fspath(image)
    try:
        arr = np.asarray(image)
    except (ValueError, TypeError) as exc:  # ragged nested lists, objects numpy cannot hold
        raise InputError(f"{name} is not an array of pixels: {exc}") from None
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (1, 3, 4)):
        raise InputError(f"{name} must be (H, W), (H, W, 3) or (H, W, 4), got shape {arr.shape}")
    if arr.size == 0:
        raise InputError(f"{name} has no pixels (shape {arr.shape})")
    if arr.dtype == bool:
        arr = arr.astype(np.float64)
    elif np.issubdtype(arr.dtype, np.integer):
        info = np.iinfo(arr.dtype)
        if arr.min() < 0:
            raise InputError(f"{name}: an integer picture must not hold negative values")
        arr = arr.astype(np.float64) / float(info.max)
    elif np.issubdtype(arr.dtype, np.floating):
        # float32 stays float32 (each value exact in float64, at half the memory: a
        # resampled picture is float32); no copy of a float64 array
        arr = arr.astype(np.float32 if arr.dtype == np.float32 else np.float64, copy=False)
        if not np.isfinite(arr).all():
            raise InputError(f"{name} contains NaN or infinite values")
        if arr.min() < 0 or arr.max() > 1:
            raise InputError(f"{name}: a float picture must lie in 0..1, got {arr.min():g}..{arr.max():g}")
    else:
        raise InputError(f"{name} of dtype {arr.dtype} is not a numeric image")
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.shape[2] == 4:
        alpha = arr[..., 3:4].astype(np.float64)
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


def resample(rgb: np.ndarray, width: int, height: int, side_by_side_channels: bool = True) -> np.ndarray:
    """The picture at (height, width): Lanczos (antialiased when shrinking), clipped to 0..1.

    Resampled, it is float32: Pillow resamples in float32, so that holds every value
    exactly at half the memory of float64; at its own size, ``rgb`` itself.  The three
    channels are resampled side by side (``side_by_side_channels``), or one after the
    other, each channel's resampled image held alone (where memory is short)."""
    if rgb.shape[:2] == (height, width):
        return rgb
    from PIL import Image

    out = np.empty((height, width, 3), dtype=np.float32)

    def channel(c: int) -> None:
        img = Image.fromarray(np.ascontiguousarray(rgb[..., c], dtype=np.float32), mode="F")
        img = img.resize((width, height), Image.Resampling.LANCZOS)
        # read out a strip of rows at a time: a whole channel's bytes would be two more
        # copies of it (Pillow's encoder chunks and their join) on top of the image
        for lo in range(0, height, 256):
            hi = min(lo + 256, height)
            out[lo:hi, :, c] = np.asarray(img.crop((0, lo, width, hi)))

    # Pillow lets go of the GIL while it resamples
    calls = [lambda c=c: channel(c) for c in range(3)]
    if side_by_side_channels:
        side_by_side(*calls)
    else:
        for call in calls:
            call()
    return np.clip(out, 0.0, 1.0, out=out)


# --------------------------------------------------------------------------- walls


def label_runs(labels: np.ndarray):
    """The row runs of a label raster: maximal stretches of one row with one label.

    Parameters
    ----------
    labels : (H, W) int array
        Cell of each pixel, -1 outside the region.

    Returns
    -------
    flat : (H*W,) int array
        ``labels`` flattened (row-major).
    starts : (R,) bool array
        ``starts[p]``: a run begins at flat pixel p.
    start, end : (R,) int64 arrays
        Run k covers flat pixels ``start[k]`` to ``end[k] - 1``; runs of -1 included,
        in raster order.
    run_labels : (R,) int array
        The label of each run.
    """
    w = labels.shape[1]
    flat = np.ascontiguousarray(labels).ravel()
    starts = np.empty(flat.size, dtype=bool)
    starts[:1] = True
    np.not_equal(flat[1:], flat[:-1], out=starts[1:])
    starts[::w] = True  # a run never wraps to the next row
    start = np.flatnonzero(starts)
    end = np.append(start[1:], flat.size)
    return flat, starts, start, end, flat[start]


def kept_runs(labels: np.ndarray, sites) -> tuple[tuple, np.ndarray]:
    """The row runs of ``labels`` and which of them :func:`split_cells` keeps.

    Parameters
    ----------
    labels, sites
        As for :func:`split_cells`.

    Returns
    -------
    runs : tuple
        :func:`label_runs` of ``labels``.
    kept : (R,) bool array
        Per run: inside the region and in its cell's kept piece.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    h, w = labels.shape
    n = len(sites)
    runs = label_runs(labels)
    flat, starts, start, end, lab = runs
    inside = lab >= 0
    # Two runs of one cell in adjacent rows touch where their columns overlap, and the
    # overlap begins at the start of one of them: looking straight up and down from
    # each start finds every touching pair, each once (down only where the run below
    # began further left, else looking up from it finds the pair).
    second_row, last_row = np.searchsorted(start, [w, flat.size - w])
    up = np.zeros(len(start), dtype=bool)
    np.equal(flat[start[second_row:] - w], lab[second_row:], out=up[second_row:])
    below_px = start[:last_row] + w
    down = flat[below_px] == lab[:last_row]
    down &= ~starts[below_px]
    r_down = np.flatnonzero(down)
    below = np.searchsorted(start, below_px[r_down], side="right") - 1
    # a cell with one run that touches nothing above it is one piece: from every other
    # run, stepping to a touching run above ends there
    top = ~up
    top[below] = False
    top &= inside
    suspect = np.bincount(lab[top], minlength=n) > 1
    if not suspect.any():
        return runs, inside
    # pieces of the suspect cells only: connected components of their runs
    of_suspect = np.append(suspect, False)[lab]  # label -1 reads the appended False
    node = np.flatnonzero(of_suspect)
    node_of = np.cumsum(of_suspect) - 1  # a suspect run's node
    r_up = np.flatnonzero(up & of_suspect)
    above = np.searchsorted(start, start[r_up] - w, side="right") - 1
    pair = of_suspect[r_down]
    lower = node_of[np.concatenate([r_up, below[pair]])]
    upper = node_of[np.concatenate([above, r_down[pair]])]
    graph = coo_matrix((np.ones(len(lower), dtype=np.int8), (lower, upper)), shape=(len(node), len(node)))
    n_pieces, piece = connected_components(graph, directed=False)
    owner = np.zeros(n_pieces, dtype=np.int64)
    owner[piece] = lab[node]
    size = np.bincount(piece, weights=end[node] - start[node], minlength=n_pieces)
    first = np.full(n_pieces, flat.size, dtype=np.int64)
    np.minimum.at(first, piece, start[node])
    # per cell its largest piece (of equal ones, the one that begins last in raster
    # order), then the site's own piece where the site is in its cell
    order = np.lexsort((first, size, owner))
    last = np.append(owner[order][1:] != owner[order][:-1], True)
    keep_piece = np.full(n, -1, dtype=np.int64)
    keep_piece[owner[order[last]]] = order[last]
    i, j = pixel_index(sites, w, h)
    at = i * w + j
    own = np.flatnonzero(suspect & (flat[at] == np.arange(n)))
    site_run = np.searchsorted(start, at[own], side="right") - 1
    keep_piece[own] = piece[node_of[site_run]]
    kept_piece = np.zeros(n_pieces, dtype=bool)
    kept_piece[keep_piece[keep_piece >= 0]] = True
    kept = inside.copy()
    kept[node] = kept_piece[piece]
    return runs, kept


def split_cells(labels: np.ndarray, sites) -> np.ndarray:
    """``labels`` with each cell cut down to one 4-connected piece (other pixels -1).

    Pixels outside the region (-1: the walls) connect nothing, so a cell that a wall
    cuts falls into pieces; the piece kept is the one that holds its site's pixel, or
    the largest where the site lies elsewhere (of equal largest pieces, the one whose
    first pixel comes last in raster order).  Pieces are found on the rows' runs of
    equal label (:func:`kept_runs`), and only for cells that could be in pieces.

    Parameters
    ----------
    labels : (H, W) int array
        Cell of each pixel, -1 outside the region.
    sites : (N, 2) array
        The cells' sites, pixel units.

    Returns
    -------
    (H, W) int array
        ``labels`` itself where every cell is one piece, else a copy with the pixels of
        the pieces not kept set to -1.
    """
    (_, _, start, end, lab), kept = kept_runs(labels, sites)
    drop = np.flatnonzero((lab >= 0) & ~kept)
    if len(drop) == 0:
        return labels
    pixels = index_ranges(start[drop], end[drop] - start[drop])
    out = labels.copy()
    out.reshape(-1)[pixels] = -1
    return out


def split_moments(labels: np.ndarray, sites) -> Moments:
    """The moments of ``split_cells(labels, sites)``, summed over its row runs.

    Parameters
    ----------
    labels, sites
        As for :func:`split_cells`.

    Returns
    -------
    Moments
        Bit-identical to ``moments_from_labels(split_cells(labels, sites), N)``.
    """
    (_, _, start, end, lab), kept = kept_runs(labels, sites)
    return moments_from_runs(start, end, np.where(kept, lab, -1), labels.shape[1], len(sites))


class WalledBackend:
    """A live backend whose cells stop at walls: the labels of ``inner`` (any backend),
    each cell cut down to the piece on its site's side of the walls
    (:func:`split_cells`), and the moments of those labels.  Without this the cells of
    a Lloyd step ignore a thin wall (its pixels only leave the sums), so sites sit
    astride it and their tiles stay small; with it each centroid moves to its site's
    side and cells line up along the wall.  An inner backend that cuts the cells itself
    (``walled_moments``, e.g. on its device) does; any other has its labels split here,
    on the host.  Everything else is the inner backend's."""

    def __init__(self, inner):
        self.inner = inner

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def label(self, sites, *, angles=None, scales=None, metric, grid) -> np.ndarray:
        labels = self.inner.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
        return split_cells(labels, sites) if grid.mask is not None else labels

    def moments(self, sites, *, angles=None, scales=None, metric, grid):
        args = dict(angles=angles, scales=scales, metric=metric, grid=grid)
        if grid.mask is None:
            return self.inner.moments(sites, **args)
        own = getattr(self.inner, "walled_moments", None)
        found = None if own is None else own(sites, **args)
        return split_moments(self.inner.label(sites, **args), sites) if found is None else found


# --------------------------------------------------------------------------- colours


def tile_colours(lab: np.ndarray, polygons, sites, tiles: np.ndarray, pixels: np.ndarray):
    """Fill of every tile: (N, 3) sRGB in 0..1 (8-bit values, as written) and their Lab.

    The geometric median, in CIELAB, of the picture's pixels whose centres lie inside or
    on the tile's outline (``tiles``, ``pixels`` from :func:`cvt.evaluate.pixels_under`):
    the colour with the least mean ΔE*ab to them, which is what the colour error
    measures (the Lab mean, the least mean *squared* ΔE*ab, measured 1.4-5.9 %
    worse on it on six photographs).  Read from the final polygons, so it holds wherever the method put the
    tile.  A tile too thin to hold a pixel centre takes the pixel under a point inside
    it; a site without a tile the pixel under the site (its colour is listed but never
    drawn).

    Parameters
    ----------
    lab : (H, W, 3) float array
        The picture in CIELAB.
    polygons : sequence of shapely geometries or None
        The tiles.
    sites : (N, 2) array
        The sites, pixel units.
    tiles, pixels : (P,) int arrays
        :func:`cvt.evaluate.pixels_under` of ``polygons``.

    Returns
    -------
    rgb : (N, 3) float64 array
        The fills in sRGB, 8-bit values.
    lab : (N, 3) float64 array
        The same in CIELAB.
    """
    fill = geometric_median(lab.reshape(-1, 3), tiles, None, index=pixels, groups=len(polygons))
    _fill_thin(fill, np.bincount(tiles, minlength=len(polygons)) > 0, lab, None, polygons, sites)
    rgb = quantised(lab_to_srgb(fill))
    return rgb, srgb_to_lab(rgb)


def _fill_thin(fill, held, image, convert, polygons, sites) -> None:
    """``fill`` of the tiles that hold no pixel centre (``~held``), in place: the pixel
    under a point inside the tile, or under the site where it has none."""
    import shapely

    if held.all():
        return
    h, w = image.shape[:2]
    points = np.array(sites, dtype=np.float64).reshape(-1, 2).copy()
    thin = [k for k in np.flatnonzero(~held) if polygons[k] is not None and not polygons[k].is_empty]
    if thin:
        points[thin] = shapely.get_coordinates(shapely.point_on_surface([polygons[k] for k in thin]))
    under = image[pixel_index(points[~held], w, h)]
    fill[~held] = under if convert is None else convert(under)


# (tile, pixel) pairs that mosaic_fills holds at once: the tiles are taken in runs of
# about this many pixels, each run's pairs found, filled and measured before the next
FILL_PAIRS = 1 << 20


def tile_runs(polygons, pairs: int = FILL_PAIRS) -> np.ndarray:
    """Bounds of consecutive runs of ``polygons`` that each cover about ``pairs`` pixels.

    Parameters
    ----------
    polygons : sequence of shapely geometries or None
        The tiles.
    pairs : int
        The pixels a run should hold, about (by the tiles' areas).

    Returns
    -------
    (R + 1,) int64 array
        Run r is ``polygons[bounds[r]:bounds[r + 1]]``.
    """
    import shapely

    geoms = np.empty(len(polygons), dtype=object)
    geoms[:] = list(polygons)
    area = np.nan_to_num(shapely.area(geoms))  # None: NaN, no pixels
    ends = np.searchsorted(np.cumsum(area), np.arange(pairs, area.sum(), pairs)) + 1
    return np.unique(np.concatenate([[0], np.minimum(ends, len(polygons)), [len(polygons)]]))


def mosaic_fills(picture: np.ndarray, polygons, sites, bounds=None) -> tuple[np.ndarray, np.ndarray, float]:
    """:func:`tile_colours` and the colour error, read from the sRGB picture.

    The picture's CIELAB is never held whole: the tiles are taken in runs
    (:func:`tile_runs`), each run's pixels found (:func:`cvt.evaluate.pixels_under`)
    and read in blocks, each block converted to CIELAB as it is read, its tiles'
    medians found and the colour error (:func:`cvt.evaluate.colour_error`) of its
    pixels summed.  The fills are those :func:`tile_colours` gives from the whole
    picture's CIELAB, bit for bit (each pixel's CIELAB is its own, each tile's median
    its own pixels'), up to :data:`SINGLE_MEDIAN_TILES` tiles; above, the medians' steps
    run in float32 (:func:`geometric_median`'s ``single``).

    Parameters
    ----------
    picture : (H, W, 3) float array
        sRGB in 0..1.
    polygons : sequence of shapely geometries or None
        The tiles.
    sites : (N, 2) array
        The sites, pixel units.
    bounds : (R + 1,) int array, optional
        The runs of tiles (default :func:`tile_runs`).

    Returns
    -------
    rgb : (N, 3) float64 array
        The fills in sRGB, 8-bit values.
    lab : (N, 3) float64 array
        The same in CIELAB.
    colour_error : float
        Mean ΔE*ab over the (tile, pixel) pairs; NaN where no tile holds a pixel.
    """
    h, w = picture.shape[:2]
    n = len(polygons)
    flat = picture.reshape(-1, 3)
    bounds = tile_runs(polygons) if bounds is None else bounds
    fill = np.zeros((n, 3))
    held = np.zeros(n, dtype=bool)
    total = [0.0, 0]

    def measure(block, sizes, pts, median):
        fills = srgb_to_lab(quantised(lab_to_srgb(median)))
        local = np.repeat(np.arange(len(block)), sizes)
        total[0] += colour_error(pts, fills, local, np.arange(len(pts))) * len(pts)
        total[1] += len(pts)

    single = n > SINGLE_MEDIAN_TILES
    runs = list(zip(bounds[:-1], bounds[1:], strict=True))

    def pixels_of(k: int):
        return pixels_under(polygons[runs[k][0] : runs[k][1]], w, h) if k < len(runs) else None

    # each run's pixels are found on a thread of their own while the pool fills the run before
    found = pixels_of(0)
    for k, (lo, hi) in enumerate(runs):
        tiles, pixels = found
        with on_its_own_thread(pixels_of, k + 1) as later:
            held[lo:hi] = np.bincount(tiles, minlength=hi - lo) > 0
            fill[lo:hi] = geometric_median(
                flat,
                tiles,
                None,
                index=pixels,
                groups=hi - lo,
                convert=srgb_to_lab,
                on_block=measure,
                single=single,
            )
            del tiles, pixels
            found = later()
    _fill_thin(fill, held, picture, srgb_to_lab, polygons, sites)
    rgb = quantised(lab_to_srgb(fill))
    return rgb, srgb_to_lab(rgb), total[0] / total[1] if total[1] else float("nan")


# points per block of groups in geometric_median: a block's arrays stay in the
# processor's cache through all the steps, where the whole picture's would stream from
# memory at every step
MEDIAN_BLOCK = 65536
# more tiles than this: mosaic_fills' medians step in float32, 1.7x quicker; the medians
# within 2e-5 of float64's (ΔE*ab; a fill's 8-bit step is some 0.4), the fills of a
# 64 000-tile mosaic the same but for a few
SINGLE_MEDIAN_TILES = 10_000


def geometric_median(
    points: np.ndarray,
    group: np.ndarray,
    start: np.ndarray | None,
    steps: int = 16,
    index: np.ndarray | None = None,
    groups: int | None = None,
    convert=None,
    on_block=None,
    single: bool = False,
) -> np.ndarray:
    """Per group, the point with the least mean Euclidean distance to the group's points.

    Weiszfeld's iteration from ``start``; a step that lands on a point keeps its distance
    from zero by a floor of 1e-9.  The groups are taken in blocks of about
    :data:`MEDIAN_BLOCK` points, each block through all its steps at once.

    Parameters
    ----------
    points : (P, D) float array
        The points (with ``index``: the rows they are read from).
    group : (P,) int array
        The group of each point, in 0..G-1 (fastest when sorted, as
        :func:`cvt.evaluate.pixels_under` gives them).
    start : (G, D) float array or None
        Where each group's iteration starts; None: at the group's mean (``groups`` then
        gives G).
    steps : int
        Weiszfeld steps.
    index : (P,) int array, optional
        The points are ``points[index]``, read a block at a time (no copy of them all).
    groups : int, optional
        G, where ``start`` is None.
    convert : callable, optional
        Applied to each block's points as they are read (e.g. sRGB to CIELAB): the
        medians are those of the converted points, which are never held all at once.
    on_block : callable, optional
        ``on_block(groups, sizes, points, medians)`` after each block: its groups (in
        0..G-1), their sizes, its (converted) points in group order, their medians.
    single : bool
        Weiszfeld's steps in float32 (on CIELAB values the medians came within 2e-5 of
        float64's); float64 medians either way.

    Returns
    -------
    (G, D) float array
        The medians; ``start`` (0 where it is None) for a group without points.
    """
    points = np.asarray(points) if convert is not None else np.asarray(points, dtype=np.float64)
    group = np.asarray(group)
    if start is None:
        m = np.zeros((int(groups), points.shape[1]))
    else:
        m = np.array(start, dtype=np.float64, copy=True)
    if len(group) == 0:
        return m
    if np.any(group[1:] < group[:-1]):
        order = np.argsort(group, kind="stable")
        group = group[order]
        if index is None:
            points = points[order]
        else:
            index = np.asarray(index)[order]
    counts = np.bincount(group, minlength=len(m))
    held = np.flatnonzero(counts)
    ends = np.cumsum(counts[held])
    # blocks of whole groups
    cuts = np.searchsorted(ends, np.arange(MEDIAN_BLOCK, ends[-1], MEDIAN_BLOCK)) + 1
    bounds = np.unique(np.concatenate([[0], cuts, [len(held)]]))

    def solve(a: int, b: int):
        first = ends[a - 1] if a else 0
        block = held[a:b]
        pts = points[first : ends[b - 1]] if index is None else points[index[first : ends[b - 1]]]
        if convert is not None:
            pts = convert(pts)
        if start is None:  # each group's sum in its points' order, as one bincount of all
            local = np.repeat(np.arange(len(block)), counts[block])
            sums = np.stack(
                [np.bincount(local, weights=pts[:, c], minlength=len(block)) for c in range(pts.shape[1])],
                axis=1,
            )
            begin = sums / counts[block].astype(np.float64)[:, None]
        else:
            begin = m[block]
        return block, pts, _weiszfeld(pts, counts[block], begin, steps, np.float32 if single else np.float64)

    # the blocks on the pool, a core's worth at a time (each block's groups are its
    # own), while this thread takes their results in order: on_block sees them as one
    # at a time would, and runs while the pool works on the next blocks
    pairs = zip(bounds[:-1], bounds[1:], strict=True)
    for block, pts, median in in_order(lambda a=a, b=b: solve(a, b) for a, b in pairs):
        m[block] = median
        if on_block is not None:
            on_block(block, counts[block], pts, median)
    return m


def _weiszfeld(
    points: np.ndarray, sizes: np.ndarray, start: np.ndarray, steps: int, dtype=np.float64
) -> np.ndarray:
    """:func:`geometric_median` of consecutive groups of ``sizes`` points, none empty,
    stepped in ``dtype``; float64 medians."""
    offsets = np.cumsum(sizes) - sizes
    cols = [np.ascontiguousarray(points[:, c], dtype=dtype) for c in range(points.shape[1])]
    m = start.T.astype(dtype)
    dist = np.empty(len(points), dtype=dtype)
    tmp = np.empty(len(points), dtype=dtype)
    for _ in range(steps):
        dist.fill(0.0)
        for c, col in enumerate(cols):
            np.subtract(col, np.repeat(m[c], sizes), out=tmp)
            tmp *= tmp
            dist += tmp
        np.sqrt(dist, out=dist)
        np.maximum(dist, 1e-9, out=dist)
        weight = np.reciprocal(dist, out=dist)
        total = np.add.reduceat(weight, offsets)
        for c, col in enumerate(cols):
            np.multiply(col, weight, out=tmp)
            m[c] = np.add.reduceat(tmp, offsets) / total
    return m.T.astype(np.float64, copy=False)


def ellipse_rows(polygons, element: str, aspect: float) -> np.ndarray | None:
    """(N, 5) exact ellipses (cx, cy, rx, ry, degrees) of circle and ellipse tiles, read
    from their polygons (centre, size from the area, angle from the first vertex), NaN
    where a tile is not a whole ellipse (clipped by a method or cut to fit a wall) or missing; None for
    polygonal shapes."""
    import shapely

    if not shape_record(element).curved:
        return None
    ball = element_ball(element, aspect)
    unit = unit_outline(element, aspect)
    unit_area = shapely.area(shapely.polygons(unit))
    rows = np.full((len(polygons), 5), np.nan)
    for k, p in enumerate(polygons):
        if p is None or p.is_empty or p.geom_type != "Polygon" or len(p.exterior.coords) != len(unit) + 1:
            continue
        c = np.asarray(p.centroid.coords[0])
        ring = np.asarray(p.exterior.coords[:-1])
        v = ring[0] - c
        size = math.sqrt(p.area / unit_area)
        # a tile cut to fit a wall can have as many vertices as the whole ellipse: it is
        # one only where every vertex is the unit outline's, turned and scaled
        turn = math.atan2(v[1], v[0]) - math.atan2(unit[0, 1], unit[0, 0])
        cos, sin = math.cos(turn), math.sin(turn)
        whole = c + size * (unit @ np.array([[cos, sin], [-sin, cos]]))
        if np.abs(whole - ring).max() > 1e-6 * max(size, 1.0):
            continue
        rows[k] = ellipse_parameters(c[None], [math.atan2(v[1], v[0])], [size], ball.semi_axes)[0]
    return rows


# --------------------------------------------------------------------------- result


@dataclass
class MosaicResult:
    """A picture turned into a mosaic: one tile per site, its colour and the measures.

    :func:`compact_distributions.mosaic` returns one; :meth:`svg` and :meth:`render`
    draw it.  Arrays are indexed by site: tile ``k`` is ``polygons[k]`` (None where the
    method placed none), centred near ``sites[k]``, filled with ``colours[k]``.

    Parameters
    ----------
    sites : numpy.ndarray
        (N, 2) sites in pixel units of the mosaic's raster.
    angles : numpy.ndarray
        (N,) tile angles in radians, positive = clockwise on screen.
    scales : numpy.ndarray
        (N,) size factors from the picture's density (ones without a density).
    polygons : list of shapely.Polygon or None
        The tiles, one per site, None where a site has none.
    colours : numpy.ndarray
        (N, 3) sRGB fills in 0..1 (8-bit values): each tile's colour, the geometric
        median in CIELAB of the picture under it.
    coverage : float
        Area of the union of the tiles / area of the raster.
    overlap : float
        Area covered more than once / area of the raster.
    colour_error : float
        Mean ΔE*ab between the picture and the fills over the tiled area.
    straddling : float
        Share of the tiles that straddle a strong edge of the picture.
    width : int
        Raster width in pixels.
    height : int
        Raster height in pixels.
    metric : str
        The Lloyd distance.
    element : str
        The tile shape.
    aspect : float
        The β of rectangles and ellipses.
    gap : float
        Grout width in pixels.
    method : str, optional
        The method that placed the tiles.
    method_options : dict, optional
        The method's own options, as given.
    contrast : float, optional
        Densest / sparsest cell area of the density from the picture.
    grout : tuple of float, optional
        The grout's sRGB colour in 0..1.
    edge_threshold : float, optional
        The contrast (ΔE*ab) from which a picture's edge is strong.
    walls : bool, optional
        Whether strong edges were walls (removed from the region).
    cut_tiles : int, optional
        The number of tiles cut to fit along the walls.
    picture : numpy.ndarray or None, optional
        (H, W, 3) the picture resampled to the raster.
    edges : numpy.ndarray or None, optional
        (H, W) bool, the strong edges.
    straddles : numpy.ndarray or None, optional
        (N,) bool, the tiles that straddle a strong edge.
    fields : PictureFields or None, optional
        The density and direction field read from the picture.
    problem : Problem or None, optional
        The problem the method solved.
    distribution : Distribution or None, optional
        What the method returned.
    evaluation : Evaluation or None, optional
        Coverage and overlap, as measured.
    backend : str, optional
        The backend variant that ran the Lloyd iterations.
    device : str, optional
        The backend's device.
    source : str, optional
        Where the picture came from (its path, or a description of the array).
    method_seconds : float, optional
        Wall time of the whole mosaic call.

    Attributes
    ----------
    placed : int
        The number of tiles placed.
    labels : numpy.ndarray or None
        The method's final label raster, where it has one.
    """

    sites: np.ndarray  # (N, 2) pixel units of the mosaic raster
    angles: np.ndarray  # (N,) radians, positive = clockwise on screen
    scales: np.ndarray  # (N,) size factor from the density (1 without density)
    polygons: list  # shapely polygons, one per site, None where skipped
    colours: np.ndarray  # (N, 3) sRGB in 0..1 (8-bit values): each tile's fill (tile_colours)
    coverage: float  # cvt.evaluate over the whole picture: area(union of tiles) / (W·H)
    overlap: float
    colour_error: float  # mean ΔE*ab between picture and fill over the tiled area (cvt.evaluate)
    straddling: float  # share of tiles that straddle a strong edge (cvt.evaluate)
    width: int
    height: int
    metric: str
    element: str
    aspect: float
    gap: float
    method: str = DEFAULT_METHOD
    method_options: dict = field(default_factory=dict)  # the method's own options as given
    contrast: float = DEFAULT_CONTRAST
    grout: tuple = DEFAULT_GROUT
    edge_threshold: float = DEFAULT_EDGE_THRESHOLD
    walls: bool = True  # strong edges were walls (removed from the region)
    cut_tiles: int = 0  # tiles cut to fit along the walls (cvt.cutting)
    picture: np.ndarray | None = field(default=None, repr=False)  # (H, W, 3) resampled input
    edges: np.ndarray | None = field(default=None, repr=False)  # (H, W) bool strong edges
    straddles: np.ndarray | None = field(default=None, repr=False)  # (N,) bool per tile
    fields: PictureFields | None = field(default=None, repr=False)
    problem: Problem | None = field(default=None, repr=False)
    distribution: Distribution | None = field(default=None, repr=False)  # what the method returned
    evaluation: Evaluation | None = field(default=None, repr=False)  # coverage and overlap, as measured
    backend: str = "numpy"
    device: str = ""
    source: str = ""
    method_seconds: float = 0.0  # the whole make_mosaic call

    @property
    def placed(self) -> int:
        return sum(p is not None for p in self.polygons)

    @property
    def labels(self):
        return None if self.distribution is None else self.distribution.labels

    def svg(self, grout=None, precision: int = 2) -> str:
        """The mosaic as SVG text: a grout-coloured background and one filled tile per
        placed site, in pixel units (viewBox = the raster).  Polygonal tiles are paths
        with their exact corners; circles and ellipses are rotated ``<ellipse>`` elements."""
        return "".join(self.svg_lines(grout, precision))

    def svg_lines(self, grout=None, precision: int = 2):
        """:meth:`svg` line by line (to write a large mosaic without holding its text)."""
        grout = self.grout if grout is None else parse_colour(grout, "grout")
        return svg_lines(
            self.polygons,
            self.width,
            self.height,
            self.colours,
            background=grout,
            region_colour=None,
            stroke=None,
            digits=precision,
            ellipses=ellipse_rows(self.polygons, self.element, self.aspect),
        )

    def render(self, scale: float = 1.0, grout=None, supersample: int = 3, as_rows: bool = False):
        """The mosaic as a PIL RGB image ``scale`` times the raster size (antialiased;
        ``as_rows``: a row source drawn band by band as it is read, for a PNG writer)."""
        grout = self.grout if grout is None else parse_colour(grout, "grout")
        return draw_elements(
            self.polygons,
            self.width,
            self.height,
            self.colours,
            background=grout,
            scale=scale,
            supersample=supersample,
            as_rows=as_rows,
        )

    def to_distribution(self) -> Distribution:
        """The run as the :class:`cvt.distribution.Distribution` the method returned."""
        return self.distribution


# --------------------------------------------------------------------------- the API


def _raster_picture(image, size, n_elements, backend, element, memory_limit):
    """The picture resampled to the mosaic's raster (H, W, 3), and where it came from;
    InputError before reading it whole when N does not fit or the memory would not do."""
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
        raise InputError(
            f"{n_elements} elements do not fit in a {w}x{h} raster "
            f"(from a {pw}x{ph} picture); "
            f"use fewer elements or a larger size (--size)"
        )
    mosaic_estimate(w, h, n_elements, type(backend), element=element).check(
        memory_limit, lower="use a smaller size or fewer elements", name="memory_limit"
    )
    if rgb is None:
        rgb, source = picture_array(image, at_least=(w, h), memory_limit=memory_limit)
    picture = resample(rgb, w, h)
    # a picture enlarged to the raster can be made again from the smaller one, the same
    # to the last bit, so it need not be held while the method runs (made again at the
    # method's peak of memory: a channel at a time)
    remake = (
        (lambda: resample(rgb, w, h, side_by_side_channels=False)) if rgb.nbytes < picture.nbytes else None
    )
    return picture, source, remake


def _return_free_memory() -> None:
    """Hand the C heap's free pages back to the system (glibc's ``malloc_trim``; nothing
    elsewhere): freed bands and temporaries otherwise stay in the process's memory, and
    the next stage's large arrays come on top of them."""
    import ctypes

    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError, TypeError):
        pass


def _release_buffers(backend) -> None:
    """Let go of the backend's kept buffers (the stages after the method need none; a
    poster's are some 150 MB, as the picture is made again) and of the C heap's free pages."""
    release = getattr(backend, "release_buffers", None)
    if callable(release):
        release()
    _return_free_memory()


# up to this many pixels the picture's fields and its edge map are made side by side (on
# two cores); above it their passes over the picture one after the other, as each holds
# a structure tensor and its temporaries (about 50 bytes a pixel) while it works
SIDE_BY_SIDE_PIXELS = 1 << 23


def _picture_analysis(picture, spacing, element, contrast, edge_threshold):
    """The picture's fields (density, direction), its strong edges (read in CIELAB,
    which is not kept: the fills read it again a block at a time) and the seconds taken."""

    def fields():
        return picture_fields(picture, spacing, element, contrast=contrast, details=False)

    # the edge map is made in any case: the straddling measure reads it
    def edges():
        return strong_edges(picture, edge_threshold, min_length=EDGE_MIN_LENGTH * spacing, srgb=True)

    t0 = time.perf_counter()
    if picture.shape[0] * picture.shape[1] <= SIDE_BY_SIDE_PIXELS:
        made = side_by_side(fields, edges)
        return made[0], made[1], time.perf_counter() - t0
    # the fields' pass over the picture first, then the rest of the fields (on their
    # blocks, mostly on one core) beside the edges' pass
    finish = picture_fields_later(picture, spacing, element, contrast=contrast, details=False)
    with on_its_own_thread(finish) as finished:
        edge_map = edges()
        made_fields = finished()
    return made_fields, edge_map, time.perf_counter() - t0


def _mosaic_problem(edge_map, walls: bool, n_elements, metric, density, field, seed) -> Problem:
    """The problem the method solves: the raster of ``edge_map`` less its edges where
    they are ``walls``, else all of it."""
    h, w = edge_map.shape
    return Problem(
        Grid(w, h, ~edge_map if walls else None),
        n_elements,
        metric,
        density=density,
        field=field,
        seed=seed,
        walls=edge_map if walls else None,
    )


def _cut_style(cut, tight: bool) -> str | None:
    """The style of :func:`cut_to_walls` that ``make_mosaic(cut=...)`` asks for (None: no
    cut; ``None`` cuts a method's tiles that are ``tight``)."""
    if cut is None:
        return "auto" if tight else None
    if cut is True or cut is False:
        return "auto" if cut else None
    if isinstance(cut, str) and cut in CUT_STYLES:
        return cut
    raise InputError(f"cut must be True, False, None or one of {', '.join(CUT_STYLES)}, got {cut!r}")


def _after_the_method(dist, picture_of, edge_map, cut, gap, spacing, picture_seconds):
    """The stages after the method: tiles cut to the walls (``cut``: the cut's style, or
    None for no cut), their colours and the measures (coverage and overlap, straddling,
    colour error), each timed; the method's distribution with the final tiles and every
    stage's time.  ``picture_of()`` gives the picture (made again, beside the cut, where
    it was let go)."""
    polygons = [None if p is None or p.is_empty else p for p in dist.elements]
    # the stages after the method are timed too (result.json's stage_seconds)
    t0 = time.perf_counter()
    if cut:
        # the picture is made beside the cut (whose GEOS calls, like Pillow's
        # resampling, let go of the GIL)
        with on_its_own_thread(picture_of) as made:
            polygons, cut_count = cut_to_walls(polygons, edge_map, gap, spacing, style=cut)
            picture = made()
    else:
        cut_count, picture = 0, picture_of()
    t1 = time.perf_counter()

    def measured():
        # the coverage beside the straddling, whose shapely calls let go of the GIL
        # (neither prepares the tiles they share: cvt.threads)
        t = time.perf_counter()
        made = side_by_side(
            lambda: evaluate(polygons, Grid(*edge_map.shape[::-1])),  # the whole picture: walls are grout
            lambda: straddling_tiles(polygons, edge_map),
        )
        return made, time.perf_counter() - t

    # the measures on a thread of their own while the tiles are filled: the fills leave
    # a core idle part of the time, which GEOS's work takes
    with on_its_own_thread(measured) as measures:
        bounds = tile_runs(polygons)
        colours, _, error = mosaic_fills(picture, polygons, dist.sites, bounds)
        t2 = time.perf_counter()
        (ev, straddles), evaluation_seconds = measures()
    _return_free_memory()  # the runs' pairs, freed on the threads, before the files are written
    stages = {
        "picture_seconds": picture_seconds,  # Lab, density, field and edges
        "cutting_seconds": t1 - t0,
        "fills_seconds": t2 - t1,
        "evaluation_seconds": evaluation_seconds,  # on its thread, beside the fills
    }
    extra = {**dist.extra, **({"cut_tiles": cut_count, "cut_style": cut} if cut else {}), **stages}
    dist = dataclasses.replace(dist, elements=polygons, extra=extra)
    return dist, picture, (polygons, colours, cut_count), (ev, straddles, error)


def _method_and_options(method, method_options):
    """The method's record, the options given (checked against it), and those it runs
    with in a mosaic (its ``mosaic_options`` under the given ones)."""
    record = resolve_method(method)
    if method_options is not None and not isinstance(method_options, dict):
        raise InputError(f"method_options must be a dict of the method's options, got {method_options!r}")
    given_options = record.parse_options(method_options or {})
    return record, given_options, {**record.mosaic_options, **given_options}


@dataclass(frozen=True)
class _Settings:
    """What :func:`make_mosaic` was asked for and ran with, as its record needs it."""

    metric_name: str
    element: str
    gap: float
    record: object  # the method's record
    given_options: dict  # the method's options as given
    contrast: float
    grout: tuple
    edge_threshold: float
    walls: bool
    backend: object  # the live backend
    source: str
    t_start: float  # perf_counter when make_mosaic began


def _result(dist, problem, fields, picture, edge_map, tiles, measures, settings: _Settings) -> MosaicResult:
    """The mosaic's record, from the stages' results and :func:`make_mosaic`'s settings."""
    polygons, colours, cut_count = tiles
    ev, straddles, error = measures
    placed = sum(p is not None for p in polygons)
    backend = settings.backend
    return MosaicResult(
        sites=dist.sites,
        angles=dist.angles,
        scales=dist.scales,
        polygons=polygons,
        colours=colours,
        coverage=ev.coverage,
        overlap=ev.overlap,
        colour_error=error,
        straddling=float(straddles.sum() / placed) if placed else 0.0,
        width=problem.grid.width,
        height=problem.grid.height,
        metric=settings.metric_name,
        element=settings.element,
        aspect=problem.metric.aspect,
        gap=settings.gap,
        method=dist.method or settings.record.name,
        method_options=settings.given_options,
        contrast=settings.contrast,
        grout=settings.grout,
        edge_threshold=settings.edge_threshold,
        walls=settings.walls,
        cut_tiles=cut_count,
        picture=picture,
        edges=edge_map,
        straddles=straddles,
        fields=fields,
        problem=problem,
        distribution=dist,
        evaluation=ev,
        backend=backend.variant,
        device=backend.device(),
        source=settings.source,
        method_seconds=time.perf_counter() - settings.t_start,
    )


def make_mosaic(
    image,
    backend,
    *,
    n_elements: int = DEFAULT_ELEMENTS,
    metric: str | None = None,
    element: str | None = None,
    size=None,
    gap: float | None = None,
    use_field: bool = True,
    use_density: bool = True,
    iterations: int = 20,
    seed: int = 0,
    aspect: float | None = None,
    contrast: float = DEFAULT_CONTRAST,
    grout=DEFAULT_GROUT,
    method=DEFAULT_METHOD,
    edges: bool = True,
    edge_threshold: float = DEFAULT_EDGE_THRESHOLD,
    method_options: dict | None = None,
    cut: bool | str | None = None,
    progress=None,
    memory_limit=None,
) -> MosaicResult:
    """Turn ``image`` (a file path or a numpy array) into a mosaic of ``n_elements``.

    ``metric``/``element``: the Lloyd distance and the tile shape; give either (the
    other follows, by the shape table), both, or neither (squares).  ``aspect``: β of
    rectangles and ellipses (default 0.5).  ``size``: raster (see :func:`raster_size`;
    default the picture's size, long side capped at 1024).  ``backend``: a live
    backend (``compact_distributions.backends.create_backend``), left open.  ``gap``: grout
    width in pixels (default ``None``: 5 % of the mean element spacing sqrt(W·H/N), e.g.
    1 px for 2000 elements on 1024x768).  ``use_field``: align tile sides with the
    picture's edges; ``use_density``: smaller tiles where the picture has detail
    (``contrast`` = densest / sparsest cell area).  ``method``: what places the tiles, a
    registered name (:mod:`cvt.registry`), a method record, or any method callable (the method interface of
    :mod:`cvt.methods`; default :data:`DEFAULT_METHOD`).  ``edges``: the picture's strong
    edges (contrast >= ``edge_threshold`` ΔE*ab, :func:`cvt.image_fields.strong_edges`)
    are walls: their pixels leave the region, so cells, tiles and the method's region
    border stop at them.  ``cut``: tiles within a spacing of a wall are then cut to fit
    (:mod:`cvt.cutting`); default ``None`` cuts the tiles of a method whose record says its
    tiles are tight (``ours-compact``), so that cutting fills what is left along the walls;
    ``True`` or a style of :func:`cvt.cutting.cut_to_walls` (``"auto"``, ``"exact"``,
    ``"straight"``; ``True``: ``"auto"``) cuts them whatever the method.  ``method_options``:
    the method's own declared options (e.g. ``{"alternate": True}`` for ours-compact's
    triangles), checked against its record.  ``progress(k, iterations, energy)`` is called
    after each Lloyd step.  ``memory_limit`` (bytes or a size such as ``"8G"``; default
    what the machine has) refuses, before any work, a mosaic estimated to need more."""
    t_start = time.perf_counter()
    live_backend(backend)
    n_elements = whole_number(n_elements, "n_elements", minimum=1)
    iterations = whole_number(iterations, "iterations", minimum=0)
    seed = whole_number(seed, "seed", minimum=0)
    contrast = real_number(contrast, "contrast", *CONTRAST_RANGE)
    edge_threshold = real_number(edge_threshold, "edge_threshold", above=0.0)
    grout = parse_colour(grout, "grout")
    record, given_options, method_options = _method_and_options(method, method_options)
    cut = _cut_style(cut, record.tight)
    metric_name, element = resolve_shapes(metric, element)
    metric_obj = make_metric(metric_name, aspect)
    picture, source, remake = _raster_picture(image, size, n_elements, backend, element, memory_limit)
    spacing = math.sqrt(picture.shape[0] * picture.shape[1] / n_elements)
    gap = AUTO_GAP * spacing if gap is None else parse_gap(gap)
    fields, edge_map, picture_seconds = _picture_analysis(picture, spacing, element, contrast, edge_threshold)
    walls = bool(edges) and bool(edge_map.any())
    density, field_ = fields.density if use_density else None, fields.field if use_field else None
    problem = _mosaic_problem(edge_map, walls, n_elements, metric_obj, density, field_, seed)
    picture = None if remake is not None else picture  # made again after the method (the fills read it)
    _return_free_memory()
    dist = record(
        problem,
        WalledBackend(backend) if walls else backend,
        iterations=iterations,
        progress=progress,
        element=element,
        gap=gap,
        **method_options,
    )
    _release_buffers(backend)
    picture_of = remake if picture is None else (lambda: picture)
    dist, picture, tiles, measures = _after_the_method(
        dist, picture_of, edge_map, cut if walls else None, gap, spacing, picture_seconds
    )
    settings = _Settings(
        metric_name,
        element,
        gap,
        record,
        given_options,
        contrast,
        grout,
        edge_threshold,
        walls,
        backend,
        source,
        t_start,
    )
    return _result(dist, problem, fields, picture, edge_map, tiles, measures, settings)


__all__ = [
    "make_mosaic",
    "MosaicResult",
    "picture_array",
    "raster_size",
    "resample",
    "resolve_shapes",
    "resolve_method",
    "tile_colours",
    "mosaic_fills",
    "tile_runs",
    "FILL_PAIRS",
    "SIDE_BY_SIDE_PIXELS",
    "DEFAULT_METHOD",
    "ELEMENT_SHAPES",
]
