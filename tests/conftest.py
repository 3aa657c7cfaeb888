"""Fixtures shared by the test modules: the NumPy reference backend, and a live OpenCL
backend (skipped with its reason where OpenCL cannot start)."""

from __future__ import annotations

import pytest

from compact_distributions.backends import REFERENCE, create_backend
from compact_distributions.cvt.errors import BackendUnavailable


@pytest.fixture(scope="session")
def reference():
    """The NumPy reference backend, the oracle every other backend is tested against."""
    with create_backend(REFERENCE) as backend:
        yield backend


@pytest.fixture(scope="module")
def ocl():
    """A live OpenCL backend with its default options (one per test module: a module that
    changes a backend's state keeps it to itself)."""
    try:
        backend = create_backend("opencl")
    except BackendUnavailable as exc:
        pytest.skip(f"OpenCL backend unavailable: {exc}")
    with backend:
        yield backend
