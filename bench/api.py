"""The Python API behind ``import compact_distributions as cd``: a problem, a method run
on it, and a mosaic of a picture, each one call (the command line's ``run`` and
``mosaic`` do the same with files)."""

from __future__ import annotations

import contextlib
import numbers
import os
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from compact_distributions.backends import Backend, create_backend
from compact_distributions.cvt.distribution import Distribution
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.evaluate import Evaluation, evaluate
from compact_distributions.cvt.fields import DensityMap, DirectionField
from compact_distributions.cvt.methods import Method
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.problem import Grid, Problem, parse_size
from compact_distributions.cvt.shapes import resolve_shapes
from compact_distributions.cvt.validate import whole_number

if TYPE_CHECKING:
    from compact_distributions.cvt.mosaic.pipeline import MosaicResult
# what each keyword of the API must be (the command line parses text; Python callers pass
# values, and a number given as text is a mistake to name, not to guess at)
_INTEGER = "a whole number (int)"
_REAL = "a real number (int or float)"
_TEXT = "a str"
TYPES = {
    "n_elements": _INTEGER,
    "seed": _INTEGER,
    "iterations": _INTEGER,
    "aspect": _REAL,
    "gap": _REAL,
    "contrast": _REAL,
    "edge_threshold": _REAL,
    "element": _TEXT,
    "metric": _TEXT,
}


def check_types(**values: Any) -> None:
    """InputError naming the first keyword of ``values`` whose value is not of the type
    :data:`TYPES` names (None passes: the default)."""
    for name, value in values.items():
        want = TYPES.get(name)
        if value is None or want is None:
            continue
        if want == _TEXT:
            ok = isinstance(value, str)
        else:
            kind = numbers.Integral if want == _INTEGER else numbers.Real
            ok = isinstance(value, kind) and not isinstance(value, (bool, np.bool_))
        if not ok:
            raise InputError(f"{name} must be {want}, got {value!r}")


def check_option_types(record: Method, values: Mapping[str, Any]) -> None:
    """InputError naming a method option whose value is not of its declared kind (a
    flag a bool, a count an int, a number an int or float, a word a str)."""
    for name, value in values.items():
        opt = record.option(name)
        if opt is None:
            continue  # the record's parse_options names an undeclared option
        if opt.kind is bool:
            ok = isinstance(value, (bool, np.bool_))
        elif opt.kind is int:
            ok = isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
        elif opt.kind is float:
            ok = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
        else:
            ok = isinstance(value, opt.kind)
        if not ok:
            raise InputError(f"{name} must be {'a ' + opt.kind.__name__}, got {value!r}")


@dataclass
class RunResult:
    """A method's run on a problem, with the suite's measures of its elements.

    :func:`compact_distributions.run` returns one.

    Parameters
    ----------
    problem : Problem
        The problem the method ran on.
    distribution : Distribution
        What the method returned: sites, angles, scales, elements, timings.
    evaluation : Evaluation
        The suite's measures of the placed elements (coverage, overlap, ...).
    method_options : dict of str to object
        The method's own options, as parsed from the call.

    Attributes
    ----------
    method : str
        The method's name.
    elements : list of shapely.Polygon or None
        The placed elements, one per site (None where a site has none).
    coverage : float
        Area of the union of the elements inside the region, as a share of the region.
    overlap : float
        Area covered more than once, as a share of the region.
    method_seconds : float
        The whole method's wall time, problem to placed elements.
    """

    problem: Problem
    distribution: Distribution
    evaluation: Evaluation
    method_options: dict[str, Any]

    @property
    def method(self) -> str:
        """The method's name."""
        return self.distribution.method

    @property
    def elements(self) -> list[Any] | None:
        """The placed elements (shapely polygons; None where a site has none)."""
        return self.distribution.elements

    @property
    def coverage(self) -> float:
        """Area of the union of the elements inside the region, as a share of the region."""
        return self.evaluation.coverage

    @property
    def overlap(self) -> float:
        """Area covered more than once, as a share of the region."""
        return self.evaluation.overlap

    @property
    def method_seconds(self) -> float:
        """The whole method's wall time, problem to placed elements."""
        return self.distribution.method_seconds


