"""Tiles cut to fit along walls (cvt.cutting), checked with exact shapely geometry built
here from the wall pixels, and the geometric-median fill against a numerical optimum."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
import shapely.affinity
from scipy.optimize import minimize

from compact_distributions.cvt.mosaic import pipeline as mosaic
from compact_distributions.cvt.mosaic.cutting import cut_to_walls
from compact_distributions.cvt.mosaic.pipeline import geometric_median

W, H = 64, 48


def staircase(slope=0.55, start=6.0):
    """(H, W) bool: a 4-connected wall of pixels along y = start + slope·x, and its centre
    line through the pixel centres in walking order (a shapely line)."""
    walls = np.zeros((H, W), dtype=bool)
    path = []
    i = int(start)
    for j in range(W):
        target = int(start + slope * (j + 0.5))
        while True:
            if 0 <= i < H:
                walls[i, j] = True
                path.append((j + 0.5, i + 0.5))
            if i >= min(target, H - 1):
                break
            i += 1
    return walls, shapely.LineString(path)


def lattice_beside(line, side, gap, turn=0.0):
    """Squares of side ``side`` on a lattice, turned by ``turn`` radians, each kept whole
    only where it is at least G/2 from ``line`` and the raster's border."""
    frame = shapely.box(gap / 2, gap / 2, W - gap / 2, H - gap / 2)
    c, s = np.cos(turn), np.sin(turn)
    pitch = side * (abs(c) + abs(s)) + gap  # turned squares' boxes stay G apart
    out = []
    for y in np.arange(pitch / 2, H, pitch):
        for x in np.arange(pitch / 2, W, pitch):
            corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * side / 2
            xy = corners @ np.array([[c, s], [-s, c]]) + [x, y]
            sq = shapely.Polygon(xy)
            if frame.contains(sq) and sq.distance(line) >= max(gap / 2, 1e-6):
                out.append(sq)
    return out


@pytest.mark.parametrize("style", ["exact", "straight"])
@pytest.mark.parametrize("gap,turn", [(0.6, 0.0), (0.6, 0.3), (0.0, 0.0)])
def test_cut_tiles_keep_the_gap_the_walls_and_their_tiles(gap, turn, style):
    walls, line = staircase()
    tiles = lattice_beside(line, 5.0, gap, turn)
    tiles.append(None)  # a site without a tile stays without one
    out, grew = cut_to_walls(tiles, walls, gap, spacing=5.0 + gap, style=style)
    assert out[-1] is None
    assert grew > 0
    assert len(out) == len(tiles)
    cut = [p for p in out if p is not None]
    for before, after in zip(tiles[:-1], cut, strict=True):
        assert after.is_valid and after.geom_type == "Polygon"
        assert after.buffer(1e-9).covers(before)  # cutting only adds
    # every pair at least G apart (all pairs, brute force), none overlapping
    for a in range(len(cut)):
        for b in range(a + 1, len(cut)):
            assert cut[a].distance(cut[b]) >= gap - 1e-9
            assert cut[a].intersection(cut[b]).area == 0.0
    # at least G/2 from the wall's centre line and the border, and no wall pixel centre
    # inside a tile eroded by a pixel (no straddling)
    frame = shapely.box(gap / 2, gap / 2, W - gap / 2, H - gap / 2)
    i, j = np.nonzero(walls)
    centres = shapely.points(j + 0.5, i + 0.5)
    for p in cut:
        assert p.distance(line) >= gap / 2 - 1e-9
        assert frame.buffer(1e-9).covers(p)
        assert not shapely.contains(p.convex_hull.buffer(-1.0, join_style="mitre"), centres).any()
    # the wedges of grout along the slanted wall are filled: area gained on the tiles
    # that touch the wall's neighbourhood
    gained = sum(p.area for p in cut) - sum(p.area for p in tiles[:-1])
    assert gained > 0.1 * line.length


@pytest.mark.parametrize("style", ["exact", "straight"])
def test_far_tiles_and_no_walls_are_left_alone(style):
    walls, line = staircase()
    tiles = lattice_beside(line, 5.0, 0.6)
    out, grew = cut_to_walls(tiles, np.zeros_like(walls), 0.6, spacing=5.6, style=style)
    assert grew == 0 and all(a is b for a, b in zip(out, tiles, strict=True))
    # reach 0: only tiles within 0 px of a wall's centre line would be cut: none are
    out, grew = cut_to_walls(tiles, walls, 0.6, spacing=5.6, reach=0.0, style=style)
    assert grew == 0


@pytest.mark.parametrize("style", ["exact", "straight"])
def test_a_wall_that_meets_the_border_is_not_rounded(style):
    """A vertical wall from the top border to the bottom one, tiles on both sides: no cut
    tile reaches the other side round the wall's end, half a pixel from the border."""
    walls = np.zeros((H, W), dtype=bool)
    walls[:, 30] = True
    line = shapely.LineString([(30.5, 0.0), (30.5, H)])
    gap = 0.1  # the wall's pixel centres stop 0.5 px from the border: a strip of 0.4 px
    tiles = lattice_beside(line, 4.0, gap, turn=0.2)
    out, grew = cut_to_walls(tiles, walls, gap, spacing=4.4, style=style)
    assert grew > 0
    for before, after in zip(tiles, out, strict=True):
        left = before.centroid.x < 30.5
        xs = np.asarray(after.exterior.coords)[:, 0]
        assert (xs <= 30.5 - gap / 2 + 1e-9).all() if left else (xs >= 30.5 + gap / 2 - 1e-9).all()


