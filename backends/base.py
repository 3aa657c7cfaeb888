"""The backend interface: how a CVT iteration's label raster (and its moments) is computed.

A backend turns sites, their angles and size factors, a metric and a grid into a label
raster: ``(H, W) int32``, the index of the nearest site under
``d_i(x) = gauge(R(-θ_i)(x - p_i)) / s_i`` for every pixel centre inside the region,
ties to the lower index, -1 outside the region.  ``moments`` may run on the device so
that the Lloyd loop need not read the raster back every iteration.

The two calls are keyword-only after the sites, in the core's order (angles, then
scales): both are (N,) float arrays, and a positional swap would run and give wrong
cells.  The base class checks the inputs once and hands the subclass clean float64
arrays through ``_label`` and ``_moments``.  A backend is a context manager that
releases its device on exit.

Adding a backend: a module in this folder with a subclass that sets ``name``, implements
``device`` and ``_label`` (and ``_moments`` if it can sum on the device), raises
:class:`BackendUnavailable` from its constructor when its runtime is missing, and one
line in ``REGISTRY`` (``backends/__init__.py``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.metrics import Metric
from compact_distributions.cvt.moments import Moments, moments_from_labels
from compact_distributions.cvt.placement.fit import FitCells, search_on_host
from compact_distributions.cvt.problem import Grid
from compact_distributions.cvt.resources import RUNTIME


class Backend(ABC):
    name: str = "?"
    metrics: tuple[str, ...] | None = None  # the metrics it computes; None: all six
    # peak host memory of one labelling with its moments (measured, rounded up): the
    # label raster and the moment sums' temporaries on the host; backends that keep
    # less on the host, or more per site, override these
    bytes_per_pixel: float = 40
    bytes_per_site: float = 1_000
    # what its runtime adds to the process: PoCL and llvmpipe load LLVM (~100 MiB) and
    # build a kernel the first time (~120 MiB more); numpy and scipy add nothing
    runtime_bytes: float = RUNTIME

    @classmethod
    def memory_estimate(cls, width: int, height: int, n_elements: int) -> float:
        """Bytes this backend needs for a CVT iteration of ``n_elements`` on ``width`` x
        ``height`` (cvt.resources adds them to the rest of a run's estimate)."""
        return cls.bytes_per_pixel * width * height + cls.bytes_per_site * n_elements

    @classmethod
    def probe(cls) -> str:
        """Describe the device this backend would use; raise BackendUnavailable if the
        runtime is missing."""
        with cls() as backend:
            return backend.device()

    @property
    def variant(self) -> str:
        """The name reports and sweeps use for this backend with its options."""
        return self.name

    @abstractmethod
    def device(self) -> str:
        """Human-readable device description (recorded in result.json)."""

    def supports(self, metric: Metric, angles: np.ndarray, scales: np.ndarray) -> str | None:
        """None if this backend computes these inputs exactly, else why not."""
        if self.metrics is not None and metric.name not in self.metrics:
            return f"metric {metric.name!r} is not supported (only {', '.join(self.metrics)})"
        return None

    # ------------------------------------------------------------------ the calls
    def label(self, sites, *, angles=None, scales=None, metric: Metric, grid: Grid) -> np.ndarray:
        """(H, W) int32 nearest-site labels, -1 outside the region."""
        sites, angles, scales = self.check_inputs(sites, angles, scales, metric, grid)
        return self._label(sites, angles, scales, metric, grid)

    def moments(self, sites, *, angles=None, scales=None, metric: Metric, grid: Grid) -> Moments:
        """Integer moments per site (counts and sums of pixel indices)."""
        sites, angles, scales = self.check_inputs(sites, angles, scales, metric, grid)
        return self._moments(sites, angles, scales, metric, grid)

    def walled_moments(
        self, sites, *, angles=None, scales=None, metric: Metric, grid: Grid
    ) -> Moments | None:
        """The moments of the labels with each cell cut to one 4-connected piece, as
        ``moments_from_labels(cvt.mosaic.split_cells(labels, sites), N)`` gives them, or
        None where the backend has no path of its own for them (the caller then splits
        the labels on the host, as :class:`cvt.mosaic.WalledBackend` does): a backend
        that finds the pieces on its device saves the host from reading the raster."""
        sites, angles, scales = self.check_inputs(sites, angles, scales, metric, grid)
        return self._walled_moments(sites, angles, scales, metric, grid)

    def _walled_moments(self, sites, angles, scales, metric: Metric, grid: Grid) -> Moments | None:
        """None: no path of its own (see :meth:`walled_moments`)."""
        return None

    @abstractmethod
    def _label(
        self, sites: np.ndarray, angles: np.ndarray, scales: np.ndarray, metric: Metric, grid: Grid
    ) -> np.ndarray:
        """The labels, from checked inputs."""

    def _moments(self, sites, angles, scales, metric: Metric, grid: Grid) -> Moments:
        """The default labels and sums on the host."""
        return moments_from_labels(self._label(sites, angles, scales, metric, grid), len(sites))

    def check_inputs(self, sites, angles, scales, metric, grid):
        """(sites (N, 2), angles (N,), scales (N,)) as float64, or InputError."""
        if not isinstance(metric, Metric):
            raise InputError(f"metric must be a Metric (cvt.metrics.make_metric), got {metric!r}")
        if not isinstance(grid, Grid):
            raise InputError(f"grid must be a Grid (cvt.problem.Grid), got {grid!r}")
        sites = np.asarray(sites, dtype=np.float64)
        if sites.ndim != 2 or sites.shape[1] != 2 or len(sites) == 0:
            raise InputError(f"sites must be a non-empty (N, 2) array, got shape {sites.shape}")
        n = len(sites)
        angles = np.zeros(n) if angles is None else np.asarray(angles, dtype=np.float64)
        scales = np.ones(n) if scales is None else np.asarray(scales, dtype=np.float64)
        if angles.shape != (n,) or scales.shape != (n,):
            raise InputError(
                f"{n} sites but angles of shape {angles.shape} and scales of shape {scales.shape}"
            )
        if not np.isfinite(sites).all():
            raise InputError("sites contain NaN or infinite coordinates")
        if not np.isfinite(angles).all():
            raise InputError("angles must be finite numbers (radians)")
        if not (np.isfinite(scales).all() and (scales > 0).all()):
            raise InputError("scales must be finite numbers > 0")
        reason = self.supports(metric, angles, scales)
        if reason is not None:
            raise InputError(f"backend {self.variant!r}: {reason}")
        return sites, angles, scales

    # ------------------------------------------------------------------ the fit
    def fit_search(self, cells: FitCells):
        """The centre search of ``cvt.placement.fit_centres`` over ``cells``: the host's
        (:func:`cvt.placement.search_on_host`, the reference); a backend with a kernel for
        it returns the same centres and sizes.

        Parameters
        ----------
        cells : cvt.placement.FitCells
            The cells, their contour samples, their elements' balls and starts.

        Returns
        -------
        centres : (2, M, 2) float64
            Where each cell's search ends, from each of its two starts.
        sizes : (2, M) float64
            The element's size there."""
        return search_on_host(cells)

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:  # noqa: B027 - optional hook, nothing to release by default
        """Release device resources (contexts, buffers)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


__all__ = ["Backend"]
