"""The method interface and the method record.

A method is a callable

    run(problem, backend, *, iterations=20, progress=None, element=None, gap=0.0, **options)
        -> Distribution

that turns a :class:`~compact_distributions.cvt.problem.Problem` into placed elements;
``backend`` is a live :class:`~compact_distributions.backends.base.Backend` (methods
that do not use one accept it and ignore it).  Everything that compares methods (the
sweeps, ``cvtbench run``, the mosaics) calls them through this one signature, so a new
method is one module.  The paper's method and its variants are records in
:mod:`compact_distributions.cvt.placement.ours`, the baselines in
:mod:`compact_distributions.baselines`; the registry finds both through entry points.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from .errors import InputError, PluginError, exception_line, kind_of
from .metrics import REFERENCE_SHAPE

if TYPE_CHECKING:
    from .distribution import Distribution
    from .problem import Problem
_PACKAGE = __name__.split(".")[0]  # code of this suite: its errors pass the boundary unchanged

# --------------------------------------------------------------------------- records

ROLES = ("paper", "extension", "baseline", "plugin")
# where the sweeps run a method: on every backend variant (its result depends on the
# backend, as ours' does), on the fastest one available (OpenCL, else the reference), or
# on the NumPy reference only
SWEEP_BACKENDS = ("every", "fastest", "reference")


@dataclass(frozen=True)
class MethodOption:
    """One keyword of a method that users may set (``--NAME`` on the command line).

    A method's record declares its options; the command line offers them as flags, the
    API checks them (:meth:`Method.parse_options`) and a run's key and report label name
    them.

    Parameters
    ----------
    name : str
        The keyword the method's ``run`` receives (a Python identifier).
    kind : type
        ``bool`` (a flag), ``int``, ``float`` or ``str``.
    default : object
        The value the method uses when the option is not given (shown in ``--help``).
    help : str
        One line for ``--help``.
    check : callable or None, optional
        ``check(value, name) -> parsed value``, raising InputError naming ``name``;
        default: ``kind``'s conversion (finite numbers only).
    tag : str or None, optional
        The option's name in a run's key: ``__TAG`` for a set flag, ``__TAGVALUE``
        otherwise; default the name.
    label : str or None, optional
        The option in report rows: a flag's word, or a format such as ``"δ={:g}"``;
        default ``NAME=VALUE``.

    Attributes
    ----------
    flag : str
        The command-line spelling, ``--name-with-dashes``.

    Examples
    --------
    >>> from compact_distributions import MethodOption
    >>> rounds = MethodOption("max_rounds", int, 4, "rounds at most", tag="r")
    >>> rounds.flag
    '--max-rounds'
    >>> rounds.parse("6")
    6
    >>> rounds.key_part(6)
    '__r6'
    """

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

    def parse(self, value: Any, name: str | None = None) -> Any:
        """Check and convert a value given for this option.

        Parameters
        ----------
        value : object
            What the user gave (a string from the command line, or a Python value).
        name : str or None, optional
            How messages name the option; default its flag.

        Returns
        -------
        object
            The value, converted to ``kind`` (or as ``check`` returns it).

        Raises
        ------
        InputError
            If the value does not convert, is not finite, or ``check`` rejects it.
        """
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

    def key_part(self, value: Any) -> str:
        """Return the part of a run's key this option makes with ``value``.

        Parameters
        ----------
        value : object
            The option's parsed value.

        Returns
        -------
        str
            ``__TAG`` for a set flag, empty for an unset one, ``__TAGVALUE`` otherwise.
        """
        tag = self.tag or self.name
        if self.kind is bool:
            return f"__{tag}" if value else ""
        return f"__{tag}{value:g}" if isinstance(value, (int, float)) else f"__{tag}{value}"

    def label_part(self, value: Any) -> str:
        """Return how report rows name this option set to ``value``.

        Parameters
        ----------
        value : object
            The option's parsed value.

        Returns
        -------
        str
            The flag's word (empty when unset), or ``label`` formatted with the value.
        """
        if self.kind is bool:
            return (self.label or self.name) if value else ""
        return (self.label or f"{self.name}={{}}").format(value)


class SweepVariant(NamedTuple):
    """Another option set the sweeps run a method with: on ``elements`` (None: every shape
    the method is compared on), with an effect picture where ``pictured``."""

    options: Mapping[str, Any]
    elements: tuple[str, ...] | None = None
    pictured: bool = False


@dataclass(frozen=True)
class Method:
    """A method as everything else sees it: one record per method.

    The registry (:func:`compact_distributions.get_method`) holds one per method: the
    paper's and its variants, the baselines, other distributions' plug-ins.  Calling
    the record runs the method and times it.

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
    entry_point : str
        The entry point the registry found it through (empty: made in this process).
    distribution : str
        The installed distribution that declares it, as ``name version``.

    Attributes
    ----------
    foreign : bool
        Whether ``run`` is another distribution's code (or a caller's callable): what
        it raises is its failure (:class:`~compact_distributions.cvt.errors.PluginError`),
        not the user's input error.
    who : str
        The method as an error names it (a plug-in with its entry point and
        distribution).

    Raises
    ------
    InputError
        If the name is not a word, ``run`` is not callable, ``role`` or
        ``sweep_backends`` is not one of the known values, an option is declared twice,
        or a sweep variant's options do not parse.

    Examples
    --------
    A method of one's own, run like the registered ones:

    >>> import numpy as np
    >>> import compact_distributions as cd
    >>> def lattice(problem, backend, **common):
    ...     k = int(np.sqrt(problem.n_elements))
    ...     w, h = problem.grid.width, problem.grid.height
    ...     x, y = np.meshgrid((np.arange(k) + 0.5) * w / k, (np.arange(k) + 0.5) * h / k)
    ...     sites = np.stack([x.ravel(), y.ravel()], axis=1)
    ...     n = len(sites)
    ...     return cd.Distribution("lattice", sites, np.zeros(n), np.ones(n))
    >>> record = cd.Method("lattice", lattice, summary="sites on a square lattice")
    >>> dist = record(cd.problem(16, 64), None)
    >>> dist.sites.shape
    (16, 2)
    """

    name: str
    run: Callable[..., Distribution]
    options: tuple[MethodOption, ...] = ()
    fixed_size: bool = False
    paper: str = ""
    year: int | None = None
    paper_table2: tuple[float, str] | None = None
    role: str = "plugin"
    elements: tuple[str, ...] | None = None
    sweep_backends: str = "reference"
    compared_on: tuple[str, ...] | None = (REFERENCE_SHAPE,)
    beyond_paper: tuple[str, ...] = ()
    sweep_variants: tuple[SweepVariant, ...] = ()
    tight: bool = False
    mosaic_options: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    summary: str = ""
    fits: bool = False
    memory: Callable[..., tuple[str, float]] | None = None
    # where the registry found it: the entry point's name and its distribution ("name
    # version"); empty for a record made in the process
    entry_point: str = ""
    distribution: str = ""

    def __post_init__(self) -> None:
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

    def __call__(self, problem: Problem, backend: Any, **options: Any) -> Distribution:
        """Run the method; the Distribution's ``method_seconds`` is the whole call's wall
        time (problem to placed elements), whatever the method measures itself.

        This is the methods' one boundary: what ``run`` returns is checked here
        (:func:`check_distribution`) and recorded under this record's name; a plug-in's
        method that raises, or returns what the suite cannot use, is one
        :class:`~.errors.PluginError` naming it (the suite's own methods' errors pass
        unchanged: an InputError of theirs is the user's)."""
        t0 = time.perf_counter()
        try:
            dist = self.run(problem, backend, **options)
        except KeyboardInterrupt:
            raise
        except BaseException as exc:  # a plug-in's SystemExit or MemoryError is its failure too
            if not self.foreign or isinstance(exc, PluginError):
                raise
            raise PluginError(f"{self.who} raised {exception_line(exc)}") from exc
        check_distribution(dist, problem, self.who)
        dist.method = self.name  # what the run records: the record's (entry point's) name
        dist.method_seconds = time.perf_counter() - t0
        return dist

    @property
    def foreign(self) -> bool:
        """Whether ``run`` is another distribution's code (or a caller's callable).

        Its exceptions are then its failures, not the user's input errors.
        """
        module = getattr(self.run, "__module__", None) or type(self.run).__module__
        return not str(module).startswith(f"{_PACKAGE}.")

    @property
    def who(self) -> str:
        """The method as an error names it: a plug-in with its entry point and distribution."""
        if not self.foreign:
            return f"method {self.name!r}"
        if self.distribution:
            entry = f"entry point {self.entry_point!r} of " if self.entry_point not in ("", self.name) else ""
            return f"method plug-in {self.name!r} ({entry}distribution {self.distribution})"
        module = getattr(self.run, "__module__", None) or "?"
        return f"method {self.name!r} (a callable of module {module}, not an installed plug-in)"

    def option(self, name: str) -> MethodOption | None:
        """Return the declared option ``name``.

        Parameters
        ----------
        name : str
            The option's keyword.

        Returns
        -------
        MethodOption or None
            The option, or None where the method declares none of that name.
        """
        return next((o for o in self.options if o.name == name), None)

    def parse_options(self, values: Mapping[str, Any] | None, flags: bool = False) -> dict[str, Any]:
        """Check option values against the declared options.

        Parameters
        ----------
        values : mapping of str to object, or None
            Option name -> value, as the user gave them.
        flags : bool, optional
            Name options as command-line flags (``--name``) in messages.

        Returns
        -------
        dict of str to object
            Option name -> parsed value, in the order given.

        Raises
        ------
        InputError
            For an undeclared option or a bad value, naming it as the user wrote it.
        """
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

    def key(self, options: Mapping[str, Any]) -> str:
        """Return the part of a run's key that its options make.

        Parameters
        ----------
        options : mapping of str to object
            Parsed option values.

        Returns
        -------
        str
            Each given option's :meth:`MethodOption.key_part`, in declared order.
        """
        return "".join(o.key_part(options[o.name]) for o in self.options if o.name in options)

    def label(self, options: Mapping[str, Any]) -> str:
        """Return how reports name a run of this method with ``options``.

        Parameters
        ----------
        options : mapping of str to object
            Parsed option values.

        Returns
        -------
        str
            The method's name, then each set option's label.
        """
        parts = [o.label_part(options[o.name]) for o in self.options if o.name in options]
        return " ".join([self.name, *[p for p in parts if p]])


# --------------------------------------------------------------------------- the boundary
_CHECK_CHUNK = 4096  # elements whose vertices are checked at once


def check_distribution(dist: object, problem: Problem, who: str = "the method") -> None:
    """Refuse, with one :class:`~.errors.PluginError` naming ``who``, a method's result
    that the suite cannot measure or write: anything but a
    :class:`~.distribution.Distribution`; sites that are not an (N, 2) array of finite
    numbers; angles or scales of another length or not finite; elements that are not
    one shapely polygon (or None) per site, or whose vertices are not finite (elements
    None: no element at any site, and so set); a label
    raster of another size than the problem's, or labels outside -1 .. N-1; timings that
    are not finite.  Whole-array checks (the elements' vertices in one pass).  A
    prepared element (``shapely.prepare``) is replaced by an unprepared copy of it, the
    method's own left as it was."""
    import shapely

    from .distribution import Distribution
    from .threads import own_copy

    def bad(what: str) -> PluginError:
        return PluginError(f"{who} returned {what}")

    if not isinstance(dist, Distribution):
        raise bad(f"{kind_of(dist)}, not a Distribution")
    arrays = {}
    for name in ("sites", "angles", "scales"):
        try:
            arrays[name] = np.asarray(getattr(dist, name), dtype=np.float64)
        except (TypeError, ValueError):
            raise bad(f"{name} that are not numbers ({kind_of(getattr(dist, name))})") from None
    sites = arrays["sites"]
    if sites.ndim != 2 or sites.shape[1] != 2:
        raise bad(f"sites of shape {sites.shape}, not (N, 2)")
    n = len(sites)
    for name, values in arrays.items():
        if name != "sites" and values.shape != (n,):
            raise bad(f"{name} of shape {values.shape} for {n} sites")
        if not np.isfinite(values).all():
            raise bad(f"{name} that are NaN or infinite")
    if dist.elements is None:  # a method that places no elements (a lattice of sites): none at any site
        dist.elements = [None] * n
    elements = dist.elements
    if not isinstance(elements, (list, tuple, np.ndarray)) or len(elements) != n:
        got = (
            f"{len(elements)} elements"
            if isinstance(elements, (list, tuple, np.ndarray))
            else kind_of(elements)
        )
        raise bad(f"{got} for {n} sites (one polygon or None per site)")
    geoms = np.empty(n, dtype=object)
    geoms[:] = list(elements)
    given = ~shapely.is_missing(geoms)  # None: a site without an element
    polygonal = shapely.is_geometry(geoms)
    polygonal[polygonal] = np.isin(shapely.get_type_id(geoms[polygonal]), (3, 6))  # (multi)polygons
    if (given & ~polygonal).any():
        k = int(np.argmax(given & ~polygonal))
        raise bad(f"element {k} that is {kind_of(geoms[k])}, not a polygon")
    placed = np.flatnonzero(given)
    # a few thousand elements at a time: all vertices at once would be a copy of every
    # outline (2 kB per curved element)
    for start in range(0, len(placed), _CHECK_CHUNK):
        part = placed[start : start + _CHECK_CHUNK]
        coords, index = shapely.get_coordinates(geoms[part], return_index=True)
        broken = ~np.isfinite(coords).all(axis=1)
        if broken.any():
            raise bad(f"element {int(part[index[np.argmax(broken)]])} with NaN or infinite vertices")
    # the suite measures and cuts elements on several threads, and GEOS's prepared
    # geometries must not be shared between threads: a prepared element is taken as a copy
    prepared = shapely.is_prepared(geoms)
    if prepared.any():
        geoms[prepared] = own_copy(geoms[prepared])
        dist.elements = list(geoms)
    labels = dist.labels
    if labels is not None:
        grid = problem.grid
        if not isinstance(labels, np.ndarray) or labels.dtype.kind not in "iu":
            raise bad(f"labels that are {kind_of(labels)}, not an integer raster")
        if labels.shape != (grid.height, grid.width):
            raise bad(f"labels of shape {labels.shape} for a {grid.width}x{grid.height} grid")
        if labels.size and (labels.min() < -1 or labels.max() >= n):
            raise bad(f"labels from {labels.min()} to {labels.max()}, outside -1 .. {n - 1}")
    for name in ("seconds", "energy"):
        try:
            values = np.asarray(getattr(dist, name), dtype=np.float64)
        except (TypeError, ValueError):
            raise bad(f"{name} that are not numbers") from None
        if values.ndim != 1 or (name == "seconds" and not np.isfinite(values).all()):
            raise bad(f"{name} that are not a list of finite numbers")
    for name in ("setup_seconds", "lloyd_seconds"):
        value = getattr(dist, name)
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float, np.number))
            or not np.isfinite(value)
        ):
            raise bad(f"{name} {value!r}, not a finite number")
    if not isinstance(dist.extra, dict):
        raise bad(f"extra that is {kind_of(dist.extra)}, not a dict")


def __getattr__(name: str) -> Any:
    # the paper's own methods moved to ``cvt.placement.ours``; their old names keep
    # working for one release
    if name in _MOVED:
        import importlib
        import warnings

        warnings.warn(
            f"compact_distributions.cvt.methods.{name} moved to "
            f"compact_distributions.cvt.placement.ours.{name}; the old path goes in the next release",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(importlib.import_module(".placement.ours", __package__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


_MOVED = frozenset(
    {
        "OURS",
        "OURS_FIT",
        "OURS_COMPACT",
        "METHODS",
        "run_ours",
        "run_ours_fit",
        "run_ours_compact",
        "density_caps",
        "compaction_memory",
        "MOSAIC_COMPACTION_ROUNDS",
        "COMPACTION_PER_SITE",
        "COMPACTION_DENSITY_FACTOR",
    }
)

__all__ = ["Method", "MethodOption", "SweepVariant", "ROLES", "SWEEP_BACKENDS", "check_distribution"]
