"""One validation layer at the edge: every option of the command line and every argument
of the Python API is checked (finite, in its documented range, named in the message);
`reproduce` checks all its parts before starting; stored json that is not an object is
refused; broken pipes and closed streams end quietly."""

from __future__ import annotations

import os
import subprocess
import time

import numpy as np
import pytest
from PIL import Image

from compact_distributions.backends import create_backend
from compact_distributions.baselines import get_method
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.fields import DensityMap, DirectionField
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.mosaic.pipeline import make_mosaic
from compact_distributions.cvt.problem import Grid, Problem

from .cli_errors import one_error
from .hostile import CLI

RUN_BAD = [
    (["--field", "constant:nan"], "--field 'constant:nan'"),
    (
        ["--metric", "linf-axial", "--aspect", "1e-300"],
        "--aspect must be a finite number between 0.01 and 100",
    ),
    (["--metric", "l2-axial", "--aspect", "1e300"], "--aspect must be a finite number between 0.01 and 100"),
    (["--seed", "-5"], "--seed must be a whole number between 0 and"),
    (["--seed=-5"], "--seed must be a whole number between 0 and"),
    (["--seed", "1" + "0" * 30], "--seed must be a whole number"),
    (["--gap", "1e308"], "--gap must be a finite number between 0 and 32768"),
    (["--elements", "inf"], "--elements must be a whole number"),
    (["--iterations", "1000000000000"], "--iterations must be a whole number between 0 and 100000"),
    (["--size", "-5x10"], "argument --size: expected one argument"),
    (["--size", "1e9"], "--size must be W or WxH"),
    (["--backend", "42"], "unknown backend '42'"),
    (["--memory-limit=-3G"], "--memory-limit must be a memory size"),
    (["--gl-mode", "fast"], "argument --gl-mode: invalid choice"),
    (["--no-such-option"], "unrecognized arguments: --no-such-option"),
]


@pytest.mark.parametrize("extra,message", RUN_BAD)
def test_run_options(extra, message, tmp_path, capsys):
    line = one_error(["run", "--size", "48", "--elements", "10", "--out", tmp_path / "o", *extra], capsys)
    assert message in line
    assert not (tmp_path / "o").exists()


MOSAIC_BAD = [
    (["--contrast", "1e308"], "--contrast must be a finite number between 1 and 100"),
    (["--contrast", "nan"], "--contrast must be a finite number between 1 and 100"),
    (["--png-scale", "1e9"], "--png-scale must be a finite number between 0.01 and 100"),
    (["--png-scale", "0"], "--png-scale must be a finite number between 0.01 and 100"),
    (
        ["--element", "rectangle", "--aspect", "1e-300"],
        "--aspect must be a finite number between 0.01 and 100",
    ),
    (["--elements", "inf"], "--elements must be a whole number"),
    (["--elements", "100000"], "--elements 100000 do not fit in a 64x48 raster"),
    (["--seed", "-5"], "--seed must be a whole number between 0 and"),
    (["--grout", "#zz"], "unknown --grout '#zz'"),
    (["--size", "40000"], "--size '40000': each side must be between 1 and 32768 pixels"),
    (["--metric", "l9"], "unknown --metric 'l9'"),
]


@pytest.mark.parametrize("extra,message", MOSAIC_BAD)
def test_mosaic_options(extra, message, tmp_path, capsys):
    Image.new("RGB", (64, 48), "teal").save(tmp_path / "p.png")
    line = one_error(["mosaic", tmp_path / "p.png", "--out", tmp_path / "o", *extra], capsys)
    assert message in line
    assert not (tmp_path / "o").exists()


@pytest.fixture(scope="module")
def numpy_backend():
    with create_backend("numpy") as backend:
        yield backend


PICTURE = np.zeros((20, 30, 3))


