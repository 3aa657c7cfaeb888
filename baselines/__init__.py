"""The methods the paper compares against, one module per paper.

Each module opens with a docstring that cites its paper, says what it implements and
where it departs from the paper, and defines ``run`` with the method signature of
:mod:`compact_distributions.cvt.methods`.  ``REGISTRY`` names them; a module is imported
only when its method is asked for.  :func:`get_method` finds any method by name: the
paper's own variants (core) and the baselines.

Adding a baseline: a new module here with ``run(problem, backend, *, iterations,
progress, element, gap, ...)`` and one line in ``REGISTRY``.
"""

from __future__ import annotations

import importlib

from compact_distributions.cvt.methods import METHODS
from compact_distributions.cvt.validate import one_of

# method name -> "module:function"
REGISTRY = {
    "hausner2001": "compact_distributions.baselines.hausner2001:run",
    "fritzsche2005": "compact_distributions.baselines.fritzsche2005:run",
    "smith2005": "compact_distributions.baselines.smith2005:run",
    "hu2016": "compact_distributions.baselines.hu2016:run",
}
# the baselines whose tiles have one fixed size (the tile budget δ applies to them)
FIXED_SIZE = ("hausner2001", "fritzsche2005", "smith2005")


def method_names() -> list[str]:
    """Every method: the paper's variants first, then the baselines."""
    return [*METHODS, *REGISTRY]


def get_method(name: str):
    """The method callable named ``name`` (InputError for an unknown name)."""
    one_of(name, "method", method_names())
    if name in METHODS:
        return METHODS[name]
    module, _, attr = REGISTRY[name].partition(":")
    return getattr(importlib.import_module(module), attr)