def problem(
    n_elements: int = 1000,
    size: int | str | tuple[int, int] = 512,
    *,
    element: str | None = None,
    metric: str | None = None,
    aspect: float | None = None,
    seed: int = 0,
    density: DensityMap | None = None,
    field: DirectionField | None = None,
    region: np.ndarray | None = None,
    mask: np.ndarray | None = None,
) -> Problem:
    """Make a problem: ``n_elements`` elements to place on a raster.

    Parameters
    ----------
    n_elements : int, optional
        N, the number of elements (and sites), 1 to the raster's pixels.
    size : int or str or tuple of int, optional
        The raster: ``W`` (a square), ``(W, H)`` or ``"WxH"``, each side 1 to 32768.
    element : str or None, optional
        The element's shape (``square``, ``rectangle``, ``ellipse``, ``triangle``,
        ``circle``, ``hexagon``, ``octagon`` or ``polygon:FILE``).  ``element`` and
        ``metric`` imply each other; neither means squares.
    metric : str or None, optional
        The Lloyd distance (``l2``, ``l1``, ``linf``, ``linf-axial``, ``l2-axial``,
        ``triangle``, ...).
    aspect : float or None, optional
        The β of rectangles and ellipses (the axial metrics), 0.01 to 100; default 0.5.
    seed : int, optional
        Seed of the initial sites.
    density : DensityMap or None, optional
        Size from a density image: denser means smaller elements.
    field : DirectionField or None, optional
        Direction of each element from a field.
    region : numpy.ndarray or None, optional
        The region, an (H, W) bool array (its mask), True inside; None: the whole raster.
        The command line's ``--region``.
    mask : numpy.ndarray or None, optional
        Deprecated name of ``region`` (a DeprecationWarning; removed in the next release).

    Returns
    -------
    Problem
        The problem, ready for :func:`run`.

    Raises
    ------
    InputError
        Naming the argument that is out of range or of the wrong kind.

    Examples
    --------
    >>> import compact_distributions as cd
    >>> p = cd.problem(100, (128, 96), element="ellipse", aspect=0.6, seed=1)
    >>> p.grid.shape, p.n_elements, p.metric.name
    ((96, 128), 100, 'l2-axial')
    """
    check_types(n_elements=n_elements, seed=seed, element=element, metric=metric, aspect=aspect)
    if mask is not None:
        if region is not None:
            raise InputError("give the region once: region= (mask= is its deprecated name)")
        warnings.warn("cd.problem(mask=...) is now cd.problem(region=...)", DeprecationWarning, stacklevel=2)
        region = mask
    if isinstance(size, bool) or not isinstance(size, (numbers.Integral, str, tuple, list)):
        raise InputError(f"size must be W, (W, H) or 'WxH', got {size!r}")
    if isinstance(size, (tuple, list)) and len(size) == 2:
        if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in size):
            raise InputError(f"size must be W, (W, H) or 'WxH' with whole numbers, got {size!r}")
        size = f"{size[0]}x{size[1]}"
    width, height = parse_size(str(size) if not isinstance(size, str) else size, "size")
    n_elements = whole_number(n_elements, "n_elements", minimum=1, maximum=width * height)
    metric_name, element_name = resolve_shapes(metric, element)
    return Problem(
        Grid(width, height, region),
        n_elements,
        make_metric(metric_name, aspect),
        density,
        field,
        seed,
        element=element_name,
    )