@pytest.mark.parametrize(
    "call,message",
    [
        (lambda b: make_mosaic(PICTURE, b, n_elements=float("inf")), "n_elements must be a whole number"),
        (lambda b: make_mosaic(PICTURE, 42), "backend must be a live backend"),
        (
            lambda b: make_mosaic(PICTURE, b, contrast=1e308),
            "contrast must be a finite number between 1 and 100",
        ),
        (lambda b: make_mosaic(PICTURE, b, size=10**9), "size 1000000000: each side"),
        (lambda b: make_mosaic(PICTURE, b, aspect=float("nan")), "aspect must be a finite number"),
        (lambda b: make_mosaic(PICTURE, b, grout=(2, 0, 0)), "grout must be three numbers in 0..1"),
        (lambda b: make_mosaic(PICTURE, b, n_elements=10, memory_limit="1M"), "set memory_limit higher"),
        (lambda b: create_backend(42), "backend must be a backend name or a Backend"),
        (lambda b: get_method("ours")(Problem(Grid(32, 32), 4), 42), "backend must be a live backend"),
        (
            lambda b: get_method("ours")(Problem(Grid(32, 32), 4), b, iterations=float("inf")),
            "iterations must be",
        ),
        (
            lambda b: get_method("ours")(Problem(Grid(32, 32), 4), b, gap=float("nan")),
            "gap must be a finite number",
        ),
        (lambda b: get_method(42), "unknown method 42"),
        (lambda b: Problem(Grid(float("inf"), 32), 4), "width must be a whole number between 1 and 32768"),
        (lambda b: Problem(Grid(32, 32), 4, seed=-5), "seed must be a whole number between 0 and"),
        (lambda b: Problem(Grid(32, 32), 4, metric="l2"), "metric must be a Metric"),
        (lambda b: Problem(Grid(32, 32), 4, field="radial"), "field must be a DirectionField or None"),
        (lambda b: make_metric("linf-axial", 1e-300), "aspect must be a finite number between 0.01 and 100"),
        (lambda b: DirectionField.named("constant:nan", 8, 8), "constant needs an angle"),
        (lambda b: DirectionField.from_angles(np.full((4, 4), 1e300)), "finite angles"),
        (lambda b: DensityMap(np.full((4, 4), np.nan)), "density must be finite"),
        (lambda b: DensityMap(np.array([[1.0, np.nan], [2.0, 3.0]])), "density must be finite"),
        (lambda b: DensityMap(np.array([[1.0, -np.inf], [2.0, 3.0]])), "density must be finite"),
        (
            lambda b: DensityMap(np.array([[1.0, 2.0], [-1e-300, 3.0]])),
            "density must be finite and non-negative",
        ),
        (lambda b: DensityMap(np.zeros((0, 4))), "density image is empty"),
    ],
)
def test_python_api_arguments(call, message, numpy_backend):
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        call(numpy_backend)


def test_density_values_may_be_huge():
    d = DensityMap(np.array([[1e308, 1e308], [1e308, 5e307]]))
    assert np.isfinite(d.scales_at(np.array([[0.5, 0.5], [1.5, 1.5]]))).all()


