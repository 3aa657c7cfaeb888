"""The methods the paper compares against, one module per paper.

Each module opens with a docstring that cites its paper, says what it implements and
where it departs from the paper, defines ``run`` with the method signature of
:mod:`compact_distributions.cvt.methods`, and ends with its record, ``METHOD``
(:func:`.common.baseline`).  :data:`METHODS` lists the records of every module of this
package; the distribution declares it in the entry point group
``compact_distributions.methods``, so the core's one registry
(:mod:`compact_distributions.cvt.registry`) finds the baselines exactly as it finds
another distribution's methods.

Adding a baseline: a new module here, with its ``run`` and its ``METHOD`` record; nothing
else (an option of its own is declared in the record).
"""

from __future__ import annotations

import importlib
import pkgutil

from compact_distributions.cvt.registry import get_method, method_names, methods


def _records() -> list:
    found = []
    for info in pkgutil.iter_modules(__path__):
        if info.name == "common" or info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        record = getattr(module, "METHOD", None)
        if record is not None:
            found.append(record)
    return sorted(found, key=lambda m: (m.year or 9999, m.name))


METHODS = _records()
"""The record of every baseline module, by the year of its paper."""

__all__ = ["METHODS", "get_method", "method_names", "methods"]
