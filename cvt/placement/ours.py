"""The paper's own method and the suite's two extensions of it, as method records.

``ours`` is the paper's method: Lloyd relaxation under the element's metric, then each
element centred at its site, as large as its cell allows.  ``ours-fit`` moves each element
inside its cell to where it can be largest; ``ours-compact`` then compacts them, so that
neighbouring elements share their walls.  The records are found by the method registry
through the ``compact_distributions.methods`` entry point group, like every other method.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np

from ..distribution import Distribution
from ..errors import InputError
from ..fields import sample_at
from ..lloyd import LLOYD_OPTIONS, LloydSetup, final_labels, lloyd
from ..methods import Method, MethodOption, SweepVariant
from ..metrics import SHAPES
from ..problem import Problem
from ..shapes import element_polygons, packing_density, shape_record
from ..validate import whole_number
from .alternate import alternate_triangles, alternating_turns, check_alternate
from .compaction import CompactionSettings, compact
from .fit import element_for, fit_centres, parse_gap, place_elements


def _backend_search(backend):
    """The backend's centre search for ``cvt.placement.fit_centres`` (its ``fit_search``:
    a kernel where it has one), None for the host's (a backend without one)."""
    return getattr(backend, "fit_search", None)


def run_ours(
    problem: Problem,
    backend,
    *,
    iterations: int = 20,
    progress=None,
    element: str | None = None,
    gap: float = 0.0,
    fit: str = "site",
    tolerance: float | None = None,
    accelerate: bool = False,
) -> Distribution:
    """The paper's method: Lloyd relaxation under the metric whose unit ball is the
    element's shape, on any backend, then one element per cell (cvt.placement).

    ``element`` (default: the metric's own shape) and ``gap`` (grout, px) are for placing
    the elements; ``fit`` "site" centres each element at its site (the default, "ours"),
    "centre" moves it inside its cell to grow it (``cvt.placement.fit_centres``,
    method "ours-fit").  ``lloyd_seconds`` covers the Lloyd iterations (what the paper's
    timings measure; the whole method's time is ``method_seconds``, set by the record); the final labelling and the placement are timed apart in
    ``extra`` (``final_label_seconds``, ``placement_seconds``).  ``tolerance`` and
    ``accelerate`` go to :func:`cvt.lloyd.lloyd`; ``extra`` says how its loop ran."""
    shape, turn = element_for(problem.metric, problem.element if element is None else element)
    gap = parse_gap(gap)
    t0 = time.perf_counter()
    res = lloyd(problem, backend, iterations, progress=progress, tolerance=tolerance, accelerate=accelerate)
    total = time.perf_counter() - t0
    t1 = time.perf_counter()
    labels = final_labels(problem, backend, res)
    t2 = time.perf_counter()
    elements = place_elements(
        labels,
        res.sites,
        res.angles + turn,
        shape,
        problem.metric.aspect,
        problem.grid,
        gap,
        fit=fit,
        search=_backend_search(backend),
    )
    t3 = time.perf_counter()
    placed = {"final_label_seconds": t2 - t1, "placement_seconds": t3 - t2}
    method = "ours" if fit == "site" else "ours-fit"
    return _distribution(method, res, res.angles, elements, labels, total, (shape, turn, gap), placed)


def run_ours_fit(problem: Problem, backend, **options) -> Distribution:
    """Ours, with each element's centre moved inside its cell to the place where it can
    be largest (the paper's "adjust the size ... based on the contour", §3.4)."""
    return run_ours(problem, backend, fit="centre", **options)


