"""Mosaics at poster scale: the memory-lean paths give the whole-array results bit for bit."""

import numpy as np
import pytest
import shapely

from compact_distributions.cvt.evaluate import colour_error, pixels_under
from compact_distributions.cvt.mosaic import image_fields as F
from compact_distributions.cvt.mosaic.colour import lab_to_srgb, srgb_to_lab
from compact_distributions.cvt.mosaic.pipeline import mosaic_fills, resample, tile_colours, tile_runs


@pytest.mark.parametrize("height", [1, 3, 13, 30, 300])
def test_tensor_by_rows_is_the_whole_tensor(height):
    rng = np.random.default_rng(height)
    picture = rng.random((height, 37, 3))
    want = F.structure_tensor(picture)
    got = [np.full((height, 37), np.nan) for _ in range(3)]

    def use(lo, hi, jxx, jxy, jyy):
        for out, part in zip(got, (jxx, jxy, jyy), strict=True):
            out[lo:hi] = part

    F.tensor_by_rows(lambda a, b: picture[a:b], height, use, rows=7)
    for w, g in zip(want, got, strict=True):
        assert np.array_equal(w, g)


def test_edge_orientation_in_place_gives_the_same():
    rng = np.random.default_rng(1)
    j = [rng.normal(size=(20, 30)) for _ in range(3)]
    want = F.edge_orientation(*j)
    got = F.edge_orientation(*[a.copy() for a in j], overwrite=True)
    assert all(np.array_equal(w, g) for w, g in zip(want, got, strict=True))


def test_strong_edges_from_srgb_by_rows():
    rng = np.random.default_rng(2)
    picture = resample(rng.random((40, 50, 3)), 300, 240)  # float32, as a mosaic reads it
    assert picture.dtype == np.float32
    want = F.strong_edges(srgb_to_lab(picture.astype(np.float64)), 11.0, min_length=5.0)
    got = F.strong_edges(picture, 11.0, min_length=5.0, srgb=True)
    assert want.any() and np.array_equal(want, got)


def test_picture_fields_without_details_are_the_same_fields():
    rng = np.random.default_rng(4)
    picture = resample(rng.random((30, 40, 3)), 260, 200)
    full = F.picture_fields(picture, 8.0, "square")
    lean = F.picture_fields(picture, 8.0, "square", details=False)
    assert np.array_equal(full.density.values, lean.density.values)
    assert np.array_equal(
        full.field.angles_at(np.argwhere(np.ones((200, 260)))[:, ::-1] + 0.5),
        lean.field.angles_at(np.argwhere(np.ones((200, 260)))[:, ::-1] + 0.5),
    )
    assert lean.strength is None and lean.detail is None and full.strength is not None


def _same_fields(a, b, height, width) -> bool:
    pixels = np.argwhere(np.ones((height, width)))[:, ::-1] + 0.5
    return (
        np.array_equal(a.density.values, b.density.values)
        and np.array_equal(a.field.angles_at(pixels), b.field.angles_at(pixels))
        and np.array_equal(a.edges, b.edges)
    )


@pytest.mark.parametrize("step", [1, 3])
def test_picture_fields_later_reads_no_more_of_the_picture(step):
    rng = np.random.default_rng(7)
    picture = resample(rng.random((30, 40, 3)), 260, 200)
    want = F.picture_fields(picture.copy(), 8.0, "square", details=False, step=step)
    finish = F.picture_fields_later(picture, 8.0, "square", details=False, step=step)
    picture[:] = rng.random(picture.shape)  # the rest must not read it again
    got = finish()
    assert want.density.values.std() > 0 and want.edges.any()
    assert _same_fields(want, got, 200, 260)


def test_picture_analysis_of_a_poster_is_that_of_the_fields_and_edges_apart(monkeypatch):
    from compact_distributions.cvt.mosaic import pipeline

    rng = np.random.default_rng(8)
    picture = resample(rng.random((30, 40, 3)), 400, 300)
    spacing = 4.0  # a coarse grid of 1-pixel blocks is no grid: field_step gives 1 here
    monkeypatch.setattr(F, "field_step", lambda h, w, s: 2)
    want_fields = F.picture_fields(picture, spacing, "square", details=False)
    want_edges = F.strong_edges(picture, 11.0, min_length=pipeline.EDGE_MIN_LENGTH * spacing, srgb=True)
    # as a picture above SIDE_BY_SIDE_PIXELS: the fields finished beside the edges' pass
    monkeypatch.setattr(pipeline, "SIDE_BY_SIDE_PIXELS", 0)
    fields, edges, seconds = pipeline._picture_analysis(picture, spacing, "square", 3.0, 11.0)
    assert want_edges.any() and np.array_equal(edges, want_edges)
    assert isinstance(fields.field, F.CoarseField) and _same_fields(want_fields, fields, 300, 400)
    assert seconds > 0


