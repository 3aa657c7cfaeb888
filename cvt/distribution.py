"""What every method returns (ours on any backend, and each baseline), so that bench/
evaluates them all alike."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Distribution:
    method: str
    sites: np.ndarray  # (N, 2) pixel units
    angles: np.ndarray  # (N,) radians
    scales: np.ndarray  # (N,) size factor per site
    elements: list | None = None  # shapely polygons, one per site (None where skipped)
    energy: list[float] = field(default_factory=list)  # per iteration
    seconds: list[float] = field(default_factory=list)  # wall time per iteration
    setup_seconds: float = 0.0  # excluded from lloyd_seconds, reported apart
    lloyd_seconds: float = 0.0  # wall time of the Lloyd iterations (the paper's "time")
    method_seconds: float = 0.0  # wall time of the whole method, problem to placed elements
    empty: list[int] = field(default_factory=list)  # empty cells per iteration
    empty_sites: list[int] = field(default_factory=list)
    labels: np.ndarray | None = None  # final label raster, where the method has one
    extra: dict = field(default_factory=dict)  # method-specific, JSON-serialisable

    @property
    def iterations(self) -> int:
        return len(self.seconds)


__all__ = ["Distribution"]
