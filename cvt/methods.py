"""The method interface, and the paper's own method.

A method is a callable

    run(problem, backend, *, iterations=20, progress=None, element=None, gap=0.0, **options)
        -> Distribution

that turns a :class:`~compact_distributions.cvt.problem.Problem` into placed elements;
``backend`` is a live :class:`~compact_distributions.backends.base.Backend` (methods
that do not use one accept it and ignore it).  Everything that compares methods (the
sweeps, ``cvtbench run``, the mosaics) calls them through this one signature, so a new
method is one module.  ``METHODS`` holds the variants of the paper's method; the
baselines are registered in ``compact_distributions.baselines.REGISTRY``.
"""

from __future__ import annotations

import math
import time

from .distribution import Distribution
from .lloyd import final_labels, lloyd
from .placement import element_for, parse_gap, place_elements
from .problem import Problem


def run_ours(problem: Problem, backend, *, iterations: int = 20, progress=None,
             element: str | None = None, gap: float = 0.0, fit: str = "site") -> Distribution:
    """The paper's method: Lloyd relaxation under the metric whose unit ball is the
    element's shape, on any backend, then one element per cell (cvt.placement).

    ``element`` (default: the metric's own shape) and ``gap`` (grout, px) are for placing
    the elements; ``fit`` "site" centres each element at its site (the default, "ours"),
    "centre" moves it inside its cell to grow it (``cvt.placement.fit_centres``,
    method "ours-fit").  ``total_seconds`` covers the Lloyd iterations only (what the paper's
    timings measure); the final labelling and the placement are timed apart in
    ``extra`` (``final_label_seconds``, ``placement_seconds``)."""
    shape, turn = element_for(problem.metric, element)
    gap = parse_gap(gap)
    t0 = time.perf_counter()
    res = lloyd(problem, backend, iterations, progress=progress)
    total = time.perf_counter() - t0
    t1 = time.perf_counter()
    labels = final_labels(problem, backend, res)
    t2 = time.perf_counter()
    elements = place_elements(labels, res.sites, res.angles + turn, shape, problem.metric.aspect,
                              problem.grid, gap, fit=fit)
    t3 = time.perf_counter()
    return Distribution(
        method="ours" if fit == "site" else "ours-fit", sites=res.sites, angles=res.angles, scales=res.scales,
        elements=elements, energy=res.energy, seconds=res.seconds, total_seconds=total,
        empty=res.empty, empty_sites=res.empty_sites, labels=labels,
        extra={"element": shape, "element_turn_deg": round(math.degrees(turn), 6),
               "gap": gap, "final_label_seconds": t2 - t1, "placement_seconds": t3 - t2},
    )


def run_ours_fit(problem: Problem, backend, **options) -> Distribution:
    """Ours, with each element's centre moved inside its cell to the place where it can
    be largest (the paper's "adjust the size ... based on the contour", §3.4)."""
    return run_ours(problem, backend, fit="centre", **options)


METHODS = {"ours": run_ours, "ours-fit": run_ours_fit}
