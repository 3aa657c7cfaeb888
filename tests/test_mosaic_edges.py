"""Mosaics: strong edges as walls, tile colours in CIELAB, and the measures of result.json.

Each check is against an independent truth: published CIELAB values, the exact geometry
of a picture whose edges are known (a line, a disc), and a hand computation of every
measure from the outlines and fills that result.json holds."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely
from PIL import Image

from compact_distributions.backends.numpy_backend import NumpyBackend
from compact_distributions.bench.commands.cli import main
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.mosaic.colour import lab_to_srgb, srgb_to_lab
from compact_distributions.cvt.mosaic.image_fields import DEFAULT_EDGE_THRESHOLD, edge_contrast, strong_edges
from compact_distributions.cvt.mosaic.pipeline import WalledBackend, make_mosaic, split_cells, split_moments

from .cli_errors import one_error

NUMPY = NumpyBackend()


# ----------------------------------------------------------------------- colour


@pytest.mark.parametrize(
    "rgb,lab",
    [
        ((1, 1, 1), (100, 0, 0)),
        ((0, 0, 0), (0, 0, 0)),
        ((1, 0, 0), (53.2408, 80.0925, 67.2032)),  # sRGB primaries, D65 (published values)
        ((0, 1, 0), (87.7347, -86.1827, 83.1793)),
        ((0, 0, 1), (32.2970, 79.1875, -107.8602)),
        ((0.5, 0.5, 0.5), (53.3889, 0, 0)),
    ],
)
def test_lab_matches_published_values(rgb, lab):
    np.testing.assert_allclose(srgb_to_lab(np.array(rgb, float)), lab, atol=2e-3)


def test_lab_round_trip():
    rgb = np.random.default_rng(1).random((500, 3))
    np.testing.assert_allclose(lab_to_srgb(srgb_to_lab(rgb)), rgb, atol=1e-9)


def test_lab_of_a_picture_in_bands_is_lab_of_each_pixel(monkeypatch):
    """A picture is converted a band of pixels at a time: bands of 7 pixels (ending
    inside rows) give what one band of the whole picture gives, within rounding of
    what each pixel gets alone, and the published white and black wherever they lie."""
    from compact_distributions.cvt.mosaic import colour

    pic = np.random.default_rng(3).random((6, 5, 3))
    pic[0, 0], pic[5, 4] = 1.0, 0.0
    alone = np.array([[srgb_to_lab(pic[i, j]) for j in range(5)] for i in range(6)])
    whole = srgb_to_lab(pic)
    monkeypatch.setattr(colour, "LAB_BAND", 7)
    got = srgb_to_lab(pic)
    assert got.shape == (6, 5, 3) and np.array_equal(got, whole)
    np.testing.assert_allclose(got, alone, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[0, 0], (100, 0, 0), atol=1e-12)
    np.testing.assert_allclose(got[5, 4], (0, 0, 0), atol=1e-12)
    assert srgb_to_lab(np.zeros((0, 3))).shape == (0, 3)
    assert np.isnan(srgb_to_lab(np.array([np.nan, 0.5, 0.5]))).any()


def test_colour_error_in_bands_is_the_mean_distance(monkeypatch):
    """Mean ΔE*ab over (tile, pixel) pairs read a band at a time (bands of 5 pairs):
    the plain per-pair distances' mean; NaN without a pair, NaN carried from a NaN fill."""
    from compact_distributions.cvt import evaluate as ev

    rng = np.random.default_rng(2)
    lab = rng.random((4, 6, 3)) * 100
    fills = rng.random((3, 3)) * 100
    tiles = np.array([0, 0, 1, 1, 1, 2, 2, 2, 2, 0, 1, 2, 0])
    pixels = rng.integers(0, 24, len(tiles))
    plain = np.mean(
        [np.linalg.norm(lab.reshape(-1, 3)[p] - fills[t]) for t, p in zip(tiles, pixels, strict=True)]
    )
    monkeypatch.setattr(ev, "ERROR_BAND", 5)
    assert ev.colour_error(lab, fills, tiles, pixels) == pytest.approx(plain, rel=1e-14)
    assert np.isnan(ev.colour_error(lab, fills, tiles[:0], pixels[:0]))
    fills[1] = np.nan
    assert np.isnan(ev.colour_error(lab, fills, tiles, pixels))


