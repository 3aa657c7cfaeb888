"""The run's writers built whole-array (cvt/render.py, bench/outputs.py) against the same
files written element by element in the plainest way."""

import json

import numpy as np
import pytest
import shapely

from compact_distributions.bench import outputs
from compact_distributions.bench.outputs import dumps, write_png, write_sites_csv
from compact_distributions.cvt.mosaic import render
from compact_distributions.cvt.mosaic.render import (
    PAPER,
    cells_image,
    draw_elements,
    element_coordinates,
    hex_colour,
    hex_colours,
    label_colours,
    svg_lines,
)
from compact_distributions.cvt.shapes import element_polygons
from compact_distributions.cvt.threads import usable_cores

W, H = 120, 90


def mixed_elements(n=160, seed=3):
    """Overlapping squares partly off the raster, a None, an empty polygon, a multipolygon,
    a polygon with a hole and a 40-gon."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-6, [W + 6, H + 6], (n, 2))
    els = list(element_polygons("square", 1.0, centres, rng.uniform(0, 3, n), rng.uniform(1, 7, n)))
    els[3], els[7] = None, shapely.Polygon()
    els[11] = shapely.MultiPolygon([shapely.box(10, 10, 20, 20), shapely.box(30, 30, 45, 41)])
    els[12] = shapely.box(50, 50, 90, 80).difference(shapely.box(60, 60, 70, 70))
    els[13] = shapely.Point(3, 3).buffer(5, 10)
    return els, rng


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"scale": 2.0},
        {"scale": 1.7, "outline": "#000000"},
        {"region_colour": PAPER, "mask": True},
        {"region_colour": PAPER, "mask": True, "scale": 0.5, "supersample": 4},
    ],
)
def test_banded_drawing_is_the_picture_drawn_at_once(monkeypatch, options):
    els, rng = mixed_elements()
    options = dict(options)
    if options.pop("mask", False):
        mask = np.zeros((H, W), dtype=bool)
        mask[8:80, 5:110] = True
        mask[40:60, 50:60] = False
        options["region_mask"] = mask
    fills = rng.random((len(els), 3))
    monkeypatch.setattr(render, "BAND_BYTES", 1 << 40)  # one band: the whole picture
    whole = np.asarray(draw_elements(els, W, H, fills, **options))
    monkeypatch.setattr(render, "BAND_BYTES", 1)  # the thinnest bands
    thin = np.asarray(draw_elements(els, W, H, fills, **options))
    assert whole.shape[:2] == (round(H * options.get("scale", 1.0)), round(W * options.get("scale", 1.0)))
    assert len(np.unique(whole.reshape(-1, 3), axis=0)) > 50
    assert np.array_equal(whole, thin)


def test_svg_element_lines_are_the_plain_formatting():
    els, rng = mixed_elements()
    fills = rng.random((len(els), 3))
    ellipses = np.full((len(els), 5), np.nan)
    ellipses[20:30] = rng.uniform(1, 40, (10, 5))
    lines = [
        s
        for s in svg_lines(els, W, H, fills, ellipses=ellipses, digits=2)
        if s.startswith("<path id=") or s.startswith("<ellipse")
    ]
    expected = []
    for k, g in enumerate(els):
        if g is None or g.is_empty:
            continue
        fill = hex_colour(fills[k])
        if k in range(20, 30):
            cx, cy, rx, ry, deg = (f"{v:.2f}" for v in ellipses[k])
            expected.append(
                f'<ellipse id="e{k}" cx="{cx}" cy="{cy}" rx="{rx}" ry="{ry}" '
                f'transform="rotate({deg} {cx} {cy})" fill="{fill}"/>\n'
            )
            continue
        d = ""
        for poly in getattr(g, "geoms", [g]):
            for ring in [poly.exterior, *poly.interiors]:
                pts = [f"{x:g},{y:g}" for x, y in np.round(np.asarray(ring.coords)[:-1], 2)]
                d += f"M{pts[0]} L{' '.join(pts[1:])}Z"
        expected.append(f'<path id="e{k}" d="{d}" fill="{fill}"/>\n')
    assert len(expected) > 100 and lines == expected


def test_hex_colours_are_the_plain_formatting():
    """Every colour as '#rrggbb' at once, against the colour-by-colour formatting and
    hand-written values at the 8-bit rounding's ties (half to even, as both round)."""
    fills = np.random.default_rng(4).random((300, 3))
    fills[0] = (0.0, 1.0, 0.5)
    fills[1] = (0.5 / 255, 1.5 / 255, 2.5 / 255)
    got = hex_colours(fills)
    assert got == [hex_colour(c) for c in fills]
    assert got[:2] == ["#00ff80", "#000202"]
    assert hex_colours(np.zeros((0, 3))) == []
    assert hex_colours(np.full((2, 3), 255, dtype=np.uint8)) == ["#ffffff", "#ffffff"]


