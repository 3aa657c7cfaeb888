"""The public Python API accepts anything a user may pass and answers with a result or
one InputError that names the argument: generated objects of every kind (numbers out of
range, NaN, strings, ragged nested lists, None, objects) go into each argument of the
declared API, and nothing else may come out (no numpy or Python exception)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import compact_distributions as cd
from compact_distributions.cvt.mosaic.pipeline import make_mosaic

# anything: numbers of every kind, text, containers (ragged ones too), None, objects
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**12), 10**12),
    st.floats(allow_nan=True),
    st.text(max_size=6),
    st.just(object()),
    st.just(math.inf),
    st.just(-0.0),
)
anything = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3),
        st.tuples(inner, inner),
        st.dictionaries(st.text(max_size=2), inner, max_size=2),
    ),
    max_leaves=6,
)
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _answers(call, name, also=()):
    """``call()`` returns, or raises InputError naming ``name`` (or one of ``also``)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return call()
        except cd.InputError as exc:
            text = str(exc)
            assert any(n in text for n in (name, *also)), (name, text)
            assert "\n" not in text.strip()
            return None


@pytest.fixture(scope="module")
def problem():
    return cd.problem(n_elements=12, size=32, seed=1)


@SETTINGS
@given(
    value=anything,
    which=st.sampled_from(["n_elements", "size", "element", "metric", "aspect", "seed", "mask"]),
)
def test_problem(value, which):
    base = dict(n_elements=8, size=24)
    if which == "size" and isinstance(value, int) and not isinstance(value, bool) and value > 64:
        value = 64  # a valid size only costs time
    _answers(lambda: cd.problem(**{**base, which: value}), which)


@SETTINGS
@given(value=anything, which=st.sampled_from(["iterations", "element", "gap", "backend", "method", "delta"]))
def test_run(problem, value, which):
    if which == "iterations" and isinstance(value, int) and not isinstance(value, bool) and value > 3:
        value = 3
    if which == "method":
        _answers(lambda: cd.run(problem, value, iterations=1), "method")
    elif which == "delta":
        _answers(lambda: cd.run(problem, "hausner2001", iterations=1, delta=value), "delta")
    else:
        _answers(lambda: cd.run(problem, "ours", **{"iterations": 1, which: value}), which)


@SETTINGS
@given(
    value=st.one_of(
        anything, st.lists(st.lists(st.floats(0, 1), min_size=1, max_size=6), min_size=1, max_size=6)
    )
)
def test_mosaic_image(reference, value):
    _answers(lambda: make_mosaic(value, reference, n_elements=4, iterations=1, size=(12, 12)), "image")


@SETTINGS
@given(
    value=anything,
    which=st.sampled_from(
        ["n_elements", "iterations", "seed", "contrast", "gap", "grout", "edge_threshold", "method_options"]
    ),
)
def test_mosaic_arguments(reference, value, which):
    picture = np.linspace(0, 1, 12 * 12 * 3).reshape(12, 12, 3)
    if which in ("n_elements", "iterations") and isinstance(value, int) and not isinstance(value, bool):
        value = min(value, 3)
    _answers(
        lambda: make_mosaic(picture, reference, **{"n_elements": 4, "iterations": 1, which: value}),
        which,
        also=("method",) if which == "method_options" else (),
    )


@SETTINGS
@given(width=anything, height=anything, mask=anything)
def test_grid(width, height, mask):
    for name, args in (("width", (width, 8)), ("height", (8, height)), ("mask", (8, 8, mask))):
        if (
            name != "mask"
            and isinstance(args[name == "height"], int)
            and not isinstance(args[name == "height"], bool)
        ):
            continue  # a valid side allocates nothing; ranges are checked elsewhere
        _answers(lambda a=args: cd.Grid(*a), name)


@SETTINGS
@given(name=anything, aspect=anything)
def test_make_metric(name, aspect):
    _answers(lambda: cd.make_metric(name), "metric")
    _answers(lambda: cd.make_metric("l2-axial", aspect), "aspect")


def test_ragged_and_nan_arrays_are_named():
    with pytest.raises(cd.InputError, match="^image is not an array of pixels"):
        make_mosaic([[1, 2], [3]], cd.create_backend("numpy"), n_elements=4)
    with pytest.raises(cd.InputError, match="^image contains NaN"):
        make_mosaic(np.full((4, 4, 3), np.nan), cd.create_backend("numpy"), n_elements=4)
    with pytest.raises(cd.InputError, match="^region \\(its mask\\) is not an array"):
        cd.problem(n_elements=4, size=8, region=[[1, 2], [3]])


def test_the_region_has_one_name():
    """``region=`` is the command line's ``--region``; ``mask=`` still works for one
    release, with a DeprecationWarning, and the same region."""
    inside = np.zeros((8, 8), bool)
    inside[2:6, 1:7] = True
    assert cd.problem(4, 8, region=inside).grid.pixel_count == 24
    with pytest.warns(DeprecationWarning, match="region="):
        assert cd.problem(4, 8, mask=inside).grid.pixel_count == 24
    with pytest.raises(cd.InputError, match="region"):
        cd.problem(4, 8, region=inside, mask=inside)
