"""The picture's fields on a coarse grid (mosaics above EXACT_TILES tiles): the pieces
against their definitions, and the fields against those made on every pixel; the strong
edges' hysteresis and length against a scene whose edges are known."""

import math

import numpy as np
import pytest

from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.mosaic import cutting
from compact_distributions.cvt.mosaic import image_fields as F
from compact_distributions.cvt.mosaic.pipeline import resample


@pytest.mark.parametrize("shape,step", [((12, 9), 3), ((13, 10), 3), ((5, 7), 4), ((1, 1), 2), ((6, 6), 1)])
def test_block_sums_are_the_blocks_sums(shape, step):
    a = np.random.default_rng(0).random(shape)
    got = F._block_sums(a, step)
    want = np.array(
        [
            [a[i : i + step, j : j + step].sum() for j in range(0, shape[1], step)]
            for i in range(0, shape[0], step)
        ]
    )
    np.testing.assert_allclose(got, want, rtol=1e-13)


@pytest.mark.parametrize("height,width,step", [(30, 41, 3), (17, 16, 4), (9, 20, 2)])
def test_upsample_of_block_means_gives_back_a_linear_ramp(height, width, step):
    """Bilinear interpolation is exact on a plane: the block means of a ramp sit on it at
    the blocks' centres, so the ramp comes back between the outermost centres (and the
    nearest centre's value outside them)."""
    i, j = np.mgrid[0:height, 0:width].astype(np.float64)
    ramp = 0.3 * i - 0.7 * j + 2.0
    counts = F._block_sums(np.ones((height, width)), step)
    coarse = F._block_sums(ramp, step) / counts
    got = F.upsample(coarse, step, height, width)
    yc, xc = F._block_centres(height, step), F._block_centres(width, step)
    want = 0.3 * np.clip(i, yc[0], yc[-1]) - 0.7 * np.clip(j, xc[0], xc[-1]) + 2.0
    assert got.shape == (height, width)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_upsample_of_step_one_is_the_array():
    a = np.random.default_rng(1).random((7, 5))
    assert np.array_equal(F.upsample(a, 1, 7, 5), a)


def test_field_step_is_one_up_to_exact_tiles():
    # 2000 tiles on a 1024 px picture, and exactly EXACT_TILES: every pixel
    assert F.field_step(683, 1024, math.sqrt(683 * 1024 / 2000)) == 1
    assert F.field_step(1000, 1000, math.sqrt(1e6 / cutting.EXACT_TILES)) == 1
    # the posters: 64 000 tiles at 4096 x 2731, 20 000 at 2560 x 2560
    assert F.field_step(2731, 4096, math.sqrt(2731 * 4096 / 64000)) == 3
    assert F.field_step(2560, 2560, math.sqrt(2560 * 2560 / 20000)) == 4
    assert F.field_step(100, 100, 1.0) == 1  # 10 000 tiles of one pixel


@pytest.mark.parametrize("deg", [30.0, -20.0])
@pytest.mark.parametrize("step", [2, 3, 4])
def test_coarse_field_runs_along_the_edges(deg, step):
    """The stripes' direction, as on every pixel (tests/test_mosaic.py), within 3°."""
    y, x = np.mgrid[0:160, 0:160] + 0.5
    t = math.radians(deg)
    picture = (np.sin(2 * math.pi * (-x * math.sin(t) + y * math.cos(t)) / 24.0) > 0).astype(np.float64)
    f = F.picture_fields(picture, 10.0, "rectangle", details=False, step=step)
    pts = np.array([[x, y] for x in (40.5, 80.5, 120.5) for y in (40.5, 80.5, 120.5)])
    err = (np.degrees(f.field.angles_at(pts)) - deg + 90.0) % 180.0 - 90.0
    assert np.abs(err).max() < 3.0
    assert f.edges.shape == (160, 160) and f.edges.any() and not f.edges.all()