# ----------------------------------------------------------------------- edges


def test_edge_contrast_of_a_step_is_its_colour_difference():
    """A pixel-aligned step between two colours scores their ΔE*ab at the step."""
    a, b = np.array([0.8, 0.2, 0.1]), np.array([0.1, 0.3, 0.7])
    pic = np.empty((40, 60, 3))
    pic[:, :30], pic[:, 30:] = a, b
    lab = srgb_to_lab(pic)
    contrast, across = edge_contrast(lab)
    delta = np.linalg.norm(srgb_to_lab(a) - srgb_to_lab(b))
    assert contrast.max() == pytest.approx(delta, rel=1e-6)
    assert np.abs(np.cos(across[20, 29:31])).min() > 0.999  # across the edge: along x
    # the edge is one pixel wide and as long as the picture, at a threshold below ΔE only
    edges = strong_edges(lab, threshold=delta - 1)
    assert edges.sum() == 40 and np.unique(np.nonzero(edges)[1]).size == 1
    assert not strong_edges(lab, threshold=delta + 1).any()
    assert not strong_edges(lab, threshold=delta - 1, min_length=41).any()  # shorter than asked


def test_edges_of_a_disc_are_a_closed_4_connected_line():
    from scipy import ndimage

    pic = disc_picture()
    edges = strong_edges(srgb_to_lab(pic))
    parts, n = ndimage.label(~edges)  # 4-connectivity: the line must separate in and out
    assert n == 2
    yy, xx = np.mgrid[0 : pic.shape[0], 0 : pic.shape[1]] + 0.5
    r = np.hypot(xx - DISC[0], yy - DISC[1])
    assert np.abs(r[edges] - DISC[2]).max() < 1.5  # the line follows the circle


def test_split_cells_keeps_each_cells_piece_on_its_sites_side():
    labels = np.zeros((6, 8), np.int32)
    labels[:, 4:] = 1
    labels[:, 2] = -1  # a wall cuts cell 0 in two pieces: columns 0-1 and column 3
    out = split_cells(labels, np.array([[0.5, 3.0], [6.0, 3.0]]))
    assert (out[:, :2] == 0).all() and (out[:, 3] == -1).all() and (out[:, 4:] == 1).all()
    # a site on its own small piece keeps it; a site on the wall keeps the largest piece
    out = split_cells(labels, np.array([[3.5, 3.0], [6.0, 3.0]]))
    assert (out[:, :2] == -1).all() and (out[:, 3] == 0).all()
    out = split_cells(labels, np.array([[2.5, 3.0], [6.0, 3.0]]))
    assert (out[:, :2] == 0).all() and (out[:, 3] == -1).all()
    labels[:, 2] = 0  # no wall: nothing changes
    np.testing.assert_array_equal(split_cells(labels, np.array([[0.5, 3.0], [6.0, 3.0]])), labels)


def flood_fill_split(labels, sites):
    """split_cells by its definition, pixel by pixel: each cell's 4-connected pieces by
    flood fill; keep the piece under the site where the site's pixel is in the cell, else
    the largest (of equal ones, the one whose first pixel comes last in raster order)."""
    h, w = labels.shape
    piece = np.full((h, w), -1)
    pieces = []  # (cell, first pixel in raster order, size)
    for i0 in range(h):
        for j0 in range(w):
            if labels[i0, j0] < 0 or piece[i0, j0] >= 0:
                continue
            k, cell, todo, size = len(pieces), labels[i0, j0], [(i0, j0)], 0
            piece[i0, j0] = k
            while todo:
                i, j = todo.pop()
                size += 1
                for a, b in ((i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)):
                    if 0 <= a < h and 0 <= b < w and labels[a, b] == cell and piece[a, b] < 0:
                        piece[a, b] = k
                        todo.append((a, b))
            pieces.append((cell, i0 * w + j0, size))
    out = np.full_like(labels, -1)
    for cell in range(len(sites)):
        mine = [k for k, p in enumerate(pieces) if p[0] == cell]
        if not mine:
            continue
        i = min(max(int(math.floor(sites[cell][1])), 0), h - 1)
        j = min(max(int(math.floor(sites[cell][0])), 0), w - 1)
        if labels[i, j] == cell:
            keep = piece[i, j]
        else:
            keep = max(mine, key=lambda k: (pieces[k][2], pieces[k][1]))
        out[piece == keep] = cell
    return out


