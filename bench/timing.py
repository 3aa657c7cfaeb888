"""The one Lloyd timing harness of the speed reports (``cvtbench backends``) and the
regression checks (``cvtbench regress``): a problem of uniform random sites, and a
stepper that runs the suite's own Lloyd step (:func:`cvt.lloyd.lloyd_step`) from its
evolving sites and returns the seconds of each step."""

from __future__ import annotations

import time


def timing_problem(metric_name: str, n_elements: int, size: int, seed: int = 0):
    """Uniform random sites of ``seed`` on the whole ``size``² raster."""
    from compact_distributions.cvt.metrics import make_metric
    from compact_distributions.cvt.problem import Grid, Problem

    return Problem(Grid(size, size), n_elements, make_metric(metric_name), seed=seed)


class LloydStepper:
    """Lloyd iterations of one timing problem on one live backend, one call at a time."""

    def __init__(self, backend, metric_name: str, n_elements: int, size: int, seed: int = 0):
        from compact_distributions.cvt.lloyd import LloydSetup, lloyd_step
        from compact_distributions.cvt.seeding import initial_sites

        problem = timing_problem(metric_name, n_elements, size, seed)
        self.sites = initial_sites(problem)
        self._step = lloyd_step(backend, LloydSetup.of(problem))

    def __call__(self) -> float:
        """Run one iteration; its wall time in seconds."""
        t0 = time.perf_counter()
        self.sites, _, _ = self._step(self.sites)
        return time.perf_counter() - t0


def time_lloyd(
    backend, metric_name: str, n_elements: int, size: int, warmup: int, repeats: int, seed: int = 0
) -> list[float]:
    """Seconds of each timed Lloyd iteration (after ``warmup`` untimed ones)."""
    step = LloydStepper(backend, metric_name, n_elements, size, seed)
    for _ in range(warmup):
        step()
    return [step() for _ in range(repeats)]


__all__ = ["timing_problem", "LloydStepper", "time_lloyd"]
