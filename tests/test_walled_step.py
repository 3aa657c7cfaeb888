"""The walled Lloyd step's device path against the host's: a backend that cuts the cells
itself (``walled_moments``: OpenCL finds the pieces on its device) must give moments
bit-identical to ``moments_from_labels(split_cells(labels, sites))`` of its own labels,
which the host path (:func:`cvt.mosaic.split_moments`, the one every backend can use)
gives and a flood fill checks (tests/test_mosaic_edges.py).

The cases have walls that cut cells into several pieces, walls that end inside cells
(cells that look split and are not), sites on the walls and off the raster, and varied
angles and scales (a direction field and a density)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from compact_distributions.backends.numpy_backend import NumpyBackend
from compact_distributions.cvt.errors import BackendUnavailable, InputError
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.moments import moments_from_labels
from compact_distributions.cvt.mosaic.pipeline import WalledBackend, make_mosaic, split_cells, split_moments
from compact_distributions.cvt.problem import Grid

from .test_mosaic_edges import flood_fill_split, hand_moments

FIELDS = ("count", "sx", "sy", "sxx", "syy")


def as_array(mom):
    return np.stack([getattr(mom, f) for f in FIELDS])


def walled_case(name, seed, w=251, h=189, n=400):
    """Sites, angles, scales, metric and a region with walls: straight lines drawn across
    the raster and short ones that end inside cells, 1 px wide, some sites on them."""
    rng = np.random.default_rng(seed)
    mask = np.ones((h, w), dtype=bool)
    for k in range(14):
        a = rng.random(2) * [w, h]
        b = a + (rng.random(2) - 0.5) * ([2 * w, 2 * h] if k < 7 else [40, 40])
        t = np.linspace(0, 1, int(np.hypot(*(b - a)) * 2) + 2)[:, None]
        xs, ys = (a + t * (b - a)).T
        keep = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
        mask[ys[keep].astype(int), xs[keep].astype(int)] = False
    sites = rng.random((n, 2)) * [w, h]
    wi, wj = np.nonzero(~mask)
    on_wall = rng.choice(len(wi), 20, replace=False)
    sites[:20] = np.stack([wj[on_wall], wi[on_wall]], axis=1) + 0.5
    sites[20] = (-3.0, h + 2.0)  # off the raster: its pixel is clamped to a corner
    angles = rng.random(n) * 2 * np.pi
    scales = 0.4 + 1.6 * rng.random(n)
    return sites, dict(angles=angles, scales=scales, metric=make_metric(name, 0.5), grid=Grid(w, h, mask))


def test_the_host_path_needs_no_device_path():
    """The NumPy backend has no path of its own: WalledBackend splits its labels."""
    sites, args = walled_case("l2", seed=1, w=60, h=50, n=30)
    numpy = NumpyBackend()
    assert numpy.walled_moments(sites, **args) is None
    labels = numpy.label(sites, **args)
    want = flood_fill_split(labels, sites)
    np.testing.assert_array_equal(
        as_array(WalledBackend(numpy).moments(sites, **args)), hand_moments(want, 30)
    )


def test_bad_sites_are_an_input_error():
    sites, args = walled_case("l2", seed=1, w=60, h=50, n=30)
    sites[3, 0] = np.nan
    with pytest.raises(InputError):
        NumpyBackend().walled_moments(sites, **args)


# ------------------------------------------------------------------------- OpenCL

try:
    from compact_distributions.backends import opencl as opencl_module
    from compact_distributions.backends.opencl import OpenCLBackend

    OpenCLBackend.probe()
    OPENCL = None
except BackendUnavailable as exc:
    OPENCL = str(exc)
needs_opencl = pytest.mark.skipif(OPENCL is not None, reason=f"OpenCL backend unavailable: {OPENCL}")


@needs_opencl
@pytest.mark.parametrize(
    "split, block",
    [(False, 8), (True, 8), (False, 0), (True, 0), (False, 16), (False, 4)],
    ids=["native", "split32", "pixels", "pixels-split32", "blocks16", "blocks4"],
)
@pytest.mark.parametrize("name", ["l2", "linf", "triangle"])
def test_device_path_equals_the_host_split_of_the_device_labels(name, split, block):
    ocl = OpenCLBackend(split_atomics=split, block=block)
    try:
        for seed in range(3):
            sites, args = walled_case(name, seed)
            labels = ocl.label(sites, **args)
            got = WalledBackend(ocl).moments(sites, **args)
            cut = split_cells(labels, sites)
            want = moments_from_labels(cut, len(sites))
            np.testing.assert_array_equal(as_array(got), as_array(want))
            np.testing.assert_array_equal(as_array(split_moments(labels, sites)), as_array(want))
            # the case is what it claims: cells in pieces, several in three or more
            pieces = [ndimage.label(labels == c)[1] for c in range(len(sites))]
            assert sum(p > 1 for p in pieces) >= 10 and sum(p > 2 for p in pieces) >= 2
            assert not np.array_equal(cut, labels)
    finally:
        ocl.close()


@needs_opencl
@pytest.mark.parametrize("block", [8, 16])
def test_the_label_kernel_leaves_which_pixels_have_the_label_below(block):
    """The block kernel's bits for row_runs: bit x of row y is whether pixel (x, y) has
    the label of pixel (x, y + 1), on every row whose next row is in the same block (the
    others row_runs reads from the labels), for the pixels of the raster."""
    sites, args = walled_case("linf", seed=4, w=203, h=77)
    with OpenCLBackend(block=block) as ocl:
        assert ocl._bits_period() == block
        ocl.walled_moments(sites, **args)
        labels = ocl.label(sites, **args)
        words = -(-203 // 64)
        bits = np.empty((77, words), dtype=np.uint64)
        ocl._read(bits, ocl._buffers["below_bits"])
    got = np.unpackbits(bits.view(np.uint8), axis=1, bitorder="little")[:, :203].astype(bool)
    want = labels[:-1] == labels[1:]
    inside = np.arange(76) % block != block - 1
    assert inside.sum() >= 60 and not want[inside].all() and want[inside].any()
    np.testing.assert_array_equal(got[:-1][inside], want[inside])


@needs_opencl
def test_bad_sites_are_an_input_error_on_the_device_path():
    sites, args = walled_case("l2", seed=1, w=60, h=50, n=30)
    sites[3, 1] = np.inf
    with OpenCLBackend() as ocl, pytest.raises(InputError):
        ocl.walled_moments(sites, **args)


def run_ends(labels, cell):
    """Top and bottom runs of a cell: runs with no pixel of the cell straight above,
    straight below (counted pixel by pixel)."""
    h, w = labels.shape
    tops = bottoms = 0
    for i in range(h):
        j = 0
        while j < w:
            if labels[i, j] != cell:
                j += 1
                continue
            e = j
            while e < w and labels[i, e] == cell:
                e += 1
            tops += not (i > 0 and (labels[i - 1, j:e] == cell).any())
            bottoms += not (i + 1 < h and (labels[i + 1, j:e] == cell).any())
            j = e
    return tops, bottoms


def runs_of(labels):
    """(first pixel, length, label) of every run of the region, row by row (NumPy)."""
    h, w = labels.shape
    left = np.concatenate([np.full((h, 1), -2), labels[:, :-1]], axis=1)
    right = np.concatenate([labels[:, 1:], np.full((h, 1), -2)], axis=1)
    first = np.flatnonzero((labels >= 0) & (labels != left))
    last = np.flatnonzero((labels >= 0) & (labels != right))
    return {(int(p), int(q - p + 1), int(labels.flat[p])) for p, q in zip(first, last, strict=True)}


@needs_opencl
@pytest.mark.parametrize("cap", [None, 5], ids=["room", "cut short"])
@pytest.mark.parametrize("group", [None, 7], ids=["group", "padded"])
@pytest.mark.parametrize("width", [700, 512, 37])
def test_device_runs_and_their_top_and_bottom_counts_are_numpy_s(width, group, cap, monkeypatch):
    """row_runs reads a row in windows of 64 labels (16 at a time): runs of 1 to 600 px
    (within a window, across windows, to the row's end), outside pixels, widths a
    multiple of 64 or not.  It
    reports the most runs of any row, its per-cell top and bottom counts are those counted
    pixel by pixel, and suspect_runs leaves at the front of each row's slots NumPy's runs
    of that row of the cells with more than one of each (all but a block), in raster
    order, each its own piece; also where the work-groups pad the rows, and where a row
    has more runs than slots (those past them are not listed)."""
    if group is not None:
        monkeypatch.setattr(opencl_module, "WALL_GROUP", group)
    rng = np.random.default_rng(width)
    h, n = 40, 7
    lengths = [v for v in (1, 2, 5, 15, 16, 17, 40, 63, 64, 65, 300, 600) if v < width]
    rows = []
    for _ in range(h):
        row = []
        while len(row) < width:
            row += [int(rng.integers(-1, n - 1))] * int(rng.choice(lengths))
        rows.append(row[:width])
    labels = np.array(rows, dtype=np.int32)
    labels[5:15, 3:30] = n - 1  # one block: one top and one bottom run
    want = sorted(runs_of(labels))
    per_row = [[r for r in want if r[0] // width == i] for i in range(h)]
    most = max(len(r) for r in per_row)
    cap = most if cap is None else cap
    assert most > 5 and min(len(r) for r in per_row) < 5  # rows cut short and rows not
    with OpenCLBackend() as ocl:
        buf = ocl._upload("labels_under_test", labels)
        counts_buf, kept_buf, (pos_buf, label_buf), parent_buf, ends_buf, _ = ocl._suspect_runs(
            make_metric("l2"), buf, width, h, n, cap
        )
        counts, kept = np.empty(1, dtype=np.uint32), np.empty(h, dtype=np.uint32)
        pos, label = np.empty((h, cap, 2), dtype=np.int32), np.empty((h, cap), dtype=np.int32)
        parent, ends = np.empty((h, cap), dtype=np.int32), np.empty((n, 2), dtype=np.uint32)
        for out, src in ((counts, counts_buf), (kept, kept_buf), (pos, pos_buf), (label, label_buf)):
            ocl._read(out, src)
        for out, src in ((parent, parent_buf), (ends, ends_buf)):
            ocl._read(out, src)
    assert counts[0] == most
    np.testing.assert_array_equal(ends, [run_ends(labels, c) for c in range(n)])
    suspect = [c for c in range(n) if min(run_ends(labels, c)) > 1]
    assert n - 1 not in suspect and len(suspect) >= 3
    for i in range(h):
        listed = [(int(p), int(q), int(c)) for (p, q), c in zip(pos[i], label[i], strict=True)][: kept[i]]
        assert listed == [r for r in per_row[i][:cap] if r[2] in suspect], i
        np.testing.assert_array_equal(parent[i, : kept[i]], i * cap + np.arange(kept[i]))


@needs_opencl
def test_a_cell_that_may_be_in_pieces_and_is_not_keeps_all_its_pixels():
    """Two cups in one cell, one open below and one open above: two top and two bottom
    runs, so the device looks for its pieces, and finds one."""
    w, h = 120, 90
    mask = np.ones((h, w), dtype=bool)
    mask[30, 10:30] = mask[30:36, 10] = mask[30:36, 29] = False  # open below
    mask[60, 35:51] = mask[55:61, 35] = mask[55:61, 50] = False  # open above
    grid, l2 = Grid(w, h, mask), make_metric("l2")
    sites = np.array([[30.0, 45.0], [90.0, 45.0]])
    with OpenCLBackend() as ocl:
        labels = ocl.label(sites, metric=l2, grid=grid)
        got = ocl.walled_moments(sites, metric=l2, grid=grid)
    assert run_ends(labels, 0) == (2, 2) and ndimage.label(labels == 0)[1] == 1
    np.testing.assert_array_equal(as_array(got), hand_moments(labels, 2))


@needs_opencl
def test_rows_with_more_runs_than_slots_are_asked_for_again(monkeypatch):
    """Eight slots a row to begin with (not the backend's guess): the rows have more
    runs, so the step labels again with as many slots as the most a row had, and more."""
    monkeypatch.setattr(OpenCLBackend, "_row_slots", lambda self, w, n, area: min(w, max(self._row_room, 8)))
    sites, args = walled_case("l2", seed=2)
    with OpenCLBackend() as ocl:
        got = WalledBackend(ocl).moments(sites, **args)
        labels = ocl.label(sites, **args)
        most = max(len({p for p, _, _ in runs_of(labels[i : i + 1])}) for i in range(labels.shape[0]))
        assert most > 8 and ocl._row_room == most + most // 4
    want = split_moments(labels, sites)
    np.testing.assert_array_equal(as_array(got), as_array(want))


@needs_opencl
def test_a_walled_mosaic_has_the_same_sites_on_either_path(monkeypatch):
    """Lloyd iterations of a walled mosaic (density, field, walls from the picture's
    edges) land on identical sites whether OpenCL lists the runs or the host reads its
    labels."""
    from compact_distributions.bench.commands.mosaic import SAMPLES_DIR

    with OpenCLBackend() as ocl:
        run = dict(n_elements=600, size=256, iterations=4, method="ours")
        fast = make_mosaic(SAMPLES_DIR / "scene.jpg", ocl, **run)
        monkeypatch.setattr(OpenCLBackend, "_walled_moments", lambda self, *a: None)
        host = make_mosaic(SAMPLES_DIR / "scene.jpg", ocl, **run)
    assert fast.problem.grid.mask is not None and not fast.problem.grid.mask.all()
    np.testing.assert_array_equal(fast.sites, host.sites)


@needs_opencl
def test_pieces_join_walks_rows_without_kept_runs_and_tall_cells():
    """pieces_join works a row each: rows without any run of a cell that may be in
    pieces (wall rows across the whole raster), cells taller than a work-group of rows,
    a raster whose height is not a multiple of it.  The moments are the host split's."""
    w, h = 90, 150
    mask = np.ones((h, w), dtype=bool)
    mask[70, :] = False  # a wall row: no runs on it
    mask[20:130, 45] = False  # a wall that ends inside cells: U-shaped cells around its ends
    mask[40, 10:80] = False
    sites = np.array([[20.0, 30.0], [70.0, 30.0], [45.0, 20.0], [45.0, 120.0], [20.0, 100.0], [45.0, 70.0]])
    l2 = make_metric("l2")
    grid = Grid(w, h, mask)
    with OpenCLBackend() as ocl:
        labels = ocl.label(sites, metric=l2, grid=grid)
        got = ocl.walled_moments(sites, metric=l2, grid=grid)
    cut = split_cells(labels, sites)
    assert not np.array_equal(cut, labels) and (labels[70] < 0).all()
    np.testing.assert_array_equal(as_array(got), hand_moments(cut, len(sites)))
