"""Triangles that alternate: each triangle may point either way.

Translates of one triangle cannot tile the plane (they pack at most 2/3 of it), but a
triangle and its copy turned by 180° tile it exactly, which is how triangles are laid in
practice.  The paper names the triangles' gaps as its second limitation (§5).  Here each
cell gets the triangle at the site's angle θ or at θ + 180°, whichever fits larger in the
cell by the placement rule (:mod:`cvt.placement`, with the centre fit or at the site);
compaction (:mod:`cvt.compaction`) then closes the gaps between neighbours that point
opposite ways.  The direction field still reads in the elements: a line direction
(modulo 180°) is kept exactly; only which way a triangle points along it is free.

The choice needs cells that leave it open.  Cells of the triangle metric are shaped for
the triangle at the site's own angle, so the per-cell choice alone flips almost nothing
there (1.9 % of 4000 cells at 1024²; coverage after compaction 0.646 against 0.634).
:func:`alternating_turns` gives half of the sites, at random, a turn of 180° for the
whole Lloyd loop (through ``LloydSetup.of(problem, angles_at=...)``): the cells then take the shape of
up and down triangles, and the per-cell choice and compaction follow them (measured at
1024², N = 4000, seed 1: placement 0.618, after compaction 0.847).  Cells of a centrally
symmetric metric (l2) leave the choice open by themselves (about half flip; 0.824).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..shapes import shape_record
from ..validate import one_of
from .fit import FITS, fit_centres, placement_sizes


def alternate_triangles(
    labels, sites, angles, aspect=None, gap: float = 0.0, fit: str = "centre", search=None
):
    """Per cell, the triangle's angle (θ or θ + π), centre and size: the orientation
    whose element fits larger.  ``fit`` "centre" (:func:`cvt.placement.fit_centres`,
    whose ``search`` this passes on) or "site".  Returns ``(angles, centres, sizes)`` as
    (N,), (N, 2), (N,)."""
    one_of(fit, "fit", FITS)
    sites = np.asarray(sites, dtype=np.float64).reshape(-1, 2)
    n = len(sites)
    theta = np.zeros(n) if angles is None else np.broadcast_to(np.asarray(angles, np.float64), (n,))
    out = []
    for turn in (0.0, math.pi):
        a = theta + turn
        if fit == "centre":
            c, s = fit_centres(labels, sites, a, "triangle", aspect, gap, search=search)
        else:
            c, s = sites.copy(), placement_sizes(labels, sites, a, "triangle", aspect, gap)
        out.append((a, c, s))
    (a0, c0, s0), (a1, c1, s1) = out
    flip = s1 > s0
    return (np.where(flip, a1, a0), np.where(flip[:, None], c1, c0), np.where(flip, s1, s0))


def alternating_turns(n: int, seed: int = 0) -> np.ndarray:
    """(n,) turns for the Lloyd loop: 0 or π per site, half of each at random (a stream
    of its own, fixed by ``seed``)."""
    rng = np.random.default_rng([int(seed), 0xA17])
    return rng.permutation(np.arange(n) % 2) * math.pi


def check_alternate(shape: str, alternate: bool) -> None:
    """``alternate`` is for shapes that are not their own half turn, triangles (the
    record's ``alternates``; InputError otherwise)."""
    if alternate and not shape_record(shape).alternates:
        raise InputError(f"alternate orientation is for triangles only, not {shape!r}")


__all__ = ["alternate_triangles", "alternating_turns", "check_alternate"]
