"""What every method returns (ours on any backend, and each baseline), so that bench/
evaluates them all alike."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Distribution:
    """The elements a method placed on a problem, with the record of how it got there.

    Every method (ours on any backend, each baseline, a plug-in) returns one, so that the
    suite measures, writes and compares them all alike.  Arrays are indexed by site:
    site ``k`` carries ``sites[k]``, ``angles[k]``, ``scales[k]`` and ``elements[k]``.

    Parameters
    ----------
    method : str
        The name of the method that made it (as the registry calls it).
    sites : numpy.ndarray
        (N, 2) float, the sites (element centres) in pixel units, x right, y down.
    angles : numpy.ndarray
        (N,) float, each element's turn in radians (positive: clockwise on screen).
    scales : numpy.ndarray
        (N,) float, each site's size factor (1 without a density).
    elements : list of shapely.Polygon or None, optional
        The placed elements, one per site, None where a site has none (an empty or
        degenerate cell); None where the method places no elements.
    energy : list of float, optional
        The CVT energy after each Lloyd iteration.
    seconds : list of float, optional
        The wall time of each Lloyd iteration.
    setup_seconds : float, optional
        Wall time spent before the iterations (excluded from ``lloyd_seconds``).
    lloyd_seconds : float, optional
        Wall time of the Lloyd iterations (the paper's "time").
    method_seconds : float, optional
        Wall time of the whole method, problem to placed elements (set by
        :class:`~compact_distributions.cvt.methods.Method` when it calls the method).
    empty : list of int, optional
        The number of empty cells after each iteration.
    empty_sites : list of int, optional
        The indices of the sites whose cells are empty at the end.
    labels : numpy.ndarray or None, optional
        The final (H, W) int32 label raster, where the method has one (-1 outside the
        region).
    extra : dict, optional
        Method-specific facts, JSON-serialisable (written to result.json as they are).

    Attributes
    ----------
    iterations : int
        The number of Lloyd iterations run (the length of ``seconds``).

    Examples
    --------
    A method that places nothing, as a plug-in might start:

    >>> import numpy as np
    >>> from compact_distributions import Distribution
    >>> sites = np.array([[8.0, 8.0], [24.0, 8.0]])
    >>> dist = Distribution("nothing", sites, np.zeros(2), np.ones(2), seconds=[0.01])
    >>> dist.iterations
    1
    """

    method: str
    sites: np.ndarray
    angles: np.ndarray
    scales: np.ndarray
    elements: list[Any] | None = None
    energy: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    setup_seconds: float = 0.0
    lloyd_seconds: float = 0.0
    method_seconds: float = 0.0
    empty: list[int] = field(default_factory=list)
    empty_sites: list[int] = field(default_factory=list)
    labels: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def iterations(self) -> int:
        """The number of Lloyd iterations run (the length of ``seconds``)."""
        return len(self.seconds)


__all__ = ["Distribution"]
