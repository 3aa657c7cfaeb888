"""Picture to mosaic: fields from a picture, the API, the CLI, bad pictures.

Pictures are small (128-192 px) and runs short (100-300 elements, a few iterations) so
that the file stays well under a minute on the shared 2-core machine."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import shapely
from PIL import Image

from compact_distributions.backends.numpy_backend import NumpyBackend
from compact_distributions.bench.commands.cli import main
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.mosaic.image_fields import gaussian_filter, gaussian_smooth, picture_fields
from compact_distributions.cvt.mosaic.pipeline import make_mosaic, picture_array, raster_size, resample

SVG = "{http://www.w3.org/2000/svg}"
NUMPY = NumpyBackend()


def stripes(n=160, deg=30.0, period=24.0):
    """Black/white stripes whose edges run at ``deg`` in the raster frame (x right,
    y down, positive = clockwise on screen)."""
    y, x = np.mgrid[0:n, 0:n] + 0.5
    t = math.radians(deg)
    u = -x * math.sin(t) + y * math.cos(t)  # coordinate across the stripes
    return (np.sin(2 * math.pi * u / period) > 0).astype(np.float64)


def angle_error_deg(angles, truth_deg, period_deg):
    d = (np.degrees(angles) - truth_deg + period_deg / 2) % period_deg - period_deg / 2
    return np.abs(d)


# ----------------------------------------------------------------------- fields


@pytest.mark.parametrize("deg", [30.0, -20.0])
def test_field_runs_along_the_edges_in_the_raster_frame(deg):
    f = picture_fields(stripes(deg=deg), spacing=10.0, element="rectangle")
    angles = f.field.angles_at(np.array([[x, y] for x in (40.5, 80.5, 120.5) for y in (40.5, 80.5, 120.5)]))
    assert angle_error_deg(angles, deg, 180.0).max() < 3.0
    assert f.edges.any() and not f.edges.all()


@pytest.mark.parametrize(
    "shape,sigma", [((40, 90), 3.0), ((40, 90), 8.0), ((61, 37), 25.5), ((2, 130), 60.0)]
)
def test_gaussian_smooth_is_ndimages_filter(shape, sigma):
    """Through the FFT for wide kernels: the same kernel, truncation and border as
    scipy's direct filter, including a kernel wider than the picture."""
    from scipy import ndimage

    image = np.random.default_rng(5).random(shape) * 10
    want = ndimage.gaussian_filter(image, sigma, mode="nearest")
    np.testing.assert_allclose(gaussian_smooth(image, sigma), want, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "shape,sigma,order",
    [
        ((70, 45), 1.0, (0, 1)),
        ((70, 45), 1.0, (1, 0)),
        ((70, 45), 2.0, (0, 0)),
        ((3, 50), 2.0, (1, 1)),  # fewer rows than the kernel's radius
        ((1, 9), 1.5, (0, 0)),
        ((33, 40), 7.9, (0, 0)),  # more rows than a band: bands of rows join without a seam
    ],
)
def test_gaussian_filter_is_ndimages_filter_bit_for_bit(shape, sigma, order, monkeypatch):
    """The structure tensor's filter: scipy's own gaussian_filter (mode nearest) is the
    truth, to the last bit; bands of 4 rows so that band edges are crossed."""
    from scipy import ndimage

    from compact_distributions.cvt.mosaic import image_fields

    monkeypatch.setattr(image_fields, "ROW_BAND", 4)
    image = np.random.default_rng(7).random(shape) * 50 - 10
    want = ndimage.gaussian_filter(image, sigma, order=order, mode="nearest")
    got = gaussian_filter(image, sigma, order=order)
    assert got.shape == want.shape and np.array_equal(got, want)


def test_gaussian_filter_refuses_what_it_cannot_filter():
    with pytest.raises(InputError, match="2-D"):
        gaussian_filter(np.zeros((4, 4, 3)), 1.0)
    with pytest.raises(InputError, match="order"):
        gaussian_filter(np.zeros((4, 4)), 1.0, order=(2, 0))
    # NaN is carried, not hidden: the filtered pixels near it are NaN, as ndimage's
    image = np.zeros((20, 20))
    image[15, 15] = np.nan
    out = gaussian_filter(image, 1.0)
    assert np.isnan(out[15, 11]) and np.isnan(out[11, 15]) and not np.isnan(out[:10, :10]).any()


