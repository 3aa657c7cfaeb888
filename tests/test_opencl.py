"""The OpenCL backend against the float64 NumPy reference, on the device probe() picks
(PoCL's CPU device in CI).

float32 against float64 may flip genuine ties (L1 and L∞ have whole tie segments), so
labels must agree on >= 99.9 % of pixels and every disagreement must be a near-tie; a
Lloyd step must land every site within 0.5 px (mean 0.01 px); after 20 iterations the
energies must agree within 1 %.  Both label kernels (per block for CPUs, per pixel for
GPUs) and both moment paths (64-bit atomics, split 32-bit counters) are checked.
"""

import json
import math
import os

import numpy as np
import pytest

from compact_distributions.backends.opencl import OpenCLBackend, choose_device
from compact_distributions.cvt.errors import BackendUnavailable, InputError
from compact_distributions.cvt.fields import DensityMap, DirectionField
from compact_distributions.cvt.lloyd import lloyd
from compact_distributions.cvt.metrics import METRIC_NAMES, compile_sites, make_metric
from compact_distributions.cvt.moments import moments_from_labels
from compact_distributions.cvt.problem import Grid, Problem

# each test is collected and skipped with the reason where no device runs the kernels
# (a module-level skip would leave pytest nothing collected: exit status 5)
try:
    DEVICE = OpenCLBackend.probe()
    UNAVAILABLE = None
except BackendUnavailable as exc:
    DEVICE, UNAVAILABLE = "", f"OpenCL backend unavailable: {exc}"
pytestmark = pytest.mark.skipif(UNAVAILABLE is not None, reason=UNAVAILABLE or "")

TIE_TOLERANCE = 1e-5  # relative
KERNELS = {"blocks": 8, "pixels": 0}


@pytest.fixture(scope="module")
def backends():
    made = {name: OpenCLBackend(block=block) for name, block in KERNELS.items()}
    yield made
    for b in made.values():
        b.close()


def notched_ellipse(w, h):
    """A non-rectangular region: an ellipse with a rectangular bite out of one side."""
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    inside = ((xs - w / 2) / (0.48 * w)) ** 2 + ((ys - h / 2) / (0.48 * h)) ** 2 < 1
    inside &= ~((xs > 0.6 * w) & (np.abs(ys - h / 2) < 0.12 * h))
    return inside


def sites_in(mask, n, rng):
    ys, xs = np.nonzero(mask)
    pick = rng.choice(len(xs), n, replace=False)
    return np.stack([xs[pick], ys[pick]], axis=1) + rng.random((n, 2))


def random_case(name, varied, seed, w=256, h=192, n=300):
    rng = np.random.default_rng(seed)
    mask = notched_ellipse(w, h)
    sites = sites_in(mask, n, rng)
    angles = rng.random(n) * 2 * np.pi if varied else None
    scales = 0.4 + 1.6 * rng.random(n) if varied else None
    return sites, angles, scales, make_metric(name, 0.5), Grid(w, h, mask)


def assert_labels_match(got, want, sites, angles, scales, metric):
    """>= 99.9 % equal, the same region, and every difference a near-tie."""
    assert got.dtype == np.int32 and got.shape == want.shape
    np.testing.assert_array_equal(got < 0, want < 0)
    diff = got != want
    assert diff.mean() <= 1e-3, f"{diff.sum()} of {diff.size} pixels differ"
    if diff.any():
        coeffs = compile_sites(metric, sites, angles, scales)
        i, j = np.nonzero(diff)
        d_got = coeffs.distance(got[diff], j + 0.5, i + 0.5)
        d_want = coeffs.distance(want[diff], j + 0.5, i + 0.5)
        gap = np.abs(d_got - d_want) / np.maximum(np.maximum(d_got, d_want), 1e-12)
        assert gap.max() <= TIE_TOLERANCE, f"a disagreement is not a tie: relative gap {gap.max():.2e}"