def hand_moments(labels, n):
    """count, Σj, Σi, Σj², Σi² per cell, summed pixel by pixel."""
    sums = np.zeros((5, n), dtype=np.int64)
    for (i, j), cell in np.ndenumerate(labels):
        if cell >= 0:
            sums[:, cell] += (1, j, i, j * j, i * i)
    return sums


def random_cells(rng):
    """A small label raster whose cells often fall into pieces: random labels in blocks of
    random size, walls (-1) among them, and sites anywhere (on their cell or not)."""
    n = int(rng.integers(1, 7))
    block = int(rng.integers(1, 4))
    h, w = rng.integers(1, 13, 2)
    coarse = rng.integers(-1, n, (h, w))
    labels = np.repeat(np.repeat(coarse, block, axis=0), block, axis=1).astype(np.int32)
    sites = rng.random((n, 2)) * [labels.shape[1] + 2, labels.shape[0] + 2] - 1  # some off the raster
    return labels, sites


def test_split_cells_and_moments_match_a_flood_fill():
    rng = np.random.default_rng(11)
    split = 0
    for _ in range(400):
        labels, sites = random_cells(rng)
        want = flood_fill_split(labels, sites)
        got = split_cells(labels, sites)
        np.testing.assert_array_equal(got, want)
        mom = split_moments(labels, sites)
        np.testing.assert_array_equal(
            np.stack([mom.count, mom.sx, mom.sy, mom.sxx, mom.syy]), hand_moments(want, len(sites))
        )
        split += not np.array_equal(want, labels)
    assert split > 100  # most rasters had a cell in pieces


def test_split_cells_of_a_real_walled_step_match_a_flood_fill():
    """A Lloyd step's labels on the disc picture (walls along the circle, cells of
    several sizes and angles): cells cut by the wall and pieces left by the raster."""
    pic = disc_picture()
    m = make_mosaic(pic, NUMPY, n_elements=150, iterations=2, seed=3, method="ours")
    p = m.problem
    raw = NUMPY.label(
        m.sites, angles=p.angles_at(m.sites), scales=p.scales_at(m.sites), metric=p.metric, grid=p.grid
    )
    want = flood_fill_split(raw, m.sites)
    assert not np.array_equal(want, raw)
    np.testing.assert_array_equal(split_cells(raw, m.sites), want)
    walled = WalledBackend(NUMPY)
    args = dict(angles=p.angles_at(m.sites), scales=p.scales_at(m.sites), metric=p.metric, grid=p.grid)
    np.testing.assert_array_equal(walled.label(m.sites, **args), want)
    mom = walled.moments(m.sites, **args)
    np.testing.assert_array_equal(
        np.stack([mom.count, mom.sx, mom.sy, mom.sxx, mom.syy]), hand_moments(want, len(m.sites))
    )


# ----------------------------------------------------------------------- known edges

LEFT, RIGHT = tuple(np.array([(217, 38, 26), (26, 89, 204)]) / 255)  # 8-bit colours, ΔE*ab ≈ 150 apart
DISC = (85.0, 70.0, 42.0)  # cx, cy, r in px
SLOPE = math.tan(math.radians(25))


def line_side(x, y, w=160, h=140):
    """True right of a line through the picture's centre, 25° off the vertical."""
    return (x - w / 2) - (y - h / 2) * SLOPE > 0


def line_picture(w=160, h=140):
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    return np.where(line_side(xx, yy, w, h)[..., None], RIGHT, LEFT)


