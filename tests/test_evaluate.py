"""Coverage and overlap (bench/evaluate.py) against hand-computed areas and against the
plain union_all formula; the SVG and PNG drawings (cvt/render.py)."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest
import shapely

from compact_distributions.cvt.evaluate import empty_cells, evaluate, pixels_under, region_polygon
from compact_distributions.cvt.mosaic.render import PAPER, draw_elements, element_coordinates, svg_document
from compact_distributions.cvt.problem import Grid

SVG = "{http://www.w3.org/2000/svg}"


def test_two_overlapping_squares_by_hand():
    grid = Grid(10, 10)
    a = shapely.box(0, 0, 4, 4)  # 16
    b = shapely.box(2, 2, 6, 6)  # 16, shares 4 with a
    ev = evaluate([a, None, b], grid)
    assert ev.coverage == pytest.approx(28 / 100)
    assert ev.overlap == pytest.approx(4 / 100)
    assert (ev.elements, ev.skipped, ev.overlapping_pairs) == (2, 1, 1)
    assert ev.min_area == ev.max_area == pytest.approx(16)


def test_clipped_to_the_region_and_touching_is_no_overlap():
    grid = Grid(10, 10)
    els = [shapely.box(-2, -2, 2, 2), shapely.box(2, 0, 4, 2), shapely.box(8, 8, 14, 9)]
    ev = evaluate(els, grid)
    assert ev.coverage == pytest.approx((4 + 4 + 2) / 100)
    assert ev.overlap == 0.0 and ev.overlapping_pairs == 0
    assert ev.max_area == pytest.approx(16)  # sizes are of the elements, not the clipped parts


def test_triple_overlap_counts_each_extra_layer():
    grid = Grid(10, 10)
    sq = shapely.box(1, 1, 3, 3)
    ev = evaluate([sq, sq, sq], grid)
    assert ev.coverage == pytest.approx(0.04)
    assert ev.overlap == pytest.approx(0.08)  # Σ area − union = 12 − 4


def test_masked_region_area_and_coverage():
    mask = np.zeros((20, 30), dtype=bool)
    yy, xx = np.mgrid[0:20, 0:30]
    mask[(xx - 15) ** 2 + (yy - 10) ** 2 < 64] = True
    grid = Grid(30, 20, mask)
    region = region_polygon(grid)
    assert region.area == mask.sum()
    full = shapely.box(0, 0, 30, 20)
    ev = evaluate([full], grid)
    assert ev.coverage == pytest.approx(1.0) and ev.overlap == 0.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_matches_the_plain_union_formula(seed):
    """The STRtree shortcut gives the same numbers as union_all over everything."""
    rng = np.random.default_rng(seed)
    grid = Grid(200, 150)
    n = 300
    centres = rng.random((n, 2)) * [220, 170] - 10
    r = rng.uniform(2, 9, n)
    els = list(shapely.buffer(shapely.points(centres), r, quad_segs=8))
    els[5] = None
    ev = evaluate(els, grid)
    region = region_polygon(grid)
    geoms = np.array([e for e in els if e is not None])
    clipped = shapely.intersection(geoms, region)
    union = shapely.area(shapely.union_all(clipped))
    total = shapely.area(clipped).sum()
    assert ev.coverage == pytest.approx(union / region.area, rel=1e-9)
    assert ev.overlap == pytest.approx((total - union) / region.area, rel=1e-7, abs=1e-12)
    assert ev.overlap > 0.01 and ev.overlapping_pairs > 10


def test_empty_cells_read_in_bands_count_as_one_pass(monkeypatch):
    from compact_distributions.cvt import evaluate as ev_mod

    rng = np.random.default_rng(3)
    labels = rng.integers(-1, 300, size=(37, 53)).astype(np.int32)
    lab = labels.ravel()

    def whole(n):
        return int((np.bincount(lab[lab >= 0], minlength=n)[:n] == 0).sum())

    monkeypatch.setattr(ev_mod, "EMPTY_BAND", 100)  # 20 bands, the last one short
    assert empty_cells(labels, 400) == whole(400) > 100
    assert empty_cells(labels, 250) == whole(250) < 5  # labels beyond N count for no site


def test_empty_cells_and_nothing_placed():
    labels = np.array([[0, 0, 2], [-1, 2, 2]], dtype=np.int32)
    assert empty_cells(labels, 4) == 2  # sites 1 and 3
    ev = evaluate([None, None, None, None], Grid(3, 2), labels=labels)
    assert (ev.coverage, ev.overlap, ev.elements, ev.skipped, ev.empty_cells) == (0.0, 0.0, 0, 4, 2)
    d = ev.as_dict()
    assert {
        "coverage",
        "overlap",
        "placed",
        "skipped",
        "empty_cells",
        "min_element_area",
        "max_element_area",
    } <= set(d)


# ------------------------------------------------------------------ drawing
def sample_elements():
    return [
        shapely.box(2, 2, 10, 8),
        None,
        shapely.Polygon([(20, 5), (30, 5), (25, 15)]),
        shapely.Point(40, 20).buffer(5),
    ]


def test_svg_is_valid_xml_with_one_closed_path_per_element():
    text = svg_document(sample_elements(), 50, 30)
    root = ET.fromstring(text)
    assert root.tag == f"{SVG}svg"
    assert root.get("viewBox") == "0 0 50 30"
    assert (root.get("width"), root.get("height")) == ("50", "30")
    assert root.find(f"{SVG}rect") is not None  # background
    paths = root.findall(f"{SVG}g/{SVG}path")
    assert len(paths) == 3
    for p in paths:
        d = p.get("d")
        assert d.startswith("M") and d.endswith("Z") and d.count("M") == 1
    # coordinates are pixel units: the square's corner is there
    assert "2,2" in paths[0].get("d") and "10,8" in paths[0].get("d")


def test_svg_of_a_masked_region_draws_the_region():
    mask = np.zeros((30, 50), dtype=bool)
    mask[5:25, 5:45] = True
    region = region_polygon(Grid(50, 30, mask))
    root = ET.fromstring(
        svg_document(
            sample_elements(), 50, 30, region=region, fills=["#ff0000", "#00ff00", "#0000ff", (1, 2, 3)]
        )
    )
    top = root.findall(f"{SVG}path")
    assert len(top) == 1 and "5,5" in top[0].get("d")
    fills = [p.get("fill") for p in root.findall(f"{SVG}g/{SVG}path")]
    assert fills == ["#ff0000", "#0000ff", "#010203"]


def test_png_paints_elements_in_their_colours():
    fills = np.array([[255, 0, 0], [0, 0, 0], [0, 255, 0], [0, 0, 255]], dtype=np.uint8)
    img = np.asarray(draw_elements(sample_elements(), 50, 30, fills, region_colour=PAPER, scale=2.0))
    assert img.shape == (60, 100, 3)
    assert tuple(img[10, 12]) == (255, 0, 0)  # inside the square (x 6, y 5)
    assert tuple(img[40, 80]) == (0, 0, 255)  # centre of the circle
    assert tuple(img[55, 5]) == (0xF4, 0xF1, 0xEA)  # free region


def test_coordinates_are_json_ready():
    coords = element_coordinates(sample_elements())
    assert coords[1] is None
    assert sorted(map(tuple, coords[0])) == [(2.0, 2.0), (2.0, 8.0), (10.0, 2.0), (10.0, 8.0)]
    assert len(coords[3]) >= 32 and all(len(p) == 2 for p in coords[3])


def test_region_of_a_mask_is_one_valid_polygon():
    yy, xx = np.mgrid[0:64, 0:64]
    r2 = (xx - 32) ** 2 + (yy - 32) ** 2
    mask = (r2 < 28**2) & (r2 > 8**2)  # a ring: one polygon with a hole
    region = region_polygon(Grid(64, 64, mask))
    assert shapely.is_valid(region) and region.geom_type == "Polygon"
    assert len(region.interiors) == 1 and region.area == mask.sum()
    # an element across many pixel rows inside the ring is inside, untouched by clipping
    ev = evaluate([shapely.box(41, 20, 51, 44)], Grid(64, 64, mask), region=region)
    assert ev.coverage == pytest.approx(240 / mask.sum())


def tricky_tiles(rng, n, w, h):
    """Tiles whose outlines run through pixel centres: rotated squares, boxes with corners
    and sides on centres, triangles with a vertex on one, slivers with a nearly flat edge,
    non-convex L shapes, a tile with a hole, tiles over the border, None and empty."""
    out = [None, shapely.Polygon()]
    for _ in range(n):
        cx, cy = rng.random(2) * [w, h]
        s = rng.random() * 8 + 0.3
        kind = rng.integers(0, 7)
        if kind == 0:
            sq = shapely.box(cx - s, cy - s, cx + s, cy + s)
            out.append(shapely.affinity.rotate(sq, rng.random() * 90, origin=(cx, cy)))
        elif kind == 1:
            x0, y0 = np.floor([cx, cy]) + 0.5 * rng.integers(0, 2, 2)
            out.append(
                shapely.box(
                    x0, y0, x0 + rng.integers(0, 6) + 0.5 * rng.integers(0, 2), y0 + rng.integers(1, 6)
                )
            )
        elif kind == 2:
            out.append(shapely.Polygon([np.floor([cx, cy]) + 0.5, (cx + s, cy), (cx, cy + s)]))
        elif kind == 3:
            out.append(shapely.box(cx, cy, cx + s, cy + s / 3).union(shapely.box(cx, cy, cx + s / 3, cy + s)))
        elif kind == 4:
            out.append(
                shapely.box(cx - s, cy - s, cx + s, cy + s).difference(
                    shapely.box(cx - 1, cy - 1, cx + 1, cy + 1)
                )
            )
        elif kind == 5:
            out.append(shapely.Polygon([(cx, cy), (cx + 9, cy + 1e-4), (cx + 9, cy + 0.7), (cx, cy + 0.5)]))
        else:
            out.append(shapely.Point(cx, cy).buffer(s, 8))
    return out


def assert_pixels_are_shapelys(tiles, w, h):
    """pixels_under against shapely's intersects asked for every pixel centre of the
    raster, tile by tile."""
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    got_tiles, got_pixels = pixels_under(tiles, w, h)
    want_tiles, want_pixels = [], []
    for k, t in enumerate(tiles):
        if t is None or t.is_empty:
            continue
        inside = np.flatnonzero(shapely.intersects_xy(t, xx.ravel(), yy.ravel()))
        want_tiles += [k] * len(inside)
        want_pixels += list(inside)
    np.testing.assert_array_equal(got_tiles, want_tiles)
    np.testing.assert_array_equal(got_pixels, want_pixels)


def test_pixels_under_matches_shapely_on_every_pixel():
    """Against shapely's intersects asked for every pixel centre of the raster, tile by tile."""
    rng = np.random.default_rng(8)
    w, h = 40, 30
    for _ in range(60):
        tiles = tricky_tiles(rng, int(rng.integers(1, 12)), w, h)
        assert_pixels_are_shapelys(tiles, w, h)


