"""The comparison point the speed targets are stated against: scipy's cKDTree labelling
of every pixel centre plus ``np.bincount`` moments (the fastest common CPU tool).

Valid for uniform, unrotated l2 / l1 / linf only (cKDTree's Minkowski p = 2, 1, inf);
ties are resolved however cKDTree resolves them, so this is a timing reference, not a
correctness oracle (that is the NumPy backend).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.spatial import cKDTree

from compact_distributions.cvt.moments import Moments, moments_from_labels

P_OF_METRIC = {"l2": 2, "l1": 1, "linf": np.inf}


@lru_cache(maxsize=2)
def _pixel_centres(width: int, height: int) -> np.ndarray:
    ys, xs = np.mgrid[0:height, 0:width]
    return np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], axis=1)


def ckdtree_labels(sites: np.ndarray, width: int, height: int, metric: str = "l2") -> np.ndarray:
    """(H, W) int32 labels by cKDTree.query over all pixel centres (2 worker threads)."""
    tree = cKDTree(sites)
    _, idx = tree.query(_pixel_centres(width, height), k=1, p=P_OF_METRIC[metric], workers=-1)
    return idx.astype(np.int32).reshape(height, width)


def ckdtree_step(sites: np.ndarray, width: int, height: int, metric: str = "l2") -> Moments:
    """One Lloyd iteration's labels and moments the common-CPU-tool way."""
    return moments_from_labels(ckdtree_labels(sites, width, height, metric), len(sites))
