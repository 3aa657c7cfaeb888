"""Property-based checks (hypothesis) of the definitions every backend relies on."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from compact_distributions.backends.numpy_backend import NumpyBackend
from compact_distributions.cvt.metrics import METRIC_NAMES, compile_sites, make_metric
from compact_distributions.cvt.problem import Grid

metrics = st.sampled_from(METRIC_NAMES)
aspects = st.floats(0.2, 1.0)
vectors = st.tuples(st.floats(-50, 50), st.floats(-50, 50))


@given(metrics, aspects, vectors, vectors)
def test_gauge_is_a_convex_norm_like_function(name, aspect, u, v):
    """Triangle inequality and positive homogeneity: what makes the cells star-shaped
    around their sites and the pruning bounds valid."""
    m = make_metric(name, aspect)
    u, v = np.array(u), np.array(v)
    assert m.gauge(u + v) <= m.gauge(u) + m.gauge(v) + 1e-9
    assert np.isclose(m.gauge(2.5 * u), 2.5 * m.gauge(u))


@settings(max_examples=25, deadline=None)
@given(metrics, aspects, st.integers(1, 30), st.integers(0, 2**31 - 1), st.booleans())
def test_reference_labels_equal_brute_force(name, aspect, n, seed, varied):
    rng = np.random.default_rng(seed)
    w, h = 41, 29
    sites = rng.random((n, 2)) * [w, h]
    angles = rng.random(n) * 6.3 if varied else None
    scales = 0.3 + 2 * rng.random(n) if varied else None
    metric = make_metric(name, aspect)
    got = NumpyBackend().label(sites, angles=angles, scales=scales, metric=metric, grid=Grid(w, h))
    co = compile_sites(metric, sites, angles, scales)
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    d = co.distance(np.arange(n)[None, None, :], xs[..., None], ys[..., None])
    np.testing.assert_array_equal(got, d.argmin(axis=2))