# ours-compact under a density: each size capped at (1 + slack) × the size that follows the
# density exactly (see density_caps); without caps compaction grows elements by the room
# around them, not by the density, and the sizes' spread about the density grows.  With
# compaction's fairness (elements short of their caps first) 0.03 measured 0.2-0.5 points
# more coverage than 0.02 and a size error still at most ours' (Table 3, 512², N = 1000)
DENSITY_CAP_SLACK = 0.03
# under density caps compaction keeps each move where the caps are steady (within ±growth ×
# the rounds left), which slows it: rounds more than the shape's by default, of which the last
# DENSITY_POINT_ROUNDS against the density read at one pixel.  Six before those: with two
# (as before the last rounds came) hubble_deep_field's circles measured 1.12x ours' size
# error and −1.5 points of coverage, with four 1.06x and −1.1, with six 1.10x and −0.6
DENSITY_EXTRA_ROUNDS = 9
# the caps follow the density's size factor smoothed (Gaussian, in log2) over this many px:
# on fine texture the factor changes from pixel to pixel, and caps that chase it shrink
# elements for a pixel's sake and hold their moves back (steady boxes of one pixel)
DENSITY_CAP_SMOOTH = 1.0
# the size error reads the density at the one pixel under each element's centre, and where
# the density changes within an element (a picture's small bright spots) that differs from
# the smoothed cap: the last rounds follow caps read at one pixel, DENSITY_POINT_SLACK above
# the smoothed caps' factor, and no element ends more than DENSITY_POINT_LIMIT above the cap
# read at its own centre's pixel (shrinking about its centre: no overlap, nothing moves).
# Measured with DENSITY_FAIRNESS and compaction's least steady move 0.2 px; the figures
# are in cvt/placement/compaction.py's module docstring (Sizes and density)
# (hubble_deep_field's circles: a limit of 0.15 measured 1.16x, a slack of 0.1 1.12x)
DENSITY_POINT_ROUNDS = 3
DENSITY_POINT_SLACK = 0.2
DENSITY_POINT_LIMIT = 0.1
# compaction's fairness under these caps (cvt/placement/compaction.py, Sizes and density;
# its default 2): with 2, motorcycle_left's and hubble_deep_field's triangles measured
# 1.13x and 1.17x ours' size error (hubble's circles 1.19x), with 3 0.97x and 0.97x (1.10x)
DENSITY_FAIRNESS = 3.0


@dataclass(frozen=True)
class DensityCaps:
    """Size caps that follow the density wherever an element stands: ``factor`` × the
    density's size factor there, smoothed over ``smooth`` px (:func:`smoothed_scales`;
    ``scales``: those factors where the caller has them).  Compaction reads them at each element's centre every round
    (``cvt.placement.compact``'s ``max_sizes``)."""

    problem: Problem
    factor: float
    smooth: float = DENSITY_CAP_SMOOTH
    scales: np.ndarray | None = field(default=None, compare=False, repr=False)

    def __call__(self, points) -> np.ndarray:
        """(M,) the caps at ``points`` ((M, 2) px): the pixel of :attr:`image` that holds each."""
        return sample_at(self.image, np.asarray(points, dtype=np.float64).reshape(-1, 2)).astype(np.float64)

    @functools.cached_property
    def image(self) -> np.ndarray:
        """(H, W) float32: the cap at every pixel (compaction reads its steady boxes here)."""
        scales = smoothed_scales(self.problem, self.smooth) if self.scales is None else self.scales
        return np.float32(self.factor) * scales


def smoothed_scales(problem: Problem, sigma: float) -> np.ndarray:
    """(H, W) float32: the density's size factor at every pixel (``problem.scales_at``
    there), its log2 smoothed by a Gaussian of ``sigma`` px (0: as it is).

    Parameters
    ----------
    problem : Problem
        A problem with a density.
    sigma : float
        The Gaussian's standard deviation, px.

    Returns
    -------
    numpy.ndarray
        (H, W) float32 size factors.
    """
    density = problem.density
    if density is None:
        raise InputError("DensityCaps needs a problem with a density")
    scales = density.scale_image()
    if sigma <= 0:
        return scales
    from scipy.ndimage import gaussian_filter

    # in place: one picture-sized array besides the filter's own
    np.log2(scales, out=scales)
    scales = gaussian_filter(scales, sigma, mode="nearest")
    return np.exp2(scales, out=scales)


def density_cap_field(
    problem: Problem, centres, sizes, shape: str, aspect: float, slack: float, packing: float = 1.0
) -> DensityCaps:
    """The caps of :func:`density_caps` as a function of position: κ·(1 + ``slack``) × the
    density's (smoothed) size factor, κ fixed by the elements at ``centres`` (the placed ones)."""
    import shapely

    from ..shapes import unit_outline

    scales = smoothed_scales(problem, DENSITY_CAP_SMOOTH)
    s = DensityCaps(problem, 1.0, scales=scales)(centres)
    unit_area = float(shapely.area(shapely.Polygon(unit_outline(shape, aspect))))
    weight = float(np.sum(s[np.asarray(sizes) > 0] ** 2)) * unit_area
    kappa = math.sqrt(packing * problem.grid.pixel_count / weight) if weight > 0 else 1.0
    return DensityCaps(problem, kappa * (1.0 + slack), scales=scales)


def density_caps(
    problem: Problem, centres, sizes, shape: str, aspect: float, slack: float, packing: float = 1.0
) -> np.ndarray:
    """(N,) size caps that follow the density: κ·s_i·(1 + ``slack``), s_i the density's
    size factor at element i's centre (smoothed, :class:`DensityCaps`) and κ the size at which elements of size κ·s_i (the
    placed ones, ``sizes`` > 0) would together have ``packing`` × the region's area (the
    shape's densest packing, the shape record's ``packing``: caps no element can reach
    would not bind)."""
    return density_cap_field(problem, centres, sizes, shape, aspect, slack, packing)(centres)


