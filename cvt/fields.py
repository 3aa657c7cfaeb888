"""Size from a density image (paper §3.3.1) and direction from a field (§3.3.2).

Both are sampled at a site's current position (the pixel that contains it) and re-read
at every Lloyd iteration.

Density: a non-negative (H, W) array, larger = denser = smaller cells.  The size factor
of a site is ``s = sqrt(mean_density / max(density(p), floor))``, with ``floor`` 1 % of
the largest density so that empty areas do not get unbounded cells; a cell's area then
scales like 1/density.  ``s`` multiplies the cone's footprint (a smaller slope α in the
paper's words), so ``d_i(x) = gauge(...) / s_i``.

Direction: an angle in radians per position, in the raster frame (x right, y down; a
positive angle turns clockwise on screen).  Named analytic fields:
``constant:DEG``, ``radial`` (pointing away from the raster centre),
``circular`` (tangent to circles around the centre), ``wave:PERIOD`` (angle oscillating
±30° with x, period in pixels).  An image field maps grey levels linearly from 0 (0°)
to 255 (180°); a 16-bit image maps 0..65535 the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .pixels import pixel_index
from .validate import real_number

DENSITY_FLOOR = 0.01


def sample_at(img: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The value of the pixel that contains each point."""
    h, w = img.shape
    return img[pixel_index(points, w, h)]


@dataclass
class DensityMap:
    values: np.ndarray  # (H, W) float64, >= 0, not all zero

    def __post_init__(self):
        v = np.asarray(self.values, dtype=np.float64)
        if v.ndim != 2:
            raise InputError(f"density must be a 2-D image, got shape {v.shape}")
        if v.size == 0:
            raise InputError(f"density image is empty (shape {v.shape})")
        # min and max carry a NaN through: both finite means every value is
        lo, hi = float(v.min()), float(v.max())
        if not (math.isfinite(lo) and math.isfinite(hi)) or lo < 0:
            raise InputError("density must be finite and non-negative everywhere")
        if hi <= 0:
            raise InputError("density image is all zero: nothing to distribute sites by")
        v = v / hi  # only ratios matter; huge values must not overflow the mean
        self.values = v
        floor = DENSITY_FLOOR  # times the largest value, hi / hi = 1 exactly
        # the values themselves where none is below the floor (a picture's density): the
        # same numbers, without a second picture-sized array
        self._clipped = v if lo / hi >= floor else np.maximum(v, floor)
        self._mean = float(self._clipped.mean())

    @property
    def shape(self):
        return self.values.shape

    def scales_at(self, sites: np.ndarray) -> np.ndarray:
        return np.sqrt(self._mean / sample_at(self._clipped, sites))

    def scale_image(self) -> np.ndarray:
        """(H, W) float32: the size factor at every pixel (what ``scales_at`` reads there)."""
        return np.sqrt(np.float32(self._mean) / self._clipped.astype(np.float32))

    def acceptance(self) -> np.ndarray:
        """Per-pixel acceptance probability for rejection sampling (density / max)."""
        return self.values / self.values.max()

    def acceptance_at(self, pixels: np.ndarray) -> np.ndarray:
        """``acceptance().ravel()[pixels]`` (``pixels``: flat indices), the same numbers,
        without the picture-sized array."""
        return self.values.ravel()[pixels] / self.values.max()

    def everywhere_accepted(self) -> bool:
        """Whether every pixel's acceptance is above 0 (the least value's is: the
        division keeps the order)."""
        return bool(self.values.min() / self.values.max() > 0)