def test_lab_of_one_pixel_is_its_lab_in_the_picture():
    rng = np.random.default_rng(5)
    flat = rng.random((5000, 3))
    lab = srgb_to_lab(flat)
    for k in (0, 17, 4999):
        assert np.array_equal(srgb_to_lab(flat[k : k + 1]), lab[k : k + 1])
        assert np.array_equal(lab_to_srgb(lab[k : k + 1]), lab_to_srgb(lab)[k : k + 1])


def test_mosaic_fills_are_tile_colours_and_colour_error():
    rng = np.random.default_rng(6)
    picture = resample(rng.random((20, 30, 3)), 120, 90)
    centres = rng.uniform([5, 5], [115, 85], size=(60, 2))
    polygons = list(shapely.buffer(shapely.points(centres), rng.uniform(0.2, 6.0, 60), quad_segs=2))
    polygons[3] = None
    polygons[7] = shapely.box(10.1, 10.1, 10.3, 10.3)  # holds no pixel centre
    lab = srgb_to_lab(picture)
    tiles, pixels = pixels_under(polygons, 120, 90)
    want_rgb, want_lab = tile_colours(lab, polygons, centres, tiles, pixels)
    want_error = colour_error(lab, want_lab, tiles, pixels)
    bounds = tile_runs(polygons, pairs=500)  # several runs
    assert len(bounds) > 3
    rgb, fills_lab, error = mosaic_fills(picture, polygons, centres, bounds)
    assert np.array_equal(rgb, want_rgb) and np.array_equal(fills_lab, want_lab)
    assert error == pytest.approx(want_error, rel=1e-12)


@pytest.mark.parametrize("sigma", [0.8, 9.0])  # the direct filter and the FFT
def test_gaussian_smooth_into_its_own_image(sigma):
    """Written over its input, the smoothing is the scipy filter's, and the input's
    buffer holds it (no second picture-sized array)."""
    from scipy import ndimage

    rng = np.random.default_rng(5)
    image = rng.random((70, 90))
    want = ndimage.gaussian_filter(image, sigma, mode="nearest")
    copy = image.copy()
    got = F.gaussian_smooth(copy, sigma, out=copy)
    assert got is copy
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert np.array_equal(got, F.gaussian_smooth(image, sigma))


def test_smooth_angles_over_its_input_gives_the_same():
    rng = np.random.default_rng(6)
    angles = rng.uniform(-np.pi, np.pi, (60, 80))
    want = F.smooth_angles(angles, 9.0, np.pi / 2)
    kept = angles.copy()
    got = F.smooth_angles(angles.copy(), 9.0, np.pi / 2, overwrite=True)
    assert np.array_equal(got, want) and np.array_equal(angles, kept)
    # by hand: the mean direction of a constant field is that field (modulo the period)
    flat = np.full((30, 40), 0.3)
    np.testing.assert_allclose(F.smooth_angles(flat, 5.0, np.pi / 2, overwrite=True), 0.3, atol=1e-12)


def test_elements_as_rows_are_the_picture(tmp_path, monkeypatch):
    """Drawn as a row source read in the PNG writer's bands, the elements give the same
    pixels as the picture drawn whole, and the rows come in order only."""
    from PIL import Image

    from compact_distributions.bench import outputs
    from compact_distributions.bench.outputs import write_png
    from compact_distributions.cvt.mosaic import render as R

    monkeypatch.setattr(R, "BAND_BYTES", 3 * 1350 * 24)  # bands of 24 supersampled rows
    monkeypatch.setattr(outputs, "PNG_BAND", 3 * 450 * 10)  # the writer reads 10 rows at a time

    rng = np.random.default_rng(8)
    centres = rng.uniform(0, 300, (400, 2))
    elements = list(shapely.buffer(shapely.points(centres), rng.uniform(2, 9, 400), quad_segs=3))
    # a window of the whole raster is drawn at once, not in bands
    want = np.asarray(R.draw_elements(elements, 300, 260, scale=1.5, window=(0, 0, 300, 260)))
    assert np.array_equal(np.asarray(R.draw_elements(elements, 300, 260, scale=1.5)), want)
    stream = R.draw_elements(elements, 300, 260, scale=1.5, as_rows=True)
    assert isinstance(stream, R.RowStream) and stream.size == (450, 390)
    write_png(tmp_path / "rows.png", stream)
    assert np.array_equal(np.asarray(Image.open(tmp_path / "rows.png")), want)
    again = R.draw_elements(elements, 300, 260, scale=1.5, as_rows=True)
    assert np.array_equal(again.rows(0, 7), want[:7]) and np.array_equal(again.rows(7, 390), want[7:])
    with pytest.raises(ValueError, match="already passed"):
        again.rows(3, 9)
