"""Seeding by region and density; size and direction fields sampled at the sites."""

import math

import numpy as np
import pytest

from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.fields import DensityMap, DirectionField
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.problem import Grid, Problem
from compact_distributions.cvt.seeding import initial_sites, region_pixels


def test_uniform_seeding_stays_in_region_and_is_deterministic():
    mask = np.zeros((60, 80), bool)
    mask[10:50, 20:70] = True
    p = Problem(Grid(80, 60, mask), 300, make_metric("l2"), seed=9)
    s = initial_sites(p)
    assert s.shape == (300, 2)
    j, i = np.floor(s).astype(int).T
    assert mask[i, j].all()
    np.testing.assert_array_equal(s, initial_sites(p))
    assert len(np.unique(np.floor(s), axis=0)) == 300  # one site per pixel at most


def test_density_seeding_follows_density():
    dens = np.ones((100, 100))
    dens[:, 50:] = 9.0  # right half nine times denser
    p = Problem(Grid(100, 100), 1000, make_metric("l2"), density=DensityMap(dens), seed=1)
    s = initial_sites(p)
    right = (s[:, 0] >= 50).mean()
    assert 0.85 < right < 0.95  # expected 0.9


def test_density_scales_smaller_where_denser():
    dens = np.ones((10, 20))
    dens[:, 10:] = 4.0
    d = DensityMap(dens)
    s = d.scales_at(np.array([[2.5, 5.0], [15.5, 5.0]]))
    assert s[0] == pytest.approx(2 * s[1])  # area ∝ 1/density -> side ∝ density^-1/2


def test_all_zero_or_negative_density_is_rejected():
    with pytest.raises(InputError, match="all zero"):
        DensityMap(np.zeros((4, 4)))
    with pytest.raises(InputError, match="non-negative"):
        DensityMap(-np.ones((4, 4)))


def test_named_fields():
    pts = np.array([[75.0, 50.0], [50.0, 75.0]])
    f = DirectionField.named("radial", 100, 100)
    np.testing.assert_allclose(f.angles_at(pts), [0.0, math.pi / 2])
    f = DirectionField.named("circular", 100, 100)
    np.testing.assert_allclose(f.angles_at(pts), [math.pi / 2, math.pi])
    f = DirectionField.named("constant:45", 100, 100)
    np.testing.assert_allclose(f.angles_at(pts), math.pi / 4)
    with pytest.raises(InputError):
        DirectionField.named("wave:-3", 10, 10)


def test_angles_are_reread_at_new_positions():
    from compact_distributions.backends.numpy_backend import NumpyBackend
    from compact_distributions.cvt.lloyd import lloyd

    p = Problem(Grid(96, 96), 40, make_metric("linf"), field=DirectionField.named("radial", 96, 96))
    res = lloyd(p, NumpyBackend(), 3)
    want = np.arctan2(res.sites[:, 1] - 48, res.sites[:, 0] - 48)
    np.testing.assert_allclose(res.angles, want)
    assert not np.allclose(res.initial_sites, res.sites)


def test_problem_validation():
    with pytest.raises(InputError, match="do not fit"):
        Problem(Grid(4, 4), 17)
    with pytest.raises(InputError, match=">= 1"):
        Problem(Grid(4, 4), 0)
    with pytest.raises(InputError, match="is empty"):
        Grid(4, 4, np.zeros((4, 4), bool))
    with pytest.raises(InputError, match="outside"):
        Problem(Grid(10, 10), 1, init_sites=np.array([[11.0, 2.0]]))


def _seeded_over_listed_pixels(problem: Problem) -> np.ndarray:
    """The seeding written over the list of every region pixel and every pixel's
    acceptance (density / max): the draws ``initial_sites`` documents, made the plain way."""
    grid, n = problem.grid, problem.n_elements
    rng = np.random.default_rng(problem.seed)
    inside = np.flatnonzero(np.ones(grid.width * grid.height, bool) if grid.mask is None else grid.mask)
    if problem.density is None:
        picks = rng.choice(inside, size=n, replace=False)
    else:
        values = problem.density.values
        accept = (values / values.max()).ravel()[inside]
        chosen = np.empty(0, dtype=np.int64)
        while len(chosen) < n:
            batch = rng.choice(len(inside), size=max(4 * n, 1024))
            chosen = np.concatenate([chosen, batch[rng.random(len(batch)) < accept[batch]]])
            _, first = np.unique(chosen, return_index=True)
            chosen = chosen[np.sort(first)]
            if len(chosen) < n and (accept > 0).sum() < n:  # then every other pixel, shuffled
                chosen = np.concatenate(
                    [chosen, rng.permutation(np.setdiff1d(np.arange(len(inside)), chosen))]
                )
        picks = inside[chosen[:n]]
    i, j = np.divmod(picks, grid.width)
    jitter = rng.random((n, 2))
    return np.stack([j + jitter[:, 0], i + jitter[:, 1]], axis=1)


@pytest.mark.parametrize("region", ["none", "most", "little"])
@pytest.mark.parametrize("density", ["none", "positive", "zeros", "few"])
def test_seeding_draws_as_over_the_listed_region_pixels(region, density):
    rng = np.random.default_rng(5)
    h, w = 90, 130
    mask = {"none": None, "most": rng.random((h, w)) > 0.1, "little": rng.random((h, w)) < 0.2}[region]
    values = {
        "none": None,
        "positive": 0.05 + rng.random((h, w)),
        "zeros": np.where(rng.random((h, w)) < 0.5, 0.0, rng.random((h, w))),  # zero on about half
        "few": np.where(rng.random((h, w)) < 0.02, 1.0, 0.0),  # fewer positive pixels than sites
    }[density]
    p = Problem(
        Grid(w, h, mask),
        700,
        make_metric("linf"),
        density=None if values is None else DensityMap(values),
        seed=3,
    )
    np.testing.assert_array_equal(initial_sites(p), _seeded_over_listed_pixels(p))


def test_region_pixels_are_the_listed_pixels_of_their_ranks():
    rng = np.random.default_rng(0)
    for _ in range(200):
        h, w = rng.integers(1, 40, 2)
        mask = rng.random((h, w)) < rng.random()
        listed = np.flatnonzero(mask)
        if len(listed) == 0:
            continue
        ranks = rng.integers(0, len(listed), size=rng.integers(1, 300))
        np.testing.assert_array_equal(region_pixels(mask)(ranks), listed[ranks])
