"""The picture stage's shortcuts against their definitions: a poster's direction field
read only where sites stand."""

import math

import numpy as np
import pytest

from compact_distributions.cvt.mosaic import image_fields as F


@pytest.mark.parametrize("step", [2, 3, 5])
def test_coarse_field_reads_the_upsampled_angle(step):
    rng = np.random.default_rng(step)
    h, w = 61, 47
    hc, wc = -(-h // step), -(-w // step)
    theta = rng.random((hc, wc)) * 2 * math.pi
    c, s = np.cos(theta) * rng.random((hc, wc)), np.sin(theta) * rng.random((hc, wc))
    m = 4.0
    field = F.CoarseField(c, s, step, m, h, w)
    assert field.shape == (h, w)
    want = np.arctan2(F.upsample(s, step, h, w), F.upsample(c, step, h, w)) / m
    np.testing.assert_array_equal(field.angles(), want)
    pts = rng.random((5000, 2)) * [w + 4, h + 4] - 2  # some outside: the border pixel's
    i = np.clip(np.floor(pts[:, 1]).astype(int), 0, h - 1)
    j = np.clip(np.floor(pts[:, 0]).astype(int), 0, w - 1)
    np.testing.assert_array_equal(field.angles_at(pts), want[i, j])


def test_fast_strength_is_the_largest_eigenvalue_root():
    rng = np.random.default_rng(4)
    jxx, jyy = rng.random((2, 50, 60)) ** 2
    jxy = (rng.random((50, 60)) - 0.5) * np.sqrt(jxx * jyy) * 2.0
    lam = np.linalg.eigvalsh(np.stack([np.stack([jxx, jxy], -1), np.stack([jxy, jyy], -1)], -2))[..., 1]
    angle, exact = F.edge_orientation(jxx, jxy, jyy)
    angle_fast, fast = F.edge_orientation(jxx.copy(), jxy.copy(), jyy.copy(), overwrite=True, exact=False)
    np.testing.assert_allclose(fast, np.sqrt(np.maximum(lam, 0.0)), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(fast, exact, rtol=4e-16, atol=0)
    np.testing.assert_array_equal(angle_fast, angle)
