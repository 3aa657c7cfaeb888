"""`cvtbench regress`: guard coverage and speed from one commit to the next (CI runs
``cvtbench regress --quick`` on every commit).

Coverage: the mean coverage over fixed seeds of each (method, backend, element) is
compared with the committed baseline file (``bench/regress_baseline.json``); a drop of
more than 0.5 percentage points fails.  Coverage is deterministic by seed, so the
threshold only has to absorb float32 ties between devices.

Speed: never absolute times (CI machines differ).  Each backend variant is timed against
the NumPy reference *in the same run* (ms / NumPy's ms, same metric, N and raster), and
NumPy itself against the cKDTree + bincount step; a ratio more than 2x the baseline's
ratio fails.  The two are timed interleaved (one iteration each, in turn) and each
keeps its fastest iteration, so background load cancels out.  A check that fails is
measured once more and fails only if it fails again:
one noisy sample on a shared machine is not a regression.

What is in the baseline but cannot run here (a backend with no runtime) is reported as
not checked, with the reason; what runs here but is not in the baseline is reported as
new.  ``--update`` writes the current figures into the baseline file (entries not
measured now are kept).  Exit status: 0 pass, 1 regression, 2 bad input or no baseline.

Quick set (~30 s here): coverage of ours on every available backend for square, circle
and triangle at 256² px, N = 250, seeds 0 and 1, plus every baseline on squares, seed 0,
all 20 iterations; speed at 512² px, N = 2000, l2 and linf, 1 warm-up + 7 timed
iterations each.  Full set: 512² px, N = 1000, seeds 0-2, every element; speed at 1024²,
N = 4000, all six metrics.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from compact_distributions.backends import REFERENCE as REFERENCE_BACKEND
from compact_distributions.backends import variant_metrics
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.metrics import (
    PAPER_METRICS,
    PAPER_SHAPES,
    REFERENCE_SHAPE,
    SHAPES,
    make_metric,
)
from compact_distributions.cvt.validate import json_object, name_list

from .. import options

CKDTREE = "ckdtree"  # the common CPU tool NumPy is timed against

BASELINE_FILE = Path(__file__).resolve().parents[1] / "regress_baseline.json"
COVERAGE_DROP_PP = 0.5  # percentage points
SLOWDOWN = 2.0  # ratio against the reference measured in the same run

SETS = {
    "quick": {
        "size": 256,
        "n_elements": 250,
        "iterations": 20,
        "seeds": [0, 1],
        "elements": [s.name for s in SHAPES.values() if s.paper and not s.axial],
        "baseline_seeds": [0],
        "speed": {
            "size": 512,
            "n_elements": 2000,
            "metrics": [m for m in PAPER_METRICS if make_metric(m).minkowski_p in (2, math.inf)],
            "warmup": 1,
            "repeats": 7,
        },
    },
    "full": {
        "size": 512,
        "n_elements": 1000,
        "iterations": 20,
        "seeds": [0, 1, 2],
        "elements": list(PAPER_SHAPES),
        "baseline_seeds": [0, 1, 2],
        "speed": {
            "size": 1024,
            "n_elements": 4000,
            "metrics": list(PAPER_METRICS),
            "warmup": 1,
            "repeats": 7,
        },
    },
}


# ---------------------------------------------------------------------------------------
# the logic (pure: tested with fabricated figures in tests/test_bench.py)


def compare(
    baseline: dict, current: dict, coverage_drop_pp: float = COVERAGE_DROP_PP, slowdown: float = SLOWDOWN
) -> tuple[list[str], list[str]]:
    """(failures, notes) of ``current`` against ``baseline``; both are sections
    ``{"coverage": {key: {"mean": float, ...}}, "speed": {key: {"ratio": float, ...}}}``
    with optional ``"unavailable": {key: reason}`` in ``current``."""
    failures, notes = [], []
    unavailable = current.get("unavailable", {})
    base_cov, cur_cov = baseline.get("coverage", {}), current.get("coverage", {})
    for key, b in base_cov.items():
        c = cur_cov.get(key)
        if c is None:
            notes.append(f"not checked: coverage {key} ({unavailable.get(key, 'not run here')})")
            continue
        drop_pp = 100 * (b["mean"] - c["mean"])
        if drop_pp > coverage_drop_pp:
            failures.append(
                f"coverage of {key} fell from {100 * b['mean']:.2f} % to {100 * c['mean']:.2f} % "
                f"(-{drop_pp:.2f} pp; more than {coverage_drop_pp} pp)"
            )
        elif drop_pp < -coverage_drop_pp:
            notes.append(
                f"coverage of {key} rose from {100 * b['mean']:.2f} % to {100 * c['mean']:.2f} % "
                "(run --update to raise the bar)"
            )
    for key in cur_cov.keys() - base_cov.keys():
        notes.append(
            f"new: coverage {key} = {100 * cur_cov[key]['mean']:.2f} % is not in the baseline (run --update)"
        )
    base_sp, cur_sp = baseline.get("speed", {}), current.get("speed", {})
    for key, b in base_sp.items():
        c = cur_sp.get(key)
        if c is None:
            notes.append(f"not checked: speed {key} ({unavailable.get(key, 'not run here')})")
            continue
        factor = c["ratio"] / b["ratio"]
        if factor > slowdown:
            failures.append(
                f"speed of {key}: {c['ratio']:.3g}x the reference's time, baseline "
                f"{b['ratio']:.3g}x ({factor:.2f} times slower; limit {slowdown}x)"
            )
    for key in cur_sp.keys() - base_sp.keys():
        notes.append(f"new: speed {key} = {cur_sp[key]['ratio']:.3g}x is not in the baseline (run --update)")
    return failures, notes


def merge(baseline: dict, current: dict) -> dict:
    """The baseline updated with the current figures; entries not measured now stay."""
    out = {"coverage": dict(baseline.get("coverage", {})), "speed": dict(baseline.get("speed", {}))}
    out["coverage"].update(current.get("coverage", {}))
    out["speed"].update(current.get("speed", {}))
    return out


# ---------------------------------------------------------------------------------------
# measuring


def coverage_specs(cfg: dict, methods: list[str], backends: list[str]):
    """The coverage runs: a method swept over every backend (its record says so) on every
    backend and element of the set, each other method on squares on the reference."""
    from compact_distributions.cvt.registry import get_method

    from ..runs import RunSpec

    specs = []
    for element in cfg["elements"]:
        for method in methods:
            if get_method(method).sweep_backends == "every":
                for b in backends:
                    specs += [
                        RunSpec(
                            "regress",
                            method,
                            b,
                            element,
                            cfg["size"],
                            cfg["size"],
                            cfg["n_elements"],
                            cfg["iterations"],
                            s,
                        )
                        for s in cfg["seeds"]
                    ]
            elif element == REFERENCE_SHAPE and REFERENCE_BACKEND in backends:
                specs += [
                    RunSpec(
                        "regress",
                        method,
                        REFERENCE_BACKEND,
                        element,
                        cfg["size"],
                        cfg["size"],
                        cfg["n_elements"],
                        cfg["iterations"],
                        s,
                    )
                    for s in cfg["baseline_seeds"]
                ]
    return specs


def coverage_key(method: str, backend: str, element: str) -> str:
    return f"{method}/{backend}/{element}"


def speed_key(backend: str, reference: str, metric: str, n: int, size: int) -> str:
    return f"{backend} vs {reference}, {metric}, N={n}, {size}²"


def measure_coverage(cfg, methods, backends, unavailable, quiet) -> tuple[dict, dict, list[str]]:
    from ..sweep import run_sweep

    specs = coverage_specs(cfg, methods, backends)
    rows = run_sweep(specs, out=".", store=False, quiet=quiet, unavailable=dict(unavailable))
    groups: dict[str, list[dict]] = {}
    for r in rows:
        groups.setdefault(coverage_key(r["method"], r["backend"], r["element"]), []).append(r)
    cov, skipped, failed = {}, {}, []
    for key, rs in groups.items():
        ok = [r for r in rs if r["status"] == "ok"]
        bad = [r for r in rs if r["status"] == "failed"]
        if bad:
            failed.append(f"{key} failed to run: {bad[0]['reason']}")
        if len(ok) == len(rs):
            cov[key] = {
                "mean": float(np.mean([r["coverage"] for r in ok])),
                "values": [round(float(r["coverage"]), 6) for r in ok],
                "seeds": [r["seed"] for r in ok],
            }
        elif not bad:
            skipped[key] = rs[0]["reason"]
    return cov, skipped, failed


def measure_speed_pair(backend: str, reference: str, metric: str, n: int, size: int, sp: dict, cache) -> dict:
    """Ratio of ``backend``'s time to ``reference``'s on the same problem, their Lloyd
    iterations interleaved (ref, backend, ref, backend, ...) so that a neighbour's load
    hits both alike, each the fastest of its timed iterations (the least disturbed one)."""
    from ..sweep import BackendCache
    from ..timing import LloydStepper

    # the reference's backend instance is made first and kept only while it is timed:
    # BackendCache holds one backend at a time, so the pair gets two caches
    ref_cache = BackendCache()
    try:
        ref_step = LloydStepper(ref_cache.get(reference), metric, n, size)
        b_step = LloydStepper(cache.get(backend), metric, n, size)
        for _ in range(sp["warmup"]):
            ref_step(), b_step()
        ref_s, b_s = [], []
        for _ in range(sp["repeats"]):
            ref_s.append(ref_step())
            b_s.append(b_step())
    finally:
        ref_cache.close()
    b_ms, ref_ms = 1000 * min(b_s), 1000 * min(ref_s)
    return {"ratio": b_ms / ref_ms, "ms": round(b_ms, 3), "reference_ms": round(ref_ms, 3)}


def speed_pairs(cfg: dict, backends: list[str]):
    """(backend, reference, metric): each variant against NumPy, NumPy against cKDTree."""
    sp = cfg["speed"]
    pairs = []
    for metric in sp["metrics"]:
        if REFERENCE_BACKEND in backends and metric in (variant_metrics(CKDTREE) or ()):
            pairs.append((REFERENCE_BACKEND, CKDTREE, metric))
        for b in backends:
            computes = variant_metrics(b)
            if b not in (REFERENCE_BACKEND, CKDTREE) and (computes is None or metric in computes):
                pairs.append((b, REFERENCE_BACKEND, metric))
    return pairs


def measure_speed(cfg, backends, unavailable, baseline_speed: dict, quiet) -> tuple[dict, dict, list[str]]:
    """Current ratios; a pair whose ratio breaks the limit is measured once more and the
    better of the two kept (a noisy neighbour must not fail CI)."""
    from tqdm import tqdm

    from ..sweep import BackendCache

    sp = cfg["speed"]
    n, size = sp["n_elements"], sp["size"]
    out, skipped, failed = {}, {}, []
    cache = BackendCache()
    pairs = speed_pairs(cfg, backends)
    try:
        for backend, ref, metric in tqdm(pairs, desc="speed", unit="pair", disable=quiet, file=sys.stderr):
            key = speed_key(backend, ref, metric, n, size)
            if backend in unavailable or ref in unavailable:
                skipped[key] = unavailable.get(backend) or unavailable.get(ref)
                continue
            try:
                cur = measure_speed_pair(backend, ref, metric, n, size, sp, cache)
                base = baseline_speed.get(key)
                if base is not None and cur["ratio"] > SLOWDOWN * base["ratio"]:
                    again = measure_speed_pair(backend, ref, metric, n, size, sp, cache)
                    cur = min(cur, again, key=lambda d: d["ratio"])
                    cur["remeasured"] = True
            except (KeyboardInterrupt, MemoryError):
                raise
            except Exception as exc:
                failed.append(f"speed {key} failed to run: {type(exc).__name__}: {exc}")
                cache.close()
                continue
            out[key] = cur
    finally:
        cache.close()
    return out, skipped, failed


# ---------------------------------------------------------------------------------------
# command


# the figures each entry must hold, finite, for a comparison to mean anything
REQUIRED_FIGURES = {"coverage": {"mean": (0.0, 1.0)}, "speed": {"ratio": (0.0, None)}}


def check_figures(section: dict, where: str) -> None:
    """Fail closed: every coverage and speed entry of ``section`` holds its figures as
    finite numbers in range (a missing key, NaN, an infinity or a string is InputError
    naming the key): a comparison with NaN is false, so a broken figure would pass."""
    for kind, figures in REQUIRED_FIGURES.items():
        entries = section.get(kind, {})
        if not isinstance(entries, dict):
            raise InputError(f"{where}: '{kind}' is not an object")
        for key, entry in entries.items():
            if not isinstance(entry, dict):
                raise InputError(f"{where}: {kind} {key!r} is not an object, got {entry!r}")
            for name, (low, high) in figures.items():
                value = entry.get(name)
                ok = (
                    isinstance(value, (int, float))
                    and not isinstance(value, bool)
                    and math.isfinite(value)
                    and value >= low
                    and (high is None or value <= high)
                )
                if not ok:
                    state = "is missing" if name not in entry else f"is {value!r}"
                    raise InputError(
                        f"{where}: {kind} {key!r}: {name!r} {state}, not a finite number"
                        + (f" in [{low:g}, {high:g}]" if high is not None else f" >= {low:g}")
                    )
            for name in ("values", "ms", "reference_ms"):
                values = entry.get(name)
                values = values if isinstance(values, list) else [] if values is None else [values]
                if any(
                    isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                    for v in values
                ):
                    raise InputError(
                        f"{where}: {kind} {key!r}: {name!r} holds {entry[name]!r}, not finite numbers"
                    )


def load_baseline(path: Path) -> dict:
    """The baseline file: a json object whose sections ("quick", "full") are objects too."""
    if not path.exists():
        raise InputError(f"no regression baseline at {path}; create it with `cvtbench regress --update`")
    data = json_object(path, "regression baseline")
    for mode in SETS:
        section = data.get(mode)
        if section is not None and not (
            isinstance(section, dict)
            and all(isinstance(section.get(k, {}), dict) for k in ("coverage", "speed"))
        ):
            raise InputError(
                f"regression baseline {path}: its {mode!r} section is not an object with "
                "'coverage' and 'speed' objects"
            )
        if section is not None:
            check_figures(section, f"regression baseline {path}, {mode!r}")
    return data


def add_parser(sub):
    p = sub.add_parser(
        "regress",
        help="fail on a coverage drop (> 0.5 pp) or a 2x slowdown vs the baseline",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--quick", action="store_true", help="the CI set (well under a minute)")
    p.add_argument("--update", action="store_true", help="write the current figures into the baseline file")
    p.add_argument("--baseline", default=None, help=f"baseline file (default {BASELINE_FILE})")
    options.add_list_options(p, "methods", "backends")
    p.add_argument("--no-speed", action="store_true", help="check coverage only")
    p.add_argument("--no-coverage", action="store_true", help="check speed only")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args) -> int:
    from compact_distributions.baselines import method_names

    from ..outputs import atomic_write, dumps, folder_problem
    from ..report import provenance
    from ..table2 import sweep_backends

    t0 = time.perf_counter()
    mode = "quick" if args.quick else "full"
    cfg = SETS[mode]
    path = Path(args.baseline) if args.baseline else BASELINE_FILE
    if args.update:
        _, problem = folder_problem(Path(os.path.realpath(path)).parent, "--baseline", path.parent)
        if problem or path.is_dir() or (path.exists() and not path.is_file()):
            raise InputError(problem or f"--baseline {path} is not a file")
    baseline_all = load_baseline(path) if (path.exists() or not args.update) else {}
    baseline = baseline_all.get(mode)
    if baseline is None and not args.update:
        raise InputError(
            f"{path} has no {mode!r} section; create it with `cvtbench regress "
            f"{'--quick ' if args.quick else ''}--update`"
        )
    baseline = baseline or {}
    all_methods = method_names()
    methods = name_list(args.methods, "method", all_methods) or all_methods
    backends, unavailable = sweep_backends(args.backends)

    current: dict = {"coverage": {}, "speed": {}, "unavailable": {}}
    run_failures: list[str] = []
    if not args.no_coverage:
        cov, skipped, failed = measure_coverage(cfg, methods, backends, unavailable, args.quiet)
        current["coverage"], run_failures = cov, run_failures + failed
        current["unavailable"].update(skipped)
    if not args.no_speed:
        sp, skipped, failed = measure_speed(cfg, backends, unavailable, baseline.get("speed", {}), args.quiet)
        current["speed"], run_failures = sp, run_failures + failed
        current["unavailable"].update(skipped)
    # compare only what was asked for: a --backends/--methods subset is not a regression
    asked = {
        "coverage": {
            k: v
            for k, v in baseline.get("coverage", {}).items()
            if not args.no_coverage and k.split("/")[0] in methods and k.split("/")[1] in backends
        },
        "speed": {
            k: v
            for k, v in baseline.get("speed", {}).items()
            if not args.no_speed and k.split(" vs ")[0] in backends
        },
    }
    check_figures(current, "this run's measurement")
    failures, notes = compare(asked, current)
    failures = run_failures + failures
    elapsed = time.perf_counter() - t0

    for key, c in sorted(current["coverage"].items()):
        b = asked["coverage"].get(key)
        ref = f"  (baseline {100 * b['mean']:.2f} %)" if b else ""
        print(f"coverage {key:<34} {100 * c['mean']:6.2f} %{ref}")
    for key, c in current["speed"].items():
        b = asked["speed"].get(key)
        ref = f"  (baseline {b['ratio']:.3g}x)" if b else ""
        print(f"speed    {key:<44} {c['ratio']:.3g}x  [{c['ms']:.1f} / {c['reference_ms']:.1f} ms]{ref}")
    if not args.update:  # when updating, "new" and "rose" are what the update records
        for note in sorted(notes):
            print(f"note: {note}")
    if args.update:
        merged = merge(baseline, current)
        merged["set"] = {k: v for k, v in cfg.items()}
        merged["provenance"] = provenance()
        baseline_all[mode] = merged
        baseline_all["tolerances"] = {"coverage_drop_pp": COVERAGE_DROP_PP, "slowdown": SLOWDOWN}
        atomic_write(path, dumps(baseline_all))
        print(
            f"updated {path} ({mode}; {len(current['coverage'])} coverage and {len(current['speed'])} "
            f"speed entries; {elapsed:.0f} s)"
        )
        return 1 if run_failures else 0
    if failures:
        for f in failures:
            print(f"REGRESSION: {f}", file=sys.stderr)
        print(
            f"cvtbench regress: {len(failures)} regression(s) against {path} ({mode}, {elapsed:.0f} s)",
            file=sys.stderr,
        )
        return 1
    print(
        f"regress ({mode}): no regression against {path}: {len(asked['coverage'])} coverage and "
        f"{len(asked['speed'])} speed checks ({elapsed:.0f} s)"
    )
    return 0


__all__ = [
    "CKDTREE",
    "BASELINE_FILE",
    "COVERAGE_DROP_PP",
    "SLOWDOWN",
    "SETS",
    "compare",
    "merge",
    "coverage_specs",
    "coverage_key",
    "speed_key",
    "measure_coverage",
    "measure_speed_pair",
    "speed_pairs",
    "measure_speed",
    "REQUIRED_FIGURES",
    "check_figures",
    "load_baseline",
    "add_parser",
    "run",
]