def test_flat_picture_gives_uniform_density_and_zero_field():
    f = picture_fields(np.full((40, 50, 3), 0.4), spacing=5.0)
    assert np.ptp(f.density.values) == 0
    assert np.all(f.field.angles_at(np.array([[10.0, 10.0], [45.0, 30.0]])) == 0)


# ----------------------------------------------------------------------- the API


@pytest.mark.parametrize("deg,element,period", [(30.0, "square", 90.0), (-20.0, "rectangle", 180.0)])
def test_elements_follow_the_edges(deg, element, period):
    m = make_mosaic(stripes(deg=deg), NUMPY, n_elements=200, element=element, iterations=6, use_density=False)
    err = angle_error_deg(m.angles, deg, period)
    assert err.mean() < 10.0, err.mean()
    # the placed polygons carry the angle: a whole rectangle's long side lies along the
    # stripes (tiles cut to fit a wall have other outlines and are left out)
    if element == "rectangle":
        whole = [p for p in m.polygons if p is not None and len(p.exterior.coords) == 5]
        assert len(whole) >= 5
        xy = np.array([np.asarray(p.exterior.coords)[:4] for p in whole])  # (T, 4, 2)
        sides = np.roll(xy, -1, axis=1) - xy
        longest = np.argmax(np.hypot(sides[..., 0], sides[..., 1]), axis=1)
        long_side = sides[np.arange(len(whole)), longest]
        err = angle_error_deg(np.arctan2(long_side[:, 1], long_side[:, 0]), deg, 180.0)
        assert np.median(err) < 12.0, np.median(err)


def test_without_field_every_element_is_upright():
    m = make_mosaic(
        stripes(deg=30.0), NUMPY, n_elements=120, iterations=2, use_field=False, use_density=False
    )
    assert np.all(m.angles == 0)
    # the fills and the measures read every tile, and leave none prepared: a prepared
    # tile tested on two threads at once crashes the process
    placed = [p for p in m.polygons if p is not None]
    assert len(placed) > 100 and not shapely.is_prepared(placed).any()
    # every stage after the method is timed, and the picture's analysis before it
    from compact_distributions.bench.results import stages_of

    stages = stages_of(m.distribution)
    for name in ("picture", "cutting", "fills", "evaluation"):
        assert 0.0 <= stages[name] < m.method_seconds