@contextlib.contextmanager
def _backend(backend: str | Backend) -> Iterator[Backend]:
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
    method: str | Method | Callable[..., Distribution] = "ours",
    *,
    backend: str | Backend = "numpy",
    iterations: int = 20,
    element: str | None = None,
    gap: float = 0.0,
    progress: Callable[[int, int, float], object] | None = None,
    tolerance: float | None = None,
    accelerate: bool = False,
    **method_options: Any,
) -> RunResult:
    """Run a method on a problem and measure its elements.

    Parameters
    ----------
    problem : Problem
        What to place (:func:`problem`).
    method : str or Method or callable, optional
        A name of :func:`compact_distributions.method_names`, a method record, or a
        callable with the method signature ``run(problem, backend, *, iterations,
        progress, element, gap, **options) -> Distribution``.
    backend : str or Backend, optional
        A name of :func:`compact_distributions.backend_names` (started for this call
        and closed after it) or a live backend (left open).
    iterations : int, optional
        Lloyd iterations.
    element : str or None, optional
        The shape placed; default the metric's own.
    gap : float, optional
        Grout between elements, in pixels.
    progress : callable or None, optional
        ``progress(k, iterations, energy)``, called after each Lloyd step.
    tolerance : float or None, optional
        Stop Lloyd once its energy settles (``iterations`` the cap), for the methods whose
        record declares it (ours, ours-fit, ours-compact); ``distribution.extra`` says why
        the loop stopped (``stopped_by``).
    accelerate : bool, optional
        Accelerated Lloyd (:mod:`cvt.accelerate`), for the same methods.
    **method_options
        The method's own declared options (its record's ``options``), such as
        ``rounds=8`` for ``ours-compact``.

    Returns
    -------
    RunResult
        The problem, the method's distribution and the suite's measures.

    Raises
    ------
    InputError
        If ``problem`` is not a Problem, the method is unknown, an option is not one the
        method declares or its value is bad, or the backend does not support the problem.
    BackendUnavailable
        If the backend named cannot start on this machine.

    Examples
    --------
    >>> import compact_distributions as cd
    >>> p = cd.problem(100, 128, element="circle", seed=1)
    >>> result = cd.run(p, "ours-compact", iterations=5, rounds=4)
    >>> len(result.elements), result.coverage > 0.8, result.overlap < 1e-6
    (100, True, True)
    """
    from compact_distributions.cvt.mosaic.pipeline import resolve_method

    if not isinstance(problem, Problem):
        raise InputError(f"problem must be a Problem (compact_distributions.problem(...)), got {problem!r}")
    check_types(iterations=iterations, element=element, gap=gap)
    if progress is not None and not callable(progress):
        raise InputError(f"progress must be a callable or None, got {progress!r}")
    record = resolve_method(method)
    if tolerance is not None:
        method_options["tolerance"] = tolerance
    if accelerate is not False:
        method_options["accelerate"] = accelerate
    check_option_types(record, method_options)
    options = record.parse_options(method_options)
    with _backend(backend) as live:
        dist = record(
            problem, live, iterations=iterations, progress=progress, element=element, gap=gap, **options
        )
    assert dist.elements is not None  # Method.__call__ checked it (None became no element per site)
    return RunResult(problem, dist, evaluate(dist.elements, problem.grid, labels=dist.labels), options)


def mosaic(
    image: str | os.PathLike[str] | npt.ArrayLike, *, backend: str | Backend = "numpy", **options: Any
) -> MosaicResult:
    """Turn a picture into a mosaic of tiles.

    The tiles follow the picture's edges and detail (a direction field and a density
    from the picture), its strong edges are walls, and each tile takes the geometric
    median, in CIELAB, of the picture's colours under it.

    Parameters
    ----------
    image : str or os.PathLike or array_like
        A picture file, or an (H, W, 3) or (H, W) array (8-bit, or floats in 0..1).
    backend : str or Backend, optional
        A name of :func:`compact_distributions.backend_names` (started for this call
        and closed after it) or a live backend (left open).
    **options
        The options of ``compact_distributions.cvt.mosaic.make_mosaic``:
        ``n_elements`` (tiles), ``element`` / ``metric`` (the tile's shape and the
        Lloyd distance), ``aspect``, ``size`` (the raster: default the picture's, long
        side at most 1024), ``gap`` (grout width in pixels; default 5 % of the spacing),
        ``method`` and ``method_options``, ``iterations``, ``seed``, ``use_field``,
        ``use_density``, ``contrast``, ``grout`` (its colour), ``edges``,
        ``edge_threshold``, ``cut``, ``progress``, ``memory_limit``.

    Returns
    -------
    MosaicResult
        The tiles, their colours and the mosaic's measures; ``svg()`` and ``render()``
        draw it.

    Raises
    ------
    InputError
        Naming the option that is out of range, an unreadable picture, or a mosaic
        estimated to need more memory than ``memory_limit``.
    BackendUnavailable
        If the backend named cannot start on this machine.

    Examples
    --------
    >>> import numpy as np
    >>> import compact_distributions as cd
    >>> y, x = np.mgrid[0:48, 0:64]
    >>> picture = np.stack([x * 4, y * 5, np.full_like(x, 128)], axis=-1).astype(np.uint8)
    >>> result = cd.mosaic(picture, n_elements=40, iterations=3)
    >>> result.placed, (result.width, result.height), result.element
    (40, (64, 48), 'square')
    """
    from compact_distributions.cvt.mosaic.pipeline import DEFAULT_METHOD, make_mosaic
    from compact_distributions.cvt.registry import resolve_method

    check_types(**{k: v for k, v in options.items() if k in TYPES})
    if isinstance(options.get("method_options"), dict):
        check_option_types(resolve_method(options.get("method", DEFAULT_METHOD)), options["method_options"])
    with _backend(backend) as live:
        return make_mosaic(image, live, **options)


__all__ = ["TYPES", "check_types", "check_option_types", "RunResult", "problem", "run", "mosaic"]