def run_ours_compact(
    problem: Problem,
    backend,
    *,
    iterations: int = 20,
    progress=None,
    element: str | None = None,
    gap: float = 0.0,
    alternate: bool = False,
    rounds: int | None = None,
    density_slack: float | None = DENSITY_CAP_SLACK,
    turn_to_field: bool = True,
    tolerance: float | None = None,
    accelerate: bool = False,
) -> Distribution:
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
    None: no caps), so that compaction keeps the sizes the density asks for; the caps
    follow the elements (:class:`DensityCaps`: the density smoothed over a pixel, read at
    each centre every round, moves kept where they are steady; compaction's ``fairness``
    ``DENSITY_FAIRNESS``), and ``rounds`` defaults to ``DENSITY_EXTRA_ROUNDS`` (nine) more
    than the shape's.  The last ``DENSITY_POINT_ROUNDS`` of them (three; at most half the
    rounds) follow caps read at one pixel, and no element ends more than
    ``DENSITY_POINT_LIMIT`` (10 %) above the cap read at its own centre's pixel: the size
    error reads the density there (:func:`_cut_to_point`).
    ``turn_to_field``: under a field, turn each element to the field at its final centre
    and run one more round (False: elements keep their sites' angles).

    Where the problem has thin walls (``Problem.walls``), elements come up to the walls'
    centre lines (G/2 off them) instead of stopping at their pixels.  ``tolerance`` and
    ``accelerate`` go to :func:`cvt.lloyd.lloyd`."""
    # under density caps, by default DENSITY_EXTRA_ROUNDS more than the shape's
    extra = DENSITY_EXTRA_ROUNDS if rounds is None and _follows_density(problem, density_slack) else 0
    shape, turn, gap, rounds = _compaction_plan(problem, element, gap, alternate, rounds)
    rounds += extra
    setup = LloydSetup.of(problem)
    if alternate:
        turns = alternating_turns(problem.n_elements, problem.seed)
        setup = LloydSetup.of(problem, angles_at=lambda sites: problem.angles_at(sites) + turns)
    aspect = problem.metric.aspect
    t0 = time.perf_counter()
    converge = dict(tolerance=tolerance, accelerate=accelerate)
    res = lloyd(problem, backend, iterations, progress=progress, setup=setup, **converge)
    total = time.perf_counter() - t0
    t1 = time.perf_counter()
    labels = final_labels(problem, backend, res, setup=setup)
    t2 = time.perf_counter()
    angles, centres, sizes = _fit_in_cells(
        labels, res.sites, res.angles + turn, shape, aspect, gap, alternate, backend
    )
    t3 = time.perf_counter()
    sizes, caps = _capped_by_density(problem, centres, sizes, shape, alternate, density_slack)
    settings = CompactionSettings(gap=gap, rounds=rounds)
    if caps is not None:
        settings = replace(settings, fairness=DENSITY_FAIRNESS)
    packed, angles = _compact_and_turn(
        problem, res.sites, (centres, angles, sizes, caps), shape, settings, turn_to_field
    )
    placed = np.flatnonzero(packed.sizes > 0)
    elements = np.full(len(res.sites), None, dtype=object)
    if len(placed):
        elements[placed] = element_polygons(
            shape, aspect, packed.centres[placed], angles[placed], packed.sizes[placed]
        )
    placement = {
        "alternate": bool(alternate),
        "final_label_seconds": t2 - t1,
        "fit_seconds": t3 - t2,
        "placement_seconds": time.perf_counter() - t2,
        **packed.as_dict(),
    }
    element = (shape, turn, gap)
    return _distribution(
        "ours-compact", res, angles - turn, elements.tolist(), labels, total, element, placement
    )


def _distribution(method, res, angles, elements, labels, lloyd_seconds, element, placement) -> Distribution:
    """The Distribution of a run of ``method``: the Lloyd result ``res``, the sites'
    ``angles``, the placed ``elements``; ``element`` is (shape, its turn, the gap), and
    ``placement`` what the placement records in ``extra`` (its times and figures)."""
    shape, turn, gap = element
    return Distribution(
        method=method,
        sites=res.sites,
        angles=angles,
        scales=res.scales,
        elements=elements,
        energy=res.energy,
        seconds=res.seconds,
        lloyd_seconds=lloyd_seconds,
        empty=res.empty,
        empty_sites=res.empty_sites,
        labels=labels,
        extra={
            "element": shape,
            "element_turn_deg": round(math.degrees(turn), 6),
            "gap": gap,
            **placement,
            **res.convergence(),
        },
    )


def _fit_in_cells(labels, sites, angles, shape, aspect, gap, alternate, backend):
    """Each element fitted in its cell (triangles pointing either way with ``alternate``):
    the angles, centres and sizes."""
    if alternate:
        return alternate_triangles(labels, sites, angles, aspect, gap, search=_backend_search(backend))
    centres, sizes = fit_centres(labels, sites, angles, shape, aspect, gap, search=_backend_search(backend))
    return angles, centres, sizes


def _follows_density(problem: Problem, density_slack) -> bool:
    """Whether ours-compact caps the sizes by the density (:class:`DensityCaps`)."""
    return problem.density is not None and density_slack is not None


def _capped_by_density(problem: Problem, centres, sizes, shape, alternate, density_slack):
    """The sizes capped by :func:`density_caps` under a density, and the caps as a
    function of position (:class:`DensityCaps`; None without a density or with
    ``density_slack`` None)."""
    if not _follows_density(problem, density_slack):
        return sizes, None
    # triangles that point either way tile the plane; one way, they pack at 2/3
    packing = 1.0 if alternate else packing_density(shape)
    caps = density_cap_field(problem, centres, sizes, shape, problem.metric.aspect, density_slack, packing)
    return np.minimum(sizes, caps(centres)), caps


def _compaction_plan(problem: Problem, element, gap, alternate, rounds):
    """ours-compact's element, its turn, the gap and the rounds, each checked."""
    shape, turn = element_for(problem.metric, problem.element if element is None else element)
    check_alternate(shape, alternate)
    gap = parse_gap(gap)
    if rounds is None:
        rounds = shape_record(shape).compaction_rounds
    spacing = float(np.sqrt(problem.grid.pixel_count / problem.n_elements))
    if gap >= spacing:
        raise InputError(
            f"gap {gap:g} px is not smaller than the elements: {problem.n_elements} elements in "
            f"{problem.grid.pixel_count} px are about {spacing:.3g} px apart"
        )
    return shape, turn, gap, rounds


def _compact_and_turn(problem: Problem, sites, placed, shape, settings, turn_to_field):
    """Compaction of the fitted elements ``placed`` (centres, angles, sizes, size caps),
    under size caps its last rounds against the density read at one pixel
    (:func:`_point_caps`), then, under a field, each element turned to the field at its
    final centre and one more round to shrink whatever that turn made overlap.  Returns
    the result and the angles."""
    centres, angles, sizes, caps = placed
    aspect, grid, walls = problem.metric.aspect, problem.grid, problem.walls

    def more(centres, sizes, angles, rounds, caps):
        # rounds of compaction from these centres and sizes
        return compact(
            centres, angles, sizes, shape, aspect, grid, settings, walls=walls, max_sizes=caps, rounds=rounds
        )

    last = 0 if caps is None else min(DENSITY_POINT_ROUNDS, settings.rounds // 2)
    packed = more(centres, sizes, angles, settings.rounds - last, caps)
    if caps is not None:
        caps = _point_caps(problem, caps)
        packed = _cut_to_point(packed, caps)
        packed = packed.followed_by(more(packed.centres, packed.sizes, angles, last, caps))
    if turn_to_field and problem.field is not None:
        # compaction moved the elements off their sites: turn each by the field's change
        # between its site and its centre
        angles = angles + problem.angles_at(packed.centres) - problem.angles_at(sites)
        # the turn's round belongs to the turn: compaction's rounds and times leave it out
        packed = packed.followed_by(more(packed.centres, packed.sizes, angles, 1, caps), counted=False)
    if caps is not None:
        packed = _cut_to_point(packed, caps)
    return packed, angles


def _point_caps(problem: Problem, caps: DensityCaps) -> DensityCaps:
    """Ours-compact's caps for its last rounds under a density: read at one pixel (no
    smoothing), ``DENSITY_POINT_SLACK`` above the factor of the smoothed ``caps``."""
    return DensityCaps(problem, caps.factor * (1 + DENSITY_POINT_SLACK), smooth=0.0)


def _cut_to_point(packed, point: DensityCaps):
    """``packed`` (a :class:`CompactionResult`) with each size cut to at most
    (1 + ``DENSITY_POINT_LIMIT``) × the smoothed caps' factor × the density's size factor
    at its centre's pixel (what the size error reads); ``point``: :func:`_point_caps`."""
    limit = (1 + DENSITY_POINT_LIMIT) / (1 + DENSITY_POINT_SLACK)
    # shrinking an element about its own centre keeps it inside itself: no overlap
    return replace(packed, sizes=np.minimum(packed.sizes, limit * point(packed.centres)))


# compaction's peak per element (near pairs, their directions, the linear program):
# measured 3-6 kB for squares, rectangles and triangles at 16 000-256 000 elements; under a
# density's size contrast (up to 10:1) the larger elements' reach brings more pairs
COMPACTION_PER_SITE = 8_000
COMPACTION_DENSITY_FACTOR = 6


def compaction_memory(pixels: int, n_elements: int, element: str | None, density: bool):
    """The peak memory of ours-compact's compaction (:attr:`Method.memory`).

    Parameters
    ----------
    pixels, n_elements : int
        The raster's pixels (unused: compaction works on the elements) and the sites.
    element : str or None
        The element shape (unused: the figure holds for every shape measured).
    density : bool
        Whether a density makes the elements' sizes differ.

    Returns
    -------
    (str, float)
        The step's name and its bytes.
    """
    factor = COMPACTION_DENSITY_FACTOR if density else 1
    return "compacting the elements", COMPACTION_PER_SITE * factor * n_elements


def _rounds(value, name: str) -> int:
    return whole_number(value, name, minimum=0, maximum=1000)


PAPER_TABLE2 = (0.856, "19 s")  # the paper's own row of its Table 2: "ours"
# tiles turned by a field and stopped by walls settle slower than a plain lattice: two
# more compaction rounds measured +1 point of coverage for +1 s at 2000 tiles
MOSAIC_COMPACTION_ROUNDS = 6

OURS = Method(
    "ours",
    run_ours,
    role="paper",
    sweep_backends="every",
    compared_on=None,
    paper_table2=PAPER_TABLE2,
    options=LLOYD_OPTIONS,
    summary="the paper's method: Lloyd under the element's metric, each element centred at its site",
)
OURS_FIT = Method(
    "ours-fit",
    run_ours_fit,
    role="extension",
    sweep_backends="fastest",
    compared_on=None,
    paper_table2=PAPER_TABLE2,
    options=LLOYD_OPTIONS,
    summary="ours, each element moved inside its cell to where it can be largest",
    fits=True,
)
OURS_COMPACT = Method(
    "ours-compact",
    run_ours_compact,
    role="extension",
    sweep_backends="fastest",
    compared_on=None,
    paper_table2=PAPER_TABLE2,
    tight=True,
    options=(
        MethodOption(
            "alternate",
            bool,
            False,
            "triangles only: each triangle points either way (its "
            "angle or the angle + 180°), whichever fits larger in its cell",
            tag="alt",
            label="alternate",
        ),
        MethodOption(
            "rounds",
            int,
            None,
            "compaction rounds at most (0 to 1000; default: the element's own, "
            + ", ".join(f"{s.name}s {s.compaction_rounds}" for s in SHAPES.values())
            + f"; {DENSITY_EXTRA_ROUNDS} more under a density)",
            check=_rounds,
            tag="r",
            label="rounds={}",
        ),
        *LLOYD_OPTIONS,
    ),
    sweep_variants=(SweepVariant({"alternate": True}, ("triangle",), pictured=True),),
    beyond_paper=tuple(s.name for s in SHAPES.values() if not s.paper),
    # mosaics keep compaction without density caps and field turn: their measured coverage,
    # figures and tests predate them
    mosaic_options=MappingProxyType(
        {"rounds": MOSAIC_COMPACTION_ROUNDS, "density_slack": None, "turn_to_field": False}
    ),
    summary="ours, fitted, then compacted: neighbouring elements share their walls",
    fits=True,
    memory=compaction_memory,
)

METHODS = (OURS, OURS_FIT, OURS_COMPACT)
"""The paper's method and its variants, in the order the reports list them."""

__all__ = [
    "METHODS",
    "OURS",
    "OURS_FIT",
    "OURS_COMPACT",
    "run_ours",
    "run_ours_fit",
    "run_ours_compact",
    "DensityCaps",
    "DENSITY_EXTRA_ROUNDS",
    "DENSITY_CAP_SMOOTH",
    "DENSITY_POINT_ROUNDS",
    "DENSITY_POINT_SLACK",
    "DENSITY_POINT_LIMIT",
    "DENSITY_FAIRNESS",
    "smoothed_scales",
    "density_cap_field",
    "density_caps",
    "MOSAIC_COMPACTION_ROUNDS",
    "COMPACTION_PER_SITE",
    "COMPACTION_DENSITY_FACTOR",
    "compaction_memory",
]