class DirectionField:
    """Angle (radians) as a function of position; ``shape`` is None for analytic fields."""

    def __init__(self, spec: str, angles: np.ndarray | None = None, width=None, height=None, arg=None):
        self.spec = spec
        self._angles = angles
        self.width, self.height = width, height
        self._named = arg if arg is not None or angles is not None else parse_field_spec(spec)

    @property
    def shape(self):
        return None if self._angles is None else self._angles.shape

    @classmethod
    def from_angles(cls, angles: np.ndarray, spec: str = "array") -> DirectionField:
        a = np.asarray(angles, dtype=np.float64)
        if a.ndim != 2 or not np.isfinite(a).all() or (a.size and np.abs(a).max() > 1e6):
            raise InputError("direction field must be a 2-D array of finite angles (radians, |angle| <= 1e6)")
        return cls(spec, a, a.shape[1], a.shape[0])

    @classmethod
    def named(cls, spec: str, width: int, height: int, name: str = "field") -> DirectionField:
        kind, arg = parse_field_spec(spec, name)
        if kind is None:
            raise InputError(f"unknown {name} {spec!r}; use {FIELD_HELP}")
        return cls(spec, None, width, height, arg=(kind, arg))

    def angles_at(self, sites: np.ndarray) -> np.ndarray:
        sites = np.asarray(sites, dtype=np.float64)
        if self._angles is not None:
            return sample_at(self._angles, sites)
        name, arg = self._named
        cx, cy = self.width / 2.0, self.height / 2.0
        if name == "constant":
            return np.full(len(sites), math.radians(arg))
        if name == "radial":
            return np.arctan2(sites[:, 1] - cy, sites[:, 0] - cx)
        if name == "circular":
            return np.arctan2(sites[:, 1] - cy, sites[:, 0] - cx) + math.pi / 2
        return math.radians(30.0) * np.sin(2 * math.pi * sites[:, 0] / arg)


# the named fields: name -> (argument, its documented range, its default); radial and
# circular take none
NAMED_FIELDS = {
    "constant": ("an angle in degrees", (-360.0, 360.0), None),
    "radial": (None, None, None),
    "circular": (None, None, None),
    "wave": ("a period in pixels", (1.0, 1e6), 200.0),
}
FIELD_HELP = (
    "constant:DEG, radial, circular, wave:PERIOD or an image file (a file named like a field "
    "is given as a path with a slash, e.g. ./radial)"
)


def parse_field_spec(spec, name: str = "field") -> tuple[str | None, float | None]:
    """(kind, argument) of a named field such as ``constant:30``; (None, None) when
    ``spec`` names no field (then it is an image file).  A named field wins over a file
    of the same name: a file named like a field is given with a slash (``./radial``)."""
    text = str(spec)
    kind, colon, arg = text.partition(":")
    if kind not in NAMED_FIELDS:
        return None, None
    what, (low, high) = NAMED_FIELDS[kind][0], NAMED_FIELDS[kind][1] or (None, None)
    default = NAMED_FIELDS[kind][2]
    if what is None:
        if colon:
            raise InputError(f"{name} {text!r}: {kind} takes no argument; use {kind}")
        return kind, None
    if not arg and default is not None:
        return kind, default
    example = f"{kind}:30" if kind == "constant" else f"{kind}:200"
    try:
        value = real_number(arg, name, minimum=low, maximum=high)
    except InputError:
        raise InputError(
            f"{name} {text!r}: {kind} needs {what} between {low:g} and {high:g}, e.g. {example}"
        ) from None
    return kind, value


def angles_from_grey(grey: np.ndarray, full_scale: float, name: str = "field image") -> np.ndarray:
    """Grey levels 0..full_scale -> angles 0..π (a line direction, modulo 180°); a float
    image (full scale 1) must hold finite values in 0..1."""
    grey = np.asarray(grey, dtype=np.float64)
    if not np.isfinite(grey).all():
        raise InputError(f"{name} holds NaN or infinite values")
    low, high = float(grey.min()), float(grey.max())
    if low < 0 or high > full_scale:
        raise InputError(
            f"{name}: values must lie in 0..{full_scale:g} (0..180 degrees), found {low:g}..{high:g}"
        )
    return grey / full_scale * math.pi


__all__ = [
    "DENSITY_FLOOR",
    "sample_at",
    "DensityMap",
    "DirectionField",
    "NAMED_FIELDS",
    "FIELD_HELP",
    "parse_field_spec",
    "angles_from_grey",
]