def disc_picture(w=160, h=140):
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    inside = np.hypot(xx - DISC[0], yy - DISC[1]) < DISC[2]
    return np.where(inside[..., None], RIGHT, LEFT)


def side_depths_line(poly, w=160, h=140):
    """How far (px) the tile reaches into each side of the line: (left, right)."""
    xy = np.asarray(poly.exterior.coords)
    n = np.array([1.0, -SLOPE]) / math.hypot(1.0, SLOPE)  # unit normal, towards the right
    d = (xy - [w / 2, h / 2]) @ n
    return max(0.0, -d.min()), max(0.0, d.max())


def side_depths_disc(poly):
    """How far (px) the tile reaches inside and outside the circle: (inside, outside)."""
    centre = shapely.Point(DISC[:2])
    far = np.hypot(*(np.asarray(poly.exterior.coords) - DISC[:2]).T).max()
    near = poly.distance(centre)
    return max(0.0, DISC[2] - near), max(0.0, far - DISC[2])


def hex_of(rgb):
    return "#" + "".join(f"{round(c * 255):02x}" for c in rgb)


@pytest.mark.parametrize(
    "kind,element,cut",
    [
        ("line", "square", None),
        ("disc", "square", None),
        ("line", "triangle", None),
        ("disc", "circle", None),
        ("disc", "square", "straight"),
        ("line", "triangle", "straight"),
    ],
)
def test_no_tile_crosses_a_known_edge_and_fills_match_their_side(kind, element, cut):
    pic = line_picture() if kind == "line" else disc_picture()
    m = make_mosaic(pic, NUMPY, n_elements=160, element=element, iterations=8, seed=2, cut=cut)
    assert m.walls and m.placed >= 150
    if cut == "straight":  # straight cuts leave every tile convex: its own hull
        tiles = [p for p in m.polygons if p is not None]
        hulls = shapely.area(shapely.convex_hull(tiles))
        np.testing.assert_allclose(shapely.area(tiles), hulls, rtol=1e-9)
    depths = [
        side_depths_line(p) if kind == "line" else side_depths_disc(p) for p in m.polygons if p is not None
    ]
    minority = np.array([min(a, b) for a, b in depths])
    # the edge is known only to the pixel: a tile keeps G/2 off the line through the
    # wall pixels' centres (carried on to the picture's border), so it reaches past the
    # true edge by no more than the farthest point of that line lies from it, less G/2
    i, j = np.nonzero(m.edges)
    x, y = j + 0.5, i + 0.5
    h, w = m.edges.shape
    x = np.concatenate(
        [x, x[i == 0], x[i == h - 1], np.zeros((j == 0).sum()), np.full((j == w - 1).sum(), w)]
    )
    y = np.concatenate(
        [y, np.zeros((i == 0).sum()), np.full((i == h - 1).sum(), h), y[j == 0], y[j == w - 1]]
    )
    if kind == "line":
        off = np.abs((np.stack([x, y], axis=1) - [80, 70]) @ np.array([1.0, -SLOPE]) / math.hypot(1.0, SLOPE))
    else:
        off = np.abs(np.hypot(x - DISC[0], y - DISC[1]) - DISC[2])
    assert minority.max() <= off.max() - m.gap / 2 + 1e-6, (minority.max(), off.max())
    assert minority.max() < 1.0
    assert m.cut_tiles > 0  # tiles were cut to fit the edge, and the bound holds for them
    assert m.straddling == 0.0
    fills = {hex_of(c) for c, p in zip(m.colours, m.polygons, strict=True) if p is not None}
    assert fills == {hex_of(LEFT), hex_of(RIGHT)}
    # each tile's fill is its own side's colour
    for p, c in zip(m.polygons, m.colours, strict=True):
        if p is None:
            continue
        x, y = p.centroid.x, p.centroid.y
        right = line_side(x, y) if kind == "line" else math.hypot(x - DISC[0], y - DISC[1]) < DISC[2]
        assert hex_of(c) == hex_of(RIGHT if right else LEFT)
    assert m.colour_error < 0.5  # 8-bit rounding of the fill only