@pytest.mark.parametrize("style", ["exact", "straight"])
@pytest.mark.parametrize("turn", [0.0, 0.35, -0.6])
def test_a_lone_tile_beside_a_straight_wall_grows_to_the_walls_margin(turn, style):
    """One tile, turned, beside a vertical wall: all that is free within its grown
    outline is the outline less the wall's G/2 margin (and the frame), and the cut tile
    is all of it, built here with shapely."""
    from compact_distributions.cvt.mosaic.cutting import CUT_ENLARGE

    walls = np.zeros((H, W), dtype=bool)
    walls[:, 30] = True
    gap = 0.4
    c, s = np.cos(turn), np.sin(turn)
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * 3.0
    tile = shapely.Polygon(corners @ np.array([[c, s], [-s, c]]) + [24.0, 20.0])
    out, grew = cut_to_walls([tile], walls, gap, spacing=6.0, style=style)
    assert grew == 1
    grown = shapely.affinity.scale(tile, CUT_ENLARGE, CUT_ENLARGE, origin="centroid")
    free = grown.intersection(shapely.box(gap / 2, gap / 2, 30.5 - gap / 2, H - gap / 2))
    assert out[0].symmetric_difference(free).area < 1e-3 * free.area  # the _MARGIN kept
    assert out[0].covers(tile) and out[0].distance(shapely.LineString([(30.5, 0), (30.5, H)])) >= gap / 2


def test_straight_cut_tiles_are_convex_and_hold_their_tiles():
    walls, truth = wall_network()
    tiles = lattice_beside(truth, 3.0, 0.5, 0.4)
    out, grew = cut_to_walls(tiles, walls, 0.5, spacing=3.5, style="straight")
    assert grew > 0
    for before, after in zip(tiles, out, strict=True):
        assert after.convex_hull.area - after.area < 1e-9 * after.area
        assert after.buffer(1e-9).covers(before)


@pytest.mark.parametrize("parts", [2, 3])
def test_straight_cut_in_parts_is_the_cut_in_one(monkeypatch, parts):
    """The tiles of a turn cut in parts side by side: every outline is the one the whole
    turn cut at once gives, vertex for vertex."""
    from compact_distributions.cvt.mosaic import cutting

    walls, truth = wall_network()
    tiles = lattice_beside(truth, 3.0, 0.5, 0.4)
    monkeypatch.setattr(cutting, "_ROWS_PER_PART", 10**9)
    whole, grew_whole = cut_to_walls(tiles, walls, 0.5, spacing=3.5, style="straight")
    monkeypatch.setattr(cutting, "_ROWS_PER_PART", 1)
    monkeypatch.setattr(cutting, "usable_cores", lambda: parts)
    calls = []
    real = cutting._cut_convex
    monkeypatch.setattr(cutting, "_cut_convex", lambda *a: calls.append(len(a[2])) or real(*a))
    split, grew_split = cut_to_walls(tiles, walls, 0.5, spacing=3.5, style="straight")
    assert grew_whole > 0 and grew_split == grew_whole
    assert max(calls) < sum(calls) and len(calls) > parts  # the turns were cut in parts
    assert (
        shapely.to_wkb(np.array(split, dtype=object)).tolist()
        == shapely.to_wkb(np.array(whole, dtype=object)).tolist()
    )


@pytest.mark.parametrize(
    "block,shuffle,single", [(None, False, False), (7, True, False), (40, False, False), (None, False, True)]
)
def test_geometric_median_minimises_the_mean_distance(monkeypatch, block, shuffle, single):
    """Against a numerical optimum, whatever the blocks the groups are taken in and the
    order of the points, and with float32 steps; a group without points keeps its start."""
    if block is not None:
        monkeypatch.setattr(mosaic, "MEDIAN_BLOCK", block)
    rng = np.random.default_rng(4)
    sizes = [1, 2, 7, 30, 0, 200]
    groups = np.repeat(np.arange(len(sizes)), sizes)
    points = rng.normal(size=(len(groups), 3)) * [20, 5, 5] + rng.normal(size=(len(sizes), 3))[groups] * 30
    if shuffle:
        order = rng.permutation(len(groups))
        points, groups = points[order], groups[order]
    means = np.stack(
        [points[groups == g].mean(axis=0) if sizes[g] else np.full(3, 7.0) for g in range(len(sizes))]
    )
    got = geometric_median(points, groups, means, single=single)
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got[4], means[4])
    for g in np.flatnonzero(sizes):
        pts = points[groups == g]

        def cost(m, pts=pts):
            return np.sqrt(((pts - m) ** 2).sum(axis=1)).mean()

        best = minimize(
            cost, means[g], method="Nelder-Mead", options={"xatol": 1e-8, "fatol": 1e-10, "maxiter": 20000}
        ).fun
        assert cost(got[g]) <= best + 1e-3
        # never worse than the mean (float32 steps: but for the rounding of values ~50)
        assert cost(got[g]) <= cost(means[g]) + (1e-4 if single else 1e-12)