@pytest.mark.parametrize("step", [2, 3, 4])
def test_coarse_fields_are_the_fields_on_every_pixel_within_tolerance(step):
    """A textured picture, 600 x 400, spacing 16: the density (0..1 after DensityMap's
    normalisation) within 0.03 everywhere and 0.001 on average of the one made on every
    pixel; the field's direction (squares: modulo 90°) within 2° at half the pixels and
    within 8° at nine in ten (where two edges' directions meet it may turn anywhere)."""
    picture = resample(np.random.default_rng(4).random((30, 40, 3)), 600, 400)
    full = F.picture_fields(picture, 16.0, "square", details=False, step=1)
    coarse = F.picture_fields(picture, 16.0, "square", details=False, step=step)
    d = np.abs(full.density.values - coarse.density.values)
    assert d.max() < 0.03 and d.mean() < 1e-3
    pts = np.argwhere(np.ones((400, 600)))[:, ::-1] + 0.5
    turn = np.degrees(full.field.angles_at(pts) - coarse.field.angles_at(pts))
    turn = np.abs((turn + 45.0) % 90.0 - 45.0)
    assert np.median(turn) < 2.0 and np.percentile(turn, 90) < 8.0


def test_picture_fields_picks_the_coarse_grid_above_exact_tiles(monkeypatch):
    picture = resample(np.random.default_rng(5).random((20, 30, 3)), 300, 200)
    lean = F.picture_fields(picture, 8.0, "square", details=False)  # 937 tiles: every pixel
    assert np.array_equal(
        lean.density.values, F.picture_fields(picture, 8.0, "square", step=1).density.values
    )
    monkeypatch.setattr(cutting, "EXACT_TILES", 500)
    auto = F.picture_fields(picture, 8.0, "square", details=False)
    two = F.picture_fields(picture, 8.0, "square", details=False, step=2)
    assert np.array_equal(auto.density.values, two.density.values)
    assert not np.array_equal(auto.density.values, lean.density.values)
    # asked for details, every pixel whatever the tiles
    assert F.picture_fields(picture, 8.0, "square").strength is not None


def test_flat_picture_on_a_coarse_grid():
    f = F.picture_fields(np.full((40, 50, 3), 0.4), spacing=8.0, details=False, step=3)
    assert np.ptp(f.density.values) == 0 and f.density.shape == (40, 50)
    assert np.all(f.field.angles_at(np.array([[10.0, 10.0], [45.0, 30.0]])) == 0)


@pytest.mark.parametrize("step", [0, -1, 2.5, True, "2"])
def test_bad_step_is_refused(step):
    with pytest.raises(InputError, match="step"):
        F.picture_fields(np.zeros((10, 10)), 4.0, details=False, step=step)


def test_details_need_every_pixel():
    with pytest.raises(InputError, match="details"):
        F.picture_fields(np.zeros((10, 10)), 4.0, details=True, step=2)


def _edge_scene():
    """CIELAB (L* only): a step of ΔE 20 (strong) that goes on as one of ΔE 8 (weak),
    a separate weak step, and a small strong square (a short closed edge)."""
    lab = np.zeros((80, 160, 3))
    lab[..., 0] = 50.0
    lab[20:, :40, 0] = 70.0  # strong: ΔE 20 along row 20 for x < 40
    lab[20:, 40:80, 0] = 58.0  # weak: ΔE 8, continuing the same line
    lab[40:, 100:150, 0] = 58.0  # weak, alone
    lab[5:11, 120:126, 0] = 70.0  # strong, about 24 pixels round
    return lab


def test_strong_edges_hysteresis_and_length():
    """An edge is seeded where its contrast reaches the threshold, goes on while it stays
    above half of it, and is kept when it is at least min_length pixels long."""
    lab = _edge_scene()
    edges = F.strong_edges(lab, 11.0, min_length=10.0)
    assert edges[18:23, 5:35].any(axis=0).all()  # the strong step, every column
    assert edges[18:23, 45:75].any(axis=0).all()  # its weak part: carried by hysteresis
    assert not edges[30:, 95:155].any()  # the weak step alone: no seed
    assert edges[3:13, 118:128].sum() >= 16  # the small square
    assert F.strong_edges(lab, 7.0, min_length=10.0)[30:, 95:155].any()  # seeded at 7
    long_only = F.strong_edges(lab, 11.0, min_length=60.0)
    assert not long_only[:15, 110:135].any() and long_only[18:23, 5:75].any(axis=0).all()
