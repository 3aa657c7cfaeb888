"""Every registered backend against the NumPy reference, on the same inputs.

One parametrised suite: labels (six metrics, with and without angles, scales and a
region mask), ties, moments, the keyword-only call and the input checks of the base
class.  Where labels differ from the reference, the difference must be a tie: the
backend's site must be as near to the pixel as the reference's, under the reference's
own float64 distance (up to float32 rounding; the GL cone mode also up to its
tessellation error).  A backend whose runtime is missing is skipped with its reason; a
case a backend does not compute (cKDTree: l2, l1 and linf only) is skipped with the
reason the backend gives.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely

from compact_distributions.backends import REFERENCE, create_backend, variant_names, variant_status
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.metrics import METRIC_NAMES, compile_sites, make_metric
from compact_distributions.cvt.moments import moments_from_labels
from compact_distributions.cvt.problem import Grid

STATUS = variant_status()
OTHERS = [v for v in variant_names() if v != REFERENCE]
# distance slack where a label may differ from the reference (distance units, px at s=1)
SLACK = {"gl-cone": 0.12}
W, H, N = 96, 80, 60


@pytest.fixture(scope="module", params=OTHERS)
def backend(request):
    ok, text = STATUS[request.param]
    if not ok:
        pytest.skip(f"backend {request.param} unavailable: {text}")
    with create_backend(request.param) as b:
        yield b


def case(metric_name: str, variant_kind: str, seed: int = 3):
    rng = np.random.default_rng(seed)
    sites = rng.random((N, 2)) * [W, H]
    angles = rng.uniform(-np.pi, np.pi, N) if "angles" in variant_kind else np.zeros(N)
    scales = rng.uniform(0.6, 1.6, N) if "scales" in variant_kind else np.ones(N)
    mask = None
    if "mask" in variant_kind:
        yy, xx = np.mgrid[0:H, 0:W] + 0.5
        mask = np.hypot(xx - W / 2, yy - H / 2) < 0.45 * H
    return sites, angles, scales, make_metric(metric_name), Grid(W, H, mask)


def supported_or_skip(backend, metric, angles, scales):
    reason = backend.supports(metric, angles, scales)
    if reason is not None:
        pytest.skip(f"{backend.variant}: {reason}")


def assert_same_up_to_ties(got, want, sites, angles, scales, metric, grid, slack):
    assert got.shape == want.shape and got.dtype == np.int32
    assert np.array_equal(got < 0, want < 0), "the region differs"
    i, j = np.nonzero(got != want)
    if len(i) == 0:
        return
    coef = compile_sites(metric, sites, angles, scales)
    x, y = j + 0.5, i + 0.5
    d_got = coef.distance(got[i, j], x, y)
    d_want = coef.distance(want[i, j], x, y)
    excess = d_got - d_want
    assert excess.max() <= slack + 1e-5 * max(1.0, float(d_want.max())), (
        f"{len(i)} pixels differ, up to {excess.max():.3g} farther than the nearest site"
    )
    assert len(i) <= 0.005 * want.size


KINDS = ["plain", "angles", "scales", "angles+scales+mask"]


@pytest.mark.parametrize("metric_name", METRIC_NAMES)
@pytest.mark.parametrize("kind", KINDS)
def test_labels_match_the_reference(backend, reference, metric_name, kind):
    sites, angles, scales, metric, grid = case(metric_name, kind)
    supported_or_skip(backend, metric, angles, scales)
    got = backend.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    want = reference.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    assert_same_up_to_ties(got, want, sites, angles, scales, metric, grid, SLACK.get(backend.variant, 0.0))


@pytest.fixture(scope="module")
def users_polygon(tmp_path_factory):
    """A generated irregular convex polygon, given as a user gives one: the hull of seeded
    random points, written as a JSON list of vertices (``--element polygon:FILE``)."""
    rng = np.random.default_rng(11)
    ring = np.asarray(shapely.MultiPoint(rng.normal(size=(12, 2)) * [3.0, 1.7]).convex_hull.exterior.coords)
    ring = ring[:-1]
    assert len(ring) >= 5  # a polygon of its own, not a triangle or a square
    path = tmp_path_factory.mktemp("polygon") / "hull.json"
    path.write_text(json.dumps(ring.tolist()))
    return f"polygon:{path}"


@pytest.mark.parametrize("kind", KINDS)
def test_labels_match_the_reference_on_a_users_polygon(backend, reference, users_polygon, kind):
    sites, angles, scales, metric, grid = case(users_polygon, kind)
    assert not metric.curved and len(metric.normals) >= 5
    supported_or_skip(backend, metric, angles, scales)
    got = backend.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    want = reference.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    assert_same_up_to_ties(got, want, sites, angles, scales, metric, grid, SLACK.get(backend.variant, 0.0))


@pytest.mark.parametrize("metric_name", ["l1", "linf", "l2"])
def test_ties_on_a_lattice(backend, reference, metric_name):
    """Sites on a lattice with whole-pixel spacing: many pixels are exactly equidistant
    from two or four sites; only those may go another way than to the lower index."""
    xs, ys = np.meshgrid(np.arange(8, W, 16) + 0.5, np.arange(8, H, 16) + 0.5)
    sites = np.stack([xs.ravel(), ys.ravel()], axis=1)
    n = len(sites)
    metric, grid = make_metric(metric_name), Grid(W, H)
    angles, scales = np.zeros(n), np.ones(n)
    supported_or_skip(backend, metric, angles, scales)
    got = backend.label(sites, metric=metric, grid=grid)
    want = reference.label(sites, metric=metric, grid=grid)
    coef = compile_sites(metric, sites, angles, scales)
    i, j = np.nonzero(got != want)
    d = coef.distance(got[i, j], j + 0.5, i + 0.5) - coef.distance(want[i, j], j + 0.5, i + 0.5)
    assert np.all(np.abs(d) <= SLACK.get(backend.variant, 0.0) + 1e-6)


@pytest.mark.parametrize("kind", ["plain", "angles+scales+mask"])
def test_moments_are_the_sums_of_its_labels(backend, reference, kind):
    sites, angles, scales, metric, grid = case("l2", kind)
    supported_or_skip(backend, metric, angles, scales)
    args = dict(angles=angles, scales=scales, metric=metric, grid=grid)
    labels = backend.label(sites, **args)
    mom, sums = backend.moments(sites, **args), moments_from_labels(labels, N)
    for field in ("count", "sx", "sy", "sxx", "syy"):
        np.testing.assert_array_equal(getattr(mom, field), getattr(sums, field), err_msg=field)
    assert mom.count.sum() == grid.pixel_count
    ref = reference.moments(sites, **args)
    same = np.all(labels == reference.label(sites, **args))
    if same:  # equal labels give bit-identical centroids
        np.testing.assert_array_equal(mom.centroids(sites), ref.centroids(sites))


def test_calls_are_keyword_only(backend):
    sites, angles, scales, metric, grid = case("l2", "plain")
    with pytest.raises(TypeError):
        backend.label(sites, angles, scales, metric, grid)
    with pytest.raises(TypeError):
        backend.moments(sites, angles, scales, metric, grid)


@pytest.mark.parametrize(
    "change,needle",
    [
        (dict(sites=np.zeros((0, 2))), "sites"),
        (dict(sites=np.array([[1.0, np.nan], [3.0, 4.0]])), "NaN"),
        (dict(angles=np.array([0.0, np.inf])), "angles"),
        (dict(scales=np.array([1.0, -1.0])), "scales"),
        (dict(scales=np.ones(3)), "shape"),
        (dict(metric="l2"), "metric"),
        (dict(grid=(10, 10)), "grid"),
    ],
)
def test_inputs_are_checked_once_for_every_backend(backend, change, needle):
    args = {
        **dict(
            sites=np.array([[2.0, 3.0], [7.0, 5.0]]),
            angles=np.zeros(2),
            scales=np.ones(2),
            metric=make_metric("l2"),
            grid=Grid(10, 10),
        ),
        **change,
    }
    sites = args.pop("sites")
    with pytest.raises(InputError, match=needle):
        backend.label(sites, **args)


def test_the_reference_is_a_context_manager():
    with create_backend(REFERENCE) as b:
        assert b.label(np.array([[1.0, 1.0]]), metric=make_metric("l2"), grid=Grid(4, 4)).max() == 0