@pytest.mark.parametrize("block", [None, 7])
def test_geometric_median_reads_indexed_points_from_their_means(monkeypatch, block):
    """Points read through ``index`` a block at a time and started at each group's mean
    (start None): the same medians, to the last bit, as the points gathered first and
    started at means summed plainly; a group without points stays at 0."""
    if block is not None:
        monkeypatch.setattr(mosaic, "MEDIAN_BLOCK", block)
    rng = np.random.default_rng(6)
    table = rng.random((50, 3)) * 100
    sizes = [3, 0, 1, 12, 9]
    groups = np.repeat(np.arange(len(sizes)), sizes)
    index = rng.integers(0, 50, len(groups))
    sums = np.stack(
        [np.bincount(groups, weights=table[index, c], minlength=len(sizes)) for c in range(3)], axis=1
    )
    means = sums / np.maximum(np.bincount(groups, minlength=len(sizes)), 1)[:, None]
    want = geometric_median(table[index], groups, means)
    got = geometric_median(table, groups, None, index=index, groups=len(sizes))
    assert np.array_equal(got, want) and np.array_equal(got[1], np.zeros(3))
    assert np.isnan(geometric_median(np.full((2, 3), np.nan), np.zeros(2, dtype=int), None, groups=1)).all()


def wall_network(seed=3):
    """(H, W) bool: 4-connected random walks (crossing, meeting the border, one closed
    loop), and their centre lines built here step by step from the pixels."""
    rng = np.random.default_rng(seed)
    walls = np.zeros((H, W), dtype=bool)
    for _ in range(4):
        i, j = rng.integers(0, H), rng.integers(0, W)
        for _ in range(60):
            walls[i, j] = True
            if rng.random() < 0.5:
                j = min(max(j + rng.choice([-1, 1]), 0), W - 1)
            else:
                i = min(max(i + rng.choice([-1, 1]), 0), H - 1)
    walls[30:37, 40] = walls[30:37, 46] = walls[30, 40:47] = walls[36, 40:47] = True  # a loop
    steps = []
    for i, j in zip(*np.nonzero(walls), strict=True):
        c = (j + 0.5, i + 0.5)
        if j + 1 < W and walls[i, j + 1]:
            steps.append(shapely.LineString([c, (j + 1.5, i + 0.5)]))
        if i + 1 < H and walls[i + 1, j]:
            steps.append(shapely.LineString([c, (j + 0.5, i + 1.5)]))
        if i in (0, H - 1):  # carried on to the border
            steps.append(shapely.LineString([c, (j + 0.5, 0.0 if i == 0 else H)]))
        if j in (0, W - 1):
            steps.append(shapely.LineString([c, (0.0 if j == 0 else W, i + 0.5)]))
        if not steps or not any(s.distance(shapely.Point(c)) == 0 for s in steps[-4:]):
            steps.append(shapely.Point(c))
    return walls, shapely.union_all(steps)


def test_wall_lines_are_the_walls_in_straight_pieces():
    """The pieces are the pixel steps (and lone pixels) built here one by one: the same
    ground, each piece straight, none longer than its run."""
    from compact_distributions.cvt.mosaic.cutting import wall_lines

    walls, truth = wall_network()
    pieces = wall_lines(walls)
    assert shapely.union_all(pieces).symmetric_difference(truth).length == pytest.approx(0.0, abs=1e-9)
    lines = pieces[shapely.get_type_id(pieces) == 1]
    assert (shapely.get_num_coordinates(lines) == 2).all()  # straight
    points = pieces[shapely.get_type_id(pieces) == 0]
    assert (shapely.distance(points[:, None], lines[None, :]) > 0.5).all()  # lone pixels


def test_merged_lines_and_their_margin_pieces_are_the_walls():
    """The exact cut's merged lines are the pixel steps, and their margin in pieces (any
    run length) covers the same ground as the steps grown one by one (square ends: right
    angles only)."""
    from compact_distributions.cvt.mosaic.cutting import _margin_pieces, _merged_lines

    walls, truth = wall_network()
    lines = _merged_lines(walls)
    assert shapely.union_all(lines).symmetric_difference(truth).length == pytest.approx(0.0, abs=1e-9)
    d = 0.37
    grown = shapely.buffer(shapely.get_parts(truth), d, cap_style="square", join_style="mitre")
    want = shapely.union_all(grown)
    for length in (1, 3, 64):
        got = shapely.union_all(_margin_pieces(lines, d, length))
        assert got.symmetric_difference(want).area < 1e-9


def test_the_style_follows_the_number_of_tiles(monkeypatch):
    from compact_distributions.cvt.errors import InputError
    from compact_distributions.cvt.mosaic import cutting

    seen = []
    monkeypatch.setattr(cutting, "_cut_exact", lambda *a: seen.append("exact") or (list(a[0]), 0))
    monkeypatch.setattr(cutting, "_cut_straight", lambda *a: seen.append("straight") or (list(a[0]), 0))
    monkeypatch.setattr(cutting, "EXACT_TILES", 3)
    walls = np.zeros((8, 8), dtype=bool)
    cutting.cut_to_walls([None] * 3, walls, 0.5, 2.0)
    cutting.cut_to_walls([None] * 4, walls, 0.5, 2.0)
    cutting.cut_to_walls([None] * 4, walls, 0.5, 2.0, style="exact")
    assert seen == ["exact", "straight", "exact"]
    with pytest.raises(InputError, match="style"):
        cutting.cut_to_walls([None], walls, 0.5, 2.0, style="round")