def test_without_walls_tiles_straddle_and_colours_mix():
    pic = line_picture()
    off = make_mosaic(pic, NUMPY, n_elements=160, iterations=8, seed=2, edges=False)
    on = make_mosaic(pic, NUMPY, n_elements=160, iterations=8, seed=2)
    assert not off.walls and off.straddling > 0.05
    assert on.straddling == 0.0 and on.colour_error < off.colour_error
    np.testing.assert_array_equal(off.edges, on.edges)  # one edge map, walls or not


def test_same_seed_same_mosaic_with_walls():
    pic = disc_picture()
    a = make_mosaic(pic, NUMPY, n_elements=120, iterations=4, seed=9)
    b = make_mosaic(pic, NUMPY, n_elements=120, iterations=4, seed=9)
    np.testing.assert_array_equal(a.sites, b.sites)
    np.testing.assert_array_equal(a.colours, b.colours)
    assert a.colour_error == b.colour_error and a.coverage == b.coverage


def test_method_is_any_registered_name_a_record_or_a_callable():
    from compact_distributions.cvt.placement.ours import run_ours
    from compact_distributions.cvt.registry import get_method

    pic = line_picture()
    m = make_mosaic(pic, NUMPY, n_elements=100, iterations=3, method=get_method("hausner2001"))
    assert m.method == "hausner2001" and m.placed > 90
    # a baseline by name: the one registry serves the API as it serves the command line
    by_name = make_mosaic(
        pic, NUMPY, n_elements=100, iterations=3, method="hausner2001", method_options={"delta": 0.8}
    )
    assert by_name.method == "hausner2001" and by_name.method_options == {"delta": 0.8}
    assert by_name.distribution.extra["delta"] == 0.8
    assert make_mosaic(pic, NUMPY, n_elements=100, iterations=3, method="ours-fit").method == "ours-fit"
    # a plain callable runs under the record made for it, named after it (as a plug-in's
    # runs carry its entry point's name, not the name of a method it calls)
    assert make_mosaic(pic, NUMPY, n_elements=100, iterations=3, method=run_ours).method == "run_ours"
    with pytest.raises(InputError, match="method"):
        make_mosaic(pic, NUMPY, n_elements=100, iterations=3, method="hausner2002")
    with pytest.raises(InputError, match="has no option 'alternate'"):
        make_mosaic(
            pic, NUMPY, n_elements=100, iterations=3, method="hausner2001", method_options={"alternate": True}
        )
    with pytest.raises(InputError, match="edge_threshold"):
        make_mosaic(pic, NUMPY, n_elements=100, iterations=3, edge_threshold=0)
    with pytest.raises(InputError, match="cut must be"):
        make_mosaic(pic, NUMPY, n_elements=100, iterations=3, cut="diagonal")


# ----------------------------------------------------------------------- result.json by hand


