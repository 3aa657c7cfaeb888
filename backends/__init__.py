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
from collections.abc import Sequence
from functools import lru_cache
from importlib.metadata import EntryPoint
from typing import Any

from compact_distributions.cvt.errors import BackendUnavailable, InputError, PluginError, exception_line
from compact_distributions.cvt.registry import distribution_of, group_entry_points
from compact_distributions.cvt.validate import one_of

from .base import Backend

# name -> "module:Class"
REGISTRY: dict[str, str] = {
    "numpy": "compact_distributions.backends.numpy_backend:NumpyBackend",
    "opencl": "compact_distributions.backends.opencl:OpenCLBackend",
    "gl": "compact_distributions.backends.gl:GLBackend",
    "ckdtree": "compact_distributions.backends.ckdtree:CKDTreeBackend",
}
# variant -> (registry name, constructor options), for backends offered in several modes;
# a backend with no entry here is its own one variant
VARIANTS: dict[str, tuple[str, dict[str, Any]]] = {
    "gl-cone": ("gl", {"mode": "cone"}),
    "gl-exact": ("gl", {"mode": "exact"}),
}
REFERENCE = "numpy"  # the oracle every other backend is tested against
BACKEND_GROUP = "compact_distributions.backends"  # entry points of other distributions' backends
BUILT_IN = tuple(REGISTRY)


@lru_cache(maxsize=1)
def _plugins() -> dict[str, EntryPoint]:
    """Entry points of other distributions' backends, by name (built-in names win)."""
    return {ep.name: ep for ep in group_entry_points(BACKEND_GROUP) if ep.name not in BUILT_IN}


def _register_plugins() -> None:
    for name, ep in _plugins().items():
        REGISTRY.setdefault(name, ep.value)


_register_plugins()


def variant_names() -> list[str]:
    """Return the name of every backend variant, in registry order.

    A variant is a backend with options under one name (``gl-cone``, ``gl-exact``); a
    backend offered in one mode is its own one variant.  Other distributions' backends
    (entry point group ``compact_distributions.backends``) come after the built-in ones.
    The names are listed whether or not their runtimes are present on this machine.

    Returns
    -------
    list of str
        The names :func:`create_backend` and ``--backend`` accept.

    Examples
    --------
    >>> import compact_distributions as cd
    >>> cd.backend_names()[:5]
    ['numpy', 'opencl', 'gl-cone', 'gl-exact', 'ckdtree']
    """
    out: list[str] = []
    for name in REGISTRY:
        out += [v for v, (base, _) in VARIANTS.items() if base == name] or [name]
    return out


def resolve(name: str, **options: Any) -> tuple[str, dict[str, Any]]:
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


def create_backend(name: str | Backend, **options: Any) -> Backend:
    """Start a backend by name.

    The backend holds its device (an OpenCL context, an EGL context) until it is closed:
    use it as a context manager.

    Parameters
    ----------
    name : str or Backend
        A name of :func:`backend_names` (a Backend is passed through as it is).
    **options
        The backend's constructor options; they override the variant's own (``mode``
        of ``gl``).

    Returns
    -------
    Backend
        The live backend.

    Raises
    ------
    InputError
        If ``name`` is neither a known name nor a Backend.
    BackendUnavailable
        If the backend's runtime is missing (no OpenCL platform, no EGL, ...); the
        message names what is missing.

    Examples
    --------
    >>> import numpy as np
    >>> import compact_distributions as cd
    >>> with cd.create_backend("numpy") as backend:
    ...     labels = backend.label(
    ...         np.array([[8.0, 8.0], [24.0, 8.0]]),
    ...         metric=cd.make_metric("l2"),
    ...         grid=cd.Grid(32, 16),
    ...     )
    >>> labels.shape, int(labels[0, 0]), int(labels[0, -1])
    ((16, 32), 0, 1)
    """
    if isinstance(name, Backend):
        return name
    if not isinstance(name, str):
        raise InputError(f"backend must be a backend name or a Backend, got {name!r}")
    base, opts = resolve(name, **options)
    cls = backend_class(base)
    if base not in _plugins():
        return cls(**opts)
    # another distribution's backend: whatever its constructor raises is one line naming
    # it, and the instance carries the name errors and records give it (its entry point's)
    who = plugin_name(base)
    try:
        backend = cls(**opts)
        backend.device()  # what every record asks of it: asked here, where a failure is named
    except KeyboardInterrupt:
        raise
    except BackendUnavailable as exc:
        raise BackendUnavailable(f"{who} is unavailable: {exc}") from None
    except BaseException as exc:
        raise PluginError(f"{who} could not start: {exception_line(exc)}") from exc
    backend.plugin, backend.name = who, base
    return backend


def plugin_name(name: str) -> str:
    """How errors name the backend plug-in ``name``: its entry point and distribution."""
    return f"backend plug-in {name!r} (distribution {distribution_of(_plugins()[name])})"


def probe_all() -> list[tuple[str, bool, str]]:
    """(name, available, device description or the reason it is unavailable), per
    registry entry."""
    rows: list[tuple[str, bool, str]] = []
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


def first_available(names: Sequence[str], status: dict | None = None) -> str:
    """The first of ``names`` (the suite's default choice, best first) that runs here,
    else the reference in its place (:func:`fall_back`, which says so).

    Parameters
    ----------
    names : sequence of str
        Backend variants, best first.
    status : dict, optional
        :func:`variant_status`'s answer, where the caller has it already.

    Returns
    -------
    str
        A variant name.
    """
    status = variant_status() if status is None else status
    for name in names:
        if status.get(name, (False, ""))[0]:
            return name
    return fall_back(names[0], status.get(names[0], (False, "not installed"))[1])


__all__ = [
    "Backend",
    "fall_back",
    "first_available",
    "BackendUnavailable",
    "REGISTRY",
    "VARIANTS",
    "REFERENCE",
    "BUILT_IN",
    "create_backend",
    "plugin_name",
    "probe_all",
    "variant_status",
    "variant_metrics",
    "variant_names",
    "backend_class",
    "resolve",
]