def _greedy_turns(pairs, n):
    """The colouring one node at a time, as a loop: the truth for the vectorised one."""
    adjacency = [set() for _ in range(n)]
    for a, b in pairs:
        if a != b:
            adjacency[a].add(b)
            adjacency[b].add(a)
    turn = [-1] * n
    for v in sorted(range(n), key=lambda v: -len(adjacency[v])):
        used = {turn[u] for u in adjacency[v]}
        t = 0
        while t in used:
            t += 1
        turn[v] = t
    return np.array(turn)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_turns_are_the_greedy_colouring(seed):
    from compact_distributions.cvt.mosaic.cutting import _turns

    rng = np.random.default_rng(seed)
    n = 300
    pts = rng.random((n, 2)) * 10
    d = np.hypot(*(pts[:, None] - pts[None, :]).transpose(2, 0, 1))
    a, b = np.nonzero(d < 1.2)
    pairs = np.stack([a, b], axis=1)  # both ways and each node with itself, as queries give them
    got = _turns(pairs, n)
    np.testing.assert_array_equal(got, _greedy_turns(pairs, n))
    assert (got[a[a != b]] != got[b[a != b]]).all()


@pytest.mark.parametrize("style", ["exact", "straight"])
@pytest.mark.parametrize("gap,turn", [(0.6, 0.2), (0.0, 0.5)])
def test_cut_tiles_keep_the_guarantees_beside_crossing_walls(gap, turn, style):
    """Junctions, ends, a loop and walls meeting the border: every cut tile checked against
    the centre lines built from the pixels and every other tile (all pairs)."""
    walls, truth = wall_network()
    tiles = lattice_beside(truth, 3.0, gap, turn)
    out, grew = cut_to_walls(tiles, walls, gap, spacing=3.0 + gap, style=style)
    assert grew > 0
    frame = shapely.box(gap / 2, gap / 2, W - gap / 2, H - gap / 2)
    i, j = np.nonzero(walls)
    centres = shapely.points(j + 0.5, i + 0.5)
    for before, after in zip(tiles, out, strict=True):
        assert after.is_valid and after.geom_type == "Polygon"
        assert after.buffer(1e-9).covers(before)
        assert after.distance(truth) >= gap / 2 - 1e-9
        assert frame.buffer(1e-9).covers(after)
        assert not shapely.contains(after.convex_hull.buffer(-1.0, join_style="mitre"), centres).any()
    for a in range(len(out)):
        for b in range(a + 1, len(out)):
            assert out[a].distance(out[b]) >= gap - 1e-9
            assert out[a].intersection(out[b]).area == 0.0


def test_a_cut_outline_starts_nearest_its_whole_tiles_first_vertex():
    from compact_distributions.cvt.mosaic.cutting import _started_as

    rng = np.random.default_rng(2)
    cut, whole = [], []
    for _ in range(20):
        pts = rng.random((12, 2)) * 10
        cut.append(shapely.convex_hull(shapely.multipoints(pts)))
        whole.append(shapely.box(*(rng.random(2) * 3 + 3), 8, 8))
    cut.append(shapely.box(0, 0, 9, 9).difference(shapely.box(4, 4, 5, 5)))  # a hole: left as it is
    whole.append(shapely.box(1, 1, 2, 2))
    cut, whole = np.array(cut), np.array(whole)
    got = _started_as(cut, whole)
    assert got[-1] is cut[-1]
    for c, w, g in zip(cut[:-1], whole[:-1], got[:-1], strict=True):
        assert g.is_valid and g.equals(c) and g.area == pytest.approx(c.area, rel=1e-12)
        ring = np.asarray(c.exterior.coords)[:-1]
        nearest = ring[np.argmin(((ring - w.exterior.coords[0]) ** 2).sum(axis=1))]
        np.testing.assert_array_equal(g.exterior.coords[0], nearest)


def test_elementwise_on_threads_gives_each_elements_own_result(monkeypatch):
    """Split across threads (four here, whatever the machine has), every element's
    difference and buffer is the one shapely gives that element alone, in order."""
    import shapely

    from compact_distributions.cvt import threads

    monkeypatch.setattr(threads, "usable_cores", lambda: 4)
    rng = np.random.default_rng(3)
    n = 4 * threads.PARALLEL_MIN + 5
    centres = rng.uniform(0, 100, (n, 2))
    a = shapely.buffer(shapely.points(centres), rng.uniform(1, 4, n))
    b = shapely.box(*(centres + 0.5).T, *(centres + 6).T)  # a corner inside every disc
    got = threads.elementwise(shapely.difference, a, b)
    alone = [shapely.difference(x, y) for x, y in zip(a, b, strict=True)]
    assert len(got) == n and all(shapely.equals_exact(g, e, 0) for g, e in zip(got, alone, strict=True))
    assert all(shapely.area(g) < shapely.area(x) for g, x in zip(got, a, strict=True))
    grown = threads.elementwise(shapely.buffer, b, distance=0.5, join_style="mitre")
    assert np.allclose(shapely.area(grown), (5.5 + 1.0) ** 2)
    assert threads.elementwise(shapely.area, a[:3]).shape == (3,)  # too few to split


