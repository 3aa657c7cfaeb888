"""The declared top-level API (``import compact_distributions as cd``), the version, and
the command line's quiet third-party output."""

from __future__ import annotations

import subprocess
import sys
from importlib.metadata import version

import numpy as np
import pytest
import shapely

import compact_distributions as cd


def test_every_declared_name_resolves():
    for name in cd.__all__:
        assert getattr(cd, name) is not None, name
    with pytest.raises(AttributeError):
        cd.no_such_name  # noqa: B018


def test_run_measures_its_own_elements(reference):
    problem = cd.problem(n_elements=60, size=(96, 80), element="square", seed=2)
    assert problem.metric.name == "linf"  # the element implies its metric
    result = cd.run(problem, "ours-compact", backend=reference, iterations=4)
    polys = [p for p in result.elements if p is not None]
    assert result.method == "ours-compact" and len(polys) > 50
    # coverage and overlap from the placed polygons, by shapely directly
    union = shapely.union_all(polys)
    assert result.coverage == pytest.approx(union.area / (96 * 80), rel=1e-9)
    assert result.overlap == pytest.approx((sum(p.area for p in polys) - union.area) / (96 * 80), abs=1e-9)
    dist = result.distribution
    assert result.method_seconds >= dist.lloyd_seconds > 0 and len(dist.seconds) == 4


def test_run_by_backend_name_and_options_checked():
    problem = cd.problem(n_elements=40, size=64, seed=1)
    result = cd.run(problem, "hausner2001", backend="numpy", iterations=2, delta=0.8)
    assert result.method_options == {"delta": 0.8} and result.distribution.extra["delta"] == 0.8
    with pytest.raises(cd.InputError, match="has no option 'shrink'"):
        cd.run(problem, "ours", backend="numpy", shrink=0.5)
    with pytest.raises(cd.InputError, match="delta"):
        cd.run(problem, "hausner2001", backend="numpy", delta=float("nan"))
    with pytest.raises(cd.InputError, match="problem must be a Problem"):
        cd.run("not a problem", "ours")
    with pytest.raises(cd.InputError, match="n_elements"):
        cd.problem(n_elements=0)


def test_mosaic_by_name():
    rng = np.random.default_rng(0)
    picture = np.repeat(np.linspace(0, 1, 64)[None, :, None], 48, axis=0) * np.ones(3) * 0.8 + 0.1
    picture = np.clip(picture + rng.normal(0, 0.01, picture.shape), 0, 1)
    m = cd.mosaic(picture, backend="numpy", n_elements=60, iterations=2, method="ours")
    assert m.method == "ours" and m.placed > 50 and 0 < m.coverage <= 1


def cvtbench(*args):
    return subprocess.run(
        [sys.executable, "-m", "compact_distributions.bench.commands.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_version():
    done = cvtbench("--version")
    assert done.returncode == 0 and done.stdout.strip() == f"cvtbench {version('compact-distributions')}"
    assert cd.__version__ == version("compact-distributions")


def test_c_output_silenced_points_descriptors_at_nothing(capfd):
    """What a C library writes to descriptors 1 and 2 inside the block is gone; after it
    both write again (the mechanism that quiets HiGHS' banner and PoCL's compiler)."""
    import os

    from compact_distributions.cvt.quiet import c_output_silenced

    with c_output_silenced(1, 2):
        os.write(1, b"banner\n")
        os.write(2, b"3 warnings generated.\n")
    os.write(1, b"after-out\n")
    os.write(2, b"after-err\n")
    out, err = capfd.readouterr()
    assert out == "after-out\n" and err == "after-err\n"


def test_a_cold_opencl_build_prints_nothing(tmp_path, ocl):
    """A first kernel build (an empty kernel cache) writes nothing on the terminal."""
    import os

    env = {**os.environ, "POCL_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("PYOPENCL_COMPILER_OUTPUT", None)
    done = subprocess.run(
        [sys.executable, "-m", "compact_distributions.bench.commands.cli", "run", "--backend", "opencl"]
        + ["--elements", "60", "--size", "64", "--iterations", "2", "--quiet", "--out", str(tmp_path / "r")],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == "" and done.stderr == ""


def test_compaction_prints_nothing_of_its_solver(tmp_path):
    done = cvtbench(
        "run",
        "--method",
        "ours-compact",
        "--element",
        "square",
        "--elements",
        "80",
        "--size",
        "96",
        "--iterations",
        "3",
        "--quiet",
        "--out",
        str(tmp_path / "r"),
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == "" and "HiGHS" not in done.stderr  # the solver's banner was printed on stdout
    assert (tmp_path / "r" / "result.json").exists()
    verbose = cvtbench("info", "--verbose")
    assert verbose.returncode == 0 and "methods:" in verbose.stdout
