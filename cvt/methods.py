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

import numpy as np

from .alternate import alternate_triangles, alternating_turns, check_alternate
from .compaction import compact
from .distribution import Distribution
from .errors import InputError
from .lloyd import LloydSetup, final_labels, lloyd
from .placement import element_for, fit_centres, parse_gap, place_elements
from .problem import Problem
from .shapes import PACKING_DENSITY, element_polygons


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


# ours-compact under a density: each size capped at (1 + slack) × the size that follows the
# density exactly (see density_caps); without caps compaction grows elements by the room
# around them, not by the density, and the sizes' spread about the density grows
DENSITY_CAP_SLACK = 0.02


def density_caps(problem: Problem, centres, sizes, shape: str, aspect: float, slack: float,
                 packing: float = 1.0) -> np.ndarray:
    """(N,) size caps that follow the density: κ·s_i·(1 + ``slack``), s_i the density's
    size factor at element i's centre and κ the size at which elements of size κ·s_i (the
    placed ones, ``sizes`` > 0) would together have ``packing`` × the region's area (the
    shape's densest packing, ``cvt.shapes.PACKING_DENSITY``: caps no element can reach
    would not bind)."""
    import shapely

    from .shapes import unit_outline

    s = problem.scales_at(centres)
    unit_area = float(shapely.area(shapely.Polygon(unit_outline(shape, aspect))))
    weight = float(np.sum(s[np.asarray(sizes) > 0] ** 2)) * unit_area
    kappa = math.sqrt(packing * problem.grid.pixel_count / weight) if weight > 0 else 1.0
    return kappa * s * (1.0 + slack)


def run_ours_compact(problem: Problem, backend, *, iterations: int = 20, progress=None,
                     element: str | None = None, gap: float = 0.0, alternate: bool = False,
                     rounds: int = 4, density_slack: float | None = DENSITY_CAP_SLACK,
                     turn_to_field: bool = True) -> Distribution:
    """Ours, then compaction: Lloyd as ``ours``, each element fitted in its cell from
    several starts (``cvt.placement.fit_centres``), then rounds of a linear program in
    which neighbouring elements share their walls (``cvt.compaction.compact``): every pair
    keeps ``gap`` px, the region's border ``gap``/2, angles stay the field's and sizes
    keep the density's contrast; after the last round each element is turned to the
    field at its own centre (compaction moves it off its site) and shrunk where that
    turn made it overlap.

    ``alternate`` (triangles only) lets each triangle point either way: half the sites
    are turned by 180° during Lloyd, so that cells take both shapes, and each cell keeps
    the orientation whose triangle fits larger (``cvt.alternate``).  ``rounds``: at most
    this many compaction rounds.  The compaction's time and rounds are in ``extra``.

    Under a density, each element starts at and grows to at most its cap of
    :func:`density_caps` (``density_slack`` above the size that follows the density;
    None: no caps), so that compaction keeps the sizes the density asks for.
    ``turn_to_field``: under a field, turn each element to the field at its final centre
    and run one more round (False: elements keep their sites' angles).

    Where the problem has thin walls (``Problem.walls``), elements come up to the walls'
    centre lines (G/2 off them) instead of stopping at their pixels."""
    shape, turn = element_for(problem.metric, element)
    check_alternate(shape, alternate)
    gap = parse_gap(gap)
    spacing = float(np.sqrt(problem.grid.pixel_count / problem.n_elements))
    if gap >= spacing:
        raise InputError(f"gap {gap:g} px is not smaller than the elements: {problem.n_elements} elements in "
                         f"{problem.grid.pixel_count} px are about {spacing:.3g} px apart")
    setup = LloydSetup.of(problem)
    if alternate:
        turns = alternating_turns(problem.n_elements, problem.seed)
        setup = LloydSetup.of(problem, angles_at=lambda sites: problem.angles_at(sites) + turns)
    aspect = problem.metric.aspect
    t0 = time.perf_counter()
    res = lloyd(problem, backend, iterations, progress=progress, setup=setup)
    total = time.perf_counter() - t0
    t1 = time.perf_counter()
    labels = final_labels(problem, backend, res, setup=setup)
    t2 = time.perf_counter()
    angles = res.angles + turn
    if alternate:
        angles, centres, sizes = alternate_triangles(labels, res.sites, angles, aspect, gap)
    else:
        centres, sizes = fit_centres(labels, res.sites, angles, shape, aspect, gap)
    t3 = time.perf_counter()
    caps = None
    if problem.density is not None and density_slack is not None:
        # triangles that point either way tile the plane; one way, they pack at 2/3
        packing = 1.0 if alternate else PACKING_DENSITY[shape]
        caps = density_caps(problem, centres, sizes, shape, aspect, density_slack, packing)
        sizes = np.minimum(sizes, caps)
    packed = compact(centres, angles, sizes, shape, aspect, problem.grid, gap=gap, walls=problem.walls,
                     rounds=rounds, max_sizes=caps)
    if turn_to_field and problem.field is not None:
        # compaction moved the elements off their sites: turn each by the field's change
        # between its site and its centre, then shrink whatever that turn made overlap
        angles = angles + problem.angles_at(packed.centres) - problem.angles_at(res.sites)
        turned = compact(packed.centres, angles, packed.sizes, shape, aspect, problem.grid, gap=gap,
                         walls=problem.walls, rounds=1, max_sizes=caps)
        packed.centres, packed.sizes = turned.centres, turned.sizes
        packed.dropped += turned.dropped
    placed = np.flatnonzero(packed.sizes > 0)
    elements = np.full(len(res.sites), None, dtype=object)
    if len(placed):
        elements[placed] = element_polygons(shape, aspect, packed.centres[placed], angles[placed],
                                            packed.sizes[placed])
    return Distribution(
        method="ours-compact", sites=res.sites, angles=angles - turn, scales=res.scales,
        elements=elements.tolist(), energy=res.energy, seconds=res.seconds, total_seconds=total,
        empty=res.empty, empty_sites=res.empty_sites, labels=labels,
        extra={"element": shape, "element_turn_deg": round(math.degrees(turn), 6), "gap": gap,
               "alternate": bool(alternate), "final_label_seconds": t2 - t1, "fit_seconds": t3 - t2,
               "placement_seconds": time.perf_counter() - t2, **packed.as_dict()},
    )


METHODS = {"ours": run_ours, "ours-fit": run_ours_fit, "ours-compact": run_ours_compact}
