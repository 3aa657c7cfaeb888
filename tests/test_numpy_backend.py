"""The NumPy reference backend against brute force and against an exact Voronoi."""

import numpy as np
import pytest
import shapely
from scipy.spatial import Voronoi

from compact_distributions.backends.numpy_backend import NumpyBackend
from compact_distributions.cvt.lloyd import lloyd
from compact_distributions.cvt.metrics import METRIC_NAMES, compile_sites, make_metric
from compact_distributions.cvt.moments import moments_from_labels
from compact_distributions.cvt.problem import Grid, Problem


def brute_force(sites, angles, scales, metric, grid):
    co = compile_sites(metric, sites, angles, scales)
    ys, xs = np.mgrid[0 : grid.height, 0 : grid.width] + 0.5
    d = co.distance(np.arange(len(sites))[None, None, :], xs[..., None], ys[..., None])
    lab = d.argmin(axis=2).astype(np.int32)  # first minimum: ties to the lower index
    if grid.mask is not None:
        lab[~grid.mask] = -1
    return lab


def disc_mask(w, h):
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    return (xs - w / 2) ** 2 + (ys - h / 2) ** 2 < (0.45 * min(w, h)) ** 2


@pytest.mark.parametrize("name", METRIC_NAMES)
@pytest.mark.parametrize("varied", [False, True])
def test_labels_equal_brute_force(name, varied):
    rng = np.random.default_rng(7)
    w, h, n = 123, 97, 60
    sites = rng.random((n, 2)) * [w, h]
    angles = rng.random(n) * 2 * np.pi if varied else None
    scales = 0.4 + 1.2 * rng.random(n) if varied else None
    grid = Grid(w, h, disc_mask(w, h) if varied else None)
    metric = make_metric(name, 0.6)
    got = NumpyBackend().label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    want = brute_force(sites, angles, scales, metric, grid)
    assert got.dtype == np.int32 and got.shape == (h, w)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("tile", [4, 16, 33])
def test_tile_size_does_not_change_labels(tile):
    rng = np.random.default_rng(8)
    sites = rng.random((200, 2)) * 150
    metric = make_metric("linf")
    ref = brute_force(sites, None, None, metric, Grid(150, 150))
    got = NumpyBackend(tile=tile).label(sites, metric=metric, grid=Grid(150, 150))
    np.testing.assert_array_equal(got, ref)


def test_ties_go_to_the_lower_index():
    # two sites at the same place tie everywhere; the lower index must win
    sites = np.array([[20.0, 20.0], [10.0, 10.0], [10.0, 10.0]])
    lab = NumpyBackend().label(sites, metric=make_metric("l1"), grid=Grid(40, 40))
    assert 2 not in lab and (lab == 1).any()
    # L∞ with sites mirrored about x = 20: pixel centres on x = 20.5 vs 19.5 are not ties,
    # but diagonal ties exist; compare to the brute force rule on them
    sites = np.array([[10.0, 20.0], [30.0, 20.0], [20.0, 10.0]])
    g = Grid(41, 41)
    np.testing.assert_array_equal(
        NumpyBackend().label(sites, metric=make_metric("linf"), grid=g),
        brute_force(sites, None, None, make_metric("linf"), g),
    )


def exact_voronoi_centroids(sites, w, h):
    """Centroids of the exact l2 Voronoi cells clipped to the raster box (shapely)."""
    far = 10 * max(w, h)
    pts = np.vstack([sites, [[-far, -far], [-far, far], [far, -far], [far, far]]])
    vor = Voronoi(pts)
    box = shapely.box(0, 0, w, h)
    out = np.empty_like(sites)
    for i in range(len(sites)):
        region = vor.regions[vor.point_region[i]]
        assert -1 not in region
        cell = shapely.Polygon(vor.vertices[region]).intersection(box)
        out[i] = [cell.centroid.x, cell.centroid.y]
    return out


def test_one_lloyd_step_matches_exact_voronoi_at_512():
    rng = np.random.default_rng(11)
    sites = rng.random((400, 2)) * 512
    grid = Grid(512, 512)
    labels = NumpyBackend().label(sites, metric=make_metric("l2"), grid=grid)
    raster = moments_from_labels(labels, len(sites)).centroids(sites)
    exact = exact_voronoi_centroids(sites, 512, 512)
    err = np.hypot(*(raster - exact).T)
    assert err.max() < 0.5, err.max()
    assert err.mean() < 0.1


@pytest.mark.parametrize("name", ["l2", "linf", "triangle"])
def test_energy_falls_and_sites_stay_in_raster(name):
    p = Problem(Grid(200, 160), 150, make_metric(name), seed=3)
    res = lloyd(p, NumpyBackend(), 12)
    e = np.array(res.energy)
    if name == "l2":  # Lloyd is a descent method for the l2 energy
        assert (np.diff(e) <= 1e-9 * e[0]).all(), e
    assert e[-1] < 0.8 * e[0]
    assert (res.sites >= 0).all() and (res.sites[:, 0] <= 200).all() and (res.sites[:, 1] <= 160).all()


def test_same_seed_same_result_and_other_seed_differs():
    def go(seed):
        p = Problem(Grid(128, 128), 80, make_metric("l1"), seed=seed)
        return lloyd(p, NumpyBackend(), 5).sites

    np.testing.assert_array_equal(go(5), go(5))
    assert not np.array_equal(go(5), go(6))


def test_empty_cell_site_stays_put_and_is_reported():
    # site 1 duplicates site 0: it loses every tie, its cell is empty
    sites = np.array([[30.0, 30.0], [30.0, 30.0], [90.0, 70.0]])
    p = Problem(Grid(128, 100), 3, make_metric("l2"), init_sites=sites)
    res = lloyd(p, NumpyBackend(), 1)
    assert res.empty == [1] and res.empty_sites == [1]
    np.testing.assert_array_equal(res.sites[1], [30.0, 30.0])


def test_moments_are_integer_sums():
    labels = np.array([[0, 0, 1], [-1, 1, 1]], dtype=np.int32)
    m = moments_from_labels(labels, 3)
    assert m.count.tolist() == [2, 3, 0]
    assert m.sx.tolist() == [1, 1 + 2 + 2, 0] and m.sy.tolist() == [0, 0 + 1 + 1, 0]
    assert m.sxx.tolist() == [1, 1 + 4 + 4, 0]
    c = m.centroids(np.array([[9.0, 9.0], [9.0, 9.0], [4.0, 5.0]]))
    np.testing.assert_allclose(c, [[1.0, 0.5], [5 / 3 + 0.5, 2 / 3 + 0.5], [4.0, 5.0]])
