"""Backends compute the label raster of a CVT iteration; see :mod:`backends.base`.

The registry imports each backend lazily so that a missing runtime (no OpenCL platform,
no EGL) only matters to the user who asks for that backend.
"""

from __future__ import annotations

import importlib

from compact_distributions.cvt.errors import BackendUnavailable, InputError

from .base import Backend

# name -> "module:Class"
REGISTRY = {
    "numpy": "compact_distributions.backends.numpy_backend:NumpyBackend",
    "opencl": "compact_distributions.backends.opencl:OpenCLBackend",
    "gl": "compact_distributions.backends.gl:GLBackend",
}


def backend_class(name: str) -> type[Backend]:
    if name not in REGISTRY:
        raise InputError(f"unknown backend {name!r}; choose one of {', '.join(REGISTRY)}")
    module, _, cls = REGISTRY[name].partition(":")
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        raise BackendUnavailable(f"backend {name!r} is not available: {exc}") from None
    return getattr(mod, cls)


def create_backend(name: str, **options) -> Backend:
    """An instance of backend ``name``; raises BackendUnavailable naming what is missing."""
    return backend_class(name)(**options)


def probe_all() -> list[tuple[str, bool, str]]:
    """(name, available, device description or the reason it is unavailable)."""
    rows = []
    for name in REGISTRY:
        try:
            rows.append((name, True, backend_class(name).probe()))
        except BackendUnavailable as exc:
            rows.append((name, False, str(exc)))
        except Exception as exc:  # a broken driver must not take `info` down
            rows.append((name, False, f"{type(exc).__name__}: {exc}"))
    return rows


__all__ = ["Backend", "BackendUnavailable", "REGISTRY", "create_backend", "probe_all", "backend_class"]
