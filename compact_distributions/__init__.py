"""compact_distributions: compact distributions of discrete elements (Chen, Yang & Yang 2019).

The declared public API::

    import compact_distributions as cd

    problem = cd.problem(n_elements=1000, size=512, element="square", seed=1)
    result = cd.run(problem, "ours-compact", backend="opencl")
    print(result.coverage, result.overlap, result.method_seconds)

    mosaic = cd.mosaic("picture.jpg", n_elements=2000, backend="opencl")
    mosaic.render().save("mosaic.png")

``run`` and ``mosaic`` take a backend by name (started and closed for the call) or a live
backend (left open); ``get_method`` / ``method_names`` read the one registry of method
records (plug-ins included), ``create_backend`` / ``backend_names`` the backends.  Bad
input raises :class:`InputError` naming the argument; a backend that cannot start raises
:class:`BackendUnavailable`.  Everything else lives in the subpackages ``cvt`` (the
core), ``backends``, ``baselines`` and ``bench`` (the command line, ``cvtbench``).

The names are loaded on first use, so that importing one of the subpackages does not
import the others.
"""

from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING, Any

try:
    __version__ = version("compact-distributions")
except PackageNotFoundError:  # a source tree that was not installed
    __version__ = "0+unknown"

# public name -> "module:attribute" (module relative to this package)
_NAMES = {
    "run": "bench.api:run",
    "mosaic": "bench.api:mosaic",
    "problem": "bench.api:problem",
    "RunResult": "bench.api:RunResult",
    "get_method": "cvt.registry:get_method",
    "method_names": "cvt.registry:method_names",
    "Method": "cvt.methods:Method",
    "MethodOption": "cvt.methods:MethodOption",
    "create_backend": "backends:create_backend",
    "backend_names": "backends:variant_names",
    "Backend": "backends.base:Backend",
    "Problem": "cvt.problem:Problem",
    "Grid": "cvt.problem:Grid",
    "make_metric": "cvt.metrics:make_metric",
    "evaluate": "cvt.evaluate:evaluate",
    "Distribution": "cvt.distribution:Distribution",
    "MosaicResult": "cvt.mosaic.pipeline:MosaicResult",
    "InputError": "cvt.errors:InputError",
    "BackendUnavailable": "cvt.errors:BackendUnavailable",
    "PluginError": "cvt.errors:PluginError",
}

# written out (the same names as _NAMES, tests/test_api_docs.py checks) so that type
# checkers know what the package exports
__all__ = [
    "__version__",
    "run",
    "mosaic",
    "problem",
    "RunResult",
    "get_method",
    "method_names",
    "Method",
    "MethodOption",
    "create_backend",
    "backend_names",
    "Backend",
    "Problem",
    "Grid",
    "make_metric",
    "evaluate",
    "Distribution",
    "MosaicResult",
    "InputError",
    "BackendUnavailable",
    "PluginError",
]

if TYPE_CHECKING:  # the same names for type checkers, which do not run __getattr__
    from .backends import create_backend as create_backend
    from .backends import variant_names as backend_names
    from .backends.base import Backend as Backend
    from .bench.api import RunResult as RunResult
    from .bench.api import mosaic as mosaic
    from .bench.api import problem as problem
    from .bench.api import run as run
    from .cvt.distribution import Distribution as Distribution
    from .cvt.errors import BackendUnavailable as BackendUnavailable
    from .cvt.errors import InputError as InputError
    from .cvt.errors import PluginError as PluginError
    from .cvt.evaluate import evaluate as evaluate
    from .cvt.methods import Method as Method
    from .cvt.methods import MethodOption as MethodOption
    from .cvt.metrics import make_metric as make_metric
    from .cvt.mosaic.pipeline import MosaicResult as MosaicResult
    from .cvt.problem import Grid as Grid
    from .cvt.problem import Problem as Problem
    from .cvt.registry import get_method as get_method
    from .cvt.registry import method_names as method_names


def __getattr__(name: str) -> Any:
    target = _NAMES.get(name)
    if target is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module, _, attr = target.partition(":")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
