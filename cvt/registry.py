"""The one registry of methods: every method that an installed
distribution declares through the entry point group ``compact_distributions.methods``.

The suite's own baselines come in through that group too (this distribution declares
them in its ``pyproject.toml``), so a third party's method is found and treated exactly
like them.  An entry point names a :class:`~.methods.Method` record, a sequence of
records (a package of methods), or a plain callable with the method signature, which
then takes the entry point's name and has no options.  An entry point that fails to load
is listed by :func:`unavailable_methods` with its reason; it never stops the others.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from functools import lru_cache
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from .errors import InputError
from .methods import Method
from .validate import one_of

METHOD_GROUP = "compact_distributions.methods"
_ROLE_ORDER = {"paper": 0, "extension": 1, "baseline": 2, "plugin": 3}


def group_entry_points(group: str) -> list[EntryPoint]:
    """The installed entry points of ``group`` (one per name: the first one found)."""
    found: dict[str, EntryPoint] = {}
    for ep in entry_points(group=group):
        found.setdefault(ep.name, ep)
    return list(found.values())


def distribution_of(ep: EntryPoint) -> str:
    """``name version`` of the distribution that declares entry point ``ep`` ("?" if
    unknown): what an error about a plug-in names."""
    dist = getattr(ep, "dist", None)
    if dist is None:
        return "?"
    try:
        return f"{dist.name} {dist.version}"
    except Exception:  # a broken METADATA file must not stop the listing
        return "?"


def records_of(obj: Any, name: str) -> list[Method]:
    """The method records an entry point's object declares (InputError if none)."""
    if isinstance(obj, Method):
        return [obj]
    if isinstance(obj, (list, tuple)) and obj and all(isinstance(m, Method) for m in obj):
        return list(obj)
    if callable(obj):
        return [Method(name, obj, summary=(getattr(obj, "__doc__", None) or "").strip().split("\n")[0])]
    raise InputError(
        f"entry point {name!r} is neither a method record, a list of them nor a callable: {obj!r}"
    )


@lru_cache(maxsize=1)
def _load() -> tuple[dict[str, Method], dict[str, str]]:
    found: dict[str, Method] = {}
    failed: dict[str, str] = {}
    loaded = []
    for ep in group_entry_points(METHOD_GROUP):
        try:
            dist = distribution_of(ep)
            loaded += [
                replace(m, entry_point=ep.name, distribution=dist) for m in records_of(ep.load(), ep.name)
            ]
        except Exception as exc:  # a broken plug-in is listed with its reason, never a crash
            failed[ep.name] = f"{type(exc).__name__}: {exc}"

    # by role, then year; a package's own records keep their declared order (the sort is
    # stable), other distributions' by name
    def order(m: Method) -> tuple[int, int, str]:
        return (_ROLE_ORDER[m.role], m.year or 9999, m.name if m.role == "plugin" else "")

    for record in sorted(loaded, key=order):
        if record.name in found:
            failed.setdefault(record.name, f"the name {record.name!r} is taken by another method")
            continue
        found[record.name] = record
    return found, failed


def methods() -> dict[str, Method]:
    """Every method record by name: the paper's variants, then the baselines (by year),
    then other distributions' methods."""
    return dict(_load()[0])


def method_names() -> list[str]:
    """Return the names of every registered method, in the registry's order.

    The paper's method and its variants come first, then the baselines by year, then
    other installed distributions' methods (entry point group
    ``compact_distributions.methods``) by name.

    Returns
    -------
    list of str
        The names :func:`get_method` and ``--method`` accept.

    Examples
    --------
    >>> import compact_distributions as cd
    >>> names = cd.method_names()
    >>> names[:3]
    ['ours', 'ours-fit', 'ours-compact']
    >>> "hausner2001" in names
    True
    """
    return list(_load()[0])


def unavailable_methods() -> dict[str, str]:
    """Entry points that could not be loaded: name -> reason."""
    return dict(_load()[1])


def get_method(name: str | Method) -> Method:
    """Return the method record of a registered name.

    Parameters
    ----------
    name : str or Method
        A name of :func:`method_names` (a record is passed through as it is).

    Returns
    -------
    Method
        The registry's record: its options, its paper, its runner.

    Raises
    ------
    InputError
        For an unknown name (the message lists the known ones), or a plug-in of that
        name that is installed but failed to load (the message gives its reason).

    Examples
    --------
    >>> import compact_distributions as cd
    >>> record = cd.get_method("ours-compact")
    >>> record.role, [o.name for o in record.options]
    ('extension', ['alternate', 'rounds', 'tolerance', 'accelerate'])
    """
    if isinstance(name, Method):
        return name
    found, failed = _load()
    if isinstance(name, str) and name in failed and name not in found:
        raise InputError(f"method {name!r} is installed but could not be loaded: {failed[name]}")
    return found[one_of(name, "method", list(found))]


def resolve_method(method: str | Method | Callable[..., Any]) -> Method:
    """The method record of ``method``: a registered name (ours, its variants, the
    baselines, plug-ins), a record, or a plain callable with the method signature (then a
    record named after it, with no options, as an entry point's callable)."""
    if isinstance(method, (str, Method)):
        return get_method(method)
    if callable(method):
        return records_of(method, getattr(method, "__name__", "method"))[0]
    raise InputError(f"method must be a method name, a method record or a callable, got {method!r}")


def reload() -> None:
    """Forget what was found (after installing a distribution in a running process)."""
    _load.cache_clear()


__all__ = [
    "METHOD_GROUP",
    "methods",
    "method_names",
    "get_method",
    "unavailable_methods",
    "group_entry_points",
    "records_of",
    "distribution_of",
    "resolve_method",
    "reload",
]
