"""The method interface, the method record, and the paper's own method.

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
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, NamedTuple

import numpy as np

from .alternate import alternate_triangles, alternating_turns, check_alternate
from .compaction import compact
from .distribution import Distribution
from .errors import InputError
from .lloyd import LloydSetup, final_labels, lloyd
from .metrics import SHAPES
from .placement import element_for, fit_centres, parse_gap, place_elements
from .problem import Problem
from .shapes import element_polygons, packing_density, shape_record
from .validate import whole_number

# --------------------------------------------------------------------------- records

ROLES = ("paper", "extension", "baseline", "plugin")
# where the sweeps run a method: on every backend variant (its result depends on the
# backend, as ours' does), on the fastest one available (OpenCL, else the reference), or
# on the NumPy reference only
SWEEP_BACKENDS = ("every", "fastest", "reference")


@dataclass(frozen=True)
class MethodOption:
    """One keyword of a method that users may set (``--NAME`` on the command line).

    ``kind`` is ``bool`` (a flag), ``int``, ``float`` or ``str``; ``check(value, name)``
    returns the parsed value or raises InputError naming ``name`` (default: ``kind``'s
    conversion).  ``tag`` names the option in a run's key (``__TAG`` for a flag,
    ``__TAGVALUE`` otherwise; default the name) and ``label`` in report rows (a flag's
    word, or a format such as ``"δ={:g}"``; default ``NAME=VALUE``)."""

    name: str
    kind: type
    default: Any
    help: str
    check: Callable[[Any, str], Any] | None = None
    tag: str | None = None
    label: str | None = None

    @property
    def flag(self) -> str:
        """The command-line spelling, ``--name-with-dashes``."""
        return "--" + self.name.replace("_", "-")

    def parse(self, value, name: str | None = None):
        """``value`` checked and converted (InputError naming ``name``, default the flag)."""
        name = name or self.flag
        if self.check is not None:
            return self.check(value, name)
        if self.kind is bool:
            if isinstance(value, (bool, np.bool_)):
                return bool(value)
            raise InputError(f"{name} must be true or false, got {value!r}")
        try:
            parsed = self.kind(value)
        except (TypeError, ValueError):
            raise InputError(f"{name} must be a {self.kind.__name__}, got {value!r}") from None
        if isinstance(parsed, float) and not math.isfinite(parsed):
            raise InputError(f"{name} must be a finite number, got {value!r}")
        return parsed

    def key_part(self, value) -> str:
        tag = self.tag or self.name
        if self.kind is bool:
            return f"__{tag}" if value else ""
        return f"__{tag}{value:g}" if isinstance(value, (int, float)) else f"__{tag}{value}"

    def label_part(self, value) -> str:
        if self.kind is bool:
            return (self.label or self.name) if value else ""
        return (self.label or f"{self.name}={{}}").format(value)


class SweepVariant(NamedTuple):
    """Another option set the sweeps run a method with: on ``elements`` (None: every shape
    the method is compared on), with an effect picture where ``pictured``."""

    options: Mapping
    elements: tuple[str, ...] | None = None
    pictured: bool = False


@dataclass(frozen=True)
class Method:
    """A method as everything else sees it: one record per method.

    Parameters
    ----------
    name : str
        What ``--method`` and the reports call it.
    run : callable
        ``run(problem, backend, *, iterations, progress, element, gap, **options) ->
        Distribution`` (the method interface of this module).
    options : tuple of MethodOption
        The keywords of ``run`` that users may set, beyond the common ones.
    fixed_size : bool
        Whether it places tiles of one fixed size (a tile budget δ applies to them).
    paper : str
        The publication it reimplements (empty for ours).
    year : int or None
        The publication's year (orders the baselines as the paper does).
    paper_table2 : (float, str) or None
        The coverage and time the paper's Table 2 gives for it.
    role : str
        ``paper`` (the paper's method as published), ``extension`` (ours, beyond the
        paper), ``baseline`` (a compared method) or ``plugin`` (another distribution's).
    elements : tuple of str or None
        The element shapes it can place (None: every shape).
    sweep_backends : str
        Where the sweeps run it: ``every`` backend variant, the ``fastest``, or the
        ``reference`` only.
    compared_on : tuple of str or None
        The element shapes Table 2 and the regression checks run it on (None: every shape).
    beyond_paper : tuple of str
        Shapes beyond the paper's five that Table 2 also runs it on by default (rows of
        their own, without the paper's figures).
    sweep_variants : tuple of SweepVariant
        More option sets the sweeps run it with.
    tight : bool
        Its tiles share their walls (compaction), so mosaics cut them to fit along walls.
    mosaic_options : mapping
        Option values a mosaic gives it unless the caller sets them.
    summary : str
        One line for ``--help`` and ``cvtbench info``.
    fits : bool
        It moves elements inside their cells (``cvt.placement.fit_centres``): the memory
        estimate counts the cells' distance transform.
    memory : callable or None
        ``memory(pixels, n_elements, element, density) -> (step, bytes)``: the peak
        memory of its own step beyond placing (``cvt.resources.run_estimate``).
    """

    name: str
    run: Callable
    options: tuple[MethodOption, ...] = ()
    fixed_size: bool = False
    paper: str = ""
    year: int | None = None
    paper_table2: tuple[float, str] | None = None
    role: str = "plugin"
    elements: tuple[str, ...] | None = None
    sweep_backends: str = "reference"
    compared_on: tuple[str, ...] | None = ("square",)
    beyond_paper: tuple[str, ...] = ()
    sweep_variants: tuple[SweepVariant, ...] = ()
    tight: bool = False
    mosaic_options: Mapping = field(default_factory=lambda: MappingProxyType({}))
    summary: str = ""
    fits: bool = False
    memory: Callable | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name or any(c.isspace() for c in self.name):
            raise InputError(f"a method's name must be a word, got {self.name!r}")
        if not callable(self.run):
            raise InputError(f"method {self.name!r}: run must be callable, got {self.run!r}")
        if self.role not in ROLES:
            raise InputError(
                f"method {self.name!r}: role must be one of {', '.join(ROLES)}, got {self.role!r}"
            )
        if self.sweep_backends not in SWEEP_BACKENDS:
            raise InputError(
                f"method {self.name!r}: sweep_backends must be one of {', '.join(SWEEP_BACKENDS)}, "
                f"got {self.sweep_backends!r}"
            )
        for variant in self.sweep_variants:
            self.parse_options(variant.options)
        names = [o.name for o in self.options]
        if len(set(names)) != len(names):
            raise InputError(f"method {self.name!r} declares an option twice: {names}")

    def __call__(self, problem, backend, **options):
        """Run the method; the Distribution's ``method_seconds`` is the whole call's wall
        time (problem to placed elements), whatever the method measures itself."""
        t0 = time.perf_counter()
        dist = self.run(problem, backend, **options)
        dist.method_seconds = time.perf_counter() - t0
        return dist

    def option(self, name: str) -> MethodOption | None:
        """The declared option ``name``, or None."""
        return next((o for o in self.options if o.name == name), None)

    def parse_options(self, values: Mapping, flags: bool = False) -> dict:
        """``values`` (option name -> value) checked against the declared options:
        InputError for an undeclared one or a bad value, naming it as the user wrote it
        (``--name`` where ``flags``)."""
        out = {}
        for name, value in dict(values or {}).items():
            opt = self.option(name)
            shown = ("--" + str(name).replace("_", "-")) if flags else str(name)
            if opt is None:
                declared = ", ".join(o.flag if flags else o.name for o in self.options) or "none"
                raise InputError(
                    f"{shown} is not an option of --method {self.name} (its options: {declared})"
                    if flags
                    else f"method {self.name!r} has no option {name!r} (its options: {declared})"
                )
            out[name] = opt.parse(value, shown)
        return out

    def key(self, options: Mapping) -> str:
        """The part of a run's key that its options make (declared order)."""
        return "".join(o.key_part(options[o.name]) for o in self.options if o.name in options)

    def label(self, options: Mapping) -> str:
        """How reports name a run of it with ``options``: the name, then its set options."""
        parts = [o.label_part(options[o.name]) for o in self.options if o.name in options]
        return " ".join([self.name, *[p for p in parts if p]])


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
) -> Distribution:
    """The paper's method: Lloyd relaxation under the metric whose unit ball is the
    element's shape, on any backend, then one element per cell (cvt.placement).

    ``element`` (default: the metric's own shape) and ``gap`` (grout, px) are for placing
    the elements; ``fit`` "site" centres each element at its site (the default, "ours"),
    "centre" moves it inside its cell to grow it (``cvt.placement.fit_centres``,
    method "ours-fit").  ``lloyd_seconds`` covers the Lloyd iterations (what the paper's
    timings measure; the whole method's time is ``method_seconds``, set by the record); the final labelling and the placement are timed apart in
    ``extra`` (``final_label_seconds``, ``placement_seconds``)."""
    shape, turn = element_for(problem.metric, element)
    gap = parse_gap(gap)
    t0 = time.perf_counter()
    res = lloyd(problem, backend, iterations, progress=progress)
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
    return Distribution(
        method="ours" if fit == "site" else "ours-fit",
        sites=res.sites,
        angles=res.angles,
        scales=res.scales,
        elements=elements,
        energy=res.energy,
        seconds=res.seconds,
        lloyd_seconds=total,
        empty=res.empty,
        empty_sites=res.empty_sites,
        labels=labels,
        extra={
            "element": shape,
            "element_turn_deg": round(math.degrees(turn), 6),
            "gap": gap,
            "final_label_seconds": t2 - t1,
            "placement_seconds": t3 - t2,
        },
    )


