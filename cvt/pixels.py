"""The one pixel lookup of the suite: which raster pixel holds a point (fields,
placement, colours and pictures use it)."""

from __future__ import annotations

import numpy as np


def pixel_index(points, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of the pixel that contains each point (x, y), clamped to the raster."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    j = np.clip(np.floor(points[:, 0]).astype(np.int64), 0, width - 1)
    i = np.clip(np.floor(points[:, 1]).astype(np.int64), 0, height - 1)
    return i, j


__all__ = ["pixel_index"]
