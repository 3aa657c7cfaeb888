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
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
import numpy.typing as npt

from compact_distributions.cvt.errors import InputError, PluginError, exception_line, kind_of
from compact_distributions.cvt.metrics import Metric
from compact_distributions.cvt.moments import Moments, moments_from_labels
from compact_distributions.cvt.placement.fit import FitCells, search_on_host
from compact_distributions.cvt.problem import Grid
from compact_distributions.cvt.resources import RUNTIME

if TYPE_CHECKING:
    from typing_extensions import Self


T = TypeVar("T")  # what a guarded call returns


class Backend(ABC):
    """How a CVT iteration's labels and moments are computed: the base of every backend.

    A subclass sets ``name``, implements :meth:`device` and ``_label(sites, angles,
    scales, metric, grid)`` (and ``_moments`` if it can sum on its device), and raises
    :class:`~compact_distributions.BackendUnavailable` from its constructor when its
    runtime is missing.  The public calls check their inputs here, once, and hand the
    subclass clean float64 arrays.  A backend is a context manager that releases its
    device on exit; :func:`compact_distributions.create_backend` makes one by name.

    Attributes
    ----------
    name : str
        The backend's registry name (``numpy``, ``opencl``, ``gl``, ``ckdtree``).
    metrics : tuple of str or None
        The metrics it computes; None: every one.
    bytes_per_pixel : float
        Peak host memory per raster pixel of one labelling with its moments.
    bytes_per_site : float
        Peak host memory per site of one labelling with its moments.
    runtime_bytes : float
        What its runtime adds to the process (LLVM, a compiled kernel).
    variant : str
        The name reports and sweeps use for this backend with its options.
    contained : bool
        Whether its runtime cannot take the process down (NumPy and SciPy only, declared
        by the class itself): a sweep runs it in its own process, others in a worker.
    plugin : str or None
        How errors name a plug-in (its entry point and distribution), set by
        :func:`compact_distributions.create_backend`; None for the suite's own.
    who : str
        The backend as an error names it.

    Examples
    --------
    A backend of one's own: the nearest site by Euclidean distance, for the ``l2``
    metric without angles or sizes, in one whole-array step.

    >>> import numpy as np
    >>> import compact_distributions as cd
    >>> class Nearest(cd.Backend):
    ...     name = "nearest"
    ...     metrics = ("l2",)
    ...     def device(self):
    ...         return "the host's NumPy"
    ...     def _label(self, sites, angles, scales, metric, grid):
    ...         y, x = np.mgrid[: grid.height, : grid.width] + 0.5
    ...         d = np.hypot(x[..., None] - sites[:, 0], y[..., None] - sites[:, 1])
    ...         return np.where(grid.inside(), d.argmin(axis=-1), -1).astype(np.int32)
    >>> sites = np.array([[4.0, 4.0], [12.0, 4.0]])
    >>> with Nearest() as backend:
    ...     counts = backend.moments(sites, metric=cd.make_metric("l2"), grid=cd.Grid(16, 8))
    >>> counts.count.tolist()
    [64, 64]
    """

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
    # whether its runtime cannot take the process down (NumPy and SciPy only): a sweep
    # runs it in its own process; otherwise (a driver, a compiler, a plug-in) in a worker
    contained: bool = False

    @classmethod
    def memory_estimate(cls, width: int, height: int, n_elements: int) -> float:
        """Estimate the host memory of one CVT iteration on this backend.

        ``cvt.resources`` adds it to the rest of a run's estimate.

        Parameters
        ----------
        width : int
            Raster width in pixels.
        height : int
            Raster height in pixels.
        n_elements : int
            The number of sites.

        Returns
        -------
        float
            Bytes.
        """
        return cls.bytes_per_pixel * width * height + cls.bytes_per_site * n_elements

    @classmethod
    def probe(cls) -> str:
        """Start the backend once and describe the device it would use.

        Returns
        -------
        str
            The device's description, as :meth:`device` gives it.

        Raises
        ------
        BackendUnavailable
            If the backend's runtime is missing.
        """
        with cls() as backend:
            return backend.device()

    @property
    def variant(self) -> str:
        """The name reports and sweeps use for this backend with its options."""
        return self.name

    @abstractmethod
    def device(self) -> str:
        """Describe the device this backend runs on (recorded in result.json).

        Returns
        -------
        str
            Human-readable: the platform, the device's name.
        """

    def supports(self, metric: Metric, angles: np.ndarray, scales: np.ndarray) -> str | None:
        """Say whether this backend computes these inputs exactly.

        Parameters
        ----------
        metric : Metric
            The distance.
        angles : numpy.ndarray
            (N,) float64 angles, radians.
        scales : numpy.ndarray
            (N,) float64 size factors.

        Returns
        -------
        str or None
            None if it does, else why not (the base class: a metric outside
            ``metrics``).
        """
        if self.metrics is not None and metric.name not in self.metrics:
            return f"metric {metric.name!r} is not supported (only {', '.join(self.metrics)})"
        return None

    # ------------------------------------------------------------------ the calls
    def label(
        self,
        sites: npt.ArrayLike,
        *,
        angles: npt.ArrayLike | None = None,
        scales: npt.ArrayLike | None = None,
        metric: Metric,
        grid: Grid,
    ) -> np.ndarray:
        """Label every pixel of the region with its nearest site.

        Pixel (i, j) is measured at its centre (j + 0.5, i + 0.5); site k's distance
        is ``gauge(R(-angles[k])(x - sites[k])) / scales[k]``; ties go to the lower
        index.

        Parameters
        ----------
        sites : array_like
            (N, 2) sites in pixel units.
        angles : array_like or None, optional
            (N,) angles in radians (default zeros).
        scales : array_like or None, optional
            (N,) size factors > 0 (default ones).
        metric : Metric
            The distance (:func:`compact_distributions.make_metric`).
        grid : Grid
            The raster and its region.

        Returns
        -------
        numpy.ndarray
            (H, W) int32 labels, -1 outside the region.

        Raises
        ------
        InputError
            If an input has the wrong shape or type, is not finite, a scale is not
            positive, or this backend does not support the inputs.
        """
        sites, angles, scales = self.check_inputs(sites, angles, scales, metric, grid)
        return self._checked_labels(sites, angles, scales, metric, grid)

    def moments(
        self,
        sites: npt.ArrayLike,
        *,
        angles: npt.ArrayLike | None = None,
        scales: npt.ArrayLike | None = None,
        metric: Metric,
        grid: Grid,
    ) -> Moments:
        """Sum each site's cell: the integer moments of the labels of :meth:`label`.

        Parameters
        ----------
        sites : array_like
            (N, 2) sites in pixel units.
        angles : array_like or None, optional
            (N,) angles in radians (default zeros).
        scales : array_like or None, optional
            (N,) size factors > 0 (default ones).
        metric : Metric
            The distance.
        grid : Grid
            The raster and its region.

        Returns
        -------
        Moments
            Per site, the pixel count and the sums of pixel indices (integers, so that
            backends with equal labels give bit-identical centroids).

        Raises
        ------
        InputError
            As :meth:`label`.
        """
        sites, angles, scales = self.check_inputs(sites, angles, scales, metric, grid)
        found = self._guarded("computing moments", self._moments, sites, angles, scales, metric, grid)
        return self.check_moments(found, len(sites), grid)

    def walled_moments(
        self,
        sites: npt.ArrayLike,
        *,
        angles: npt.ArrayLike | None = None,
        scales: npt.ArrayLike | None = None,
        metric: Metric,
        grid: Grid,
    ) -> Moments | None:
        """Sum each site's cell cut to one 4-connected piece.

        The moments ``moments_from_labels(cvt.mosaic.split_cells(labels, sites), N)``
        gives: a backend that finds the pieces on its device saves the host from reading
        the raster.

        Parameters
        ----------
        sites : array_like
            (N, 2) sites in pixel units.
        angles : array_like or None, optional
            (N,) angles in radians (default zeros).
        scales : array_like or None, optional
            (N,) size factors > 0 (default ones).
        metric : Metric
            The distance.
        grid : Grid
            The raster and its region.

        Returns
        -------
        Moments or None
            The moments, or None where the backend has no path of its own for them
            (the caller then splits the labels on the host, as
            ``cvt.mosaic.WalledBackend`` does).

        Raises
        ------
        InputError
            As :meth:`label`.
        """
        sites, angles, scales = self.check_inputs(sites, angles, scales, metric, grid)
        found = self._guarded(
            "computing walled moments", self._walled_moments, sites, angles, scales, metric, grid
        )
        return None if found is None else self.check_moments(found, len(sites), grid)

    def _walled_moments(
        self, sites: np.ndarray, angles: np.ndarray, scales: np.ndarray, metric: Metric, grid: Grid
    ) -> Moments | None:
        """None: no path of its own (see :meth:`walled_moments`)."""
        return None

    @abstractmethod
    def _label(
        self, sites: np.ndarray, angles: np.ndarray, scales: np.ndarray, metric: Metric, grid: Grid
    ) -> np.ndarray:
        """The labels, from checked inputs."""

    def _moments(
        self, sites: np.ndarray, angles: np.ndarray, scales: np.ndarray, metric: Metric, grid: Grid
    ) -> Moments:
        """The default labels and sums on the host."""
        return moments_from_labels(self._checked_labels(sites, angles, scales, metric, grid), len(sites))

    # ------------------------------------------------------------------ the boundary
    # a plug-in (another distribution's backend) is named by backends.create_backend,
    # which sets ``plugin``; what any backend returns is checked here, once per call
    plugin: str | None = None

    @property
    def who(self) -> str:
        """The backend as an error names it: a plug-in with its entry point and distribution."""
        return self.plugin or f"backend {self.variant!r}"

    def _guarded(self, doing: str, call: Callable[..., T], *args: Any) -> T:
        """``call(*args)``; a plug-in's exception is a PluginError naming it (the suite's
        own backends' errors pass unchanged)."""
        if self.plugin is None:
            return call(*args)
        try:
            return call(*args)
        except (KeyboardInterrupt, PluginError):
            raise
        except BaseException as exc:
            raise PluginError(f"{self.who} raised {exception_line(exc)} while {doing}") from exc

    def _checked_labels(
        self, sites: np.ndarray, angles: np.ndarray, scales: np.ndarray, metric: Metric, grid: Grid
    ) -> np.ndarray:
        labels = self._guarded("labelling", self._label, sites, angles, scales, metric, grid)
        return self.check_labels(labels, len(sites), grid)

    def check_labels(self, labels: object, n: int, grid: Grid) -> np.ndarray:
        """Check a label raster this backend returned, once, where it enters the suite.

        Parameters
        ----------
        labels : object
            What the backend returned as labels.
        n : int
            The number of sites they label.
        grid : Grid
            The grid they were computed on.

        Returns
        -------
        numpy.ndarray
            ``labels`` as an (H, W) int32 array.

        Raises
        ------
        PluginError
            Naming this backend, if ``labels`` is not an integer array, has another size
            than ``grid`` or holds a label outside -1 .. n-1.
        """
        if not isinstance(labels, np.ndarray) or labels.dtype.kind not in "iu":
            what = f"{labels.dtype} values" if isinstance(labels, np.ndarray) else kind_of(labels)
            raise PluginError(f"{self.who} returned labels that are {what}, not an integer raster")
        if labels.shape != (grid.height, grid.width):
            raise PluginError(
                f"{self.who} returned labels of shape {labels.shape} for a {grid.width}x{grid.height} "
                f"grid (shape ({grid.height}, {grid.width}))"
            )
        low, high = int(labels.min()), int(labels.max())
        if low < -1 or high >= n:
            raise PluginError(
                f"{self.who} returned labels from {low} to {high} for {n} sites (-1 .. {n - 1})"
            )
        return labels.astype(np.int32, copy=False)

    def check_moments(self, found: object, n: int, grid: Grid) -> Moments:
        """Check the moments this backend returned, once, where they enter the suite.

        Parameters
        ----------
        found : object
            What the backend returned as moments.
        n : int
            The number of sites.
        grid : Grid
            The grid they were computed on.

        Returns
        -------
        Moments
            ``found``, five integer arrays of length ``n``.

        Raises
        ------
        PluginError
            Naming this backend, if ``found`` is not :class:`Moments` of ``n`` sites, a
            count or sum is negative, or a centroid lies off the raster.
        """
        if not isinstance(found, Moments):
            raise PluginError(f"{self.who} returned moments that are {kind_of(found)}, not Moments")
        for name in ("count", "sx", "sy", "sxx", "syy"):
            value = getattr(found, name)
            if not isinstance(value, np.ndarray) or value.dtype.kind not in "iu" or value.shape != (n,):
                what = (
                    f"{value.dtype} values of shape {value.shape}"
                    if isinstance(value, np.ndarray)
                    else kind_of(value)
                )
                raise PluginError(f"{self.who} returned moments whose {name} is {what}, not {n} integers")
        count = found.count
        if (
            (count < 0).any()
            or (found.sx < 0).any()
            or (found.sy < 0).any()
            or (found.sxx < 0).any()
            or (found.syy < 0).any()
            or (found.sx > (grid.width - 1) * count).any()
            or (found.sy > (grid.height - 1) * count).any()
        ):
            raise PluginError(
                f"{self.who} returned moments that no labelling of a {grid.width}x{grid.height} grid "
                "has (a negative count or sum, or a centroid off the raster)"
            )
        return found

    def check_inputs(
        self,
        sites: npt.ArrayLike,
        angles: npt.ArrayLike | None,
        scales: npt.ArrayLike | None,
        metric: Any,
        grid: Any,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Check a call's inputs once, for every backend.

        Parameters
        ----------
        sites : array_like
            (N, 2) sites in pixel units, N >= 1.
        angles : array_like or None
            (N,) angles in radians; None: zeros.
        scales : array_like or None
            (N,) size factors > 0; None: ones.
        metric : Metric
            The distance.
        grid : Grid
            The raster and its region.

        Returns
        -------
        sites : numpy.ndarray
            (N, 2) float64.
        angles : numpy.ndarray
            (N,) float64.
        scales : numpy.ndarray
            (N,) float64.

        Raises
        ------
        InputError
            If ``metric`` or ``grid`` has the wrong type, an array the wrong shape, a
            value is not finite or a scale not positive, or :meth:`supports` refuses.
        """
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
    def fit_search(self, cells: FitCells) -> tuple[np.ndarray, np.ndarray]:
        """Search where each cell's element can be largest (the fit of ``ours-fit``).

        The centre search of ``cvt.placement.fit_centres`` over ``cells``: the host's
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
            The element's size there.
        """
        return search_on_host(cells)

    # ------------------------------------------------------------------ lifetime
    def release_buffers(self) -> None:  # noqa: B027 - optional hook, nothing kept by default
        """Let go of the buffers kept from one call to the next.

        They are made again when next needed: a caller done with the backend for a
        while frees their memory without closing it.
        """

    def close(self) -> None:  # noqa: B027 - optional hook, nothing to release by default
        """Release device resources (contexts, buffers)."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["Backend"]