def _area_sum_in_child(queue):
    import shapely

    from compact_distributions.cvt import threads

    discs = shapely.buffer(shapely.points(np.zeros((4 * threads.PARALLEL_MIN, 2))), 1.0, quad_segs=1)
    queue.put(float(np.sum(threads.elementwise(shapely.area, discs))))


def test_elementwise_keeps_one_pool_and_a_forked_child_makes_its_own(monkeypatch):
    """Calls share the process's worker threads; a child forked after them (as a Dask or
    multiprocessing worker is) still gets its answer instead of waiting on threads it did
    not inherit."""
    import multiprocessing
    import threading

    import shapely

    from compact_distributions.cvt import threads

    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("this platform cannot fork")
    monkeypatch.setattr(threads, "usable_cores", lambda: 2)
    monkeypatch.setattr(threads, "_pool", None)  # a pool of two, made here
    monkeypatch.setattr(threads, "_pool_workers", 0)
    seen = set()

    def who(x):
        seen.add(threading.current_thread().name)
        return shapely.area(x)

    discs = shapely.buffer(shapely.points(np.zeros((4 * threads.PARALLEL_MIN, 2))), 1.0, quad_segs=1)
    for _ in range(3):
        assert np.allclose(threads.elementwise(who, discs), 2.0)  # a diamond of diagonal 2
    assert 1 <= len(seen) <= 2 and all(name.startswith("elementwise") for name in seen)
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_area_sum_in_child, args=(queue,))
    child.start()
    child.join(timeout=60)
    if child.is_alive():
        child.kill()
        pytest.fail("elementwise in a forked child did not finish")
    assert child.exitcode == 0 and queue.get(timeout=5) == pytest.approx(2.0 * 4 * threads.PARALLEL_MIN)


def test_side_by_side_runs_the_calls_at_once_and_returns_them_in_order(monkeypatch):
    """The first call waits for a signal only the second gives: both must run at the same
    time.  Results come back in the order given; an error in any call is raised."""
    import threading

    from compact_distributions.cvt import threads

    monkeypatch.setattr(threads, "usable_cores", lambda: 2)
    signal = threading.Event()
    got = threads.side_by_side(lambda: signal.wait(timeout=30) and "first", lambda: signal.set() or "second")
    assert got == ["first", "second"]
    assert threads.side_by_side(lambda: 1) == [1]

    def broken():
        raise ValueError("broken call")

    with pytest.raises(ValueError, match="broken call"):
        threads.side_by_side(lambda: 1, broken)
    monkeypatch.setattr(threads, "usable_cores", lambda: 1)  # one core: one after the other
    assert threads.side_by_side(lambda: 3, lambda: 4) == [3, 4]


def test_in_order_runs_calls_ahead_and_yields_them_in_order(monkeypatch):
    """The first call waits for a signal only the second gives: both run at once.  The
    calls are drawn only as room is made (two running, then one more for each result
    taken), results come in the order given, and an error is raised at its place."""
    import threading

    from compact_distributions.cvt import threads

    monkeypatch.setattr(threads, "usable_cores", lambda: 2)
    signal = threading.Event()
    drawn = []

    def calls():
        yield lambda: signal.wait(timeout=30) and "first"
        for k in range(5):
            drawn.append(k)
            yield (lambda: signal.set() or "second") if k == 0 else (lambda k=k: k)

    results = threads.in_order(calls(), ahead=2)
    assert next(results) == "first" and drawn == [0, 1]
    assert list(results) == ["second", 1, 2, 3, 4]

    def broken():
        raise ValueError("broken call")

    results = threads.in_order([lambda: 1, broken, lambda: 3])
    assert next(results) == 1
    with pytest.raises(ValueError, match="broken call"):
        next(results)
    monkeypatch.setattr(threads, "usable_cores", lambda: 1)  # one core: one after the other
    assert list(threads.in_order([lambda: 3, lambda: 4])) == [3, 4]


def test_calls_nested_on_the_pool_run_in_their_own_thread(monkeypatch):
    """An elementwise operation that calls elementwise, and a side_by_side call on the
    pool that does, with a pool of two: waiting on the pool from inside it would wait
    for ever (every thread waiting on slices queued behind it); the nested calls run in
    the calling thread and give the same result as the operation alone."""
    import threading

    import shapely

    from compact_distributions.cvt import threads

    monkeypatch.setattr(threads, "usable_cores", lambda: 2)
    monkeypatch.setattr(threads, "_pool", None)  # a pool of two, made here
    monkeypatch.setattr(threads, "_pool_workers", 0)
    discs = shapely.buffer(shapely.points(np.zeros((8 * threads.PARALLEL_MIN, 2))), 1.0, quad_segs=1)
    inner_threads = set()

    def nested_area(part):
        here, seen = threading.current_thread().name, set()
        inner = threads.elementwise(
            lambda x: seen.add(threading.current_thread().name) or shapely.area(x), part
        )
        assert seen == {here}  # the inner slices ran in this pool thread
        inner_threads.add(here)
        return inner

    out = {}

    def work():
        out["elementwise"] = threads.elementwise(nested_area, discs)
        out["side"] = threads.side_by_side(
            lambda: 1, lambda: float(threads.elementwise(shapely.area, discs).sum())
        )

    runner = threading.Thread(target=work, daemon=True)
    runner.start()
    runner.join(timeout=60)
    assert not runner.is_alive(), "a nested call waited on the pool for ever"
    assert len(inner_threads) >= 1 and all(name.startswith("elementwise") for name in inner_threads)
    np.testing.assert_allclose(out["elementwise"], 2.0)  # a diamond of diagonal 2
    assert out["side"] == [1, pytest.approx(2.0 * 8 * threads.PARALLEL_MIN)]
    assert not threads._nested()  # the flag is only ever set on the pool's threads


