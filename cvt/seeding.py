"""Initial sites: uniform in the region, or rejection-sampled from a density image.

Both draw from ``numpy.random.Generator(PCG64(seed))`` so a seed fixes the sites.
A site is a pixel of the region chosen at random plus a uniform offset inside that
pixel, so sites never fall outside the region's pixels.
"""

from __future__ import annotations

import numpy as np

from .problem import Problem


def _pixels_to_points(flat: np.ndarray, width: int, rng: np.random.Generator) -> np.ndarray:
    i, j = np.divmod(flat, width)
    jitter = rng.random((len(flat), 2))
    return np.stack([j + jitter[:, 0], i + jitter[:, 1]], axis=1)


def initial_sites(problem: Problem) -> np.ndarray:
    """(N, 2) float64 sites in pixel units."""
    if problem.init_sites is not None:
        return problem.init_sites.copy()
    grid, n = problem.grid, problem.n_elements
    rng = np.random.default_rng(problem.seed)
    # the region's pixel indices; without a mask, the raster's are 0 .. W·H - 1 and are
    # not made (choosing among a count draws the same as among that many indices)
    inside = None if grid.mask is None else np.flatnonzero(grid.mask.ravel())
    count = grid.width * grid.height if inside is None else len(inside)
    if problem.density is None:
        picks = rng.choice(count if inside is None else inside, size=n, replace=False)
        return _pixels_to_points(picks, grid.width, rng)
    accept = problem.density.acceptance().ravel()
    if inside is not None:
        accept = accept[inside]
    if not (accept > 0).any():
        from .errors import InputError

        raise InputError("density is zero everywhere inside the region")
    chosen = np.empty(0, dtype=np.int64)
    # Rejection sampling by batches: propose pixels uniformly in the region, accept with
    # probability density/max; distinct pixels so two sites never coincide.
    while len(chosen) < n:
        batch = rng.choice(count, size=max(4 * n, 1024))
        keep = batch[rng.random(len(batch)) < accept[batch]]
        chosen = np.concatenate([chosen, keep])
        _, first = np.unique(chosen, return_index=True)
        chosen = chosen[np.sort(first)]
        if len(chosen) >= n or (accept > 0).sum() >= n:
            continue
        # fewer positive pixels than sites: fill with the remaining region pixels
        rest = np.setdiff1d(np.arange(count), chosen)
        chosen = np.concatenate([chosen, rng.permutation(rest)])
    picks = chosen[:n] if inside is None else inside[chosen[:n]]
    return _pixels_to_points(picks, grid.width, rng)


__all__ = ["initial_sites"]
