"""The one Lloyd timing harness of the speed reports (``cvtbench backends``) and the
regression checks (``cvtbench regress``): a problem of uniform random sites, and a
stepper that runs the suite's own Lloyd step (:func:`cvt.lloyd.lloyd_step`) from its
evolving sites and returns the seconds of each step.

:func:`speed_ratio` times two backends on the same problem in one process, rounds
alternating, for the speed targets stated as "x times backend B" (the machine may be
shared: a ratio measured in one run carries over, absolute times do not).  From the shell::

    python -m compact_distributions.bench.timing --backend opencl --against ckdtree \
        --metrics l2,linf --elements 4000 --size 1024
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


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


def speed_ratio(
    backend,
    against,
    metric_name: str,
    n_elements: int,
    size: int,
    warmup: int = 3,
    repeats: int = 7,
    rounds: int = 3,
) -> dict:
    """Median seconds per Lloyd iteration of ``backend`` and ``against`` (live backends) on
    one problem, and their ratio (``against`` / ``backend``: how many times faster).

    Each round runs :func:`time_lloyd` (``warmup`` + ``repeats`` iterations from the
    seeded sites) on one backend, then on the other, so both see the same load; the
    medians are over every timed iteration of every round, ``ratios`` per round."""
    mine, theirs, ratios = [], [], []
    for _ in range(rounds):
        a = time_lloyd(backend, metric_name, n_elements, size, warmup, repeats)
        b = time_lloyd(against, metric_name, n_elements, size, warmup, repeats)
        mine += a
        theirs += b
        ratios.append(float(np.median(b) / np.median(a)))
    med_a, med_b = float(np.median(mine)), float(np.median(theirs))
    return {"seconds": med_a, "against_seconds": med_b, "ratio": med_b / med_a, "ratios": ratios}


def main(argv=None) -> int:
    """Print the medians and the ratio of :func:`speed_ratio` for each metric."""
    from compact_distributions.backends import create_backend

    p = argparse.ArgumentParser(prog="python -m compact_distributions.bench.timing", description=__doc__)
    p.add_argument("--backend", default="opencl")
    p.add_argument("--against", default="ckdtree")
    p.add_argument("--metrics", default="l2,linf")
    p.add_argument("--elements", type=int, default=4000)
    p.add_argument("--size", type=int, default=1024)
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args(argv)
    with create_backend(args.backend) as mine, create_backend(args.against) as theirs:
        print(f"{args.backend}: {mine.device()}\n{args.against}: {theirs.device()}")
        for metric in args.metrics.split(","):
            r = speed_ratio(
                mine, theirs, metric, args.elements, args.size, args.warmup, args.repeats, args.rounds
            )
            load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
            print(
                f"{metric}, N = {args.elements}, {args.size}²: {args.backend} {r['seconds'] * 1e3:.2f} ms, "
                f"{args.against} {r['against_seconds'] * 1e3:.1f} ms, ratio {r['ratio']:.1f}x "
                f"(rounds: {', '.join(f'{x:.1f}x' for x in r['ratios'])}; load {load})"
            )
    return 0


__all__ = ["timing_problem", "LloydStepper", "time_lloyd", "speed_ratio", "main"]

if __name__ == "__main__":
    raise SystemExit(main())