def test_result_json_measures_match_a_hand_computation(tmp_path, capsys):
    """A 24x16 picture, black left of x = 12 and white right of it, 6 upright squares of
    one size and no walls: coverage, overlap, fills, colour error and straddling recomputed by
    hand from the outlines and fills in result.json."""
    w, h = 24, 16
    pic = np.zeros((h, w, 3), np.uint8)
    pic[:, 12:] = 255
    Image.fromarray(pic).save(tmp_path / "half.png")
    out = tmp_path / "out"
    code = main(
        [
            "mosaic",
            str(tmp_path / "half.png"),
            "--out",
            str(out),
            "--elements",
            "6",
            "--iterations",
            "3",
            "--no-field",
            "--no-density",
            "--no-edges",
            "--method",
            "ours",
            "--seed",
            "3",
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    res = json.loads((out / "result.json").read_text())
    assert res["walls"] is False and res["edge_threshold"] == DEFAULT_EDGE_THRESHOLD

    def lightness(v):  # CIE L* of the sRGB grey v/255 (the standard formulas)
        c = v / 255
        y = c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4
        return 116 * y ** (1 / 3) - 16 if y > (6 / 29) ** 3 else y * (29 / 3) ** 3

    area, pairs, errors, straddle = 0.0, 0, 0.0, 0
    placed = [(np.array(e), c) for e, c in zip(res["elements"], res["colours"], strict=True) if e is not None]
    for ring, colour in placed:
        x0, y0 = ring.min(axis=0)
        x1, y1 = ring.max(axis=0)
        assert len(ring) == 4 and np.allclose(sorted(set(np.round(ring[:, 0], 9))), [x0, x1])  # upright
        area += (x1 - x0) * (y1 - y0)
        cols = [j for j in range(w) if x0 <= j + 0.5 <= x1]
        rows = [i for i in range(h) if y0 <= i + 0.5 <= y1]
        white = sum(j >= 12 for j in cols) * len(rows)
        black = len(cols) * len(rows) - white
        # the fill: an 8-bit grey (a* = b* = 0) whose mean ΔE to the pixels is within 0.25 of
        # the best grey's, found by trying all 256 (on a line the best is the median: the
        # majority's L*; the mean L* is several ΔE worse)
        grey = int(colour[1:3], 16)
        assert colour == f"#{grey:02x}{grey:02x}{grey:02x}"

        def mean_error(v, white=white, black=black):
            return (white * (100 - lightness(v)) + black * lightness(v)) / (white + black)

        assert mean_error(grey) <= min(mean_error(v) for v in range(256)) + 0.25
        errors += white * (100 - lightness(grey)) + black * lightness(grey)
        pairs += white + black
        # straddling: the strong edge is the pixel column right of the step (x centre
        # 12.5); the square eroded by 1 px holds one of its pixel centres
        straddle += (x0 + 1 <= 12.5 <= x1 - 1) and any(y0 + 1 <= i + 0.5 <= y1 - 1 for i in range(h))
    assert res["edge_pixels"] == h
    assert res["placed"] == len(placed)
    # outlines are stored to 0.001 px: the area from them is good to ~perimeter x 0.0005 px
    assert res["coverage"] == pytest.approx(area / (w * h), abs=3e-4)
    assert res["overlap"] == 0.0
    assert res["colour_error"] == pytest.approx(errors / pairs, abs=1e-6)
    assert res["straddling"] == pytest.approx(straddle / len(placed))
    assert 0 < straddle < len(placed)  # the case tests both outcomes


# ----------------------------------------------------------------------- the CLI


@pytest.fixture
def two_colours(tmp_path):
    path = tmp_path / "two.png"
    Image.fromarray((line_picture(96, 80) * 255).astype(np.uint8)).save(path)
    return path


@pytest.mark.parametrize(
    "argv,match",
    [
        (["--edge-threshold", "0"], "--edge-threshold"),
        (["--edge-threshold", "lots"], "--edge-threshold"),
        (["--edge-threshold", "nan"], "--edge-threshold"),
        (["--method", "magic"], "magic"),
        (["--cut", "straight", "--no-cut"], "--no-cut"),
        (["--cut", "diagonal"], "--cut"),
    ],
)
def test_cli_bad_edge_and_method_options_exit_2(two_colours, tmp_path, capsys, argv, match):
    out = tmp_path / "out"
    assert match in one_error(["mosaic", two_colours, "--out", out, *argv], capsys)
    assert not out.exists()


@pytest.mark.parametrize("what,panels", [("method", 4), ("edges", 3)])
def test_cli_compare_writes_one_panel_each(two_colours, tmp_path, capsys, what, panels):
    """method: original, ours, ours-compact (or its stand-in), hausner2001; edges:
    original, without and with walls."""
    out = tmp_path / "out"
    code = main(
        [
            "mosaic",
            str(two_colours),
            "--out",
            str(out),
            "--elements",
            "60",
            "--iterations",
            "2",
            "--compare",
            what,
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    with Image.open(out / f"compare_{what}.png") as img:
        assert panels * 96 < img.width < (panels + 1) * 96 and img.height > 80
    res = json.loads((out / "result.json").read_text())
    assert res["kind"] == "mosaic" and 0 <= res["straddling"] <= 1 and res["colour_error"] >= 0