def test_tiles_near_walls_are_those_shapely_finds():
    """The straight cut's choice of tiles near a wall (most settled by the nearest wall
    pixel centre, the rest looked up) is the set of tiles that shapely finds within the
    reach of the walls' centre lines, at every reach."""
    from compact_distributions.cvt.mosaic import cutting

    rng = np.random.default_rng(4)
    walls = rng.random((90, 120)) < 0.002
    walls[40, 10:100] = True
    walls[np.arange(20, 80), np.arange(20, 80)] = True
    walls[np.arange(20, 79), np.arange(21, 80)] = True
    xy = rng.uniform(0, 120, (300, 2)) * [1, 0.75]
    box = shapely.box(-2, -1.5, 2, 1.5)
    turns = rng.uniform(0, 90, len(xy))
    tiles = np.array(
        [
            shapely.affinity.translate(shapely.affinity.rotate(box, a), x, y)
            for (x, y), a in zip(xy, turns, strict=True)
        ],
        dtype=object,
    )
    pieces = cutting.wall_lines(walls)
    lines = shapely.union_all(pieces)
    for reach in (0.0, 0.7, 3.0, 8.0):
        truth = np.flatnonzero(shapely.distance(tiles, lines) <= reach)
        got = cutting._near_walls(pieces, tiles, reach, walls)
        assert np.array_equal(got, truth), reach
        assert 0 < len(got) < len(tiles)


def _convex_polygons(rng, n, spread=60.0):
    """Random convex polygons (3 to 9 vertices, some turned squares), as shapely and as
    the straight cut's padded vertex arrays."""
    from compact_distributions.cvt.mosaic import cutting

    out = []
    for _ in range(n):
        k = rng.integers(3, 10)
        angles = np.sort(rng.uniform(0, 2 * np.pi, k))
        radius = rng.uniform(1.0, 6.0)
        xy = np.stack([np.cos(angles), np.sin(angles)], axis=1) * radius + rng.uniform(0, spread, 2)
        out.append(shapely.Polygon(xy))
    geoms = np.array(out, dtype=object)
    return geoms, cutting._vertex_arrays(geoms)


def test_pairs_within_a_distance_are_those_shapely_finds():
    """The straight cut's pairs of tiles, and of wall pieces and tiles, within a distance
    (settled by disks where they can be, by GEOS where not) are the pairs that shapely
    finds by brute force, with pieces placed exactly at the distance from an edge."""
    from compact_distributions.cvt.mosaic import cutting

    rng = np.random.default_rng(7)
    geoms, (poly, count) = _convex_polygons(rng, 120)
    query, (qpoly, qcount) = _convex_polygons(rng, 40)
    distance = 0.8
    got = cutting._within(geoms, query, distance, cutting._tile_bounds(cutting._disks(qpoly, qcount), geoms))
    qi, gi = np.meshgrid(np.arange(len(query)), np.arange(len(geoms)), indexing="ij")
    truth = shapely.dwithin(query[qi.ravel()], geoms[gi.ravel()], distance=distance)
    assert sorted(zip(*got, strict=True)) == sorted(zip(qi.ravel()[truth], gi.ravel()[truth], strict=True))
    assert 0 < len(got[0]) < truth.size
    # queries that are some of the geometries themselves: each such pair asked once
    sel = rng.choice(len(geoms), 50, replace=False)
    twin = np.full(len(geoms), -1)
    twin[sel] = np.arange(len(sel))
    bounds = cutting._tile_bounds(cutting._disks(poly[sel], count[sel]), geoms)
    got = cutting._within(geoms, geoms[sel], distance, bounds, twin)
    qi, gi = np.meshgrid(np.arange(len(sel)), np.arange(len(geoms)), indexing="ij")
    truth = shapely.dwithin(geoms[sel][qi.ravel()], geoms[gi.ravel()], distance=distance)
    assert sorted(zip(*got, strict=True)) == sorted(zip(qi.ravel()[truth], gi.ravel()[truth], strict=True))
    # axis-aligned pieces and points, some exactly ``distance`` beyond a vertex
    ends = rng.integers(0, 60, (300, 2)) + 0.5
    length = rng.integers(0, 6, 300)
    down = rng.random(300) < 0.5
    segs = np.stack([ends, ends + np.where(down[:, None], [[0, 1]], [[1, 0]]) * length[:, None]], axis=1)
    top = poly[
        np.arange(len(poly)),
        np.argmax(poly[..., 1] - 1e9 * (np.arange(poly.shape[1]) >= count[:, None]), axis=1),
    ]
    segs[:40] = np.stack([top[:40] + [-1, distance], top[:40] + [1, distance]], axis=1)  # just touching reach
    pieces = np.array([shapely.LineString(s) if (s[0] != s[1]).any() else shapely.Point(s[0]) for s in segs])
    bounds = cutting._piece_bounds(cutting._disks(poly, count), segs)
    pi, gi = cutting._within(geoms, pieces, distance, bounds)
    pq, gq = np.meshgrid(np.arange(len(pieces)), np.arange(len(geoms)), indexing="ij")
    truth = shapely.dwithin(pieces[pq.ravel()], geoms[gq.ravel()], distance=distance)
    assert sorted(zip(pi, gi, strict=True)) == sorted(zip(pq.ravel()[truth], gq.ravel()[truth], strict=True))
    assert (pi[1:] >= pi[:-1]).all()  # each piece's pairs together, the pieces in order