def non_convex_tiles(rng, w, h):
    """Stars (some with their points on pixel centres), two-part multipolygons, a polygon
    with two holes, tiles cut like a mosaic's (a box less rotated boxes), a bow-tie and
    a multipolygon whose parts overlap (both invalid)."""
    out = []
    for _ in range(4):
        cx, cy = rng.random(2) * [w, h]
        n = int(rng.integers(5, 12))
        ang = np.sort(rng.random(n)) * 2 * np.pi
        rad = np.where(np.arange(n) % 2 == 0, 2 + rng.random(n) * 8, 0.5 + rng.random(n) * 2)
        xy = np.column_stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang)])
        if rng.random() < 0.5:
            xy = np.floor(xy) + 0.5
        out.append(shapely.make_valid(shapely.Polygon(xy)))
    cx, cy = rng.random(2) * [w, h]
    out.append(
        shapely.MultiPolygon(
            [shapely.box(cx, cy, cx + 4, cy + 3), shapely.box(cx + 5.5, cy + 1, cx + 9, cy + 6)]
        )
    )
    out.append(
        shapely.box(cx - 8, cy - 8, cx + 8, cy + 8)
        .difference(shapely.box(cx - 6, cy - 6, cx - 2, cy - 2))
        .difference(shapely.box(cx + 1, cy + 1, cx + 5.5, cy + 4.5))
    )
    cut = shapely.box(cx - 6, cy - 6, cx + 6, cy + 6)
    for _ in range(3):
        bx, by = rng.random(2) * 12 - 6 + [cx, cy]
        cut = cut.difference(shapely.affinity.rotate(shapely.box(bx, by, bx + 5, by + 5), rng.random() * 90))
    out.append(cut)
    out.append(shapely.Polygon([(cx, cy), (cx + 7, cy + 5), (cx + 7, cy), (cx, cy + 5)]))
    out.append(
        shapely.MultiPolygon(
            [shapely.box(cx, cy, cx + 5, cy + 5), shapely.box(cx + 2, cy + 2, cx + 8, cy + 7)]
        )
    )
    return out