def test_smaller_elements_where_the_picture_has_detail():
    rng = np.random.default_rng(3)
    h, w = 128, 192
    pic = np.full((h, w, 3), 0.6)
    blocks = rng.random((h // 8, w // 16, 3)).repeat(8, axis=0).repeat(8, axis=1)
    pic[:, : w // 2] = blocks  # busy left half, flat right half
    # no walls: the blocks' edges would cut the busy half's tiles smaller on their own
    m = make_mosaic(pic, NUMPY, n_elements=250, iterations=8, use_field=False, edges=False)
    areas = np.array([0.0 if p is None else p.area for p in m.polygons])
    placed = areas > 0
    left = placed & (m.sites[:, 0] < w / 2 - 10)
    right = placed & (m.sites[:, 0] > w / 2 + 10)
    assert left.sum() > right.sum()  # more elements where the detail is
    assert areas[left].mean() < 0.7 * areas[right].mean()
    # and without the density both halves are alike
    u = make_mosaic(pic, NUMPY, n_elements=250, iterations=8, use_field=False, use_density=False, edges=False)
    ua = np.array([0.0 if p is None else p.area for p in u.polygons])
    ul, ur = u.sites[:, 0] < w / 2 - 10, u.sites[:, 0] > w / 2 + 10
    assert 0.8 < ua[ul].mean() / ua[ur].mean() < 1.25


def test_colours_match_a_flat_colour_picture():
    pic = np.zeros((160, 160, 3))
    quads = np.array([[0.9, 0.1, 0.1], [0.1, 0.7, 0.2], [0.2, 0.3, 0.9], [0.95, 0.9, 0.2]])
    pic[:80, :80], pic[:80, 80:], pic[80:, :80], pic[80:, 80:] = quads
    m = make_mosaic(pic, NUMPY, n_elements=200, iterations=6, element="square")
    assert m.colours.shape == (200, 3)
    i = (m.sites[:, 1] >= 80).astype(int) * 2 + (m.sites[:, 0] >= 80).astype(int)
    err = np.abs(m.colours - quads[i]).mean(axis=1)
    assert err.mean() < 0.03, err.mean()
    # an element wholly inside one quadrant has that quadrant's colour, to the 8 bits of
    # the '#rrggbb' fill
    inner = [
        k
        for k, p in enumerate(m.polygons)
        if p is not None
        and shapely.box(
            *(np.array([0, 0, 80, 80]) + 80 * np.array([i[k] % 2, i[k] // 2, i[k] % 2, i[k] // 2]))
        ).contains(p)
    ]
    assert len(inner) > 100
    assert np.abs(m.colours[inner] - quads[i[inner]]).max() <= 0.5 / 255 + 1e-12
    # coverage against an independent estimate: the share of a fine point lattice that
    # falls inside some element
    ys, xs = (np.mgrid[0:640, 0:640] + 0.5) / 4
    inside = shapely.contains_xy(shapely.union_all([p for p in m.polygons if p is not None]), xs, ys)
    assert m.coverage == pytest.approx(inside.mean(), abs=0.01)
    assert 0.3 < m.coverage <= 1.0


def test_the_measures_run_beside_the_fills(monkeypatch):
    """The coverage and straddling are measured on a thread of their own while the tiles
    are filled, and the mosaic records what they measured."""
    import threading

    from compact_distributions.cvt.mosaic import pipeline

    filling, seen = threading.Event(), []
    real_fills, real_evaluate = pipeline.mosaic_fills, pipeline.evaluate

    def fills(*args, **kwargs):
        filling.set()
        try:
            return real_fills(*args, **kwargs)
        finally:
            filling.clear()

    def evaluate(*args, **kwargs):
        filling.wait(5.0)  # the fills are under way when the measures begin
        seen.append((threading.current_thread() is threading.main_thread(), filling.is_set()))
        return real_evaluate(*args, **kwargs)

    monkeypatch.setattr(pipeline, "mosaic_fills", fills)
    monkeypatch.setattr(pipeline, "evaluate", evaluate)
    m = make_mosaic(stripes(n=96), NUMPY, n_elements=60, iterations=3, element="square")
    assert seen == [(False, True)]
    tiles = [p for p in m.polygons if p is not None]
    assert m.coverage == pytest.approx(shapely.union_all(tiles).area / (96 * 96), abs=1e-9)


def test_same_seed_same_mosaic_and_numpy_input_equals_file(tmp_path):
    pic = (stripes(n=128, deg=10.0) * 200 + 20).astype(np.uint8)
    Image.fromarray(pic).save(tmp_path / "s.png")
    a = make_mosaic(pic, NUMPY, n_elements=100, iterations=3, seed=5)
    b = make_mosaic(tmp_path / "s.png", NUMPY, n_elements=100, iterations=3, seed=5)
    np.testing.assert_array_equal(a.sites, b.sites)
    np.testing.assert_allclose(a.colours, b.colours, atol=1e-12)


def test_raster_size_and_resampling():
    assert raster_size(3000, 1500) == (1024, 512)  # capped, aspect kept
    assert raster_size(300, 200) == (300, 200)  # never enlarged by default
    assert raster_size(300, 200, "600") == (600, 400)  # long side
    assert raster_size(300, 200, "64x64") == (64, 64)
    with pytest.raises(InputError, match="size"):
        raster_size(300, 200, "big")
    flat = np.full((900, 1800, 3), 0.25)
    small = resample(flat, 256, 128)
    assert small.shape == (128, 256, 3) and np.allclose(small, 0.25, atol=1e-6)


@pytest.mark.parametrize(
    "bad,match",
    [
        (np.full((20, 20), 1.5), "0..1"),
        (np.zeros((20, 20, 2)), "shape"),
        (np.zeros((0, 5)), "shape|no pixels"),
        (np.full((20, 20), np.nan), "NaN"),
    ],
)
def test_bad_arrays_raise_input_error(bad, match):
    with pytest.raises(InputError, match=match):
        picture_array(bad)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(n_elements=0), "elements"),
        (dict(n_elements=5000), "do not fit"),
        (dict(element="heptagon"), "heptagon"),
        (dict(metric="l3"), "l3"),
        (dict(gap=-1), "gap"),
        (dict(grout="not-a-colour"), "colour"),
        (dict(contrast=0.5), "contrast"),
    ],
)
def test_bad_options_raise_input_error(kwargs, match):
    with pytest.raises(InputError, match=match):
        make_mosaic(np.zeros((40, 40)), NUMPY, **{"n_elements": 20, "iterations": 1, **kwargs})


# ----------------------------------------------------------------------- the CLI


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, err


@pytest.fixture
def picture_file(tmp_path):
    rgb = np.zeros((120, 150, 3), np.uint8)
    rgb[:, :75] = (200, 40, 40)
    rgb[:, 75:] = (30, 90, 200)
    rgb[40:80, 50:100] = (250, 220, 50)
    path = tmp_path / "pic.png"
    Image.fromarray(rgb).save(path)
    return path


@pytest.mark.parametrize("element,tag", [("square", "path"), ("ellipse", "ellipse")])
def test_cli_writes_svg_png_and_result(picture_file, tmp_path, capsys, element, tag):
    out = tmp_path / "out"
    code, err = _run(
        [
            "mosaic",
            str(picture_file),
            "--out",
            str(out),
            "--elements",
            "150",
            "--iterations",
            "3",
            "--element",
            element,
            "--grout",
            "#101010",
        ],
        capsys,
    )
    assert code == 0, err
    assert "iteration 3/3" in err  # progress on stderr
    root = ET.parse(out / "mosaic.svg").getroot()
    elements = root.findall(f".//{SVG}{tag}")
    res = json.loads((out / "result.json").read_text())
    # whole ellipses are <ellipse>s; those cut to fit a wall are paths
    cut = res["extra"].get("cut_tiles", 0)
    assert (
        len(elements)
        == res["placed"] - (cut if tag == "ellipse" else 0)
        == 150 - res["skipped"] - (cut if tag == "ellipse" else 0)
    )
    assert len(root.findall(f".//{SVG}path")) + len(root.findall(f".//{SVG}ellipse")) == res["placed"]
    assert res["skipped"] <= 3
    assert root.find(f"{SVG}rect").get("fill") == "#101010"
    for key in (
        "backend",
        "device",
        "metric",
        "aspect",
        "size",
        "sites",
        "angles",
        "scales",
        "iterations",
        "energy",
        "seconds",
        "coverage",
        "image",
        "colours",
    ):
        assert key in res, key
    assert res["size"] == [150, 120] and res["iterations"] == 3 and len(res["sites"]) == 150
    assert res["metric"] == ("linf" if element == "square" else "l2-axial")
    assert 0.3 < res["coverage"] <= 1.0
    # each element's fill is the colour recorded for its site
    fills = {e.get("fill") for e in elements}
    assert fills <= set(res["colours"]) and "#c82828" in fills
    with Image.open(out / "mosaic.png") as png:
        assert png.size == (150, 120)
        # at each placed site the picture shows that element's colour
        rgb = np.asarray(png.convert("RGB"), dtype=int)
    sites = np.array(res["sites"])
    centre = rgb[sites[:, 1].astype(int), sites[:, 0].astype(int)]
    want = np.array([[int(c[k : k + 2], 16) for k in (1, 3, 5)] for c in res["colours"]])
    assert np.median(np.abs(centre - want).max(axis=1)) <= 2


@pytest.fixture
def bad_pictures(tmp_path):
    d = {}
    noise = np.random.default_rng(0).integers(0, 255, (64, 64, 3), dtype=np.uint8)
    Image.fromarray(noise).save(tmp_path / "full.png")
    data = (tmp_path / "full.png").read_bytes()
    d["truncated"] = tmp_path / "truncated.png"
    d["truncated"].write_bytes(data[: len(data) // 2])
    d["text"] = tmp_path / "notes.png"
    d["text"].write_text("this is not an image\n")
    d["missing"] = tmp_path / "nope.png"
    d["one"] = tmp_path / "one.png"
    Image.fromarray(np.array([[[10, 200, 30]]], np.uint8)).save(d["one"])
    return d


@pytest.mark.parametrize(
    "name,match",
    [
        ("truncated", "cannot read image|truncated"),
        ("text", "not an image"),
        ("missing", "not found"),
        ("one", "1x1"),
    ],
)
def test_cli_bad_pictures_exit_2_with_one_line(bad_pictures, tmp_path, capsys, name, match):
    out = tmp_path / "out"
    code, err = _run(["mosaic", str(bad_pictures[name]), "--out", str(out), "--elements", "50"], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert lines[-1].startswith("cvtbench: error:") and "Traceback" not in err
    import re

    assert re.search(match, lines[-1]), lines[-1]
    assert not out.exists()


def test_cli_one_pixel_picture_works_when_enlarged(bad_pictures, tmp_path, capsys):
    out = tmp_path / "out"
    code, err = _run(
        [
            "mosaic",
            str(bad_pictures["one"]),
            "--out",
            str(out),
            "--size",
            "32",
            "--elements",
            "12",
            "--iterations",
            "2",
            "--quiet",
        ],
        capsys,
    )
    assert code == 0, err
    res = json.loads((out / "result.json").read_text())
    assert res["size"] == [32, 32] and set(res["colours"]) == {"#0ac81e"}


def _save_16bit(path):
    arr = np.full((64, 80), 30000, np.uint16)
    arr[:, 40:] = 60000
    Image.fromarray(arr).save(path)
    return [30000 / 65535, 60000 / 65535]


def _save_palette(path):
    img = Image.new("P", (80, 64))
    img.putpalette([255, 0, 0, 0, 0, 255] + [0] * 762)
    px = np.zeros((64, 80), np.uint8)
    px[:, 40:] = 1
    img.putdata(px.ravel().tolist())
    img.save(path)
    return [(1.0, 0.0, 0.0), (0.0, 0.0, 1.0)]


def _save_rgba(path):
    rgba = np.zeros((64, 80, 4), np.uint8)
    rgba[:, :40] = (0, 0, 0, 255)
    rgba[:, 40:] = (0, 0, 0, 0)  # transparent: composited on white
    Image.fromarray(rgba, "RGBA").save(path)
    return [(0.0, 0.0, 0.0), (1.0, 1.0, 1.0)]


def _save_grey_jpeg(path):
    arr = np.full((64, 80), 40, np.uint8)
    arr[:, 40:] = 220
    Image.fromarray(arr).save(path, quality=95)
    return [40 / 255, 220 / 255]


@pytest.mark.parametrize(
    "maker,suffix",
    [(_save_16bit, ".png"), (_save_palette, ".png"), (_save_rgba, ".png"), (_save_grey_jpeg, ".jpg")],
)
def test_cli_other_formats_give_correct_colours(tmp_path, capsys, maker, suffix):
    path = tmp_path / f"pic{suffix}"
    left, right = (np.broadcast_to(np.asarray(c, float), (3,)) for c in maker(path))
    out = tmp_path / "out"
    code, err = _run(
        ["mosaic", str(path), "--out", str(out), "--elements", "60", "--iterations", "3", "--quiet"], capsys
    )
    assert code == 0, err
    res = json.loads((out / "result.json").read_text())
    cols = np.array([[int(c[k : k + 2], 16) / 255 for k in (1, 3, 5)] for c in res["colours"]])
    x = np.array(res["sites"])[:, 0]
    far_left, far_right = x < 30, x > 50
    assert far_left.any() and far_right.any()
    tol = 0.04 if suffix == ".jpg" else 0.01
    assert np.abs(cols[far_left] - left).max() < tol
    assert np.abs(cols[far_right] - right).max() < tol


@pytest.mark.parametrize(
    "argv,match",
    [
        (["--elements", "many"], "--elements"),
        (["--gap", "-2"], "--gap"),
        (["--iterations", "-1"], "--iterations"),
        (["--metric", "l7"], "l7"),
        (["--backend", "quantum"], "quantum"),
        (["--size", "0"], "size"),
    ],
)
def test_cli_bad_options_exit_2(picture_file, tmp_path, capsys, argv, match):
    out = tmp_path / "out"
    code, err = _run(["mosaic", str(picture_file), "--out", str(out), *argv], capsys)
    assert code == 2 and match in err and "Traceback" not in err
    assert not out.exists()


def test_cli_compare_writes_three_panels(picture_file, tmp_path, capsys):
    out = tmp_path / "out"
    code, err = _run(
        [
            "mosaic",
            str(picture_file),
            "--out",
            str(out),
            "--elements",
            "80",
            "--iterations",
            "2",
            "--element",
            "triangle",
            "--compare",
            "density",
            "--quiet",
        ],
        capsys,
    )
    assert code == 0, err
    with Image.open(out / "compare_density.png") as img:
        assert img.width > 3 * 150 and img.height > 120
    assert json.loads((out / "result.json").read_text())["metric"] == "triangle"


def test_rgba_uint16_array_is_composited_on_white():
    rgba = np.zeros((48, 64, 4), np.uint16)
    rgba[..., 0] = 65535  # red where opaque
    rgba[:, :32, 3] = 65535
    rgb, _ = picture_array(rgba)
    assert np.allclose(rgb[:, :32], [1, 0, 0]) and np.allclose(rgb[:, 32:], [1, 1, 1])
