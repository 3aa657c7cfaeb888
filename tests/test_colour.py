"""sRGB -> CIELAB against the standard's formulas written out per pixel, and known colours."""

import math

import numpy as np
import pytest

from compact_distributions.cvt.mosaic import colour

_M = [[0.4124564, 0.3575761, 0.1804375], [0.2126729, 0.7151522, 0.0721750], [0.0193339, 0.1191920, 0.9503041]]


def _lab_by_hand(r, g, b):
    """IEC 61966-2-1 decoding, the sRGB primaries, CIE 15's L*a*b* relative to D65 white."""
    lin = [v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4 for v in (r, g, b)]
    white = [sum(row) for row in _M]
    xyz = [sum(m * c for m, c in zip(row, lin, strict=True)) / w for row, w in zip(_M, white, strict=True)]
    d = 6.0 / 29.0
    f = [t ** (1.0 / 3.0) if t > d**3 else t / (3 * d * d) + 4.0 / 29.0 for t in xyz]
    return 116.0 * f[1] - 16.0, 500.0 * (f[0] - f[1]), 200.0 * (f[1] - f[2])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_srgb_to_lab_is_the_formula(dtype):
    rng = np.random.default_rng(3)
    rgb = rng.random((700, 3)).astype(dtype)
    rgb[:50] *= 0.05  # the linear segment and the cube root's linear part
    want = np.array([_lab_by_hand(*map(float, p)) for p in rgb])
    np.testing.assert_allclose(colour.srgb_to_lab(rgb), want, rtol=0, atol=1e-9)
    # a picture-shaped array, banded, gives each pixel's value
    picture = rgb.reshape(35, 20, 3)
    np.testing.assert_array_equal(colour.srgb_to_lab(picture).reshape(-1, 3), colour.srgb_to_lab(rgb))


def test_known_colours():
    lab = colour.srgb_to_lab(np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    np.testing.assert_allclose(lab[0], [100.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(lab[1], [0.0, 0.0, 0.0], atol=1e-12)
    # sRGB red: L* 53.24, a* 80.09, b* 67.20 (published tables)
    np.testing.assert_allclose(lab[2], [53.24, 80.09, 67.20], atol=0.01)
    assert math.isclose(float(colour.lab_to_srgb(lab)[2, 0]), 1.0, abs_tol=1e-9)


def test_planes_are_the_same_numbers_each_channel_contiguous():
    rgb = np.random.default_rng(5).random((37, 41, 3)).astype(np.float32)
    lab = colour.srgb_to_lab(rgb, planes=True)
    assert lab.shape == rgb.shape and all(lab[..., k].flags.c_contiguous for k in range(3))
    np.testing.assert_array_equal(lab, colour.srgb_to_lab(rgb))
    np.testing.assert_array_equal(colour.srgb_to_lab(rgb[0, 0], planes=True), colour.srgb_to_lab(rgb[0, 0]))