def test_result_json_lists_are_the_plain_json():
    els, rng = mixed_elements()
    sites = rng.uniform(0, 100, (len(els), 2))
    data = {
        "sites": sites,
        "angles": sites[:, 0],
        "ids": np.arange(len(els)),
        "elements": els,
        "with_nan": np.r_[np.nan, sites[1:, 1]],
    }
    parsed = json.loads(dumps(data))
    assert parsed["sites"] == sites.tolist() and parsed["angles"] == sites[:, 0].tolist()
    assert parsed["ids"] == list(range(len(els)))
    assert parsed["elements"] == element_coordinates(els)
    text = dumps(data)
    for key in ("sites", "elements"):
        line = next(s for s in text.splitlines() if s.startswith(f' "{key}"'))
        items = data[key].tolist() if key == "sites" else element_coordinates(els)
        assert line.rstrip(",") == f' "{key}": [' + ", ".join(json.dumps(v) for v in items) + "]"


def test_result_json_written_after_the_work_beside(tmp_path, monkeypatch):
    """write_result_json turns the values into text while the pictures are still being
    written, then writes what dumps writes, the wait counted as writing."""
    import threading
    import time

    els, rng = mixed_elements()
    result = {
        "sites": rng.uniform(0, 100, (len(els), 2)),
        "stage_seconds": {"lloyd": 1.5, "writing": 0.25},
        "elements": els,
        "gap": 1.0,
    }
    started, formatted = threading.Event(), []
    real = outputs._value_chunks

    def chunks(value):  # which values were formatted before the work beside ended
        formatted.append(started.is_set())
        return real(value)

    monkeypatch.setattr(outputs, "_value_chunks", chunks)
    with outputs.Beside() as beside:
        beside.run(lambda: (time.sleep(0.3), started.set()))
        outputs.write_result_json(tmp_path / "result.json", result, beside)
    monkeypatch.undo()  # dumps below formats as it always does
    text = (tmp_path / "result.json").read_text()
    assert result["stage_seconds"]["writing"] >= 0.25 + 0.29  # the wait, added
    assert text == dumps(result) and json.loads(text)["stage_seconds"]["writing"] >= 0.54
    if usable_cores() > 1:  # the three other values before the work ended, stage_seconds after
        assert formatted[:3] == [False] * 3 and formatted[3:] == [True]


def test_sites_csv_is_the_plain_formatting(tmp_path):
    rng = np.random.default_rng(1)
    sites, angles, scales = rng.uniform(0, 500, (300, 2)), rng.uniform(-4, 4, 300), rng.uniform(0.1, 3, 300)
    write_sites_csv(tmp_path / "s.csv", sites, angles, scales)
    rows = [
        f"{x:.6f},{y:.6f},{np.degrees(a):.6f},{s:.6f}"
        for (x, y), a, s in zip(sites, angles, scales, strict=True)
    ]
    assert (tmp_path / "s.csv").read_text() == "\n".join(["x,y,angle_deg,scale", *rows]) + "\n"


def test_cells_image_paints_each_label_its_colour_and_the_sites_dark():
    rng = np.random.default_rng(2)
    labels = rng.integers(-1, 40, (H, W)).astype(np.int32)
    sites = np.array([[3.5, 4.5], [100.2, 80.9]])
    img = np.asarray(cells_image(labels, 40, sites))
    want = label_colours(40)[np.where(labels >= 0, labels, 40)]
    want[[4, 80], [3, 100]] = 20
    assert img.dtype == np.uint8 and np.array_equal(img, want)