def test_clipped_arrays_are_shapely_half_plane_intersections():
    """Padded vertex arrays clipped to a half-plane (whole-array Sutherland-Hodgman) are
    the polygons' intersections with it as shapely computes them; an outline wholly
    inside is left as it was, vertex for vertex."""
    from compact_distributions.cvt.mosaic import cutting

    rng = np.random.default_rng(8)
    geoms, (poly, count) = _convex_polygons(rng, 200, spread=10.0)
    angle = rng.uniform(0, 2 * np.pi, len(geoms))
    normal = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    centre = shapely.get_coordinates(shapely.centroid(geoms))
    offset = (normal * centre).sum(axis=1) + rng.uniform(-4, 8, len(geoms))
    out, n = cutting._clip_arrays(poly, count, normal, offset)
    got = cutting._polygons(out, n)
    # the half-plane as a large polygon: the line's two far points and two beyond them
    along = np.stack([-normal[:, 1], normal[:, 0]], axis=1)
    foot = normal * offset[:, None]
    far = 1e3
    halves = shapely.polygons(
        np.stack(
            [
                foot - far * along,
                foot + far * along,
                foot + far * along - far * normal,
                foot - far * along - far * normal,
            ],
            axis=1,
        )
    )
    truth = shapely.intersection(geoms, halves)
    assert np.allclose(shapely.area(got), shapely.area(truth), rtol=0, atol=1e-9)
    assert (shapely.area(shapely.symmetric_difference(got, truth)) < 1e-9).all()
    whole = np.flatnonzero(np.isclose(shapely.area(truth), shapely.area(geoms), rtol=0, atol=0))
    assert len(whole) and all(np.array_equal(out[k, : n[k]], poly[k, : count[k]]) for k in whole)
    assert 0 < (n == 0).sum() < len(n)  # some cut away whole, most kept in part


def test_padded_vertices_give_each_geometrys_least_projection():
    """The straight cut's least of normal·vertex, read from padded arrays at a narrow
    width with the wider outlines apart, is the least over each geometry's own vertices
    (shapely's coordinates), for one normal each and for several."""
    from compact_distributions.cvt.mosaic import cutting

    rng = np.random.default_rng(9)
    geoms, (poly, count) = _convex_polygons(rng, 80)
    padded = cutting._padded(poly, count)
    narrow = 5
    wide = np.flatnonzero(count > narrow)
    items = rng.integers(0, len(geoms), 500)
    shapes = cutting._Padded(np.ascontiguousarray(padded[:, :narrow]), geoms, items, wide, padded[wide])
    which = rng.permutation(len(items))[:300]
    normal = rng.normal(size=(300, 2))
    several = rng.normal(size=(300, 9, 2))
    coords = [shapely.get_coordinates(g) for g in geoms[items[which]]]

    def least(c, m):  # over one geometry's vertices, in the same arithmetic
        return (c[:, None, 0] * m[..., 0] + c[:, None, 1] * m[..., 1]).min(axis=0)

    assert np.array_equal(
        shapes.least(which, normal), [least(c, m[None])[0] for c, m in zip(coords, normal, strict=True)]
    )
    assert np.array_equal(
        shapes.least(which, several), [least(c, m) for c, m in zip(coords, several, strict=True)]
    )
    assert 0 < len(wide) < len(geoms)


def test_outlines_start_at_the_vertex_nearest_a_point():
    """Padded outlines rolled to begin at their vertex nearest a point (the first of
    equally near ones) keep their vertices and their order round the ring."""
    from compact_distributions.cvt.mosaic import cutting

    rng = np.random.default_rng(10)
    geoms, (poly, count) = _convex_polygons(rng, 60)
    first = rng.uniform(0, 60, (len(geoms), 2))
    first[:5] = poly[:5, 2]  # on a vertex
    out, n = cutting._started_at(poly, count, first)
    assert np.array_equal(n, count)
    for k in range(len(geoms)):
        ring = poly[k, : count[k]]
        start = int(np.argmin(((ring - first[k]) ** 2).sum(axis=1)))
        assert np.array_equal(out[k, : n[k]], np.roll(ring, -start, axis=0))
        assert not out[k, n[k] :].any()
    assert np.array_equal(out[:5, 0], first[:5])


