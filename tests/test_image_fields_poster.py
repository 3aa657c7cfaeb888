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


def _strong_edges_on_every_pixel(lab, threshold):
    """strong_edges written out on whole arrays: the ridge across the edge at every pixel,
    hysteresis, the diagonal steps filled (min_length 0)."""
    from scipy import ndimage

    contrast, across = F.edge_contrast(lab)
    sector = np.round(across / (0.25 * math.pi)).astype(np.int64) % 4
    h, w = contrast.shape
    pad = np.pad(contrast, 1)
    ridge = np.zeros((h, w), dtype=bool)
    for k, (di, dj) in enumerate(((0, 1), (1, 1), (1, 0), (1, -1))):
        ahead = pad[1 + di : 1 + di + h, 1 + dj : 1 + dj + w]
        behind = pad[1 - di : 1 - di + h, 1 - dj : 1 - dj + w]
        ridge |= (sector == k) & (contrast > ahead) & (contrast >= behind)
    weak = ridge & (contrast >= F.EDGE_HYSTERESIS * threshold)
    parts, n = ndimage.label(weak, structure=np.ones((3, 3), dtype=bool))
    seeded = np.zeros(n + 1, dtype=bool)
    seeded[parts[weak & (contrast >= threshold)]] = True
    seeded[0] = False
    edges = seeded[parts]
    tl, tr, bl, br = (
        edges[:-1, :-1].copy(),
        edges[:-1, 1:].copy(),
        edges[1:, :-1].copy(),
        edges[1:, 1:].copy(),
    )
    down, up = tl & br & ~tr & ~bl, tr & bl & ~tl & ~br
    edges[:-1, 1:] |= down & (contrast[:-1, 1:] >= contrast[1:, :-1])
    edges[1:, :-1] |= down & (contrast[:-1, 1:] < contrast[1:, :-1])
    edges[:-1, :-1] |= up & (contrast[:-1, :-1] >= contrast[1:, 1:])
    edges[1:, 1:] |= up & (contrast[:-1, :-1] < contrast[1:, 1:])
    return edges


@pytest.mark.parametrize("seed", [0, 1, None])
def test_strong_edges_are_the_ridge_found_on_every_pixel(seed, monkeypatch):
    from scipy import ndimage

    from compact_distributions.cvt.mosaic.colour import srgb_to_lab

    monkeypatch.setattr(F, "SLAB_ROWS", 16)  # several bands, their candidates joined
    if seed is None:  # flat: a pixel-aligned step's two sides tie, a flat ridge
        rgb = np.full((96, 120, 3), 0.5)
    else:
        rgb = np.clip(ndimage.zoom(np.random.default_rng(seed).random((12, 15, 3)), (8, 8, 1), order=3), 0, 1)
    rgb[30:60, 20:70] = [0.9, 0.2, 0.1]  # a block with straight and corner edges
    lab = srgb_to_lab(rgb)
    want = _strong_edges_on_every_pixel(lab, 11.0)
    assert want.sum() > 100
    np.testing.assert_array_equal(F.strong_edges(lab, 11.0), want)
    np.testing.assert_array_equal(F.strong_edges(rgb, 11.0, srgb=True), want)


def test_resample_is_each_channel_resized_by_pillow_and_clipped():
    from PIL import Image

    from compact_distributions.cvt.mosaic.pipeline import resample

    rgb = np.random.default_rng(6).random((31, 47, 3))
    rgb[5:9, 5:9] = [1.0, 0.0, 1.0]  # Lanczos overshoots beside a hard step: clipped
    got = resample(rgb, 430, 601)  # rows not a whole number of strips
    for c in range(3):
        img = Image.fromarray(rgb[..., c].astype(np.float32), mode="F")
        want = np.clip(np.asarray(img.resize((430, 601), Image.Resampling.LANCZOS)), 0.0, 1.0)
        np.testing.assert_array_equal(got[..., c], want)
    assert got.dtype == np.float32 and got.min() == 0.0 and got.max() == 1.0
    assert resample(rgb, 47, 31) is rgb
