"""Initial sites: uniform in the region, or rejection-sampled from a density image.

Both draw from ``numpy.random.Generator(PCG64(seed))`` so a seed fixes the sites.
A site is a pixel of the region chosen at random plus a uniform offset inside that
pixel, so sites never fall outside the region's pixels.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .problem import Problem


def _pixels_to_points(flat: np.ndarray, width: int, rng: np.random.Generator) -> np.ndarray:
    i, j = np.divmod(flat, width)
    jitter = rng.random((len(flat), 2))
    return np.stack([j + jitter[:, 0], i + jitter[:, 1]], axis=1)


def region_pixels(mask: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """``pixels(ranks)``: the flat indices of the region pixels of the given ranks in
    raster order, ``np.flatnonzero(mask)[ranks]``; where the region is most of the
    raster, without that array of every region pixel.

    The pixel of rank r is r plus the pixels outside the region before it: the outside
    pixels whose count of region pixels before them is at most r.

    Parameters
    ----------
    mask : (H, W) bool ndarray
        The region.

    Returns
    -------
    callable
        ``pixels(ranks)`` for int ranks, each in 0 .. ``mask.sum()`` - 1; int64, the
        shape of ``ranks``.
    """
    flat = np.ravel(mask)
    if 2 * np.count_nonzero(flat) <= flat.size:  # a small region: its pixels are listed
        inside = np.flatnonzero(flat)
        return lambda ranks: inside[ranks]
    outside = np.flatnonzero(~flat)
    before = outside - np.arange(len(outside))  # region pixels before each outside one
    return lambda ranks: ranks + np.searchsorted(before, ranks, side="right")


def initial_sites(problem: Problem) -> np.ndarray:
    """(N, 2) float64 sites in pixel units."""
    if problem.init_sites is not None:
        return problem.init_sites.copy()
    grid, n = problem.grid, problem.n_elements
    rng = np.random.default_rng(problem.seed)
    # sites are drawn as ranks among the region's pixels (without a mask, the raster's
    # 0 .. W·H - 1), each then turned into its pixel: choosing among a count draws the
    # same as among that many indices
    mask = grid.mask
    count = grid.width * grid.height if mask is None else int(np.count_nonzero(mask))
    pixels = _unchanged if mask is None else region_pixels(mask)
    if problem.density is None:
        return _pixels_to_points(pixels(rng.choice(count, size=n, replace=False)), grid.width, rng)
    density = problem.density
    if density.everywhere_accepted():
        # read at the proposed pixels only: no array of every region pixel is made
        positive = count

        def accept_at(ranks: np.ndarray) -> np.ndarray:
            return density.acceptance_at(pixels(ranks))

    else:
        accept = density.acceptance().ravel()
        if mask is not None:
            accept = accept[np.flatnonzero(mask)]
        positive = int(np.count_nonzero(accept > 0))
        if positive == 0:
            from .errors import InputError

            raise InputError("density is zero everywhere inside the region")

        def accept_at(ranks: np.ndarray) -> np.ndarray:
            return accept[ranks]

    chosen = np.empty(0, dtype=np.int64)
    # Rejection sampling by batches: propose pixels uniformly in the region, accept with
    # probability density/max; distinct pixels so two sites never coincide.
    while len(chosen) < n:
        batch = rng.choice(count, size=max(4 * n, 1024))
        keep = batch[rng.random(len(batch)) < accept_at(batch)]
        chosen = np.concatenate([chosen, keep])
        _, first = np.unique(chosen, return_index=True)
        chosen = chosen[np.sort(first)]
        if len(chosen) >= n or positive >= n:
            continue
        # fewer positive pixels than sites: fill with the remaining region pixels
        rest = np.setdiff1d(np.arange(count), chosen)
        chosen = np.concatenate([chosen, rng.permutation(rest)])
    return _pixels_to_points(pixels(chosen[:n]), grid.width, rng)


def _unchanged(ranks: np.ndarray) -> np.ndarray:
    return ranks


__all__ = ["initial_sites", "region_pixels"]