def test_pixels_under_matches_shapely_on_non_convex_tiles():
    """The spans between a row's crossings of every ring, against shapely's intersects
    asked for every pixel centre, on non-convex, holed, multi-part and invalid tiles."""
    rng = np.random.default_rng(21)
    w, h = 40, 30
    for _ in range(40):
        tiles = non_convex_tiles(rng, w, h) + tricky_tiles(rng, 3, w, h)
        assert_pixels_are_shapelys(tiles, w, h)


@pytest.mark.parametrize("block", [None, 7])
@pytest.mark.parametrize("seed", range(6))
def test_straddling_tiles_against_every_pixel(seed, block, monkeypatch):
    """straddling_tiles against its definition tested pixel by pixel: a tile straddles
    when some edge pixel's centre is inside or on its convex hull eroded by a pixel (tiles
    of several kinds, pixel-aligned sides among them, None, a multipolygon)."""
    from compact_distributions.cvt import evaluate as measures
    from compact_distributions.cvt.evaluate import STRADDLE_DEPTH, straddling_tiles

    if block is not None:  # the edge pixels looked up a few at a time
        monkeypatch.setattr(measures, "STRADDLE_PIXELS", block)
    rng = np.random.default_rng(seed)
    h, w = 40, 50
    tiles = [None, shapely.box(10, 10, 20, 14), shapely.box(30.5, 2.0, 33.5, 9.0)]
    for _ in range(30):
        x, y, r = rng.uniform(-3, w + 3), rng.uniform(-3, h + 3), rng.uniform(0.5, 7)
        kind = rng.integers(0, 3)
        if kind == 0:
            tiles.append(
                shapely.box(np.floor(x), np.floor(y), np.floor(x) + np.ceil(r), np.floor(y) + np.ceil(r))
            )
        elif kind == 1:
            tiles.append(shapely.Point(x, y).buffer(r, quad_segs=3))
        else:
            tiles.append(
                shapely.MultiPolygon(
                    [shapely.box(x, y, x + r, y + r), shapely.box(x + r + 1, y, x + 2 * r + 1, y + r)]
                )
            )
    edges = rng.random((h, w)) < 0.1
    edges[12, :] = True  # a wall through the first box, 2 px inside it on either side
    got = straddling_tiles(tiles, edges)
    ii, jj = np.nonzero(edges)
    expected = np.zeros(len(tiles), dtype=bool)
    for k, tile in enumerate(tiles):
        if tile is None:
            continue
        eroded = shapely.convex_hull(tile).buffer(-STRADDLE_DEPTH, join_style="mitre")
        expected[k] = any(
            eroded.intersects(shapely.Point(j + 0.5, i + 0.5)) for i, j in zip(ii, jj, strict=True)
        )
    assert expected[1] and not expected[0]
    assert expected.sum() < len(tiles) - 1  # some tiles hold no edge pixel
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("seed", range(8))
def test_evaluate_against_brute_force(seed):
    """Coverage, overlap and overlapping pairs against shapely's union and every pair's
    intersection: tiles that overlap, touch along a side, nest, leave the region, hold a
    hole or come in two parts."""
    rng = np.random.default_rng(seed)
    w, h = 40, 30
    tiles = [shapely.box(0, 0, 5, 5), shapely.box(5, 0, 10, 5), shapely.box(2, 2, 3, 3)]  # touch; nest
    for _ in range(40):
        x, y, r = rng.uniform(-4, w + 4), rng.uniform(-4, h + 4), rng.uniform(0.3, 6)
        kind = rng.integers(0, 4)
        if kind == 0:
            tiles.append(shapely.Polygon([(x, y), (x + r, y), (x, y + r)]))
        elif kind == 1:
            tiles.append(shapely.Point(x, y).buffer(r, quad_segs=2))
        elif kind == 2:
            tiles.append(
                shapely.box(x, y, x + r, y + r).difference(
                    shapely.box(x + r / 4, y + r / 4, x + r / 2, y + r / 2)
                )
            )
        else:
            tiles.append(
                shapely.MultiPolygon(
                    [shapely.box(x, y, x + r, y + r), shapely.box(x + r + 1, y, x + 2 * r + 1, y + r)]
                )
            )
    region = shapely.box(0, 0, w, h)
    inside = [t.intersection(region) for t in tiles]
    union = shapely.union_all(inside).area
    pairs = sum(
        inside[i].intersection(inside[j]).area > 0
        for i in range(len(tiles))
        for j in range(i + 1, len(tiles))
    )
    ev = evaluate(tiles, Grid(w, h))
    assert pairs > 0 and ev.overlapping_pairs == pairs
    assert ev.coverage == pytest.approx(union / (w * h), abs=1e-12)
    assert ev.overlap == pytest.approx((sum(t.area for t in inside) - union) / (w * h), abs=1e-12)


def test_measures_leave_the_callers_geometries_unprepared():
    """A prepared geometry is not safe to share between threads, so the measures and the
    baselines' clipping prepare copies, never what they were given."""
    from compact_distributions.baselines.common import make_elements
    from compact_distributions.cvt.shapes import element_ball

    grid = Grid(40, 30)
    region = shapely.box(2, 2, 38, 28)
    tiles = [shapely.box(x, 5, x + 6, 11) for x in range(0, 40, 5)]
    ev = evaluate(tiles, grid, region=region)
    assert ev.elements == len(tiles) and ev.coverage > 0
    pixels_under(tiles, 40, 30)
    placed, _ = make_elements(
        element_ball("square"), [[20.0, 15.0], [1.0, 1.0]], [0.0, 0.0], [4.0, 4.0], grid, region=region
    )
    assert sum(p is not None for p in placed) == 2
    assert not shapely.is_prepared([*tiles, region]).any()
