"""Memory estimates before any large allocation (cvt/resources.py): a refused run answers
at once with one line; the estimates cover what runs really use (measured in child
processes) without asking for several times more; placement and evaluation stay linear
in the sites."""

from __future__ import annotations

import pytest

from compact_distributions.backends import backend_class
from compact_distributions.baselines import get_method
from compact_distributions.cvt import resources
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.resources import Estimate, ResourceError, mosaic_estimate, run_estimate
from compact_distributions.cvt.validate import byte_size

from .hostile import run_measured


def test_byte_sizes():
    assert byte_size("8G", "--memory-limit") == 8 * 2**30
    assert byte_size("512MiB", "x") == 512 * 2**20
    assert byte_size("1.5 GB", "x") == int(1.5 * 2**30)
    assert byte_size("2e9", "x") == 2 * 10**9
    for bad in ("0", "-1G", "lots", "inf", "nan", "1e30T", True, None):
        with pytest.raises(InputError, match="--memory-limit must be a memory size"):
            byte_size(bad, "--memory-limit")


def test_the_limit_is_what_the_machine_has_unless_set():
    avail, source = resources.available_memory()
    assert 0 < avail < 2**50 and source
    assert resources.memory_limit("3G") == (3 * 2**30, "the limit --memory-limit sets")


def test_an_estimate_over_the_limit_names_itself_the_limit_and_the_remedy():
    est = Estimate("this run").add("the pictures", 5 * 2**30)
    with pytest.raises(ResourceError) as info:
        est.check("1G", lower="use a smaller --size")
    text = str(info.value)
    assert "this run needs about 5.12 GiB" in text and "the pictures 5 GiB" in text
    assert "the limit --memory-limit sets (1 GiB)" in text and "use a smaller --size" in text
    assert "\n" not in text
    est.check("8G", lower="-")  # within the limit: no error


def test_estimates_grow_with_raster_sites_and_canvas():
    numpy = backend_class("numpy")
    small = run_estimate(512, 512, 1000, numpy).total
    assert run_estimate(1024, 1024, 1000, numpy).total > small
    assert (
        run_estimate(512, 512, 100_000, numpy, element="circle").total
        > run_estimate(512, 512, 100_000, numpy, element="square").total
        > small
    )
    assert (
        mosaic_estimate(512, 512, 1000, numpy, png_scale=8).total
        > mosaic_estimate(512, 512, 1000, numpy).total
    )


def test_a_huge_run_is_refused_at_once_and_small(tmp_path):
    code, err, peak, secs = run_measured(
        ["run", "--size", "32768", "--elements", "1", "--out", tmp_path / "o"]
    )
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "needs about" in lines[0] and "--memory-limit" in lines[0], err
    assert peak < 1024 and secs < 30, (peak, secs)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "argv,what",
    [
        (
            [
                "backends",
                "--quick",
                "--sizes",
                "32768",
                "--elements",
                "1000",
                "--backends",
                "numpy",
                "--metrics",
                "l2",
            ],
            "timing numpy l2 N=1000 32768²",
        ),
        (["mosaic", "IMAGE", "--size", "1024", "--png-scale", "60"], "mosaic.png"),
    ],
)
def test_sweeps_and_canvases_are_refused_before_they_start(argv, what, tmp_path):
    from PIL import Image

    Image.new("RGB", (64, 48), "red").save(tmp_path / "p.png")
    argv = [str(tmp_path / "p.png") if a == "IMAGE" else a for a in argv] + ["--out", tmp_path / "o"]
    code, err, peak, secs = run_measured(argv)
    assert code == 2 and len(err.strip().splitlines()) == 1 and what in err, err
    assert peak < 1024 and secs < 30
    assert not (tmp_path / "o").exists()


