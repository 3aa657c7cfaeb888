"""Each metric's unit ball: gauge 1 on its boundary, bounds, and paper Table 1 sizes."""

import math

import numpy as np
import pytest

from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.metrics import METRIC_NAMES, compile_sites, make_metric


@pytest.mark.parametrize("name", METRIC_NAMES)
@pytest.mark.parametrize("aspect", [0.5, 0.8])
def test_gauge_is_one_on_the_boundary(name, aspect):
    m = make_metric(name, aspect)
    ring = m.outline(512)
    # vertices and edge midpoints of the outline are on the boundary
    mids = (ring + np.roll(ring, -1, axis=0)) / 2
    np.testing.assert_allclose(m.gauge(ring), 1.0, atol=1e-12)
    if not m.curved:
        np.testing.assert_allclose(m.gauge(mids), 1.0, atol=1e-12)
    # homogeneous of degree 1, zero at the origin, positive elsewhere
    v = np.random.default_rng(0).normal(size=(100, 2))
    np.testing.assert_allclose(m.gauge(3.5 * v), 3.5 * m.gauge(v), rtol=1e-12)
    assert m.gauge(np.zeros(2)) == 0
    assert (m.gauge(v) > 0).all()


@pytest.mark.parametrize("name", METRIC_NAMES)
def test_radius_bounds_hold(name):
    m = make_metric(name, 0.6)
    v = np.random.default_rng(1).normal(size=(2000, 2))
    r = np.hypot(*v.T)
    g = m.gauge(v)
    assert (g >= r / m.circumradius - 1e-12).all()
    assert (g <= r / m.inradius + 1e-12).all()


def test_paper_formulas():
    rng = np.random.default_rng(2)
    v = rng.normal(size=(500, 2))
    x, y = np.abs(v[:, 0]), np.abs(v[:, 1])
    np.testing.assert_allclose(make_metric("l2").gauge(v), np.hypot(x, y))
    np.testing.assert_allclose(make_metric("l1").gauge(v), x + y)
    np.testing.assert_allclose(make_metric("linf").gauge(v), np.maximum(x, y))
    b = 0.5  # §3.1.2 and §3.1.3
    np.testing.assert_allclose(make_metric("linf-axial", b).gauge(v), np.maximum(b * x, y / b))
    np.testing.assert_allclose(make_metric("l2-axial", b).gauge(v), np.sqrt(b * b * x * x + y * y / (b * b)))


def test_triangle_is_equilateral_with_centroid_at_origin():
    m = make_metric("triangle")
    verts = m.outline()
    assert len(verts) == 3
    np.testing.assert_allclose(verts.mean(axis=0), 0, atol=1e-12)
    np.testing.assert_allclose(np.hypot(*verts.T), 1.0)  # centroid to vertex = 1
    sides = np.hypot(*(np.roll(verts, -1, axis=0) - verts).T)
    np.testing.assert_allclose(sides, math.sqrt(3))
    assert verts[:, 1].min() == pytest.approx(-1.0)  # one vertex up on screen (y down)


@pytest.mark.parametrize("la", [1.0, 7.5])
def test_table1_geometry(la):
    """Paper Table 1 (bottom size for La, height) from the one definition."""
    cone = make_metric("l2").cone(la)  # circular cone: radius La, height La
    assert cone["geometry"] == "circular cone"
    assert cone["axis_x"] / 2 == pytest.approx(la) and cone["height"] == la
    h = math.sqrt(2) / 2 * la  # Manhattan: square of side La, height √2/2 La
    sq = make_metric("l1").cone(h)
    np.testing.assert_allclose(sq["sides"], la)
    h = la / 2  # Chebyshev: side La, height La/2
    np.testing.assert_allclose(make_metric("linf").cone(h)["sides"], la)
    beta = 0.5  # axial Chebyshev: length La/β, width βLa (height La/2 under §3.1.2's formula)
    rect = make_metric("linf-axial", beta).cone(la / 2)
    assert rect["width"] == pytest.approx(la / beta) and rect["depth"] == pytest.approx(beta * la)
    ell = make_metric("l2-axial", beta).cone(la)  # §3.1.3: β=1/2, radius r -> 4r by r
    assert ell["axis_x"] == pytest.approx(4 * la) and ell["axis_y"] == pytest.approx(la)
    tri = make_metric("triangle").cone(math.sqrt(3) / 3 * la)  # side La, height √3/3 La
    assert tri["geometry"] == "triangular pyramid"
    np.testing.assert_allclose(tri["sides"], la)


@pytest.mark.parametrize("name", METRIC_NAMES)
def test_compiled_coefficients_match_rotated_scaled_gauge(name):
    m = make_metric(name, 0.7)
    rng = np.random.default_rng(3)
    sites = rng.random((20, 2)) * 100
    ang, sc = rng.random(20) * 6.3, 0.5 + rng.random(20)
    co = compile_sites(m, sites, ang, sc)
    x, y = rng.random(20) * 100, rng.random(20) * 100
    d = co.distance(np.arange(20), x, y)
    v = np.stack([x - sites[:, 0], y - sites[:, 1]], axis=1)
    c, s = np.cos(-ang), np.sin(-ang)
    local = np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=1)
    np.testing.assert_allclose(d, m.gauge(local) / sc, rtol=1e-10)
    # the pruning polygon contains the ball: max_k bounds·v <= d
    lower = np.einsum("nkc,nc->nk", co.bounds, v).max(axis=1)
    assert (lower <= d + 1e-9).all()


@pytest.mark.parametrize("bad", [0, -1, float("nan"), float("inf"), "x"])
def test_bad_aspect(bad):
    with pytest.raises(InputError, match="aspect"):
        make_metric("linf-axial", bad)


def test_unknown_metric():
    with pytest.raises(InputError, match="unknown metric 'l3'"):
        make_metric("l3")