def test_segment_distances_are_geos_distances_bit_for_bit():
    """The whole-array distance of convex polygons to segments and points is shapely's
    (GEOS's) own number wherever it answers; it leaves open (NaN) only pairs that meet
    or nearly do, and answers for all that are apart."""
    from compact_distributions.cvt.mosaic import cutting

    rng = np.random.default_rng(11)
    geoms, (poly, count) = _convex_polygons(rng, 400, spread=30.0)
    padded = cutting._padded(poly, count)
    ends = rng.uniform(0, 36, (400, 2))
    step = rng.normal(size=(400, 2)) * rng.choice([0.0, 1.0, 8.0], (400, 1))  # some points
    step[:100] = np.round(step[:100])  # some along the axes, as the walls' pieces
    segs = np.stack([ends, ends + step], axis=1)
    pieces = np.array([shapely.LineString(s) if (s[0] != s[1]).any() else shapely.Point(s[0]) for s in segs])
    got = cutting.segment_distances(padded, segs)
    truth = shapely.distance(geoms, pieces)
    answered = ~np.isnan(got)
    assert np.array_equal(got[answered], truth[answered])
    assert (truth[~answered] < 1e-6).all()  # left open: they meet
    assert answered[truth > 1e-6].all() and 0 < (~answered).sum() < 400
    assert (shapely.get_type_id(pieces[answered]) == 0).any()


def test_a_prepared_first_operand_stays_in_one_thread(monkeypatch):
    """Two threads must not test one prepared geometry at once (GEOS keeps working state
    in it): with a prepared geometry in the first operand the operation runs in the
    calling thread; prepared only in the second (which shapely's predicates do not
    prepare-read) or nowhere, it is split.  The caller's geometries stay as they were."""
    import threading

    import shapely

    from compact_distributions.cvt import threads

    monkeypatch.setattr(threads, "usable_cores", lambda: 2)
    n = 4 * threads.PARALLEL_MIN
    discs = shapely.buffer(shapely.points(np.arange(2.0 * n).reshape(n, 2)), 1.0, quad_segs=1)
    boxes = shapely.box(*np.arange(2.0 * n).reshape(n, 2).T, *(np.arange(2.0 * n).reshape(n, 2) + 2).T)
    seen = []

    def who(a, b):
        seen.append(threading.current_thread().name)
        return shapely.intersects(a, b)

    shapely.prepare(discs[[5]])
    assert threads.elementwise(who, discs, boxes).all()
    assert seen == [threading.current_thread().name]
    seen.clear()
    assert threads.elementwise(who, boxes, discs).all()
    assert len(seen) == 2 and all(name.startswith("elementwise") for name in seen)
    assert shapely.is_prepared(discs).tolist() == [k == 5 for k in range(n)]


_PREPARED_IN_THREADS = """
import numpy as np, shapely
from compact_distributions.cvt.threads import elementwise
rng = np.random.default_rng(1)
xy = rng.uniform(-60, 55, (20000, 2))
boxes = shapely.box(xy[:, 0], xy[:, 1], xy[:, 0] + 3, xy[:, 1] + 3)
which = rng.integers(0, 4, len(boxes))
truth = shapely.intersects(shapely.buffer(shapely.points(np.zeros((4, 2))), 50 + np.arange(4), 64)[which], boxes)
for _ in range(20):
    discs = shapely.buffer(shapely.points(np.zeros((4, 2))), 50 + np.arange(4), 64)
    shapely.prepare(discs)
    assert (elementwise(shapely.intersects, discs[which], boxes) == truth).all()
print(int(truth.sum()))
"""


def test_prepared_geometries_tested_on_threads_do_not_crash_the_process():
    """Four prepared discs, each tested against thousands of boxes across their outline,
    split across threads, crashed the process within the first round before
    ``elementwise`` kept a prepared first operand in one thread; the answers are
    shapely's on the unprepared discs."""
    import subprocess
    import sys

    from compact_distributions.cvt import threads

    if threads.usable_cores() < 2:
        pytest.skip("one core: elementwise never splits")
    done = subprocess.run(
        [sys.executable, "-c", _PREPARED_IN_THREADS], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert int(done.stdout) > 1000  # many boxes meet a disc: the test tests something


@pytest.mark.parametrize("with_hole", [False, True])
def test_vertex_arrays_are_each_exterior_written_out(with_hole):
    """The padded vertex arrays are each polygon's exterior vertices as written (less the
    closing one), zeros past its count; a polygon with a hole among them reads its
    exterior alone."""
    from compact_distributions.cvt.mosaic import cutting

    square = [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)]
    triangle = [(10.0, 1.0), (13.0, 1.0), (11.5, 5.0)]
    hole = [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0)] if with_hole else None
    geoms = np.array([shapely.Polygon(triangle), shapely.Polygon(square, None if hole is None else [hole])])
    poly, count = cutting._vertex_arrays(geoms)
    np.testing.assert_array_equal(count, [3, 4])
    np.testing.assert_array_equal(poly[0], triangle + [(0.0, 0.0)])
    np.testing.assert_array_equal(poly[1], square)