def test_the_limit_option_lowers_and_raises_the_bar(tmp_path, capsys):
    from compact_distributions.bench.commands.cli import main

    argv = [
        "run",
        "--size",
        "256",
        "--elements",
        "50",
        "--iterations",
        "1",
        "--quiet",
        "--out",
        str(tmp_path / "o"),
    ]
    assert main(argv + ["--memory-limit", "100M"]) == 2
    err = capsys.readouterr().err
    assert "more than the limit --memory-limit sets (100 MiB)" in err
    assert main(argv + ["--memory-limit", "2G"]) == 0
    assert main(argv + ["--memory-limit", "lots"]) == 2
    assert "--memory-limit must be a memory size" in capsys.readouterr().err


# (argv, estimate) pairs: the estimate must cover the measured peak and stay within 2.5x
# of it (one process per configuration; the child's own peak after exec)
MEASURED = [
    (
        ["run", "--size", "1536", "--elements", "4000", "--metric", "linf", "--iterations", "2"],
        lambda: run_estimate(1536, 1536, 4000, backend_class("numpy"), element="square"),
    ),
    (
        ["run", "--size", "384", "--elements", str(384 * 384 // 2), "--metric", "l2", "--iterations", "1"],
        lambda: run_estimate(384, 384, 384 * 384 // 2, backend_class("numpy"), element="circle"),
    ),
    (
        ["mosaic", "PICTURE", "--size", "1024", "--elements", "3000", "--iterations", "2"],
        lambda: mosaic_estimate(1024, 1024, 3000, backend_class("numpy"), element="square", png_scale=1.0),
    ),
]
# the same on OpenCL (its runtime held, labels on the device), ours-compact at growing N:
# the figures per pixel and per site must hold as the raster grows
OPENCL_COMPACT = ["run", "--backend", "opencl", "--method", "ours-compact", "--element"]
MEASURED += [
    (
        [*OPENCL_COMPACT, element, "--size", str(size), "--elements", str(n), "--iterations", "5"],
        lambda element=element, size=size, n=n: run_estimate(
            size, size, n, backend_class("opencl"), element=element, method=get_method("ours-compact")
        ),
    )
    for element, size, n in (("square", 1024, 4000), ("square", 2048, 16000), ("triangle", 2048, 16000))
]


@pytest.mark.slow
@pytest.mark.parametrize(
    "argv,estimate",
    MEASURED,
    ids=[
        "run-1536",
        "run-sites-half-pixels",
        "mosaic-1024",
        "compact-opencl-4000",
        "compact-opencl-16000",
        "compact-opencl-triangles-16000",
    ],
)
def test_estimates_cover_measured_peaks(argv, estimate, tmp_path):
    import numpy as np
    from PIL import Image

    if "opencl" in argv:
        from compact_distributions.cvt.errors import BackendUnavailable

        try:
            backend_class("opencl").probe()
        except BackendUnavailable as exc:
            pytest.skip(f"OpenCL backend unavailable: {exc}")
    rng = np.random.default_rng(0)
    Image.fromarray((rng.random((900, 1200, 3)) * 255).astype(np.uint8)).save(tmp_path / "pic.png")
    argv = [str(tmp_path / "pic.png") if a == "PICTURE" else a for a in argv]
    code, err, peak, _ = run_measured(argv + ["--quiet", "--out", tmp_path / "o"])
    assert code == 0, err
    mib = estimate().total / 2**20
    assert peak <= mib <= 2.5 * peak, (peak, mib)


@pytest.mark.slow
def test_placement_memory_is_linear_when_sites_fill_the_raster(tmp_path):
    """Every pixel a site, circles (128-gons): a few kB per site, not tens."""
    code, err, peak, _ = run_measured(
        [
            "run",
            "--size",
            "256",
            "--elements",
            str(256 * 256),
            "--iterations",
            "1",
            "--quiet",
            "--out",
            tmp_path / "o",
        ],
        timeout=600,
    )
    assert code == 0, err
    assert peak < 150 + 256 * 256 * 6 / 1024, peak  # program + 6 kB per site