def run_ours_fit(problem: Problem, backend, **options) -> Distribution:
    """Ours, with each element's centre moved inside its cell to the place where it can
    be largest (the paper's "adjust the size ... based on the contour", §3.4)."""
    return run_ours(problem, backend, fit="centre", **options)


# ours-compact under a density: each size capped at (1 + slack) × the size that follows the
# density exactly (see density_caps); without caps compaction grows elements by the room
# around them, not by the density, and the sizes' spread about the density grows
DENSITY_CAP_SLACK = 0.02


def density_caps(
    problem: Problem, centres, sizes, shape: str, aspect: float, slack: float, packing: float = 1.0
) -> np.ndarray:
    """(N,) size caps that follow the density: κ·s_i·(1 + ``slack``), s_i the density's
    size factor at element i's centre and κ the size at which elements of size κ·s_i (the
    placed ones, ``sizes`` > 0) would together have ``packing`` × the region's area (the
    shape's densest packing, the shape record's ``packing``: caps no element can reach
    would not bind)."""
    import shapely

    from .shapes import unit_outline

    s = problem.scales_at(centres)
    unit_area = float(shapely.area(shapely.Polygon(unit_outline(shape, aspect))))
    weight = float(np.sum(s[np.asarray(sizes) > 0] ** 2)) * unit_area
    kappa = math.sqrt(packing * problem.grid.pixel_count / weight) if weight > 0 else 1.0
    return kappa * s * (1.0 + slack)


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
    None: no caps), so that compaction keeps the sizes the density asks for.
    ``turn_to_field``: under a field, turn each element to the field at its final centre
    and run one more round (False: elements keep their sites' angles).

    Where the problem has thin walls (``Problem.walls``), elements come up to the walls'
    centre lines (G/2 off them) instead of stopping at their pixels."""
    shape, turn = element_for(problem.metric, element)
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
        angles, centres, sizes = alternate_triangles(
            labels, res.sites, angles, aspect, gap, search=_backend_search(backend)
        )
    else:
        centres, sizes = fit_centres(
            labels, res.sites, angles, shape, aspect, gap, search=_backend_search(backend)
        )
    t3 = time.perf_counter()
    caps = None
    if problem.density is not None and density_slack is not None:
        # triangles that point either way tile the plane; one way, they pack at 2/3
        packing = 1.0 if alternate else packing_density(shape)
        caps = density_caps(problem, centres, sizes, shape, aspect, density_slack, packing)
        sizes = np.minimum(sizes, caps)
    packed = compact(
        centres,
        angles,
        sizes,
        shape,
        aspect,
        problem.grid,
        gap=gap,
        walls=problem.walls,
        rounds=rounds,
        max_sizes=caps,
    )
    if turn_to_field and problem.field is not None:
        # compaction moved the elements off their sites: turn each by the field's change
        # between its site and its centre, then shrink whatever that turn made overlap
        angles = angles + problem.angles_at(packed.centres) - problem.angles_at(res.sites)
        turned = compact(
            packed.centres,
            angles,
            packed.sizes,
            shape,
            aspect,
            problem.grid,
            gap=gap,
            walls=problem.walls,
            rounds=1,
            max_sizes=caps,
        )
        packed.centres, packed.sizes = turned.centres, turned.sizes
        packed.dropped += turned.dropped
    placed = np.flatnonzero(packed.sizes > 0)
    elements = np.full(len(res.sites), None, dtype=object)
    if len(placed):
        elements[placed] = element_polygons(
            shape, aspect, packed.centres[placed], angles[placed], packed.sizes[placed]
        )
    return Distribution(
        method="ours-compact",
        sites=res.sites,
        angles=angles - turn,
        scales=res.scales,
        elements=elements.tolist(),
        energy=res.energy,
        seconds=res.seconds,
        lloyd_seconds=total,
        empty=res.empty,
        empty_sites=res.empty_sites,
        labels=labels,
        extra={
            "element": shape,
            "element_turn_deg": round(math.degrees(turn), 6),
            "gap": gap,
            "alternate": bool(alternate),
            "final_label_seconds": t2 - t1,
            "fit_seconds": t3 - t2,
            "placement_seconds": time.perf_counter() - t2,
            **packed.as_dict(),
        },
    )


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
    summary="the paper's method: Lloyd under the element's metric, each element centred at its site",
)
OURS_FIT = Method(
    "ours-fit",
    run_ours_fit,
    role="extension",
    sweep_backends="fastest",
    compared_on=None,
    paper_table2=PAPER_TABLE2,
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
            + ")",
            check=_rounds,
            tag="r",
            label="rounds={}",
        ),
    ),
    sweep_variants=(SweepVariant({"alternate": True}, ("triangle",), pictured=True),),
    beyond_paper=("hexagon", "octagon"),
    # mosaics keep compaction without density caps and field turn: their measured coverage,
    # figures and tests predate them
    mosaic_options=MappingProxyType(
        {"rounds": MOSAIC_COMPACTION_ROUNDS, "density_slack": None, "turn_to_field": False}
    ),
    summary="ours, fitted, then compacted: neighbouring elements share their walls",
    fits=True,
    memory=compaction_memory,
)

METHODS = {m.name: m for m in (OURS, OURS_FIT, OURS_COMPACT)}
"""The paper's method and its variants, by name (:mod:`.registry` adds the others)."""

__all__ = [
    "Method",
    "MethodOption",
    "SweepVariant",
    "METHODS",
    "OURS",
    "OURS_FIT",
    "OURS_COMPACT",
    "run_ours",
    "run_ours_fit",
    "run_ours_compact",
    "ROLES",
    "SWEEP_BACKENDS",
    "MOSAIC_COMPACTION_ROUNDS",
    "COMPACTION_PER_SITE",
    "COMPACTION_DENSITY_FACTOR",
    "compaction_memory",
]
