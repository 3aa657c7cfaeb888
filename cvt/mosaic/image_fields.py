"""A density map and a direction field extracted from a picture (paper §4.1, Figs. 16-19).

The paper turns a picture into a mosaic whose element sizes follow a "density graph" and
whose directions follow a "vector field", both taken from the picture, without saying
how.  This module makes both from one filter, the colour structure tensor, computed
with Gaussian derivative and Gaussian smoothing filters: ``scipy.ndimage``'s, with the
pass down the columns done a band of rows at a time (:func:`gaussian_filter`, the same
result bit for bit), and through the FFT for wide Gaussians (:func:`gaussian_smooth`).

Why the structure tensor
------------------------
For a colour picture I (channels c) the tensor is ``J = G_ρ * Σ_c ∇I_c ∇I_cᵀ``, with
``∇I_c`` a Gaussian derivative at scale σ (Di Zenzo's colour gradient).  Its largest
eigenvalue λ₁ measures how strong the local edge is and its eigenvector points across
the edge, so the edge runs at ``½·atan2(2J_xy, J_xx − J_yy) + 90°``.  Unlike a single
gradient it (a) finds edges between colours of equal brightness (the channels are
summed), (b) treats a direction and its opposite alike (an edge from dark to light and
one from light to dark have the same orientation, so two sides of a thin stripe do not
cancel when smoothed) and (c) stays stable under noise thanks to the window G_ρ.

Direction field: the edge direction, carried to every pixel
-----------------------------------------------------------
The tensor's orientation is meaningful only near edges; in a flat area it is noise.
Hausner (SIGGRAPH 2001) lines tiles up with the nearest edge by taking the gradient of
the distance transform of an edge map.  That gradient is undefined on the edges
themselves and jumps on the medial axis, so we keep his idea (each pixel takes the
direction of its *nearest edge*) but read that direction from the tensor at the nearest
edge pixel, found with ``scipy.ndimage.distance_transform_edt(return_indices=True)``.
The result is then smoothed a little with a Gaussian of about half the element
spacing, in the element's own symmetry: angles are averaged as unit vectors of
``m·θ`` where ``m = 2π / period`` and ``period`` is the rotation after which the element
again has a side along the same line (90° for squares, 180° for rectangles and ellipses,
60° for triangles).  With m = 4 a horizontal and a vertical edge agree for squares (they
would cancel with the usual m = 2).  Where the picture has no edge at all the field is 0.

Angles are in radians, in the raster frame (x right, y down), a positive angle turning
clockwise on screen, as :class:`cvt.fields.DirectionField` expects; an element at angle θ
has a side (a rectangle its long side) along the line at θ.

Density: detail, smoothed
-------------------------
The density is the colour gradient magnitude ``sqrt(trace J)`` smoothed with a Gaussian
of about one element spacing (so one sharp edge raises the density of a band of a few
elements, not of a one-pixel line), divided by its 99th percentile and clipped to
[0, 1], then mapped linearly to ``1 .. contrast``.  ``contrast`` is the ratio of the
densest to the sparsest cell area (default 3: elements on detail about 1.7 times
smaller across than on flat areas).  A picture without detail gives a uniform density.

Posters: the fields on a coarse grid
------------------------------------
Both fields are smoothed over a spacing or more, so a mosaic of more tiles than
``cvt.mosaic.cutting.EXACT_TILES`` (whose spacing is a few pixels on a poster) takes
them from a grid of ``step`` = floor(spacing / 4) pixels (:func:`field_step`): the
derivative is taken on every pixel as above, its products are averaged over step x step
blocks (the tensor's window, less the block's own spread, applied on the blocks), the
edges, density and field are made on the blocks as on the pixels (the smoothing in
pixels the same) and interpolated bilinearly to every pixel (the field as its unit
vectors of ``m·θ``, and only where it is read: :class:`CoarseField` keeps them on the
blocks and interpolates at each site's pixel, the value the whole picture's
interpolation would have there).  Measured against the fields made on every pixel: density within
0.03 (of 1), direction within 2° at half the pixels (tests/test_image_fields_coarse.py).
Up to ``EXACT_TILES`` tiles the fields are those of every pixel, bit for bit.

Strong edges: walls for the mosaic's tiles
------------------------------------------
:func:`strong_edges` marks the picture's strong edges as thin (one pixel wide,
4-connected) lines, which the mosaic removes from the region so that no tile crosses
one.  Strength is measured in the unit that says how different the two sides look: the
same structure tensor, computed on the picture in CIELAB (:mod:`cvt.colour`) and divided
by the tensor's response to an ideal step of ΔE*ab = 1, gives at every pixel the
*edge contrast*: the colour difference (ΔE*ab) of the step edge that would give the
same response.  A blurred edge scores lower than its two sides differ, so the contrast
is a lower bound on that difference.  Pixels on the ridge of the contrast across the
edge (non-maximum suppression, as Canny's detector) with contrast >= ``threshold`` seed an
edge; it is continued along the ridge while the contrast stays >= ``threshold / 2``
(hysteresis: one edge does not fall apart where it weakens for a few pixels) and kept
when it is at least ``min_length`` pixels long (shorter ones are detail below a tile).
The ridge test and the direction across it are computed only where the contrast reaches
``threshold / 2`` (a few pixels in a hundred), the only pixels they can keep.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import InputError
from ..fields import DensityMap, DirectionField
from ..pixels import pixel_index
from ..shapes import DEFAULT_ELEMENT, check_shape, shape_record
from ..validate import real_number

DEFAULT_CONTRAST = 3.0
FIELD_SMOOTHING = 1.5  # the field's Gaussian, in element spacings
CONTRAST_RANGE = (1.0, 100.0)  # densest / sparsest cell area
EDGE_FRACTION = 0.25  # edge pixels: tensor strength >= this share of its 99th percentile
EDGE_FLOOR = 0.02  # ... and >= this many intensity units (0..1) per pixel: not just noise
# A strong edge (a wall for the tiles): contrast >= this ΔE*ab, about five times the
# just noticeable difference (2.3).  A tile across a step of this contrast takes the
# mean of both sides and differs from each by half of it.  Walls cost little coverage
# since the tiles beside them are cut to fit (cvt.cutting), and more walls keep more
# tiles off the picture's contours: on six photographs (2000 squares) the colour error
# fell 5-13 % from a threshold of 40 to 11, while coverage stayed >= 0.82 (0.83-0.86
# at 40, 0.827-0.858 at 11); at 10 the astronaut portrait fell to 0.820.
DEFAULT_EDGE_THRESHOLD = 11.0
EDGE_HYSTERESIS = 0.5  # an edge continues while its contrast >= this share of the threshold


@dataclass
class PictureFields:
    """What :func:`picture_fields` extracts; arrays are (H, W)."""

    density: DensityMap
    field: DirectionField
    edge_angles: np.ndarray | None  # tensor edge orientation at every pixel (radians, mod π)
    strength: np.ndarray | None  # sqrt(λ₁): local edge strength, intensity units per pixel
    edges: np.ndarray  # bool: the pixels the direction field is carried from
    detail: np.ndarray | None  # smoothed gradient magnitude, 0..1 after normalisation
    # (edge_angles, strength and detail are None where picture_fields was asked for no details)


def _ndimage():
    """scipy.ndimage, imported on first use: importing this module (every command's
    parser does, for the mosaic's defaults) stays cheap."""
    from scipy import ndimage

    return ndimage


def as_channels(picture: np.ndarray) -> np.ndarray:
    """(H, W, C) float from a (H, W) grey or (H, W, C) colour array: float32 stays float32
    (the filters widen a channel at a time, exactly), anything else is float64."""
    arr = np.asarray(picture)
    if arr.dtype != np.float32:
        arr = arr.astype(np.float64, copy=False)
    if arr.ndim == 2:
        return arr[..., None]
    if arr.ndim == 3 and arr.shape[2] >= 1:
        return arr
    raise InputError(f"a picture must be (H, W) or (H, W, channels), got shape {arr.shape}")


def structure_tensor(picture: np.ndarray, sigma: float = 1.0, window: float = 2.0):
    """Colour structure tensor (Jxx, Jxy, Jyy), each (H, W).

    ``sigma``: scale of the Gaussian derivative; ``window``: the Gaussian G_ρ that
    averages the outer products (both in pixels).  x is the column axis, y the row axis
    (down), so orientations come out in the raster frame."""
    chans = as_channels(picture)
    tmp = None
    for c in range(chans.shape[2]):
        # one channel's plane, copied (float32 widened, exactly): both passes down the
        # columns then read it contiguously, as views, where they would gather and
        # widen each band of rows from the strided channel
        ch = np.ascontiguousarray(chans[..., c], dtype=np.float64)
        gx = gaussian_filter(ch, sigma, order=(0, 1))
        gy = gaussian_filter(ch, sigma, order=(1, 0))
        if c == 0:
            # the sums start from the first channel's products plus 0 (what adding them
            # to zeros gives, -0 turned +0), in the derivatives' own memory
            jxy = np.multiply(gx, gy)
            jxx = np.multiply(gx, gx, out=gx)
            jyy = np.multiply(gy, gy, out=gy)
            for part in (jxx, jxy, jyy):
                part += 0.0
            continue
        # the products in place: one picture-sized temporary for all of them
        tmp = np.multiply(gx, gy, out=tmp)
        jxy += tmp
        jxx += np.multiply(gx, gx, out=gx)
        jyy += np.multiply(gy, gy, out=gy)
        del gx, gy
    del tmp
    if window > 0:
        jxx = gaussian_filter(jxx, window)
        jxy = gaussian_filter(jxy, window)
        jyy = gaussian_filter(jyy, window)
    return jxx, jxy, jyy


# rows of the structure tensor made at once by tensor_by_rows: a band and its halo hold
# the tensor's temporaries (about 100 bytes a pixel), never the whole picture
SLAB_ROWS = 256


def _reach(sigma: float) -> int:
    """Rows on either side a Gaussian filter of ``sigma`` reads (ndimage's truncation)."""
    return int(4.0 * float(sigma) + 0.5) if sigma > 1e-15 else 0


def tensor_by_rows(source, height: int, use, sigma: float = 1.0, window: float = 2.0, rows: int = SLAB_ROWS):
    """The structure tensor a band of rows at a time, bit for bit the whole picture's.

    Each band is computed from its rows and a halo of the rows its filters reach (the
    derivative's and the window's), read by ``source``; the rows the halo leaves
    uncertain (those a cut band's repeated border reaches) are never used.  Two bands are
    computed at a time, side by side.

    Parameters
    ----------
    source : callable
        ``source(a, b)``: the (b - a, W[, C]) channels of rows a..b-1 (e.g. a slice of
        the picture, or the slice converted to CIELAB).
    height : int
        H, the picture's rows.
    use : callable
        ``use(lo, hi, jxx, jxy, jyy)`` for each band of rows lo..hi-1 with its tensor
        (views of the band's own arrays, which ``use`` may overwrite); bands may come
        in any order, two at once.
    sigma, window : float
        As for :func:`structure_tensor`.
    rows : int
        Rows per band.
    """
    from ..threads import side_by_side

    halo = _reach(sigma) + (_reach(window) if window > 0 else 0)

    def band(lo: int) -> None:
        hi = min(lo + rows, height)
        a, b = max(0, lo - halo), min(height, hi + halo)
        jxx, jxy, jyy = structure_tensor(source(a, b), sigma, window)
        use(lo, hi, jxx[lo - a : hi - a], jxy[lo - a : hi - a], jyy[lo - a : hi - a])

    starts = range(0, height, rows)
    for k in range(0, len(starts), 2):
        side_by_side(*(lambda lo=lo: band(lo) for lo in starts[k : k + 2]))


def gaussian_weights(sigma: float, order: int = 0) -> np.ndarray:
    """The Gaussian kernel (``order`` 0) or its derivative (1) of ``ndimage.gaussian_filter1d``,
    sampled at -r .. r with r = round(4 sigma), computed as it computes it.

    Parameters
    ----------
    sigma : float
        Standard deviation in pixels, > 0.
    order : int
        0 or 1.

    Returns
    -------
    (2r + 1,) float64 array
    """
    radius = int(4.0 * float(sigma) + 0.5)  # ndimage's truncation
    x = np.arange(-radius, radius + 1)
    sigma2 = sigma * sigma
    phi = np.exp(-0.5 / sigma2 * x**2)
    phi = phi / phi.sum()
    if order == 0:
        return phi
    if order == 1:
        return x * (1.0 / -sigma2) * phi
    raise InputError(f"a Gaussian filter's order must be 0 or 1, got {order!r}")


ROW_BAND = 32  # output rows filtered at once down the columns: the band's rows stay in cache


def _filter_columns(image: np.ndarray, sigma: float, order: int) -> np.ndarray:
    """``ndimage.gaussian_filter1d(image, sigma, axis=0, order=order, mode="nearest")``,
    bit for bit: the same weights summed in the same order (ndimage folds a symmetric or
    antisymmetric kernel about its centre), but over whole rows at a time, where ndimage
    copies the picture column by column (strided reads).  Each band of rows is read
    (widened to float64, its border rows repeated) as it is filtered: no padded copy of
    the picture."""
    weights = gaussian_weights(sigma, order)[::-1]  # ndimage correlates with the reversed kernel
    r = len(weights) // 2
    h = image.shape[0]
    fold = np.add if order == 0 else np.subtract
    out = np.empty(image.shape)
    tmp = np.empty((min(ROW_BAND, h),) + image.shape[1:])
    for lo in range(0, h, ROW_BAND):
        n = min(ROW_BAND, h - lo)
        if lo >= r and lo + n + r <= h and image.dtype == np.float64:
            src = image[lo - r : lo + n + r]
        else:  # rows beyond the border repeat the edge row ("nearest")
            src = image[np.clip(np.arange(lo - r, lo + n + r), 0, h - 1)].astype(np.float64, copy=False)
        o, t = out[lo : lo + n], tmp[:n]
        np.multiply(src[r : r + n], weights[r], out=o)
        for j in range(r, 0, -1):
            fold(src[r - j : r - j + n], src[r + j : r + j + n], out=t)
            t *= weights[r - j]
            o += t
    return out


def gaussian_filter(image: np.ndarray, sigma: float, order: tuple[int, int] = (0, 0)) -> np.ndarray:
    """``ndimage.gaussian_filter(image, sigma, order=order, mode="nearest")`` of a 2-D array,
    bit for bit, several times faster on a large picture.

    The pass down the columns (ndimage's slow one: it reads each column with a stride)
    is :func:`_filter_columns`, the pass along the rows is ndimage's own, in place.

    Parameters
    ----------
    image : (H, W) float array
        float32 is widened a band of rows at a time (exactly).
    sigma : float
        Standard deviation in pixels, the same along both axes (0: no filtering).
    order : (int, int)
        Derivative order along the rows' axis (y) and the columns' axis (x): 0 or 1 each.

    Returns
    -------
    (H, W) float64 array
    """
    image = np.asarray(image)
    if image.dtype != np.float32:
        image = image.astype(np.float64, copy=False)
    if image.ndim != 2:
        raise InputError(f"gaussian_filter takes a 2-D array, got shape {image.shape}")
    if sigma <= 1e-15:  # ndimage leaves an axis with no width alone, whatever its order
        return image.astype(np.float64)
    down = _filter_columns(image, sigma, order[0])
    return _ndimage().gaussian_filter1d(down, sigma, axis=1, order=order[1], mode="nearest", output=down)


def edge_orientation(
    jxx, jxy, jyy, overwrite: bool = False, exact: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """(edge angle in radians modulo π, strength sqrt(λ₁)) from the tensor.

    ``overwrite``: ``jxx`` and ``jyy`` may be used as scratch (the strength is returned
    in ``jyy``'s memory), so that the tensor and its results need one picture-sized
    array more than the tensor, not three.  ``exact``: λ₁'s root term by ``np.hypot``
    (False: ``sqrt(a² + b²)``, within one unit in the last place of it and several times
    faster: ``hypot`` costs more than the rest together)."""
    half_trace = jxx + jyy
    half_trace *= 0.5
    diff = np.subtract(jxx, jyy, out=jxx if overwrite else None)
    twice_xy = np.multiply(jxy, 2.0, out=jyy if overwrite else None)
    along = np.arctan2(twice_xy, diff)
    del twice_xy
    along *= 0.5  # the gradient's line, mod π
    along += 0.5 * math.pi
    return along, _largest_root(half_trace, diff, jxy, jyy if overwrite else None, exact)


def _largest_root(half_trace, diff, jxy, out, exact: bool) -> np.ndarray:
    """sqrt(λ₁) from half the trace and Jxx - Jyy (``diff``, used as scratch), into
    ``out`` (None: a new array); ``exact`` as for :func:`edge_orientation`."""
    diff *= 0.5
    if exact:
        lam1 = np.hypot(diff, jxy, out=out)
    else:
        np.multiply(diff, diff, out=diff)
        lam1 = np.multiply(jxy, jxy, out=out)
        lam1 += diff
        np.sqrt(lam1, out=lam1)
    del diff
    lam1 += half_trace
    del half_trace
    np.maximum(lam1, 0.0, out=lam1)
    return np.sqrt(lam1, out=lam1)


# from this sigma (px) on, gaussian_smooth filters through the FFT: the direct filter's
# kernel spans 8 sigma, while the FFT's cost does not grow with it
FFT_SIGMA = 8.0


# rows (and spectrum columns) gaussian_smooth transforms at once
FFT_BAND = 256


def gaussian_smooth(image: np.ndarray, sigma: float, out: np.ndarray | None = None) -> np.ndarray:
    """``ndimage.gaussian_filter(image, sigma, mode="nearest")`` of a 2-D array.

    The same kernel (truncated at 4 sigma) and border (the edge pixels repeated); from
    :data:`FFT_SIGMA` on it is applied through the FFT of the picture padded by twice the
    kernel's reach, which agrees with the direct filter to rounding (about 1e-15 of the
    values).  The transform is ``scipy.fft.rfft2`` / ``irfft2``'s, bit for bit, taken one
    axis at a time: the rows' transforms once per distinct row (the repeated border
    rows share theirs), the columns' a band of columns at a time, and only the rows
    that are kept transformed back, so that it holds one complex array of the picture's
    size (not the padded picture, its spectrum and the padded result at once).

    Parameters
    ----------
    image : (H, W) float array
    sigma : float
        The Gaussian's standard deviation in pixels, the same along both axes.
    out : (H, W) float64 array, optional
        Where to write the result; it may be ``image`` itself (the image is read whole
        before any of the result is written), which saves a picture-sized array.

    Returns
    -------
    (H, W) float64 array
        ``out`` where given.
    """
    if sigma < FFT_SIGMA:
        if out is None:
            return gaussian_filter(image, sigma)
        out[...] = gaussian_filter(image, sigma)
        return out
    from scipy import fft

    r = int(4.0 * sigma + 0.5)  # ndimage's truncation
    x = np.arange(-r, r + 1, dtype=np.float64)
    kernel = np.exp(-0.5 / (sigma * sigma) * x * x)
    kernel /= kernel.sum()
    h, w = image.shape
    size_y, size_x = fft.next_fast_len(h + 4 * r, real=True), fft.next_fast_len(w + 4 * r, real=True)
    cols = size_x // 2 + 1
    # along the rows: each row padded by r repeated edge pixels (then zeros to size_x)
    spectrum = np.empty((h, cols), dtype=np.complex128)
    for lo in range(0, h, FFT_BAND):
        rows = np.pad(np.asarray(image[lo : lo + FFT_BAND], dtype=np.float64), ((0, 0), (r, r)), mode="edge")
        spectrum[lo : lo + len(rows)] = fft.rfft(rows, size_x, axis=1, workers=-1)
    zero_row = fft.rfft(np.zeros((1, size_x)), size_x, axis=1)[0]
    along_y = fft.fft(kernel, size_y)[:, None]
    along_x = fft.rfft(kernel, size_x)[None, :]
    # down the columns: the padded column (r copies of the first and last row, zeros to
    # size_y), filtered, transformed back (unscaled, as irfft2's first pass) and cut to h
    block = np.empty((size_y, min(FFT_BAND, cols)), dtype=np.complex128)
    for c0 in range(0, cols, FFT_BAND):
        c1 = min(c0 + FFT_BAND, cols)
        b = block[:, : c1 - c0]
        b[:r] = spectrum[0, c0:c1]
        b[r : r + h] = spectrum[:, c0:c1]
        b[r + h : h + 2 * r] = spectrum[h - 1, c0:c1]
        b[h + 2 * r :] = zero_row[c0:c1]
        b = fft.fft(b, size_y, axis=0, workers=-1)
        b *= along_y
        b *= along_x[:, c0:c1]
        spectrum[:, c0:c1] = fft.ifft(b, size_y, axis=0, norm="forward", workers=-1)[2 * r : 2 * r + h]
        del b
    # back along the rows, scaled as pocketfft scales irfft2 (1 / N in long double)
    scale = np.float64(np.longdouble(1) / np.longdouble(size_y * size_x))
    if out is None:
        out = np.empty((h, w))
    for lo in range(0, h, FFT_BAND):
        rows = fft.irfft(spectrum[lo : lo + FFT_BAND], size_x, axis=1, norm="forward", workers=-1)
        rows *= scale
        out[lo : lo + len(rows)] = rows[:, 2 * r : 2 * r + w]
    return out


def _turned_and_smoothed(angles, sigma: float, m: float, overwrite: bool):
    """(cos, sin) of ``m`` times ``angles``, each Gaussian-smoothed (``sigma`` > 0)."""
    turned = np.multiply(angles, m, out=angles if overwrite else None)
    c = np.cos(turned)
    s = np.sin(turned, out=turned if overwrite else None)
    del turned
    c = gaussian_smooth(c, sigma, out=c)
    s = gaussian_smooth(s, sigma, out=s)
    return c, s


def smooth_angles(angles: np.ndarray, sigma: float, period: float, overwrite: bool = False) -> np.ndarray:
    """Gaussian smoothing of an angle field that is defined modulo ``period``
    (``overwrite``: ``angles``, a float64 array of the caller's, may hold the result, so
    that a large picture's field needs two picture-sized arrays less; the same numbers)."""
    if sigma <= 0:
        return angles
    m = 2.0 * math.pi / period
    c, s = _turned_and_smoothed(angles, sigma, m, overwrite)
    return np.divide(np.arctan2(s, c, out=s), m, out=s)


# Mosaics of more tiles than the straight cut's bound (cvt.mosaic.cutting.EXACT_TILES) take
# their density and field from a coarse grid (field_step): both are smoothed over one
# spacing or more, so a grid a quarter of a spacing apart carries them, at a tenth of
# the work on a poster.  Up to the bound they are computed on every pixel, as before.
FIELD_STEP_SPACINGS = 4.0  # the coarse grid's step: at most this share of the spacing


def field_step(height: int, width: int, spacing: float) -> int:
    """The grid step (pixels) :func:`picture_fields` computes its fields on by default.

    Parameters
    ----------
    height, width : int
        The picture's size in pixels.
    spacing : float
        The mean element spacing in pixels, sqrt(height * width / N).

    Returns
    -------
    int
        1 (every pixel) for a mosaic of at most ``EXACT_TILES`` tiles
        (:mod:`cvt.mosaic.cutting`), else ``floor(spacing / FIELD_STEP_SPACINGS)``, at
        least 1.
    """
    from .cutting import EXACT_TILES

    spacing = max(float(spacing), 1.0)
    if height * width / (spacing * spacing) <= EXACT_TILES + 0.5:
        return 1
    return max(1, int(spacing / FIELD_STEP_SPACINGS))


def _block_sums(band: np.ndarray, step: int) -> np.ndarray:
    """(ceil(n / step), ceil(W / step)) sums of ``band``'s step x step blocks (the last
    row and column of blocks may be cut short by the band's edge).  Whole rows and
    strided columns are added a block's offset at a time: several times faster than
    ``np.add.reduceat`` on small blocks."""
    n, w = band.shape
    nf, wf = n - n % step, w - w % step
    rows = np.empty((-(-n // step), w))
    whole = band[:nf].reshape(nf // step, step, w)
    np.copyto(rows[: nf // step], whole[:, 0])
    for k in range(1, step):
        rows[: nf // step] += whole[:, k]
    if nf < n:
        rows[-1] = band[nf:].sum(axis=0)
    out = np.empty((rows.shape[0], -(-w // step)))
    np.copyto(out[:, : wf // step], rows[:, 0:wf:step])
    for k in range(1, step):
        out[:, : wf // step] += rows[:, k:wf:step]
    if wf < w:
        out[:, -1] = rows[:, wf:].sum(axis=1)
    return out


def _block_centres(n: int, step: int) -> np.ndarray:
    """The centres (pixel index units) of the step-wide blocks that cover n pixels."""
    starts = np.arange(0, n, step)
    return starts + (np.minimum(step, n - starts) - 1) / 2.0


def _linear_weights(n: int, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each of n pixels: the two blocks around it and the second one's weight."""
    centres = _block_centres(n, step)
    p = np.arange(n, dtype=np.float64)
    hi = np.searchsorted(centres, p, side="right")
    lo = np.clip(hi - 1, 0, len(centres) - 1)
    hi = np.clip(hi, 0, len(centres) - 1)
    span = centres[hi] - centres[lo]
    frac = np.divide(p - centres[lo], span, out=np.zeros(n), where=span > 0)
    return lo, hi, frac


def upsample(coarse: np.ndarray, step: int, height: int, width: int) -> np.ndarray:
    """Bilinear interpolation to (height, width) of a grid of step x step block means.

    Each coarse value sits at its block's centre; pixels outside the outermost centres
    take the nearest one's value (as a "nearest" border).

    Parameters
    ----------
    coarse : (ceil(height / step), ceil(width / step)) float array
    step : int
        The blocks' size in pixels, >= 1.
    height, width : int
        The fine grid's size.

    Returns
    -------
    (height, width) float64 array
    """
    coarse = np.asarray(coarse, dtype=np.float64)
    x0, x1, fx = _linear_weights(width, step)
    y0, y1, fy = _linear_weights(height, step)
    # along the rows first: the coarse rows at full width (np.take keeps them in C order,
    # where coarse[:, x0] would not, and the row gathers below would crawl)
    along = np.take(coarse, x0, axis=1)
    along += (np.take(coarse, x1, axis=1) - along) * fx
    out = np.empty((height, width))
    # down the columns a run of rows at a time: the rows between two block centres share
    # their two coarse rows, so each is their difference times its weight plus the
    # first (what along[y0] + (along[y1] - along[y0]) * fy gives, to the last bit),
    # with no gathered copy of a row; a run outside the outermost centres (one coarse
    # row, weight 0) is that row plus 0
    ends = np.flatnonzero(np.diff(y0) | np.diff(y1)) + 1
    for a, b in zip(np.append(0, ends).tolist(), np.append(ends, height).tolist(), strict=True):
        k, k1, o = y0[a], y1[a], out[a:b]
        if k1 == k:
            np.add(along[k], 0.0, out=o)
        else:
            np.multiply(fy[a:b, None], along[k1] - along[k], out=o)
            o += along[k]
    return out


def picture_fields(
    picture: np.ndarray,
    spacing: float,
    element: str = DEFAULT_ELEMENT,
    contrast: float = DEFAULT_CONTRAST,
    sigma: float = 1.0,
    details: bool = True,
    step: int | None = None,
) -> PictureFields:
    """Density map and direction field of ``picture`` ((H, W) or (H, W, C), values 0..1).

    ``spacing`` is the mean element spacing in pixels (sqrt(area / N)): the density is
    smoothed over about one spacing, the field over one and a half (coherent rows of tiles
    pack tighter: measured +1.7 points of compacted coverage on a portrait against half a
    spacing, while the tiles still turn with every edge longer than their rows).  ``element`` picks the
    symmetry the field is smoothed in (the shape record's ``side_period``).
    ``details``: also return the tensor's edge angles, its strength and the detail map
    (False: None, each freed as soon as it is used, as a large mosaic wants).
    ``step``: the grid the fields are computed on, in pixels (None: :func:`field_step`,
    or 1 where details are asked for).  Above 1 the structure tensor's products are
    averaged over step x step blocks, the density and field are made on that grid as on
    the pixels (the window and the smoothing in pixels, the same) and interpolated
    bilinearly to every pixel; the edges are the coarse grid's, each block's pixels
    alike; no details."""
    return picture_fields_later(picture, spacing, element, contrast, sigma, details, step)()


def picture_fields_later(
    picture: np.ndarray,
    spacing: float,
    element: str = DEFAULT_ELEMENT,
    contrast: float = DEFAULT_CONTRAST,
    sigma: float = 1.0,
    details: bool = True,
    step: int | None = None,
) -> Callable[[], PictureFields]:
    """:func:`picture_fields` in two parts: the pass over the picture now, and the rest in
    the call returned, which reads no more of ``picture`` and may run on another thread
    beside other work (on a coarse grid, ``step`` above 1, the rest is the blocks' fields,
    their upsampling and smoothing; on every pixel all is done now).

    Parameters
    ----------
    picture : (H, W) or (H, W, C) float ndarray
        Values 0..1.
    spacing : float
        The mean element spacing in pixels.
    element : str
        The element's shape (a ``cvt.shapes`` name).
    contrast : float
        The densest to the sparsest cell area.
    sigma : float
        The derivative's scale in pixels.
    details : bool
        Also give the tensor's edge angles, its strength and the detail map.
    step : int or None
        The grid the fields are computed on, in pixels (None: :func:`field_step`).

    Returns
    -------
    callable
        ``finish()``: the :class:`PictureFields` :func:`picture_fields` returns (call it
        once).
    """
    check_shape(element)
    contrast = real_number(contrast, "contrast", *CONTRAST_RANGE)
    chans = as_channels(picture)
    if not np.isfinite(chans).all():
        raise InputError("picture contains NaN or infinite values")
    spacing = max(float(spacing), 1.0)
    h, w = chans.shape[:2]
    if step is None:
        step = 1 if details else field_step(h, w, spacing)
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 1:
        raise InputError(f"step must be a whole number >= 1, got {step!r}")
    if step > 1 and details:
        raise InputError(f"details are made on every pixel only (step 1), got step {step}")
    period = shape_record(element).side_period
    if step > 1:
        return _coarse_fields(chans, spacing, period, contrast, sigma, int(step))
    trace = np.empty((h, w))  # the density's gradient energy
    edge_angles = np.empty((h, w))
    strength = np.empty((h, w))

    def use(lo, hi, jxx, jxy, jyy):
        np.add(jxx, jyy, out=trace[lo:hi])
        edge_angles[lo:hi], strength[lo:hi] = edge_orientation(jxx, jxy, jyy, overwrite=True)

    tensor_by_rows(lambda a, b: chans[a:b], h, use, sigma=sigma, window=max(1.0, 2.0 * sigma))
    edges = _edge_pixels(strength)
    if not details:
        strength = None

    # density: smoothed colour gradient magnitude, 1 .. contrast (before the field, so
    # that the trace is freed before the field's temporaries are made)
    detail = _detail(trace, spacing)  # in the trace's memory: it is not needed after
    trace = None
    values = np.multiply(detail, contrast - 1.0, out=None if details else detail)
    values += 1.0
    density = DensityMap(values)
    del values
    if not details:
        detail = None

    # direction: each pixel takes the tensor orientation at its nearest edge pixel
    if edges.any():
        carried = _carried(edges, edge_angles)
        if not details:
            edge_angles = None
        angles = smooth_angles(carried, FIELD_SMOOTHING * spacing, period, overwrite=True)
        del carried
    else:
        angles = np.zeros(edges.shape)
        if not details:
            edge_angles = None
    field = DirectionField.from_angles(angles, spec="picture")
    made = PictureFields(density, field, edge_angles, strength, edges, detail)
    return lambda: made


def _edge_pixels(strength: np.ndarray) -> np.ndarray:
    """The pixels whose tensor strength marks an edge (EDGE_FRACTION, EDGE_FLOOR)."""
    top = float(np.percentile(strength, 99)) if strength.size else 0.0
    return strength >= max(EDGE_FRACTION * top, EDGE_FLOOR)


def _detail(trace: np.ndarray, sigma: float) -> np.ndarray:
    """The detail map 0..1 from the tensor's trace smoothed over ``sigma``, in its memory."""
    magnitude = gaussian_smooth(trace, sigma, out=trace)
    np.sqrt(np.maximum(magnitude, 0.0, out=magnitude), out=magnitude)
    ref = float(np.percentile(magnitude, 99)) if magnitude.size else 0.0
    if ref > EDGE_FLOOR / 10:
        return np.clip(np.divide(magnitude, ref, out=magnitude), 0.0, 1.0, out=magnitude)
    magnitude[...] = 0.0
    return magnitude


def _carried(edges: np.ndarray, edge_angles: np.ndarray) -> np.ndarray:
    """Each pixel's angle from ``edge_angles`` at its nearest ``edges`` pixel."""
    ii, jj = _ndimage().distance_transform_edt(~edges, return_distances=False, return_indices=True)
    return edge_angles[ii, jj]


def _coarse_fields(
    chans, spacing: float, period: float, contrast: float, sigma: float, step: int
) -> Callable[[], PictureFields]:
    """:func:`picture_fields` on a grid of ``step`` x ``step`` blocks (no details), in two
    parts: the derivative's pass over the picture now (on every core), and the rest, which
    reads only the blocks' sums, in the call returned."""
    h, w = chans.shape[:2]
    hc, wc = -(-h // step), -(-w // step)
    sums = [np.empty((hc, wc)) for _ in range(3)]  # the block sums of the products

    def use(lo, hi, jxx, jxy, jyy):
        for out, part in zip(sums, (jxx, jxy, jyy), strict=True):
            out[lo // step : -(-hi // step)] = _block_sums(part, step)

    # the derivative on every pixel, its products averaged over the blocks
    tensor_by_rows(
        lambda a, b: chans[a:b], h, use, sigma=sigma, window=0.0, rows=step * max(1, SLAB_ROWS // step)
    )
    return functools.partial(_fields_from_block_sums, sums, (h, w), spacing, period, contrast, sigma, step)


def _fields_from_block_sums(sums: list, size: tuple, spacing, period, contrast, sigma, step) -> PictureFields:
    """The rest of :func:`_coarse_fields`, from the blocks' sums of the tensor's products
    (``sums``, emptied here) of a picture of ``size`` (H, W)."""
    h, w = size
    rows, cols = np.diff(np.append(np.arange(0, h, step), h)), np.diff(np.append(np.arange(0, w, step), w))
    counts = np.outer(rows, cols).astype(np.float64)
    # the window in pixels less the block's own spread (a box of step pixels has
    # variance (step² - 1) / 12), on the coarse grid
    window = max(1.0, 2.0 * sigma)
    left = math.sqrt(max(window * window - (step * step - 1) / 12.0, 0.0)) / step
    jxx, jxy, jyy = (gaussian_filter(np.divide(c, counts, out=c), left) for c in sums)
    sums.clear()
    trace = jxx + jyy
    edge_angles, strength = edge_orientation(jxx, jxy, jyy, overwrite=True)
    del jxx, jxy, jyy
    edges = _edge_pixels(strength)
    del strength

    values = _detail(trace, spacing / step)
    values *= contrast - 1.0
    values += 1.0
    density = DensityMap(upsample(values, step, h, w))
    del values

    m = 2.0 * math.pi / period
    if edges.any():
        c, s = _turned_and_smoothed(_carried(edges, edge_angles), FIELD_SMOOTHING * spacing / step, m, True)
    else:  # no edge: angle 0 everywhere (atan2(0, 1))
        c, s = np.ones(edges.shape), np.zeros(edges.shape)
    del edge_angles
    full_edges = np.repeat(np.repeat(edges, step, axis=0)[:h], step, axis=1)[:, :w]
    return PictureFields(density, CoarseField(c, s, step, m, h, w), None, None, full_edges, None)


class CoarseField(DirectionField):
    """A direction field kept on a coarse grid, as the smoothed unit vectors of ``m·θ``.

    The field is read only where sites stand (:meth:`angles_at`), so it is interpolated
    there, not at every pixel: each read is, to the last bit, the value
    :func:`upsample` of both vector components and their angle would give at that
    pixel, without the two picture-sized arrays and the arctangent of every pixel.

    Parameters
    ----------
    cos, sin : (ceil(height / step), ceil(width / step)) float64 arrays
        The smoothed unit vectors' components on the blocks.
    step : int
        The blocks' size in pixels.
    m : float
        The symmetry: 2π / the element's side period.
    height, width : int
        The raster's size in pixels.
    """

    def __init__(self, cos: np.ndarray, sin: np.ndarray, step: int, m: float, height: int, width: int):
        super().__init__("picture", None, width, height, arg=("picture", None))
        # each block's (sin, cos) side by side: a site's read fetches both at once
        self._vectors = np.stack([sin, cos], axis=-1)
        self._sin, self._cos = self._vectors[..., 0], self._vectors[..., 1]
        self._step, self._m = int(step), float(m)
        # per pixel column and row: the two blocks around it and the second one's weight
        self._x_weights = _linear_weights(width, self._step)
        self._y_weights = _linear_weights(height, self._step)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    def angles_at(self, sites: np.ndarray) -> np.ndarray:
        """The angle (radians) at the pixel that holds each of the (N, 2) ``sites``."""
        i, j = pixel_index(sites, self.width, self.height)
        return self._at(i, j)

    def angles(self) -> np.ndarray:
        """(H, W) float64: the angle at every pixel (as :meth:`angles_at` reads it)."""
        s = upsample(self._sin, self._step, self.height, self.width)
        np.arctan2(s, upsample(self._cos, self._step, self.height, self.width), out=s)
        s /= self._m
        return s

    def _at(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        x0, x1, fx = (a.take(j) for a in self._x_weights)
        y0, y1, fy = (a.take(i) for a in self._y_weights)
        fx, fy = fx[:, None], fy[:, None]
        # the four blocks around each site by flat index, (sin, cos) together: on a
        # poster's grid the reads are cache misses, and a gather by row and column
        # costs more again
        row0, row1 = y0 * self._vectors.shape[1], y1 * self._vectors.shape[1]
        vectors = self._vectors.reshape(-1, 2)
        at00, at01, at10, at11 = (
            vectors.take(k, axis=0) for k in (row0 + x0, row0 + x1, row1 + x0, row1 + x1)
        )
        # upsample's arithmetic, term for term: along the rows, then down the columns
        top = at00
        top += (at01 - top) * fx
        bottom = at10
        bottom += (at11 - bottom) * fx
        top += (bottom - top) * fy
        parts = top[:, 0], top[:, 1]
        out = np.arctan2(parts[0], parts[1])
        out /= self._m
        return out


# ----------------------------------------------------------------- strong edges


@lru_cache(maxsize=8)
def step_response(sigma: float = 1.0, window: float = 2.0) -> float:
    """Largest strength sqrt(λ₁) of the tensor at a pixel-aligned step of height 1 in
    one channel: the factor that turns strength into the step's colour difference."""
    step = np.zeros((8, 64, 1))
    step[:, 32:] = 1.0
    _, strength = edge_orientation(*structure_tensor(step, sigma, window))
    return float(strength.max())


def edge_contrast(lab: np.ndarray, sigma: float = 1.0, srgb: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(contrast in ΔE*ab, direction across the edge in radians mod π) of a CIELAB
    picture (H, W, 3); see the module docstring.  ``srgb``: the picture is sRGB in 0..1,
    converted to CIELAB a band of rows at a time (never whole)."""
    h, w = lab.shape[:2]
    contrast = np.empty((h, w))
    across = np.empty((h, w))
    _contrast_rows(lab, sigma, srgb, contrast, across)
    return contrast, across


def _contrast_rows(picture, sigma: float, srgb: bool, contrast, across=None, found=None, least=0.0) -> None:
    """:func:`edge_contrast` into ``contrast`` and ``across``, a band of rows at a time;
    or, where ``found`` (a list) is given, the contrast only, and for the pixels whose
    contrast is >= ``least`` a pair (their flat indices, the 45° sector of the direction
    across there (0..3, int8)) appended to ``found`` for each band."""
    from .colour import srgb_to_lab

    window = max(1.0, 2.0 * sigma)
    step = step_response(sigma, window)
    width = picture.shape[1]

    def use(lo, hi, jxx, jxy, jyy):
        if found is None:
            along, strength = edge_orientation(jxx, jxy, jyy, overwrite=True, exact=False)
            np.divide(strength, step, out=contrast[lo:hi])
            along -= 0.5 * math.pi
            across[lo:hi] = along
            return
        # as edge_orientation(exact=False) gives it, keeping Jxx and Jyy for the sectors
        half_trace = jxx + jyy
        half_trace *= 0.5
        strength = _largest_root(half_trace, np.subtract(jxx, jyy), jxy, None, False)
        band = np.divide(strength, step, out=contrast[lo:hi])
        del strength
        at = np.flatnonzero(band >= least)
        found.append((at + lo * width, _sectors(jxx.ravel()[at], jxy.ravel()[at], jyy.ravel()[at])))

    # in CIELAB a plane per channel: the tensor's filters read each channel without a copy
    source = (lambda a, b: srgb_to_lab(picture[a:b], planes=True)) if srgb else (lambda a, b: picture[a:b])
    tensor_by_rows(source, picture.shape[0], use, sigma=sigma, window=window)


def _sectors(jxx, jxy, jyy) -> np.ndarray:
    """The 45° sector (0..3, int8) of the direction across the edge, ``round(4 φ / π)
    mod 4`` of φ = edge_orientation's angle - 90°, computed as it computes it."""
    along = np.arctan2(np.multiply(jxy, 2.0), np.subtract(jxx, jyy))
    along *= 0.5
    along += 0.5 * math.pi
    along -= 0.5 * math.pi
    along /= 0.25 * math.pi
    return np.round(along, out=along).astype(np.int8) & 3  # -2 .. 2 before: mod 4


# neighbour offsets (row, column) along the direction across the edge, per 45° sector
_ACROSS = ((0, 1), (1, 1), (1, 0), (1, -1))


def strong_edges(
    lab: np.ndarray,
    threshold: float = DEFAULT_EDGE_THRESHOLD,
    min_length: float = 0.0,
    sigma: float = 1.0,
    srgb: bool = False,
) -> np.ndarray:
    """(H, W) bool: the strong edges of a CIELAB picture as thin 4-connected lines.

    ``threshold`` in ΔE*ab (see the module docstring), ``min_length`` in pixels.
    ``srgb``: ``lab`` is the sRGB picture (0..1), read in CIELAB a band of rows at a time."""
    h, w = lab.shape[:2]
    # the contrast inside a border of zeros: the neighbours are read from it without a
    # padded copy of a picture-sized array
    pad = np.zeros((h + 2, w + 2))
    contrast = pad[1:-1, 1:-1]
    found: list = []
    # the ridge is looked for only where the contrast reaches the hysteresis threshold
    # (a few pixels in a hundred): the same pixels as on the whole picture
    _contrast_rows(lab, sigma, srgb, contrast, found=found, least=EDGE_HYSTERESIS * threshold)
    at = np.concatenate([f[0] for f in found]) if found else np.zeros(0, dtype=np.int64)
    sector = np.concatenate([f[1] for f in found]) if found else np.zeros(0, dtype=np.int8)
    del found
    flat = pad.ravel()
    i, j = np.divmod(at, w)
    here = (i + 1) * (w + 2) + (j + 1)
    del i, j
    offset = np.array([di * (w + 2) + dj for di, dj in _ACROSS])[sector]
    del sector
    value = flat[here]
    # strictly above one neighbour, at least the other: one pixel of a flat ridge
    ridge = (value > flat[here + offset]) & (value >= flat[here - offset])
    del here, offset, value
    weak = np.zeros((h, w), dtype=bool)
    weak.ravel()[at[ridge]] = True
    del at, ridge
    parts, n = _ndimage().label(weak, structure=np.ones((3, 3), dtype=bool))
    if n == 0:
        return weak
    # the weak pixels only (a few in a hundred), not whole picture-sized arrays
    at = np.nonzero(weak)
    part = parts[at]
    del parts
    keep = np.zeros(n + 1, dtype=bool)
    keep[part[contrast[at] >= threshold]] = True  # a part with a seed
    keep &= np.bincount(part, minlength=n + 1) >= min_length
    edges = np.zeros((h, w), dtype=bool)
    edges[at] = keep[part]
    del at, part
    # a diagonal step leaves two pixels that touch at a corner only; add the one of the
    # two pixels beside the step that has the higher contrast (the edge passes nearer to
    # it), so that the line separates 4-connected pixels (cells, tiles)
    tl, tr, bl, br = edges[:-1, :-1], edges[:-1, 1:], edges[1:, :-1], edges[1:, 1:]
    ctl, ctr, cbl, cbr = contrast[:-1, :-1], contrast[:-1, 1:], contrast[1:, :-1], contrast[1:, 1:]
    down = tl & br & ~tr & ~bl  # a step down to the right
    up = tr & bl & ~tl & ~br  # a step up to the right
    fill_tr, fill_bl = down & (ctr >= cbl), down & (ctr < cbl)
    fill_tl, fill_br = up & (ctl >= cbr), up & (ctl < cbr)
    edges[:-1, 1:] |= fill_tr
    edges[1:, :-1] |= fill_bl
    edges[:-1, :-1] |= fill_tl
    edges[1:, 1:] |= fill_br
    return edges


__all__ = [
    "DEFAULT_CONTRAST",
    "FIELD_SMOOTHING",
    "CONTRAST_RANGE",
    "EDGE_FRACTION",
    "EDGE_FLOOR",
    "DEFAULT_EDGE_THRESHOLD",
    "EDGE_HYSTERESIS",
    "PictureFields",
    "as_channels",
    "structure_tensor",
    "SLAB_ROWS",
    "tensor_by_rows",
    "gaussian_weights",
    "ROW_BAND",
    "gaussian_filter",
    "edge_orientation",
    "FFT_SIGMA",
    "FFT_BAND",
    "gaussian_smooth",
    "smooth_angles",
    "FIELD_STEP_SPACINGS",
    "field_step",
    "upsample",
    "CoarseField",
    "picture_fields",
    "picture_fields_later",
    "step_response",
    "edge_contrast",
    "strong_edges",
]
