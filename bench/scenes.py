"""The standard problems of Table 3 (the paper's Figures 14-15 made standard): a density
of known contrast, a direction field, a region that is not convex, and all three at once.

A scene is a name; :func:`scene_problem` builds its :class:`~compact_distributions.cvt.problem.Problem`
on a square raster of ``size`` px with about the spacing of ``n`` sites on the whole
raster (a region holds its share of them), so every scene's elements have the same
mean size.
"""

from __future__ import annotations

import math

import numpy as np

DENSITY_CONTRAST = 3.0  # densest / sparsest: element areas 3:1, sides sqrt(3):1

# scene -> (density, field, region): what each scene sets
SCENES = {
    "density": ("radial", None, None),
    "field": (None, "circular", None),
    "region": (None, None, "star"),
    "combined": ("radial", "circular", "ring"),
}
SCENE_TEXT = {
    "density": f"whole square, radial density gradient of contrast {DENSITY_CONTRAST:g} (dense centre), no field",
    "field": "whole square, uniform density, circular field (tangent to circles about the centre)",
    "region": "five-pointed star (non-convex), uniform density, no field",
    "combined": f"ring, radial density of contrast {DENSITY_CONTRAST:g}, circular field",
}


def radial_gradient(size: int, contrast: float = DENSITY_CONTRAST):
    """Density falling linearly with the distance from the centre, from ``contrast`` at
    the centre to 1 at the corners (a :class:`cvt.fields.DensityMap`)."""
    from compact_distributions.cvt.fields import DensityMap

    yy, xx = np.mgrid[0:size, 0:size] + 0.5
    r = np.hypot(xx - size / 2, yy - size / 2) / (size / 2 * math.sqrt(2))
    return DensityMap(contrast - (contrast - 1.0) * r)


def scene_problem(scene: str, size: int, n: int, metric, seed: int):
    """The Problem of ``scene`` on a ``size`` x ``size`` raster (see the module docstring)."""
    from compact_distributions.cvt.fields import DirectionField
    from compact_distributions.cvt.problem import Grid, Problem
    from compact_distributions.cvt.validate import one_of

    from .commands.figures import ring_mask, star_mask

    density, field, region = SCENES[one_of(scene, "scene", list(SCENES))]
    mask = {"star": star_mask, "ring": ring_mask, None: lambda _: None}[region](size)
    grid = Grid(size, size, mask)
    n_region = n if mask is None else max(1, round(n * grid.pixel_count / size**2))
    return Problem(
        grid,
        n_region,
        metric,
        density=radial_gradient(size) if density else None,
        field=DirectionField.named(field, size, size) if field else None,
        seed=seed,
    )


__all__ = ["DENSITY_CONTRAST", "SCENES", "SCENE_TEXT", "radial_gradient", "scene_problem"]