@pytest.mark.parametrize("n, seed", [(0, 12345), (1, 12345), (7, 3), (5000, 12345)])
def test_label_colours_are_matplotlibs_hsv_to_rgb(n, seed):
    """The cells' colours (HSV converted without importing matplotlib) are those of
    matplotlib.colors.hsv_to_rgb, bit for bit; the last is black."""
    mcolors = pytest.importorskip("matplotlib.colors")
    rng = np.random.default_rng(seed)
    hsv = np.stack(
        [(np.arange(n) * 0.618033988749895) % 1.0, 0.45 + 0.35 * rng.random(n), 0.70 + 0.30 * rng.random(n)],
        axis=1,
    )
    got = label_colours(n, seed)
    assert got.shape == (n + 1, 3) and got.dtype == np.uint8
    assert np.array_equal(got[:n], np.round(mcolors.hsv_to_rgb(hsv) * 255).astype(np.uint8))
    assert got[n].tolist() == [0, 0, 0]


@pytest.mark.parametrize(
    "shape, band", [((1, 1), 1 << 22), ((37, 53), 1 << 22), ((37, 53), 300), ((90, 7), 1)]
)
def test_png_holds_the_pictures_pixels(tmp_path, monkeypatch, shape, band):
    """The PNG writer (Up filter, zlib) read back by PIL's decoder: the same pixels, from
    an array and from a PIL picture alike, in one band or in many (the row above a band
    comes from the band before)."""
    from PIL import Image

    monkeypatch.setattr(outputs, "PNG_BAND", band)
    rng = np.random.default_rng(5)
    pixels = rng.integers(0, 256, (*shape, 3), dtype=np.uint8)
    pixels[shape[0] // 2 :] = pixels[: shape[0] - shape[0] // 2]  # repeated rows: Up differences of 0
    write_png(tmp_path / "a.png", pixels)
    write_png(tmp_path / "b.png", Image.fromarray(pixels))
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    with Image.open(tmp_path / "a.png") as img:
        img.verify()
    with Image.open(tmp_path / "a.png") as img:
        assert img.format == "PNG" and img.mode == "RGB" and img.size == (shape[1], shape[0])
        assert np.array_equal(np.asarray(img), pixels)


def _field_texts(rows):
    return [bytes(row[row != 0]).decode() for row in rows]


@pytest.mark.parametrize("digits", [0, 1, 3, 6])
def test_decimal_texts_are_pythons_repr_and_g(digits):
    """Numbers rounded to ``digits`` decimals, written whole-array, against Python's own
    repr (JSON) and format(v, "g") (SVG), with g's halfway cases: exact (dyadic) ties go to
    even, the others by the double's side of the tie."""
    from compact_distributions.cvt.mosaic.numbers import decimal_fields

    rng = np.random.default_rng(digits)
    vals = np.concatenate(
        [
            rng.uniform(-5000, 5000, 4000),
            rng.uniform(-99999, 99999, 1000),
            rng.uniform(-1, 1, 1000),
            [0.0, -0.0, 1000.0, 999.9995, 9999.995, 99999.95, 1234.125, 1234.375, 1234.625, 4095.5, 2.5],
            np.arange(0, 4000) * 0.005 + 999.0,
            np.arange(-300, 300) / 8,
        ]
    )
    vals = np.round(vals, digits)
    vals = vals[(vals == 0) | (np.abs(vals) >= 1e-4)]
    assert _field_texts(decimal_fields(vals, digits, "json")) == [repr(v) for v in vals.tolist()]
    assert _field_texts(decimal_fields(vals, digits, "svg")) == [format(v, "g") for v in vals.tolist()]


def test_decimal_texts_leave_what_they_cannot_write_to_python():
    from compact_distributions.cvt.mosaic.numbers import decimal_fields

    assert decimal_fields(np.array([1.0, np.nan]), 3, "json") is None
    assert decimal_fields(np.array([2.0**41]), 3, "json") is None
    assert decimal_fields(np.array([1e-5]), 5, "json") is None  # repr writes 1e-05
    assert decimal_fields(np.array([1234567.0]), 0, "svg") is None  # g writes 1.23457e+06
    assert decimal_fields(np.array([999999.6]), 1, "svg") is None  # rounds up to 1e+06
    assert decimal_fields(np.array([0.1234]), 3, "json") is None  # not rounded to 3 decimals
    with pytest.raises(ValueError, match="style"):
        decimal_fields(np.array([1.0]), 3, "csv")


def test_outline_texts_are_the_templates():
    """The JSON and SVG rings built whole-array are those the templates format."""
    from compact_distributions.cvt.mosaic.numbers import ring_texts

    rng = np.random.default_rng(8)
    count = rng.integers(2, 9, 300)
    xy = np.round(rng.uniform(-20, 5000, (int(count.sum()), 2)), 3)
    starts = np.cumsum(count) - count
    for style, template in (("json", render._json_ring), ("svg", render._svg_ring)):
        want = [
            template(c).format(*xy[s : s + c].ravel().tolist()) for s, c in zip(starts, count, strict=True)
        ]
        assert ring_texts(xy, count, 3, style) == want
    assert ring_texts(xy[:1], np.array([1]), 3, "svg") is None
    assert ring_texts(np.zeros((0, 2)), np.zeros(0, dtype=int), 3, "json") == []


@pytest.mark.parametrize("band", [1 << 22, 500])
def test_cells_png_written_by_bands_is_the_cells_picture(tmp_path, monkeypatch, band):
    """cells.png streamed a band of rows at a time (render.CellRows) holds the pixels of
    cells_image: each label's colour, outside labels (-1 and below) black, sites dark on
    whichever band they fall."""
    from PIL import Image

    monkeypatch.setattr(outputs, "PNG_BAND", band)
    rng = np.random.default_rng(6)
    labels = rng.integers(-3, 40, (H, W)).astype(np.int32)
    sites = np.vstack([rng.uniform(0, [W, H], (40, 2)), [[0.2, 0.3], [W - 0.5, H - 0.5]]])
    write_png(tmp_path / "cells.png", render.CellRows(labels, 42, sites))
    with Image.open(tmp_path / "cells.png") as img:
        got = np.asarray(img)
    assert np.array_equal(got, np.asarray(cells_image(labels, 42, sites)))
    want = label_colours(42)[np.where(labels >= 0, labels, 42)]
    i, j = np.floor(sites[:, 1]).astype(int), np.floor(sites[:, 0]).astype(int)
    want[i, j] = 20
    assert np.array_equal(got, want)


def test_drawn_pixels_are_the_block_means_of_the_supersampled_drawing():
    """Each pixel of the picture is the mean of its supersample x supersample block of
    the same elements drawn at that scale without reduction: within one level (Pillow's
    reduce rounds once), exactly where the block is one colour."""
    els, rng = mixed_elements()
    fills = rng.random((len(els), 3))
    small = np.asarray(draw_elements(els, W, H, fills, supersample=3)).astype(np.int64)
    big = np.asarray(draw_elements(els, W, H, fills, scale=3.0, supersample=1)).astype(np.int64)
    blocks = big.reshape(H, 3, W, 3, 3).transpose(0, 2, 4, 1, 3).reshape(H, W, 3, 9)
    mean = blocks.mean(axis=-1)
    assert np.abs(small - mean).max() < 1
    flat = (blocks == blocks[..., :1]).all(axis=-1)
    assert flat.mean() > 0.5 and np.array_equal(small[flat], blocks[..., 0][flat])


@pytest.mark.parametrize("shape", ["square", "triangle", "circle"])
def test_drawn_coverage_of_each_element_is_its_area(shape):
    """White elements on black, apart: the grey of the pixels around each element sums to
    its area (shapely's) and at most a fifth of a pixel more along its outline (the 3 x 3
    samples that the outline touches are filled)."""
    n_side, pitch = 6, 19.0
    rng = np.random.default_rng(5)
    ij = np.stack(np.meshgrid(np.arange(n_side), np.arange(n_side)), -1).reshape(-1, 2)
    centres = (ij + 0.5) * pitch + rng.uniform(-1.5, 1.5, (len(ij), 2))
    els = list(
        element_polygons(shape, 1.0, centres, rng.uniform(0, 3, len(ij)), rng.uniform(4, 6.5, len(ij)))
    )
    size = int(n_side * pitch)
    grey = (
        np.asarray(draw_elements(els, size, size, np.ones((len(els), 3)), background="#000000"))[
            ..., 0
        ].astype(np.float64)
        / 255
    )
    for (i, j), el in zip(ij, els, strict=True):
        cell = grey[int(j * pitch) : int((j + 1) * pitch), int(i * pitch) : int((i + 1) * pitch)]
        # PIL fills each sample its outline touches: a little more than the area, never less
        assert 0 <= cell.sum() - el.area <= 0.2 * el.length, (shape, cell.sum(), el.area, el.length)
