"""The Python API behind ``import compact_distributions as cd``: a problem, a method run
on it, and a mosaic of a picture, each one call (the command line's ``run`` and
``mosaic`` do the same with files)."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

from compact_distributions.backends import Backend, create_backend
from compact_distributions.cvt.distribution import Distribution
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.evaluate import Evaluation, evaluate
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.problem import Grid, Problem, parse_size
from compact_distributions.cvt.shapes import resolve_shapes
from compact_distributions.cvt.validate import whole_number


@dataclass
class RunResult:
    """A method's run on a problem: the problem, what the method returned, and the
    suite's measures of its placed elements."""

    problem: Problem
    distribution: Distribution
    evaluation: Evaluation
    method_options: dict

    @property
    def method(self) -> str:
        return self.distribution.method

    @property
    def elements(self) -> list:
        """The placed elements (shapely polygons; None where a site has none)."""
        return self.distribution.elements

    @property
    def coverage(self) -> float:
        return self.evaluation.coverage

    @property
    def overlap(self) -> float:
        return self.evaluation.overlap

    @property
    def method_seconds(self) -> float:
        """The whole method's wall time, problem to placed elements."""
        return self.distribution.method_seconds


def problem(
    n_elements: int = 1000,
    size=512,
    *,
    element: str | None = None,
    metric: str | None = None,
    aspect: float | None = None,
    seed: int = 0,
    density=None,
    field=None,
    mask=None,
) -> Problem:
    """A problem on a ``size`` raster (``W``, ``(W, H)`` or ``"WxH"``) with ``n_elements``.

    ``element`` and ``metric`` imply each other (neither: squares); ``aspect`` is β of
    rectangles and ellipses; ``density`` (:class:`cvt.fields.DensityMap`), ``field``
    (:class:`cvt.fields.DirectionField`) and ``mask`` (an (H, W) bool region) are
    optional."""
    if isinstance(size, (tuple, list)) and len(size) == 2:
        size = f"{size[0]}x{size[1]}"
    width, height = parse_size(str(size) if not isinstance(size, str) else size, "size")
    n_elements = whole_number(n_elements, "n_elements", minimum=1, maximum=width * height)
    metric_name, _ = resolve_shapes(metric, element)
    return Problem(
        Grid(width, height, mask), n_elements, make_metric(metric_name, aspect), density, field, seed
    )


@contextlib.contextmanager
def _backend(backend):
    """A live backend: a name is started here and closed after; a Backend is lent."""
    if isinstance(backend, Backend):
        yield backend
        return
    if not isinstance(backend, str):
        raise InputError(f"backend must be a backend name or a Backend, got {backend!r}")
    with create_backend(backend) as live:
        yield live


def run(
    problem: Problem,
    method="ours",
    *,
    backend="numpy",
    iterations: int = 20,
    element: str | None = None,
    gap: float = 0.0,
    progress=None,
    tolerance: float | None = None,
    accelerate: bool = False,
    **method_options,
) -> RunResult:
    """Run ``method`` (a registered name, a record, or a callable with the method
    signature) on ``problem`` and measure its elements.

    ``element``: the shape placed (default the metric's own); ``gap``: grout in px;
    ``method_options``: the method's own declared options (checked against its record);
    ``progress(k, iterations, energy)`` is called after each Lloyd step.  ``tolerance``
    (stop Lloyd once its energy settles, ``iterations`` the cap) and ``accelerate``
    (accelerated Lloyd) are for the methods whose record declares them (ours, ours-fit,
    ours-compact; :func:`cvt.lloyd.lloyd`); the result's ``distribution.extra`` says
    why the loop stopped (``stopped_by``)."""
    from compact_distributions.cvt.mosaic.pipeline import resolve_method

    if not isinstance(problem, Problem):
        raise InputError(f"problem must be a Problem (compact_distributions.problem(...)), got {problem!r}")
    record = resolve_method(method)
    if tolerance is not None:
        method_options["tolerance"] = tolerance
    if accelerate is not False:
        method_options["accelerate"] = accelerate
    options = record.parse_options(method_options)
    with _backend(backend) as live:
        dist = record(
            problem, live, iterations=iterations, progress=progress, element=element, gap=gap, **options
        )
    return RunResult(problem, dist, evaluate(dist.elements, problem.grid, labels=dist.labels), options)


def mosaic(image, *, backend="numpy", **options):
    """A mosaic of ``image`` (a file path or an array): :func:`cvt.mosaic.make_mosaic` with
    the backend given by name (started and closed here) or live; ``options`` are
    make_mosaic's (``n_elements``, ``element``, ``method``, ``method_options``, ...)."""
    from compact_distributions.cvt.mosaic.pipeline import make_mosaic

    with _backend(backend) as live:
        return make_mosaic(image, live, **options)


__all__ = ["RunResult", "problem", "run", "mosaic"]
