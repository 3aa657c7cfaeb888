"""The backend interface: how a label raster (and its moments) is computed.

A backend turns sites, their size factors and angles, a metric and a grid into a label
raster: ``(H, W) int32``, the index of the nearest site under
``d_i(x) = gauge(R(-θ_i)(x - p_i)) / s_i`` for every pixel centre inside the region,
ties to the lower index, -1 outside the region.  ``moments`` may run on the device so
that the Lloyd loop need not read the raster back every iteration.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from compact_distributions.cvt.metrics import Metric
from compact_distributions.cvt.moments import Moments, moments_from_labels
from compact_distributions.cvt.problem import Grid


class Backend(ABC):
    name: str = "?"

    @classmethod
    def probe(cls) -> str:
        """Describe the device this backend would use; raise BackendUnavailable if the
        runtime is missing."""
        return cls().device()

    @abstractmethod
    def device(self) -> str:
        """Human-readable device description (recorded in result.json)."""

    @abstractmethod
    def label(self, sites: np.ndarray, scales: np.ndarray, angles: np.ndarray,
              metric: Metric, grid: Grid) -> np.ndarray:
        """(H, W) int32 nearest-site labels, -1 outside the region."""

    def moments(self, sites: np.ndarray, scales: np.ndarray, angles: np.ndarray,
                metric: Metric, grid: Grid) -> Moments:
        """Integer moments per site; the default labels and sums on the host."""
        labels = self.label(sites, scales, angles, metric, grid)
        return moments_from_labels(labels, len(sites))

    def close(self) -> None:  # noqa: B027 - optional hook, nothing to release by default
        """Release device resources (contexts, buffers)."""