# ---------------------------------------------------------------- reproduce and sweeps
@pytest.mark.parametrize(
    "extra,message",
    [
        (["--seeds", "0"], "--seeds must be a whole number between 1 and 1000"),
        (["--seeds", "1e9"], "--seeds must be a whole number between 1 and 1000"),
        (["--out", "/dev/null"], "--out /dev/null is a character device, not a folder"),
        (["--memory-limit", "50M"], "more than the limit --memory-limit sets (50 MiB)"),
    ],
)
def test_reproduce_checks_every_part_before_starting(extra, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    t0 = time.perf_counter()
    line = one_error(["reproduce", "--quick", "--quiet", *extra], capsys)
    assert message in line and time.perf_counter() - t0 < 30
    assert list(tmp_path.iterdir()) == []  # nothing ran, nothing was written


@pytest.mark.parametrize(
    "argv,message",
    [
        (["backends", "--sizes", "40000"], "--sizes must be a whole number between 1 and 32768"),
        (
            ["backends", "--quick", "--sizes", "64", "--elements", "5000"],
            "--elements must be a whole number between 1 and 4096",
        ),
        (["backends", "--repeats", "0"], "--repeats must be a whole number between 1 and 1000"),
        (["table2", "--seeds", "2000"], "--seeds must be a whole number between 1 and 1000"),
        (["table2", "--methods", "ours,nope"], "unknown --methods 'nope'"),
    ],
)
def test_sweep_options(argv, message, tmp_path, capsys):
    assert message in one_error(argv + ["--out", tmp_path / "o"], capsys)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("content", ["[1, 2, 3]", '"text"', "null", "{not json"])
def test_stored_json_that_is_not_an_object(content, tmp_path, capsys):
    path = tmp_path / "stored.json"
    path.write_text(content)
    line = one_error(["regress", "--quick", "--baseline", path], capsys)
    assert str(path) in line
    line = one_error(["backends", "--from-benchmark-json", path, "--out", tmp_path / "o"], capsys)
    assert str(path) in line
    folder = tmp_path / "folder.json"
    folder.mkdir()
    assert "is a folder, not a json file" in one_error(["regress", "--quick", "--baseline", folder], capsys)
    assert "is not a file" in one_error(["regress", "--quick", "--update", "--baseline", folder], capsys)


def test_a_stored_run_that_is_not_an_object_is_run_again(tmp_path):
    from compact_distributions.bench import sweep
    from compact_distributions.bench.runs import RunSpec

    spec = RunSpec("t", "ours", "numpy", "square", 48, 48, 12, 2, 0)
    path = sweep.raw_path(tmp_path, spec)
    path.parent.mkdir(parents=True)
    path.write_text("[1, 2]")
    (row,) = sweep.run_sweep([spec], tmp_path, quiet=True)
    assert row["status"] == "ok" and not row.get("cached")


# ---------------------------------------------------------------- streams
def shell(cmd: str) -> subprocess.CompletedProcess:
    exe = " ".join(CLI)
    return subprocess.run(
        ["bash", "-c", cmd.replace("CVTBENCH", exe)], capture_output=True, text=True, timeout=120
    )


def test_a_reader_that_leaves_ends_the_command_quietly():
    r = shell("CVTBENCH info | head -1; echo status ${PIPESTATUS[0]}")
    assert r.stdout.splitlines() == ["backends:", "status 141"] and r.stderr == "", r


def test_closed_streams_end_quietly(tmp_path):
    r = shell("CVTBENCH info >&-; echo status $?")
    assert r.stdout.strip() == "status 0" and r.stderr == ""
    r = shell(
        f"CVTBENCH run --size 32 --elements 4 --iterations 1 --out {tmp_path / 'o'} 2>&-; echo status $?"
    )
    assert r.stdout.strip() == "status 0" and (tmp_path / "o" / "result.json").exists()
    r = shell("CVTBENCH run --elements nope 2>&-; echo status $?")
    assert r.stdout.strip() == "status 2"
    r = shell("CVTBENCH info > /dev/full; echo status $?")
    assert (
        r.stdout.strip() == "status 1"
        and r.stderr.strip() == "cvtbench: error: cannot write the output (No space left on device)"
    )


def test_opencl_names_an_unwritable_cache_instead_of_no_device(tmp_path):
    pytest.importorskip("pyopencl")
    from compact_distributions.backends.opencl import cache_problem

    locked = tmp_path / "home"
    locked.write_text("a file where HOME's folders should be")
    env = {**os.environ, "HOME": str(locked)}
    env.pop("POCL_CACHE_DIR", None)
    env.pop("XDG_CACHE_HOME", None)
    r = subprocess.run(CLI + ["info"], capture_output=True, text=True, env=env, timeout=120)
    line = next(x for x in r.stdout.splitlines() if x.strip().startswith("opencl"))
    if " available " in line:
        pytest.skip(f"this OpenCL device needs no kernel cache folder: {line.strip()}")
    assert "kernel cache folder" in line and str(locked) in line, line
    assert cache_problem() is None  # here, with the real HOME, the cache is fine
