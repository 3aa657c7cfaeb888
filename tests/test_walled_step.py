"""The walled Lloyd step's device path against the host's: a backend that lists the runs
of the cells that may be in pieces (``moments_with_runs``, OpenCL) must give moments
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
from compact_distributions.cvt.mosaic import (
    WalledBackend,
    kept_pieces,
    label_runs,
    make_mosaic,
    split_cells,
    split_moments,
    split_moments_from_runs,
)
from compact_distributions.cvt.problem import Grid

from .test_mosaic_edges import flood_fill_split, hand_moments, random_cells

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


def test_kept_pieces_match_a_flood_fill_on_the_runs_of_split_cells():
    """kept_pieces alone, on runs in a shuffled order, against the flood fill."""
    rng = np.random.default_rng(5)
    for _ in range(300):
        labels, sites = random_cells(rng)
        _, _, start, end, lab = label_runs(labels)
        inside = np.flatnonzero(lab >= 0)
        if len(inside) == 0:
            continue
        shuffle = rng.permutation(inside)
        kept = kept_pieces(
            start[shuffle], end[shuffle], lab[shuffle], sites, labels.shape[1], labels.shape[0]
        )
        want = flood_fill_split(labels, sites).ravel()
        np.testing.assert_array_equal(kept, want[start[shuffle]] >= 0)


def test_kept_pieces_of_no_runs_is_empty():
    none = np.zeros(0, dtype=np.int64)
    assert kept_pieces(none, none, none, np.zeros((3, 2)), 4, 4).shape == (0,)


def test_a_cells_last_row_and_the_next_cells_first_row_do_not_touch():
    """Runs of cell 0 in the last row and of cell 1 in row 0 share columns; they are
    different cells, so cell 1's two pieces stay two (its site keeps the right one)."""
    labels = np.array([[1, 1, -1, 1], [0, 0, 0, 0], [0, 0, 0, 0]], dtype=np.int32)
    sites = np.array([[1.5, 2.5], [3.5, 0.5]])
    np.testing.assert_array_equal(split_cells(labels, sites)[0], [-1, -1, -1, 1])


def test_the_host_path_needs_no_device_runs():
    """The NumPy backend has no device path: WalledBackend reads its labels."""
    sites, args = walled_case("l2", seed=1, w=60, h=50, n=30)
    numpy = NumpyBackend()
    assert numpy.moments_with_runs(sites, **args) is None
    labels = numpy.label(sites, **args)
    want = flood_fill_split(labels, sites)
    np.testing.assert_array_equal(
        as_array(WalledBackend(numpy).moments(sites, **args)), hand_moments(want, 30)
    )


def test_bad_sites_are_an_input_error():
    sites, args = walled_case("l2", seed=1, w=60, h=50, n=30)
    sites[3, 0] = np.nan
    with pytest.raises(InputError):
        NumpyBackend().moments_with_runs(sites, **args)


def test_no_runs_leaves_the_moments_as_they_are():
    mom = moments_from_labels(np.array([[0, 1], [1, -1]]), 2)
    none = np.zeros(0, dtype=np.int64)
    got = split_moments_from_runs(mom, (none, none, none), np.zeros((2, 2)), 2, 2)
    np.testing.assert_array_equal(as_array(got), as_array(mom))


# ------------------------------------------------------------------------- OpenCL

try:
    from compact_distributions.backends.opencl import OpenCLBackend

    OpenCLBackend.probe()
    OPENCL = None
except BackendUnavailable as exc:
    OPENCL = str(exc)
needs_opencl = pytest.mark.skipif(OPENCL is not None, reason=f"OpenCL backend unavailable: {OPENCL}")


@needs_opencl
@pytest.mark.parametrize("block", [8, 0], ids=["blocks", "pixels"])
@pytest.mark.parametrize("split", [False, True], ids=["native", "split32"])
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
def test_device_runs_are_every_run_of_each_cell_that_may_be_in_pieces():
    """The runs listed are exactly the row runs of some cells; every cell in pieces is
    among them, and some that are one piece are left out."""
    sites, args = walled_case("linf", seed=4)
    with OpenCLBackend() as ocl:
        labels = ocl.label(sites, **args)
        mom, (start, end, lab) = ocl.moments_with_runs(sites, **args)
    np.testing.assert_array_equal(as_array(mom), as_array(moments_from_labels(labels, len(sites))))
    listed = np.unique(lab)
    _, _, all_start, all_end, all_lab = label_runs(labels)
    of_listed = np.isin(all_lab, listed)
    order = np.argsort(start)
    np.testing.assert_array_equal(start[order], all_start[of_listed])
    np.testing.assert_array_equal(end[order], all_end[of_listed])
    np.testing.assert_array_equal(lab[order], all_lab[of_listed])
    pieces = np.array([ndimage.label(labels == c)[1] for c in range(len(sites))])
    assert np.isin(np.flatnonzero(pieces > 1), listed).all()
    assert len(listed) < (pieces > 0).sum()


@needs_opencl
def test_more_runs_than_the_buffer_holds_are_asked_for_again():
    sites, args = walled_case("l2", seed=2)
    with OpenCLBackend() as ocl:
        ocl._run_room = 8
        got = WalledBackend(ocl).moments(sites, **args)
        assert ocl._run_room > 8
        want = split_moments(ocl.label(sites, **args), sites)
    np.testing.assert_array_equal(as_array(got), as_array(want))


@needs_opencl
def test_a_walled_mosaic_has_the_same_sites_on_either_path(monkeypatch):
    """Lloyd iterations of a walled mosaic (density, field, walls from the picture's
    edges) land on identical sites whether OpenCL lists the runs or the host reads its
    labels."""
    from compact_distributions.bench.mosaic_cmd import SAMPLES_DIR

    with OpenCLBackend() as ocl:
        run = dict(n_elements=600, size=256, iterations=4, method="ours")
        fast = make_mosaic(SAMPLES_DIR / "scene.jpg", ocl, **run)
        monkeypatch.setattr(OpenCLBackend, "_moments_with_runs", lambda self, *a: None)
        host = make_mosaic(SAMPLES_DIR / "scene.jpg", ocl, **run)
    assert fast.problem.grid.mask is not None and not fast.problem.grid.mask.all()
    np.testing.assert_array_equal(fast.sites, host.sites)
