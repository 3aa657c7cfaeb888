"""Backends compute the label raster of a CVT iteration; see :mod:`.base`.

``REGISTRY`` names each backend's class; it is imported only when asked for, so a missing
runtime (no OpenCL platform, no EGL) only matters to the user who asks for that backend.
A *variant* is a backend with options under one name (``gl-cone``, ``gl-exact``): the
vocabulary of ``--backend`` and of the reports.  A registry name alone is a variant with
the backend's default options (``gl`` is ``gl-cone``).

Other distributions add backends through the entry point group
``compact_distributions.backends``: each entry point names a :class:`~.base.Backend`
subclass and is treated exactly like the built-in ones (listed by ``cvtbench info``,
offered by ``--backend``, run by the sweeps and the conformance tests); one that fails to
load is listed as unavailable with its reason.
"""

from __future__ import annotations

import importlib
import sys
from functools import lru_cache

from compact_distributions.cvt.errors import BackendUnavailable, InputError
from compact_distributions.cvt.registry import group_entry_points
from compact_distributions.cvt.validate import one_of

from .base import Backend

# name -> "module:Class"
REGISTRY = {
    "numpy": "compact_distributions.backends.numpy_backend:NumpyBackend",
    "opencl": "compact_distributions.backends.opencl:OpenCLBackend",
    "gl": "compact_distributions.backends.gl:GLBackend",
    "ckdtree": "compact_distributions.backends.ckdtree:CKDTreeBackend",
}
# variant -> (registry name, constructor options), for backends offered in several modes;
# a backend with no entry here is its own one variant
VARIANTS = {
    "gl-cone": ("gl", {"mode": "cone"}),
    "gl-exact": ("gl", {"mode": "exact"}),
}
REFERENCE = "numpy"  # the oracle every other backend is tested against
BACKEND_GROUP = "compact_distributions.backends"  # entry points of other distributions' backends
BUILT_IN = tuple(REGISTRY)


@lru_cache(maxsize=1)
def _plugins() -> dict:
    """Entry points of other distributions' backends, by name (built-in names win)."""
    return {ep.name: ep for ep in group_entry_points(BACKEND_GROUP) if ep.name not in BUILT_IN}


def _register_plugins() -> None:
    for name, ep in _plugins().items():
        REGISTRY.setdefault(name, ep.value)


_register_plugins()


def variant_names() -> list[str]:
    """Every variant, in registry order."""
    out = []
    for name in REGISTRY:
        out += [v for v, (base, _) in VARIANTS.items() if base == name] or [name]
    return out


def resolve(name: str, **options) -> tuple[str, dict]:
    """(registry name, options) of a backend or variant name plus explicit options."""
    one_of(name, "backend", [*REGISTRY, *VARIANTS])
    if name in VARIANTS:
        base, preset = VARIANTS[name]
        return base, {**preset, **options}
    return name, options


def backend_class(name: str) -> type[Backend]:
    base, _ = resolve(name)
    if base in _plugins():
        try:
            cls = _plugins()[base].load()
        except Exception as exc:  # a broken plug-in is unavailable with its reason, never a crash
            raise BackendUnavailable(
                f"backend {base!r} could not be loaded: {type(exc).__name__}: {exc}"
            ) from None
        if not (isinstance(cls, type) and issubclass(cls, Backend)):
            raise BackendUnavailable(
                f"backend {base!r}: its entry point names {cls!r}, not a Backend subclass"
            )
        return cls
    module, _, cls = REGISTRY[base].partition(":")
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        raise BackendUnavailable(f"backend {base!r} is not available: {exc}") from None
    return getattr(mod, cls)


def create_backend(name: str, **options) -> Backend:
    """An instance of backend or variant ``name`` (options override the variant's);
    raises BackendUnavailable naming what is missing."""
    if isinstance(name, Backend):
        return name
    if not isinstance(name, str):
        raise InputError(f"backend must be a backend name or a Backend, got {name!r}")
    base, opts = resolve(name, **options)
    return backend_class(base)(**opts)


def probe_all() -> list[tuple[str, bool, str]]:
    """(name, available, device description or the reason it is unavailable), per
    registry entry."""
    rows = []
    for name in REGISTRY:
        try:
            rows.append((name, True, backend_class(name).probe()))
        except BackendUnavailable as exc:
            rows.append((name, False, str(exc)))
        except Exception as exc:  # a broken driver must not take `info` down
            rows.append((name, False, f"{type(exc).__name__}: {exc}"))
    return rows


def variant_metrics(name: str) -> tuple[str, ...] | None:
    """The metrics a backend or variant computes (None: all six, or unknown because its
    runtime is missing: then its runs are skipped with the reason anyway)."""
    try:
        return backend_class(name).metrics
    except BackendUnavailable:
        return None


def variant_status() -> dict[str, tuple[bool, str]]:
    """variant -> (available, device text or the reason it is unavailable)."""
    probed = {name: (ok, text) for name, ok, text in probe_all()}
    return {v: probed[resolve(v)[0]] for v in variant_names()}


_FELL_BACK: set[str] = set()  # defaults already said to be replaced, in this process


def fall_back(name: str, reason: str) -> str:
    """The reference backend, in place of ``name``, which the suite chose by default and
    which cannot run here for ``reason``; says so in one line on standard error, once per
    process (a backend the user named that cannot run is refused instead).

    Parameters
    ----------
    name : str
        The backend the suite would have chosen.
    reason : str
        Why it is unavailable (as :func:`variant_status` gives it).

    Returns
    -------
    str
        The reference backend's name.
    """
    if name not in _FELL_BACK:
        _FELL_BACK.add(name)
        print(f"note: using {REFERENCE}, as {name} cannot run here: {reason}", file=sys.stderr, flush=True)
    return REFERENCE


__all__ = [
    "Backend",
    "fall_back",
    "BackendUnavailable",
    "REGISTRY",
    "VARIANTS",
    "REFERENCE",
    "BUILT_IN",
    "create_backend",
    "probe_all",
    "variant_status",
    "variant_metrics",
    "variant_names",
    "backend_class",
    "resolve",
]