def test_probe_names_platform_and_device():
    assert " / " in DEVICE and DEVICE.endswith(")")


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("varied", [False, True], ids=["plain", "angles+scales"])
@pytest.mark.parametrize("name", METRIC_NAMES)
def test_labels_agree_with_reference(backends, reference, name, varied, kernel):
    sites, angles, scales, metric, grid = random_case(name, varied, seed=METRIC_NAMES.index(name))
    got = backends[kernel].label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    want = reference.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    assert_labels_match(got, want, sites, angles, scales, metric)


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("name", ["l2-axial", "linf-axial", "triangle"])
def test_search_bound_holds_for_clusters_and_extreme_shapes(backends, reference, name, kernel):
    """Most sites in one corner, a few far away, scales over a 20x range and a thin
    ball (aspect 0.25): the ring search must go far and still stop correctly."""
    rng = np.random.default_rng(11)
    w, h = 200, 150
    sites = np.concatenate([rng.random((150, 2)) * [40, 30], rng.random((6, 2)) * [w, h]])
    angles = rng.random(len(sites)) * 2 * np.pi
    scales = np.exp(rng.uniform(np.log(0.15), np.log(3.0), len(sites)))
    metric = make_metric(name, 0.25)
    grid = Grid(w, h)
    got = backends[kernel].label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    want = reference.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    assert_labels_match(got, want, sites, angles, scales, metric)


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("name", ["l2", "linf", "triangle"])
def test_far_from_the_origin(backends, reference, name, kernel):
    """A 16384-px-wide strip: float32 keeps only ~0.001 px there, so L∞'s tie segments
    flip on hundreds of pixels unless v = x - p keeps the site's low bits (hi/lo split)."""
    rng = np.random.default_rng(4)
    w, h = 16384, 48
    sites = rng.random((1500, 2)) * [w, h]
    angles, scales = None, None
    metric, grid = make_metric(name), Grid(w, h)
    got = backends[kernel].label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    want = reference.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    assert_labels_match(got, want, sites, angles, scales, metric)


@pytest.mark.parametrize("kernel", KERNELS)
def test_ties_go_to_the_lower_index(backends, kernel):
    # sites 1 and 2 coincide: they tie everywhere, 1 must win; the grid puts them in one
    # cell after site 3, whose index order must not matter
    sites = np.array([[30.0, 30.0], [10.0, 10.0], [10.0, 10.0], [10.2, 10.1]])
    lab = backends[kernel].label(sites, metric=make_metric("l1"), grid=Grid(40, 40))
    assert 2 not in lab and (lab == 1).any()


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("name", ["l2", "l1", "linf"])
def test_exact_ties_across_cells_go_to_the_lower_index(backends, name, kernel):
    """Site 1 (left cell) and site 0 (right cell) are exactly equidistant from column
    x = 30.5: pixels there search their own cell, meet site 1 first, and must still
    end with site 0."""
    sites = np.array([[50.5, 10.5], [10.5, 10.5]])
    lab = backends[kernel].label(sites, metric=make_metric(name), grid=Grid(64, 64))
    assert (lab[:, 30] == 0).all() and (lab[:20, 29] == 1).all() and (lab[:, 31] == 0).all()


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("split", [False, True], ids=["native", "split32"])
@pytest.mark.parametrize("name", ["l2", "linf", "triangle"])
@pytest.mark.parametrize("n", [300, 6000], ids=["sparse", "dense"])
def test_device_moments_equal_host_sums_of_device_labels(name, split, kernel, n):
    """The block kernel sums its own labels, the pixel kernel's are summed by row runs:
    both must give the host's sums of the labels exactly (the raster is not a multiple
    of the block, and the region is not a rectangle).  Dense sites put more labels in
    a work-item's blocks than its table of sums holds."""
    sites, angles, scales, metric, grid = random_case(name, True, seed=5, w=251, h=189, n=n)
    ocl = OpenCLBackend(split_atomics=split, block=KERNELS[kernel])
    try:
        labels = ocl.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
        got = ocl.moments(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    finally:
        ocl.close()
    want = moments_from_labels(labels, len(sites))
    for field in ("count", "sx", "sy", "sxx", "syy"):
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)


