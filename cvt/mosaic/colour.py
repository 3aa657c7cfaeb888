"""sRGB <-> CIELAB, the one conversion of the suite (mosaic fills, colour error, edges).

The standard formulas: sRGB (IEC 61966-2-1) decoded to linear light, to CIE XYZ with the
sRGB primaries, to CIELAB (CIE 15) relative to the sRGB white point (D65), so white is
exactly L* = 100, a* = b* = 0 and black L* = 0.  Distances between Lab colours are
ΔE*ab (CIE76, Euclidean): about 2.3 is a just noticeable difference, pure black to pure
white is 100.

Why Lab: a mosaic tile's fill stands for the pixels under it, and a distance in Lab is a
*perceived* difference, so the mean in Lab is the colour with the least mean squared
perceived difference to them; in sRGB (gamma-encoded, proportional neither to light nor
to lightness) the mean of a dark and a light pixel comes out too dark.
"""

from __future__ import annotations

import numpy as np

# linear sRGB -> XYZ (sRGB primaries, D65)
_RGB_TO_XYZ = np.array(
    [[0.4124564, 0.3575761, 0.1804375], [0.2126729, 0.7151522, 0.0721750], [0.0193339, 0.1191920, 0.9503041]]
)
_XYZ_TO_RGB = np.linalg.inv(_RGB_TO_XYZ)
_WHITE = _RGB_TO_XYZ.sum(axis=1)  # XYZ of sRGB white: the reference white
_D = 6.0 / 29.0


# pixels converted at once by srgb_to_lab: its temporaries stay in the processor's cache
# (a picture-sized temporary would be written to memory and read back at every step)
LAB_BAND = 1 << 15


def srgb_to_lab(rgb, planes: bool = False) -> np.ndarray:
    """(..., 3) sRGB in 0..1 -> (..., 3) CIELAB (L* 0..100), each pixel's the same whatever
    else is converted with it (a block of a picture gives the picture's values).

    Parameters
    ----------
    rgb : (..., 3) array_like
        sRGB values, 0..1.
    planes : bool
        Hold each of L*, a*, b* in a plane of its own: the result is the same (..., 3)
        array of the same numbers, a view of a (3, ...) array, so that ``lab[..., k]`` is
        contiguous (a filter that reads one channel at a time then needs no copy of it).

    Returns
    -------
    (..., 3) float64 array
    """
    rgb = np.asarray(rgb)
    if not np.issubdtype(rgb.dtype, np.floating):
        rgb = rgb.astype(np.float64)
    flat = rgb.reshape(-1, 3)
    lab = np.empty((3, len(flat))).T if planes else np.empty(flat.shape)
    for lo in range(0, len(flat), LAB_BAND):
        # float32 pictures are widened a band at a time (exact), never whole
        _lab_band(flat[lo : lo + LAB_BAND].astype(np.float64, copy=False), lab[lo : lo + LAB_BAND])
    if planes:
        return lab.T.reshape((3, *rgb.shape[:-1])).transpose((*range(1, rgb.ndim), 0))
    return lab.reshape(rgb.shape)


def _lab_band(rgb: np.ndarray, lab: np.ndarray) -> None:
    """:func:`srgb_to_lab` of (n, 3) ``rgb`` into ``lab`` (n, 3), any strides."""
    if len(rgb) == 1:  # one row would take BLAS's vector product, a bit off the matrix one
        two = np.empty((2, 3))
        _lab_band(np.repeat(rgb, 2, axis=0), two)
        lab[:] = two[:1]
        return
    lin = rgb + 0.055
    lin /= 1.055
    np.power(lin, 2.4, out=lin)
    np.divide(rgb, 12.92, out=lin, where=rgb <= 0.04045)
    xyz = lin @ _RGB_TO_XYZ.T
    # from here on a plane per channel: an (n, 3) array broadcast against 3 numbers or
    # written through a mask runs a loop of 3 per pixel (several times slower); the
    # same operations on the same numbers, so the same result to the last bit
    planes = np.empty((3, len(rgb)))
    f = np.empty_like(planes)
    for c in range(3):
        x = planes[c]
        np.divide(xyz[:, c], _WHITE[c], out=x)
        np.cbrt(x, out=f[c])
    small = planes <= _D**3
    np.divide(planes, 3 * _D * _D, out=f, where=small)
    np.add(f, 4.0 / 29.0, out=f, where=small)
    np.multiply(f[1], 116.0, out=lab[:, 0])
    lab[:, 0] -= 16.0
    np.subtract(f[0], f[1], out=planes[0])
    np.multiply(planes[0], 500.0, out=lab[:, 1])
    np.subtract(f[1], f[2], out=planes[1])
    np.multiply(planes[1], 200.0, out=lab[:, 2])


def lab_to_srgb(lab) -> np.ndarray:
    """(..., 3) CIELAB -> (..., 3) sRGB in 0..1 (colours outside the sRGB gamut are
    clipped per channel)."""
    lab = np.asarray(lab, dtype=np.float64)
    if lab.shape[:-1] == (1,):  # as in _lab_band: every row as the matrix product gives it
        return lab_to_srgb(np.repeat(lab, 2, axis=0))[:1]
    fy = (lab[..., 0] + 16.0) / 116.0
    f = np.stack([fy + lab[..., 1] / 500.0, fy, fy - lab[..., 2] / 200.0], axis=-1)
    xyz = np.where(f > _D, f**3, 3 * _D * _D * (f - 4.0 / 29.0)) * _WHITE
    lin = np.clip(xyz @ _XYZ_TO_RGB.T, 0.0, 1.0)
    return np.clip(np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055), 0.0, 1.0)


def quantised(rgb) -> np.ndarray:
    """sRGB in 0..1 rounded to the 8 bits a '#rrggbb' fill keeps (what SVG and PNG show)."""
    return np.round(np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0) * 255.0) / 255.0


__all__ = ["LAB_BAND", "srgb_to_lab", "lab_to_srgb", "quantised"]
