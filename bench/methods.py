"""Methods: ours (Lloyd under the shape metric on a backend) and the baselines.

A method is a callable
``run(problem, backend, iterations=20, progress=None, element=None, gap=0.0) -> Distribution``;
bench/ treats them all alike.  Baselines register themselves in ``METHODS`` under the
name used by ``cvtbench run --method``.
"""

from __future__ import annotations

import math
import time

from compact_distributions.cvt.distribution import Distribution
from compact_distributions.cvt.lloyd import lloyd
from compact_distributions.cvt.problem import Problem


def run_ours(problem: Problem, backend, iterations: int = 20, progress=None,
             element: str | None = None, gap: float = 0.0, fit: str = "site") -> Distribution:
    """The paper's method: Lloyd relaxation under the metric whose unit ball is the
    element's shape, on any backend, then one element per cell (cvt.placement).

    ``element`` (default: the metric's own shape) and ``gap`` (grout, px) are for placing
    the elements; ``fit`` "site" centres each element at its site (the default, "ours"),
    "centre" moves it inside its cell to grow it (``cvt.placement.fit_centres``,
    method "ours-fit").  ``total_seconds`` covers the Lloyd iterations only (what the paper's
    timings measure); the final labelling and the placement are timed apart in
    ``extra`` (``final_label_seconds``, ``placement_seconds``)."""
    from compact_distributions.cvt.lloyd import final_labels
    from compact_distributions.cvt.placement import element_for, parse_gap, place_elements

    shape, turn = element_for(problem.metric, element)
    gap = parse_gap(gap)
    t0 = time.perf_counter()
    res = lloyd(problem, backend, iterations, progress=progress)
    total = time.perf_counter() - t0
    t1 = time.perf_counter()
    labels = final_labels(problem, backend, res)
    t2 = time.perf_counter()
    elements = place_elements(labels, res.sites, res.angles + turn, res.scales, shape,
                              problem.metric.aspect, problem.grid, gap, fit=fit)
    t3 = time.perf_counter()
    return Distribution(
        method="ours" if fit == "site" else "ours-fit", sites=res.sites, angles=res.angles, scales=res.scales,
        elements=elements, energy=res.energy, seconds=res.seconds, total_seconds=total,
        empty=res.empty, empty_sites=res.empty_sites, labels=labels,
        extra={"element": shape, "element_turn_deg": round(math.degrees(turn), 6),
               "gap": gap, "final_label_seconds": t2 - t1, "placement_seconds": t3 - t2},
    )


def run_ours_fit(problem: Problem, backend, iterations: int = 20, progress=None,
                 element: str | None = None, gap: float = 0.0) -> Distribution:
    """Ours, with each element's centre moved inside its cell to the place where it can
    be largest (the paper's "adjust the size ... based on the contour", §3.4)."""
    return run_ours(problem, backend, iterations, progress, element, gap, fit="centre")


METHODS = {"ours": run_ours, "ours-fit": run_ours_fit}


def method_names() -> list[str]:
    _load_baselines()
    return list(METHODS)


def get_method(name: str):
    from compact_distributions.cvt.errors import InputError

    _load_baselines()
    if name not in METHODS:
        raise InputError(f"unknown method {name!r}; choose one of {', '.join(METHODS)}")
    return METHODS[name]


def _load_baselines() -> None:
    """Import baselines/ so that each registers itself (a no-op when none exist yet)."""
    import importlib
    import pkgutil

    from compact_distributions import baselines

    for mod in pkgutil.iter_modules(baselines.__path__):
        importlib.import_module(f"baselines.{mod.name}")
