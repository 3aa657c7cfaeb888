"""The picture stage of a poster-size mosaic (result.json's ``stage_seconds['picture']``):
the density and field on every pixel against the coarse grid :func:`field_step` picks
above EXACT_TILES tiles, and the strong edges, each timed on the same picture in one
run (the stage is the fields and the edges).

With the suite's default --benchmark-disable each case runs once on a small picture
(512 px, 2000 tiles: every pixel) and checks the fields' shapes; with --benchmark-enable
the picture is samples/scene.jpg at 2560 px with 20 000 tiles (step 4), and the ratio of
the coarse fields' median to every pixel's is in the coarse case's ``extra_info``::

    pytest tests/benchmarks/test_bench_picture.py --benchmark-enable
"""

from __future__ import annotations

import math

import pytest

from compact_distributions.bench.commands.mosaic import SAMPLES_DIR
from compact_distributions.cvt.mosaic import image_fields as F
from compact_distributions.cvt.mosaic.pipeline import EDGE_MIN_LENGTH, picture_array, raster_size, resample

MEDIANS: dict = {}  # case -> median seconds, filled by the benchmarks of one run


def _enabled(config) -> bool:
    return bool(config.getoption("benchmark_enable", False)) or not config.getoption(
        "benchmark_disable", True
    )


@pytest.fixture(scope="module")
def poster(request):
    """(picture, spacing): scene.jpg at 2560 px for 20 000 tiles (512 px, 2000 untimed)."""
    size, n = (2560, 20000) if _enabled(request.config) else (512, 2000)
    rgb, _ = picture_array(SAMPLES_DIR / "scene.jpg")
    w, h = raster_size(rgb.shape[1], rgb.shape[0], size)
    return resample(rgb, w, h), math.sqrt(w * h / n)


@pytest.mark.parametrize("grid", ["every-pixel", "coarse"])
def test_bench_picture_fields(benchmark, poster, grid):
    picture, spacing = poster
    h, w = picture.shape[:2]
    step = 1 if grid == "every-pixel" else F.field_step(h, w, spacing)
    benchmark.group = "picture stage: fields"
    fields = benchmark.pedantic(
        F.picture_fields,
        args=(picture, spacing, "square"),
        kwargs=dict(details=False, step=step),
        rounds=3,
        iterations=1,
    )
    assert fields.density.shape == (h, w) and fields.edges.shape == (h, w)
    if benchmark.stats is not None:
        MEDIANS[grid] = benchmark.stats.stats.median
        benchmark.extra_info.update(step=step, pixels=h * w)
        if grid == "coarse" and "every-pixel" in MEDIANS:
            benchmark.extra_info["coarse_over_every_pixel"] = MEDIANS["coarse"] / MEDIANS["every-pixel"]


def test_bench_strong_edges(benchmark, poster):
    picture, spacing = poster
    benchmark.group = "picture stage: strong edges"
    edges = benchmark.pedantic(
        F.strong_edges,
        args=(picture, F.DEFAULT_EDGE_THRESHOLD),
        kwargs=dict(min_length=EDGE_MIN_LENGTH * spacing, srgb=True),
        rounds=3,
        iterations=1,
    )
    assert edges.shape == picture.shape[:2] and edges.any()
