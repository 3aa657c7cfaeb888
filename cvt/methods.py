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
from typing import Any, NamedTuple

import numpy as np

from .errors import InputError
from .metrics import REFERENCE_SHAPE

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
    compared_on: tuple[str, ...] | None = (REFERENCE_SHAPE,)
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


def __getattr__(name: str):
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

__all__ = ["Method", "MethodOption", "SweepVariant", "ROLES", "SWEEP_BACKENDS"]
