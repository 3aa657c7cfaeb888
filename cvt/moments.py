"""Per-site integer moments of a label raster, and the centroids and energy from them.

Sums are over pixel indices (column j, row i) with integer weights, so two backends that
produce the same labels produce bit-identical centroids.  Pixel centres are at
(j + 0.5, i + 0.5), which the centroid adds back after the division.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@dataclass
class Moments:
    count: np.ndarray  # Σ w        (N,) int64
    sx: np.ndarray  # Σ w·j         (N,) int64
    sy: np.ndarray  # Σ w·i         (N,) int64
    sxx: np.ndarray  # Σ w·j²       (N,) int64
    syy: np.ndarray  # Σ w·i²       (N,) int64

    @property
    def empty(self) -> np.ndarray:
        return self.count == 0

    def centroids(self, sites: np.ndarray) -> np.ndarray:
        """Cell centroids; a site whose cell is empty stays where it is."""
        out = np.array(sites, dtype=np.float64, copy=True)
        full = self.count > 0
        c = self.count[full].astype(np.float64)
        out[full, 0] = self.sx[full] / c + 0.5
        out[full, 1] = self.sy[full] / c + 0.5
        return out

    def energy(self, sites: np.ndarray) -> float:
        """Mean squared Euclidean distance (px²) from each pixel to its site:
        the quantity Lloyd's step decreases for the l2 metric."""
        total = self.count.sum()
        if total == 0:
            return float("nan")
        px = sites[:, 0] - 0.5  # site in index coordinates
        py = sites[:, 1] - 0.5
        n = self.count.astype(np.float64)
        ex = self.sxx - 2 * px * self.sx + px * px * n
        ey = self.syy - 2 * py * self.sy + py * py * n
        return float((ex + ey).sum() / total)


@lru_cache(maxsize=4)
def _pixel_indices(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Column and row index of every pixel, flattened (cached: reused every iteration)."""
    cols = np.tile(np.arange(w, dtype=np.float64), h)
    rows = np.repeat(np.arange(h, dtype=np.float64), w)
    return cols, rows


def moments_from_labels(labels: np.ndarray, n_elements: int, weights: np.ndarray | None = None) -> Moments:
    """Moments of a (H, W) int label raster (-1 = outside) with np.bincount.

    float64 bincount sums of integers are exact below 2**53 (any raster up to 8192²)."""
    flat = labels.ravel()
    cols, rows = _pixel_indices(*labels.shape)
    wts = None if weights is None else weights.ravel().astype(np.float64)
    keep = flat >= 0
    if not keep.all():
        flat, cols, rows = flat[keep], cols[keep], rows[keep]
        wts = None if wts is None else wts[keep]

    def total(values):
        if wts is not None:
            values = wts if values is None else values * wts
        return np.rint(np.bincount(flat, weights=values, minlength=n_elements)).astype(np.int64)

    return Moments(total(None), total(cols), total(rows), total(cols * cols), total(rows * rows))


def moments_from_runs(
    start: np.ndarray, end: np.ndarray, run_labels: np.ndarray, width: int, n_elements: int
) -> Moments:
    """Moments of a label raster given as row runs of one label.

    Each run's sums have a closed form, so the cost follows the number of runs, not of
    pixels; the totals are those of :func:`moments_from_labels` on the same raster.

    Parameters
    ----------
    start, end : (R,) int arrays
        Run k covers the flat (row-major) pixel indices ``start[k]`` to ``end[k] - 1``,
        all in one row.
    run_labels : (R,) int array
        The cell of each run, in 0..n_elements-1; -1: a run left out.
    width : int
        Columns of the raster.
    n_elements : int
        Number of cells.

    Returns
    -------
    Moments
        Integer sums per cell, bit-identical to those of :func:`moments_from_labels`.
    """
    # float64 throughout: every term and sum is an integer below 2**53 (any raster up to
    # 8192²), so exact, as in moments_from_labels
    start = np.asarray(start, dtype=np.int64)
    row_int = start // width
    length = np.subtract(end, start, dtype=np.float64)
    j0 = np.subtract(start, row_int * width, dtype=np.float64)
    row = row_int.astype(np.float64)
    last = length - 1
    sx = last * 0.5
    sx += j0
    sx *= length
    # sum of j² over j0..j0+last: length·j0·(j0 + last) + last·length·(2·last + 1) / 6,
    # the second term an integer before the division
    sxx = 2 * last + 1
    sxx *= last
    sxx *= length
    sxx /= 6
    sxx += length * j0 * (j0 + last)
    sy = length * row
    bins = np.where(run_labels < 0, n_elements, run_labels)  # left-out runs: one spare bin
    count, sx, sy, sxx, syy = (
        np.rint(np.bincount(bins, weights=v, minlength=n_elements + 1)[:n_elements]).astype(np.int64)
        for v in (length, sx, sy, sxx, sy * row)
    )
    return Moments(count, sx, sy, sxx, syy)


__all__ = ["Moments", "moments_from_labels", "moments_from_runs"]
