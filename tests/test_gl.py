"""The GL backend (cones and pyramids in a z-buffer, or exact per-fragment distances)
against the NumPy float64 reference, on llvmpipe in CI.

Skipped, with the reason, where moderngl, EGL or an OpenGL 4.3 driver is missing."""

import json

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from compact_distributions.backends import create_backend
from compact_distributions.cvt.errors import BackendUnavailable, InputError
from compact_distributions.cvt.fields import DensityMap, DirectionField
from compact_distributions.cvt.lloyd import final_labels, lloyd
from compact_distributions.cvt.metrics import METRIC_NAMES, make_metric
from compact_distributions.cvt.moments import moments_from_labels
from compact_distributions.cvt.problem import Grid, Problem

from .test_backend_conformance import SLACK, assert_same_up_to_ties

gl = pytest.importorskip("compact_distributions.backends.gl")


def _backend(mode):
    try:
        return gl.GLBackend(mode=mode)
    except BackendUnavailable as exc:
        pytest.skip(str(exc))


@pytest.fixture(scope="module")
def cone():
    b = _backend("cone")
    yield b
    b.close()


@pytest.fixture(scope="module")
def exact():
    b = _backend("exact")
    yield b
    b.close()


def disc_mask(w, h):
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    return (xs - w / 2) ** 2 + (ys - h / 2) ** 2 < (0.47 * min(w, h)) ** 2


def random_case(seed, w=384, h=256, n=300, masked=False):
    rng = np.random.default_rng(seed)
    sites = rng.random((n, 2)) * [w, h]
    angles = rng.random(n) * 2 * np.pi
    scales = 0.6 + 0.8 * rng.random(n)
    grid = Grid(w, h, disc_mask(w, h) if masked else None)
    return sites, scales, angles, grid


def check_region(labels, grid):
    """-1 exactly outside the region: a region pixel that no cone reached is a bug."""
    inside = grid.inside()
    assert labels.dtype == np.int32 and labels.shape == grid.shape
    assert (labels[inside] >= 0).all()
    assert (labels[~inside] == -1).all()