@pytest.mark.parametrize("block", [4, 16])
@pytest.mark.parametrize("name", ["l2", "linf", "hexagon"])
def test_every_block_size_gives_the_pixel_kernels_labels_and_sums(backends, name, block):
    """Rows of 4 or 16 lanes: labels bit-identical to the per-pixel kernel (the same
    float expression, one pixel at a time), sums equal to the host's sums of them."""
    sites, angles, scales, metric, grid = random_case(name, True, seed=8, w=203, h=149)
    args = dict(angles=angles, scales=scales, metric=metric, grid=grid)
    want = backends["pixels"].label(sites, **args)
    with OpenCLBackend(block=block) as ocl:
        mom = ocl.moments(sites, **args)
        np.testing.assert_array_equal(ocl.label(sites, **args), want)
    host = moments_from_labels(want, len(sites))
    for field in ("count", "sx", "sy", "sxx", "syy"):
        np.testing.assert_array_equal(getattr(mom, field), getattr(host, field), err_msg=field)


def test_block_size_without_a_vector_width_is_an_input_error():
    with pytest.raises(InputError, match="block"):
        OpenCLBackend(block=6)


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("split", [False, True], ids=["native", "split32"])
def test_moment_sums_past_32_bits(split, kernel):
    """One site owning a 4096 x 300 raster: Σj² = 300·Σ_{j<4096} j² ≈ 6.9e12, and the
    split counters wrap their low word many times."""
    ocl = OpenCLBackend(split_atomics=split, block=KERNELS[kernel])
    try:
        mom = ocl.moments(np.array([[5.0, 5.0]]), metric=make_metric("l2"), grid=Grid(4096, 300))
    finally:
        ocl.close()
    j, i = np.arange(4096, dtype=np.int64), np.arange(300, dtype=np.int64)
    assert mom.count[0] == 4096 * 300
    assert mom.sx[0] == 300 * j.sum() and mom.sy[0] == 4096 * i.sum()
    assert mom.sxx[0] == 300 * (j * j).sum() > 2**32
    assert mom.syy[0] == 4096 * (i * i).sum()


@pytest.mark.parametrize("varied", [False, True], ids=["plain", "angles+scales"])
@pytest.mark.parametrize("name", METRIC_NAMES)
def test_one_lloyd_step_lands_where_the_reference_does(backends, reference, name, varied):
    sites, angles, scales, metric, grid = random_case(name, varied, seed=20 + METRIC_NAMES.index(name))
    got = (
        backends["blocks"]
        .moments(sites, angles=angles, scales=scales, metric=metric, grid=grid)
        .centroids(sites)
    )
    ref_labels = reference.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    want = moments_from_labels(ref_labels, len(sites)).centroids(sites)
    moved = np.hypot(*(got - want).T)
    assert moved.max() <= 0.5 and moved.mean() <= 0.01, (moved.max(), moved.mean())


@pytest.mark.parametrize("name", METRIC_NAMES)
def test_energy_after_20_iterations_matches_reference(backends, reference, name):
    w, h = 160, 128
    yy, xx = np.mgrid[0:h, 0:w]
    density = DensityMap(1.0 + 3.0 * xx / w)
    field = DirectionField.named("wave:90", w, h) if name != "l2" else None
    problem = Problem(Grid(w, h, notched_ellipse(w, h)), 120, make_metric(name), density, field, seed=3)
    ours = lloyd(problem, backends["blocks"], iterations=20)
    ref = lloyd(problem, reference, iterations=20)
    assert ours.energy[0] == pytest.approx(ref.energy[0], rel=1e-3)  # same start: ties at most
    assert ours.energy[-1] == pytest.approx(ref.energy[-1], rel=0.01)
    assert ours.energy[-1] < ours.energy[0]


