"""The one pixel lookup of the suite: which raster pixel holds a point (fields,
placement, colours and pictures use it), and the one expansion of runs of indices."""

from __future__ import annotations

import numpy as np

PIXEL_BAND = 1 << 22  # pixels handled at once where a raster-sized temporary is avoided


def pixel_index(points, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of the pixel that contains each point (x, y), clamped to the raster."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    j = np.clip(np.floor(points[:, 0]).astype(np.int64), 0, width - 1)
    i = np.clip(np.floor(points[:, 1]).astype(np.int64), 0, height - 1)
    return i, j


def index_ranges(starts, counts) -> np.ndarray:
    """The indices starts[i] .. starts[i] + counts[i] - 1, for every i in turn (runs of
    pixels or vertices expanded to their indices, whole-array)."""
    offsets = np.cumsum(counts) - counts
    return np.repeat(np.asarray(starts) - offsets, counts) + np.arange(int(np.sum(counts)))


__all__ = ["PIXEL_BAND", "pixel_index", "index_ranges"]