@pytest.mark.parametrize("name", METRIC_NAMES)
@pytest.mark.parametrize("mode, floor", [("exact", 0.999), ("cone", 0.99)])
def test_labels_agree_with_reference(name, mode, floor, cone, exact, reference):
    backend = exact if mode == "exact" else cone
    sites, scales, angles, grid = random_case(METRIC_NAMES.index(name), masked=name in ("l1", "l2-axial"))
    metric = make_metric(name, 0.6)
    got = backend.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    want = reference.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    check_region(got, grid)
    agree = (got == want)[grid.inside()].mean()
    assert agree >= floor, f"{mode} {name}: {agree:.5f} of region pixels agree"
    # moments on the device equal the host sums of the device's own labels, exactly
    mom = backend.moments(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    host = moments_from_labels(got, len(sites))
    for field in ("count", "sx", "sy", "sxx", "syy"):
        np.testing.assert_array_equal(getattr(mom, field), getattr(host, field), err_msg=field)


@pytest.mark.parametrize("name", METRIC_NAMES)
def test_exact_one_lloyd_step_lands_with_reference(name, exact, reference):
    sites, scales, angles, grid = random_case(100 + METRIC_NAMES.index(name), w=256, h=256, n=250)
    metric = make_metric(name, 0.5)
    ours = exact.moments(sites, angles=angles, scales=scales, metric=metric, grid=grid).centroids(sites)
    theirs = reference.moments(sites, angles=angles, scales=scales, metric=metric, grid=grid).centroids(sites)
    gap = np.hypot(*(ours - theirs).T)
    assert gap.max() <= 0.5 and gap.mean() <= 0.01, (gap.max(), gap.mean())


def field_problem(name, n=220, w=256, h=256, seed=3):
    """A problem with a density map (scales 0.7..1.4) and a wave field (angles)."""
    xs = np.linspace(0.0, 1.0, w)[None, :].repeat(h, axis=0)
    density = DensityMap(0.5 + 1.5 * xs)
    field = DirectionField.named("wave:150", w, h)
    return Problem(Grid(w, h), n, make_metric(name), density, field, seed=seed)


@pytest.mark.parametrize("name", METRIC_NAMES)
def test_cone_twenty_iterations_energy_and_coverage(name, cone, reference):
    from compact_distributions.cvt.evaluate import evaluate
    from compact_distributions.cvt.placement.fit import element_for, place_elements

    problem = field_problem(name)
    runs = {}
    for label, backend in (("gl", cone), ("ref", reference)):
        res = lloyd(problem, backend, iterations=20)
        labels = final_labels(problem, backend, res)
        check_region(labels, problem.grid)
        shape, turn = element_for(problem.metric)
        elements = place_elements(
            labels, res.sites, res.angles + turn, shape, problem.metric.aspect, problem.grid
        )
        runs[label] = (res.energy[-1], evaluate(elements, problem.grid).coverage)
    (e_gl, c_gl), (e_ref, c_ref) = runs["gl"], runs["ref"]
    assert abs(e_gl - e_ref) <= 0.01 * e_ref, (e_gl, e_ref)
    assert abs(c_gl - c_ref) <= 0.005, (c_gl, c_ref)


@pytest.mark.parametrize("mode", ["cone", "exact"])
def test_ties_go_to_the_lower_index(mode, cone, exact):
    backend = exact if mode == "exact" else cone
    # sites 1 and 2 coincide with equal angle and scale: they tie on every pixel
    sites = np.array([[10.0, 12.0], [30.5, 20.25], [30.5, 20.25], [50.0, 40.0]])
    for name in ("l1", "l2", "triangle"):
        lab = backend.label(
            sites, angles=np.full(4, 0.3), scales=np.ones(4), metric=make_metric(name), grid=Grid(64, 48)
        )
        assert (lab == 1).any() and not (lab == 2).any(), name
        assert (
            backend.moments(
                sites, angles=np.full(4, 0.3), scales=np.ones(4), metric=make_metric(name), grid=Grid(64, 48)
            ).count[2]
            == 0
        )


@pytest.mark.parametrize("mode", ["cone", "exact"])
def test_every_region_pixel_is_reached_by_clustered_sites(mode, cone, exact, reference):
    """Cone heights come from the actual sites: a tight cluster and one far site must
    still cover the whole raster (a fixed 1/sqrt(N) radius would not)."""
    backend = exact if mode == "exact" else cone
    rng = np.random.default_rng(5)
    sites = np.vstack([rng.random((200, 2)) * 20 + 5, [[250.0, 190.0]]])
    scales = 0.5 + rng.random(201)
    angles = rng.random(201) * 6.3
    grid = Grid(256, 200)
    for name in ("linf-axial", "l2"):
        metric = make_metric(name, 0.5)
        got = backend.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
        check_region(got, grid)
        want = reference.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
        assert (got == want).mean() >= 0.99
        assert (
            backend.moments(sites, angles=angles, scales=scales, metric=metric, grid=grid).count.sum()
            == grid.pixel_count
        )


def test_cone_heights_bound_every_cell(cone, reference):
    """r_i >= the largest d_i over the pixels of cell i (the reference's cells)."""
    from compact_distributions.cvt.metrics import compile_sites

    sites, scales, angles, grid = random_case(9, masked=True)
    for name in ("l2-axial", "triangle"):
        metric = make_metric(name, 0.5)
        coeffs = compile_sites(metric, sites, angles, scales)
        heights = gl.cone_heights(coeffs, scales, metric, gl._Blocks(grid, 8))
        labels = reference.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
        ys, xs = np.nonzero(labels >= 0)
        d = coeffs.distance(labels[ys, xs], xs + 0.5, ys + 0.5)
        largest = np.zeros(len(sites))
        np.maximum.at(largest, labels[ys, xs], d)
        assert (heights >= largest).all()


def test_curved_cone_error_bound():
    # relative height error tan²(π/2M), and the chosen M meets the requested bound
    assert gl.ellipse_height_error(32) == pytest.approx(np.tan(np.pi / 64) ** 2)
    for radius in (5.0, 20.0, 80.0):
        m = gl.ellipse_segments(radius, 0.1)
        assert gl.ellipse_height_error(m) * radius <= 0.1
    # the drawn cone: heights within ±δ of the exact gauge along each face
    metric = make_metric("l2-axial", 0.5)
    verts, reach = gl.cone_vertices(metric, 16)
    tri = verts.reshape(-1, 3, 3).astype(np.float64)
    w = np.random.default_rng(0).dirichlet([1, 1, 1], size=200)
    pts = np.einsum("sk,tkc->tsc", w, tri)  # points on every face
    exact_h = metric.gauge(pts[..., :2])
    delta = gl.ellipse_height_error(16)
    assert np.all(np.abs(pts[..., 2] - exact_h) <= delta * exact_h + 1e-6)
    # and the footprint contains the ball
    assert np.all(metric.gauge(tri[:, 1, :2]) >= 1.0 - 1e-9)
    assert reach == pytest.approx(1 / np.cos(np.pi / 16))


@pytest.mark.parametrize("mode", ["cone", "exact"])
def test_deterministic(mode, cone, exact):
    backend = exact if mode == "exact" else cone
    sites, scales, angles, grid = random_case(11, w=256, h=256, n=200)
    metric = make_metric("l2", 1.0)
    a = backend.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    m1 = backend.moments(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    backend.label(
        sites[:50], angles=angles[:50], scales=scales[:50], metric=make_metric("triangle"), grid=Grid(100, 70)
    )
    b = backend.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    m2 = backend.moments(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(m1.sxx, m2.sxx)


def test_moment_sums_beyond_32_bits(exact):
    """Σj² of one cell over a 2048-pixel-wide raster exceeds 2**32: the shader carries."""
    grid = Grid(2048, 40)
    sites = np.array([[1000.0, 20.0]])
    mom = exact.moments(sites, metric=make_metric("linf"), grid=grid)
    j = np.arange(2048, dtype=np.int64)
    i = np.arange(40, dtype=np.int64)
    assert mom.sxx[0] == 40 * (j * j).sum() > 2**32
    assert mom.sx[0] == 40 * j.sum() and mom.sy[0] == 2048 * i.sum()
    assert mom.syy[0] == 2048 * (i * i).sum() and mom.count[0] == 2048 * 40


def test_registry_device_and_options():
    try:
        backend = create_backend("gl", mode="exact")
    except BackendUnavailable as exc:
        pytest.skip(str(exc))
    text = backend.device()
    assert backend.ctx.info["GL_RENDERER"] in text and "exact" in text
    assert gl.GLBackend.probe()
    backend.close()
    with pytest.raises(InputError, match="mode"):
        gl.GLBackend(mode="pyramid")
    with pytest.raises(InputError, match="max_error_px"):
        gl.GLBackend(max_error_px=0)


def test_bad_inputs(exact):
    grid = Grid(32, 32)
    with pytest.raises(InputError, match="sites"):
        exact.label(np.zeros((0, 2)), metric=make_metric("l2"), grid=grid)
    with pytest.raises(InputError, match="scales"):
        exact.label(
            np.ones((2, 2)), angles=None, scales=np.array([1.0, -1.0]), metric=make_metric("l2"), grid=grid
        )


def test_missing_moderngl_is_one_clear_error(monkeypatch):
    import sys

    monkeypatch.setattr(gl, "_CONTEXT", None)
    monkeypatch.setattr(gl, "_CONTEXT_ERROR", None)
    monkeypatch.setitem(sys.modules, "moderngl", None)  # import fails as if not installed
    with pytest.raises(BackendUnavailable, match="moderngl is not installed"):
        gl.GLBackend()
    with pytest.raises(BackendUnavailable, match="moderngl"):  # the failure is remembered
        gl.GLBackend.probe()


def generated_polygon(tmp_path, corners, seed):
    """An irregular convex polygon: random points on a random ellipse (so all are corners),
    their convex hull written as the user would give it (a JSON list of [x, y], at an
    arbitrary offset and scale)."""
    rng = np.random.default_rng(seed)
    t = (np.arange(corners) + rng.uniform(0.2, 0.8, corners)) * (2 * np.pi / corners)  # no two too close
    a, b, turn = rng.uniform(1.0, 3.0), rng.uniform(1.0, 3.0), rng.uniform(0, np.pi)
    x, y = a * np.cos(t), b * np.sin(t)
    pts = np.stack([x * np.cos(turn) - y * np.sin(turn), x * np.sin(turn) + y * np.cos(turn)], axis=1)
    hull = pts[ConvexHull(pts).vertices] * 7.0 + [40.0, -7.0]
    path = tmp_path / f"poly{corners}.json"
    path.write_text(json.dumps(hull.tolist()))
    return make_metric(f"polygon:{path}")


@pytest.mark.parametrize("mode", ["cone", "exact"])
@pytest.mark.parametrize("corners", [7, 64])
def test_the_users_polygon_matches_the_reference(tmp_path, mode, corners, cone, exact, reference):
    """Any convex polygon: 7 corners (exact mode: all facets as flat varyings) and 64
    (more than the varyings hold on llvmpipe: each face's own facet and its neighbours'),
    with angles, scales and a region mask; labels equal to the reference's up to ties,
    moments the sums of them."""
    backend = exact if mode == "exact" else cone
    metric = generated_polygon(tmp_path, corners, seed=corners)
    assert len(metric.normals) == corners
    sites, scales, angles, grid = random_case(corners, w=200, h=160, n=150, masked=True)
    args = dict(angles=angles, scales=scales, metric=metric, grid=grid)
    got = backend.label(sites, **args)
    want = reference.label(sites, **args)
    check_region(got, grid)
    assert_same_up_to_ties(got, want, sites, angles, scales, metric, grid, SLACK.get(backend.variant, 0.0))
    mom = backend.moments(sites, **args)
    host = moments_from_labels(got, len(sites))
    for field in ("count", "sx", "sy", "sxx", "syy"):
        np.testing.assert_array_equal(getattr(mom, field), getattr(host, field), err_msg=field)
    assert mom.count.sum() == grid.pixel_count


def test_the_face_local_facets_give_the_labels_of_all_facets(tmp_path, reference):
    """Exact mode with more facets than the varyings hold takes only the facets of the face
    drawn and its neighbours: the same labels as the max over all K, up to float ties."""
    metric = generated_polygon(tmp_path, 9, seed=4)
    sites, scales, angles, grid = random_case(4, w=240, h=200, n=300)
    args = dict(angles=angles, scales=scales, metric=metric, grid=grid)
    every = _backend("exact")
    local = _backend("exact")
    local._varying_facets = lambda: 0  # as on a driver with too few varyings
    try:
        assert every._varying_facets() >= 9  # the default path does take every facet
        a, b = every.label(sites, **args), local.label(sites, **args)
    finally:
        every.close()
        local.close()
    want = reference.label(sites, **args)
    for got in (a, b):
        assert_same_up_to_ties(got, want, sites, angles, scales, metric, grid, 0.0)
    assert (a != b).mean() <= 1e-4


def test_the_pyramid_has_one_face_per_facet(tmp_path):
    """The pyramid over a K-gon ball has K faces, each a linear facet of the gauge: the
    height over every face point equals the gauge there (so depth interpolation is exact),
    and that facet is the one face_facets names (what exact mode's face-local path reads)."""
    for metric in (
        *(make_metric(n, 0.6) for n in ("hexagon", "octagon", "triangle", "linf-axial")),
        generated_polygon(tmp_path, 11, seed=2),
    ):
        verts, reach = gl.cone_vertices(metric, 0)
        tri = verts.reshape(-1, 3, 3).astype(np.float64)
        assert len(tri) == len(metric.normals) and reach == 1.0
        w = np.random.default_rng(1).dirichlet([1, 1, 1], size=100)
        pts = np.einsum("sk,tkc->tsc", w, tri)
        gauge = metric.gauge(pts[..., :2])
        np.testing.assert_allclose(pts[..., 2], gauge, atol=1e-6)
        own = metric.normals[gl.face_facets(metric)] / metric.offsets[gl.face_facets(metric), None]
        np.testing.assert_allclose(np.einsum("tsc,tc->ts", pts[..., :2], own), gauge, atol=1e-9)


def test_exact_mode_declines_polygons_where_the_vertex_stage_has_no_storage_buffers():
    """OpenGL 4.3 lets a driver give the vertex stage no storage buffers; exact mode then
    says so for polygons (cone mode and ellipses do not need them)."""
    from types import SimpleNamespace

    backend = _backend("exact")
    real = backend.ctx
    backend.ctx = SimpleNamespace(info={**real.info, "GL_MAX_VERTEX_SHADER_STORAGE_BLOCKS": 0})
    try:
        assert backend.supports(make_metric("l2"), np.zeros(2), np.ones(2)) is None
        with pytest.raises(InputError, match="storage buffers in the vertex stage"):
            backend.label(
                np.array([[5.0, 5.0], [20.0, 9.0]]), metric=make_metric("hexagon"), grid=Grid(32, 32)
            )
    finally:
        backend.ctx = real
        backend.close()