def test_same_input_same_labels(backends):
    sites, angles, scales, metric, grid = random_case("linf", True, seed=9)
    first = backends["blocks"].label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    again = backends["blocks"].label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    fresh = OpenCLBackend()
    try:
        other = fresh.label(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    finally:
        fresh.close()
    np.testing.assert_array_equal(first, again)
    np.testing.assert_array_equal(first, other)


def test_released_buffers_are_made_again_with_the_same_labels_and_moments():
    """After release_buffers the backend holds no buffer and the next calls (labels, and
    the walled moments with their mask) make them again: the same answers as before."""
    sites, angles, scales, metric, grid = random_case("l2-axial", True, seed=4)
    backend = OpenCLBackend()
    try:
        call = dict(angles=angles, scales=scales, metric=metric, grid=grid)
        labels, moments = backend.label(sites, **call), backend.walled_moments(sites, **call)
        backend.release_buffers()
        assert not backend._buffers
        again = backend.walled_moments(sites, **call)
        np.testing.assert_array_equal(backend.label(sites, **call), labels)
    finally:
        backend.close()
    for field in ("count", "sx", "sy", "sxx", "syy"):
        np.testing.assert_array_equal(getattr(moments, field), getattr(again, field))
    # pixels counted (the pieces a cell does not keep are left out): not an empty answer
    assert 0.5 * grid.mask.sum() < moments.count.sum() <= grid.mask.sum()


class _TrackedCopies:
    """pyopencl with each host copy that does not block logged when it is let go (its
    event dropped), beside the backend's reads of the sums."""

    def __init__(self, cl, log):
        self._cl, self._log = cl, log

    def __getattr__(self, name):
        return getattr(self._cl, name)

    def enqueue_copy(self, *args, is_blocking=True, **kwargs):
        event = self._cl.enqueue_copy(*args, is_blocking=is_blocking, **kwargs)
        if is_blocking:
            return event
        self._log.append("copy")
        return _LetGo(event, self._log)


class _LetGo:
    def __init__(self, event, log):
        self.event, self.log = event, log

    def __del__(self):
        self.log.append("let go")


def test_walled_moments_hold_each_copy_until_the_sums_are_read():
    """pyopencl waits for a host copy that does not block when its event is let go, and
    holds the GIL meanwhile: the walled moments let go of theirs only once the sums are
    read (a wait without the GIL), so that threads beside run during the kernels."""
    sites, angles, scales, metric, grid = random_case("linf", True, seed=6)
    backend = OpenCLBackend()
    log: list = []
    try:
        backend._cl = _TrackedCopies(backend._cl, log)
        read = backend._read_moments

        def logged_read(*args):
            log.append("read")
            return read(*args)

        backend._read_moments = logged_read
        backend.walled_moments(sites, angles=angles, scales=scales, metric=metric, grid=grid)
    finally:
        backend.close()
    assert "copy" in log and "read" in log
    # each copy let go only after a read of the sums that comes after it
    for k, entry in enumerate(log):
        if entry == "let go":
            last_copy = max(i for i in range(k) if log[i] == "copy")
            assert "read" in log[last_copy:k], f"a copy let go before the sums were read: {log}"
    assert log.count("copy") == log.count("let go"), log


def test_programs_are_built_once_per_metric_kind():
    ocl = OpenCLBackend()
    try:
        sites = np.random.default_rng(0).random((50, 2)) * 64
        for name in ("l1", "linf", "l1", "l2", "l2-axial", "triangle"):
            ocl.label(sites, metric=make_metric(name), grid=Grid(64, 64))
        kinds = sorted((curved, k) for curved, k, *_ in ocl._programs if curved != "fit")
        assert kinds == [(False, 3), (False, 4), (True, 0)]  # (curved, facets K)
        # the element fit's kernel is built with them, in the same programs
        fits = sorted(key[1:] for key in ocl._programs if key[0] == "fit")
        assert fits == ([(False, 3), (False, 4), (True,)] if ocl._fits_on_device else [])
        for key, kernels in ocl._programs.items():
            if key[0] == "polygon":
                assert ocl._programs[("fit", False, key[1])] == kernels[0].program
    finally:
        ocl.close()


# ---------------------------------------------------------------- device choice, errors
def test_device_option_and_pyopencl_ctx_pick_the_same_device(monkeypatch):
    import pyopencl as cl

    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    by_option = choose_device(cl, "0:0")
    monkeypatch.setenv("PYOPENCL_CTX", "0:0")
    by_env = choose_device(cl, None)
    assert by_option == by_env == cl.get_platforms()[0].get_devices()[0]
    ocl = OpenCLBackend(device="0")
    try:
        assert ocl.device().startswith(cl.get_platforms()[0].name.strip() + " / ")
    finally:
        ocl.close()


@pytest.mark.parametrize(
    "bad",
    [
        dict(scales=np.zeros(3)),
        dict(angles=np.array([0.0, np.nan, 0.0])),
        dict(sites=np.array([[1.0, np.inf], [2, 2], [3, 3]])),
    ],
)
def test_bad_site_data_is_an_input_error(backends, bad):
    args = dict(sites=np.array([[1.0, 1.0], [2, 2], [3, 3]]), scales=None, angles=None)
    args.update(bad)
    with pytest.raises(InputError):
        backends["blocks"].label(
            args["sites"],
            angles=args["angles"],
            scales=args["scales"],
            metric=make_metric("l2"),
            grid=Grid(8, 8),
        )


@pytest.mark.parametrize("spec", ["99", "0:99", "no-such-platform", "0:0:0"])
def test_bad_device_is_an_input_error(spec, monkeypatch):
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    with pytest.raises(InputError, match="device") as err:
        OpenCLBackend(device=spec)
    assert "\n" not in str(err.value)


def test_bad_pyopencl_ctx_makes_probe_say_why(monkeypatch):
    monkeypatch.setenv("PYOPENCL_CTX", "42")
    with pytest.raises(BackendUnavailable, match="PYOPENCL_CTX"):
        OpenCLBackend.probe()


def test_kernel_that_fails_to_build_is_one_clear_error(tmp_path, monkeypatch):
    import compact_distributions.backends.opencl as module

    broken = tmp_path / "broken.cl"
    broken.write_text("__kernel void label_blocks(__global int *x) { x[0] = undefined_name; }\n")
    monkeypatch.setattr(module, "KERNEL_FILE", broken)
    with pytest.raises(BackendUnavailable, match="failed to build") as err:  # tried before it is chosen
        OpenCLBackend().label(np.array([[1.0, 1.0]]), metric=make_metric("l2"), grid=Grid(8, 8))
    assert "\n" not in str(err.value)


def test_raster_too_large_for_the_device_is_one_clear_error():
    ocl = OpenCLBackend()
    try:
        limit = ocl._device.max_mem_alloc_size
        side = math.isqrt(limit // 4) + 1  # the label raster alone exceeds one allocation
        if side > 32768:
            pytest.skip(f"device allows {limit} bytes per buffer: no raster is too large")
        with pytest.raises(BackendUnavailable, match="MiB"):
            ocl.label(np.array([[1.0, 1.0]]), metric=make_metric("l2"), grid=Grid(side, side))
    finally:
        ocl.close()


def test_cli_run_and_info(tmp_path, capsys):
    from compact_distributions.bench.commands.cli import main

    out = tmp_path / "run"
    code = main(
        [
            "run",
            "--backend",
            "opencl",
            "--device",
            "0:0",
            "--elements",
            "150",
            "--size",
            "96",
            "--iterations",
            "3",
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert code == 0
    result = json.loads((out / "result.json").read_text())
    assert result["backend"] == "opencl" and " / " in result["device"]
    assert main(["info"]) == 0
    info = capsys.readouterr().out
    line = next(ln for ln in info.splitlines() if ln.strip().startswith("opencl"))
    assert "available" in line and " / " in line


def test_missing_pyopencl_is_backend_unavailable(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "pyopencl", None)  # import now fails
    with pytest.raises(BackendUnavailable, match="pyopencl is not importable"):
        OpenCLBackend.probe()


def test_no_platform_is_backend_unavailable(monkeypatch):
    import types

    class FakeError(Exception):
        pass

    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    empty = types.SimpleNamespace(Error=FakeError, get_platforms=lambda: [])
    with pytest.raises(BackendUnavailable, match="no OpenCL platform"):
        choose_device(empty)

    def no_icd():
        raise FakeError("PLATFORM_NOT_FOUND_KHR")

    with pytest.raises(BackendUnavailable, match="no OpenCL platform"):
        choose_device(types.SimpleNamespace(Error=FakeError, get_platforms=no_icd))


def _fake_cl(devices_by_platform, broken):
    """A stand-in for pyopencl whose devices listed in ``broken`` fail every build."""
    import types

    class FakeError(Exception):
        pass

    kinds = types.SimpleNamespace(GPU=4, CPU=2, to_string=lambda t: {4: "GPU", 2: "CPU"}[t])
    platforms = []
    for pname, devs in devices_by_platform:
        plat = types.SimpleNamespace(name=pname)
        plat.get_devices = (lambda ds: lambda: ds)(
            [types.SimpleNamespace(name=d, type=t, platform=plat) for d, t in devs]
        )
        platforms.append(plat)

    class Program:
        def __init__(self, ctx, source):
            self.dev = ctx

        def build(self, options=None):
            if self.dev.name in broken:
                raise FakeError("Build on device:\nerror: unknown target CPU 'generic'")
            return self

    return types.SimpleNamespace(
        Error=FakeError,
        get_platforms=lambda: platforms,
        device_type=kinds,
        Context=lambda devs: devs[0],
        Program=Program,
    )


def test_a_device_that_cannot_compile_is_passed_over_or_refused(monkeypatch):
    """An OpenCL runtime may list a CPU whose compiler fails on every kernel (PoCL whose
    LLVM does not know the processor); the device chosen is one that compiles, and
    where none does (or the one named does not) the backend is unavailable with the
    compiler's line, never an error at the first Lloyd step."""
    import compact_distributions.backends.opencl as module

    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    # the fakes build in this process: the child's check needs a real runtime
    monkeypatch.setattr(module, "suite_problem", lambda cl, dev, **_: module.compile_problem(cl, dev))
    cl = _fake_cl([("old", [("cpu-a", 2)]), ("new", [("cpu-b", 2)])], broken={"cpu-a"})
    assert choose_device(cl).name == "cpu-b"
    assert choose_device(cl, "new").name == "cpu-b"
    with pytest.raises(BackendUnavailable, match="cpu-a.*unknown target CPU 'generic'"):
        choose_device(cl, "old")
    gpu_broken = _fake_cl([("p", [("gpu", 4), ("cpu", 2)])], broken={"gpu"})
    assert choose_device(gpu_broken).name == "cpu"
    none = _fake_cl([("p", [("cpu-a", 2), ("cpu-b", 2)])], broken={"cpu-a", "cpu-b"})
    with pytest.raises(BackendUnavailable, match="no OpenCL device runs the suite's kernels.*cpu-a.*cpu-b"):
        choose_device(none)


@pytest.mark.parametrize("name", ["l2", "linf", "triangle", "l2-axial", "hexagon"])
@pytest.mark.parametrize("n", [200, 2200], ids=["cells-wider-than-half-a-block", "cells-narrower"])
def test_seeded_search_gives_the_unseeded_labels_over_lloyd_iterations(reference, name, n):
    """The block search seeded by the last call's labels only tightens its bound: over
    Lloyd iterations (random, then relaxing sites; angles and sizes varied) the labels,
    and so the sites, are bit-identical to a search with no seeds and to the per-pixel
    kernel (its own search, the same float expression), also when the seeds are labels
    of other sites, and when a grid cell is narrower than half an 8x8 block (a block
    then covers cells that no ring searched whole)."""
    rng = np.random.default_rng(11)
    w, h = 160, 128
    field = DirectionField.from_angles(rng.uniform(-np.pi, np.pi, (h, w)))
    density = DensityMap(rng.uniform(0.3, 1.0, (h, w)))
    problem = Problem(Grid(w, h), n, make_metric(name), density=density, field=field, seed=5)
    with OpenCLBackend(seed=True) as seeded, OpenCLBackend(seed=False) as plain:
        a, b = lloyd(problem, seeded, 5), lloyd(problem, plain, 5)
        np.testing.assert_array_equal(a.sites, b.sites)
        with OpenCLBackend(block=0) as pixels:
            np.testing.assert_array_equal(a.sites, lloyd(problem, pixels, 5).sites)
        args = dict(angles=a.angles, scales=a.scales, metric=problem.metric, grid=problem.grid)
        seeded.label(a.sites + rng.normal(0, 1.5, a.sites.shape), **args)  # seeds of other sites
        got = seeded.label(a.sites, **args)
        np.testing.assert_array_equal(got, plain.label(a.sites, **args))
    assert_labels_match(got, reference.label(a.sites, **args), a.sites, a.angles, a.scales, problem.metric)


@pytest.mark.parametrize("block", [4, 8, 16])
def test_the_block_kernel_s_mask_words_hold_each_pixel_in_its_block_s_bit(block):
    """A region's mask as label_blocks reads it, checked pixel by pixel: bit x of word yy
    of block (by, bx) is pixel (by * block + yy, bx * block + x), on a raster whose sides
    are not multiples of the block (the pixels past them are 0)."""
    from compact_distributions.backends.opencl import block_mask_words

    h, w = 29, 45
    mask = np.random.default_rng(block).random((h, w)) < 0.7
    words = block_mask_words(mask, block).ravel()
    cols = -(-w // block)
    assert words.dtype == np.uint16 and words.size == -(-h // block) * cols * block
    for i in range(-(-h // block) * block):
        for j in range(cols * block):
            bit = (int(words[((i // block) * cols + j // block) * block + i % block]) >> (j % block)) & 1
            assert bit == (i < h and j < w and mask[i, j]), (i, j)


def test_only_labels_of_about_the_same_sites_seed_the_search():
    """The last labels seed the block search only where they are of this raster and of as
    many sites, none moved more than the reach (a grid cell) since: a sweep's next
    problem on the same raster, or another picture's mosaic, searches without them (their
    seeds would make every block's first bound far too wide)."""
    from compact_distributions.backends.opencl import _near

    sites = np.random.default_rng(1).random((50, 2)) * 100
    last = ((100, 80), sites.copy())
    assert _near(last, (100, 80), sites + 2.9, 3.0) and _near(last, (100, 80), sites, 0.0)
    assert not _near(last, (100, 80), sites + [0.0, -3.1], 3.0)
    assert not _near(last, (100, 81), sites, 3.0)
    assert not _near(last, (100, 80), sites[:-1], 3.0)
    assert not _near(None, (100, 80), sites, 3.0)


def test_speed_ratio_medians_and_rounds(monkeypatch, capsys):
    """The one-run ratio tool: medians over every timed step of every round, one ratio
    per round (times given, not measured), and its command line on a small problem."""
    from compact_distributions.bench import timing

    given = iter([[1.0, 3.0], [10.0, 30.0], [2.0, 2.0], [30.0, 50.0]])  # mine, theirs per round
    monkeypatch.setattr(timing, "time_lloyd", lambda *a, **k: next(given))
    r = timing.speed_ratio("mine", "theirs", "l2", 10, 32, warmup=0, repeats=2, rounds=2)
    assert r["seconds"] == 2.0 and r["against_seconds"] == 30.0 and r["ratio"] == 15.0
    assert r["ratios"] == [10.0, 20.0]
    monkeypatch.undo()
    args = ["--backend", "opencl", "--against", "numpy", "--metrics", "l2,linf", "--elements", "30"]
    assert timing.main(args + ["--size", "48", "--warmup", "1", "--repeats", "2", "--rounds", "1"]) == 0
    out = capsys.readouterr().out
    assert out.count("ratio") == 2 and "l2, N = 30, 48²: opencl" in out


def test_pocl_workers_are_pinned_unless_the_user_says_otherwise(monkeypatch):
    """PoCL reads POCL_AFFINITY when the platforms are first listed: the backend sets it
    to pin one worker per core before that, and leaves a user's own value alone."""
    import types

    from compact_distributions.backends import opencl

    seen = []
    cl = types.SimpleNamespace(
        Error=Exception, get_platforms=lambda: seen.append(os.environ.get("POCL_AFFINITY")) or [1]
    )
    monkeypatch.delenv("POCL_AFFINITY", raising=False)
    opencl._platforms(cl)
    monkeypatch.setenv("POCL_AFFINITY", "0")
    opencl._platforms(cl)
    assert seen == ["1", "0"]
