"""`cvtbench regress`: guard what the tables report from one commit to the next (CI runs
``cvtbench regress --quick`` on every commit).

Everything is compared with the committed baseline file (``bench/regress_baseline.json``),
each figure with its own tolerance stored beside it.

Measures.  Every method of the registry runs on the shapes its record compares it on
(``compared_on``; every shape: the paper's five and the record's ``beyond_paper``), with
each of its sweep variants, on the backends its record names (``sweep_backends``: every
variant; the reference and the fastest available one; or the reference only), on one
standard scene of Table 3 (``combined``: a ring, a radial density and a circular field,
so that walls, sizes and directions all count) for fixed seeds.  Its coverage, overlap,
size error and direction error (``cvt.evaluate.MEASURES``) are averaged over the seeds
and compared with the baseline's mean over the same seeds: a figure worse by more than
its tolerance fails.  A direction error that does not apply (circles) is not guarded.

Tolerances, from the spread over seeds.  ``--update`` runs more seeds than the check
(``spread_seeds``) and sets each figure's tolerance to
``max(RESOLUTION[unit], SPREAD_Z × sd / √S)``: sd the sample standard deviation of the
figure over the spread seeds, S the number of seeds the check averages, SPREAD_Z = 3.  A
change that moves the checked mean by more than three standard errors of it fails; the
resolution (0.2 pp of coverage, 0.005 of log2 size error, 0.1° of direction error, 0.05
ΔE*ab) only keeps a figure that never varies (an overlap of 0) from failing on rounding.
The rule and its constants are written into the baseline file with the figures.

Whole-method speed, machine-independent.  Each method's ``method_seconds`` (problem to
placed elements: fit, compaction, walls, cutting) is divided by the Lloyd time of the
same run (``lloyd_seconds``; a method without Lloyd iterations by the paper method's
whole time on the same problem), on the reference backend, and so is each stage the
method times itself (final labels, fit, placement, compaction, ...).  The whole time
fails when its part beyond Lloyd grows more than SLOWDOWN (2x) plus SPEED_SLACK (0.05 of
the Lloyd time, the timer's noise on small problems), ``ratio - 1 > 2 (baseline - 1) +
0.05``; a stage when ``ratio > 2 baseline + 0.05``.  A machine twice as slow makes Lloyd
and the rest twice as slow alike; a stage that got slower moves its own ratio.  The
check keeps the fastest of its seeds (the least disturbed), the baseline the median of
its spread seeds (one fast outlier must not become the bar).  At the quick set's size
the fit and compaction are 5-40 % of the Lloyd time, so a stage must slow down about 3x
to fail in some groups (measured: compaction made 3x slower fails 4 checks, the fit 3x
slower 1; nothing fails unchanged).

Mosaic.  ``cvtbench mosaic`` (the command, its writers included) on ``samples/small.png``
on the reference backend: coverage, colour error and straddling against the baseline (the
same tolerance rule), its whole time over its Lloyd time and each stage (picture fields,
fit, compaction, cutting, fills, evaluation, writing, ...) over its Lloyd time (the same
rules; the first mosaic of a process is timed twice, its imports are no stage).

Lloyd step speed.  Each backend variant's Lloyd step is timed against the NumPy
reference *in the same run* (ms / NumPy's ms, same metric, N and raster), and NumPy's
against the cKDTree + bincount step, interleaved (one iteration each, in turn), each
the fastest of its timed iterations; a ratio more than 2x the baseline's fails.

A speed check that fails is measured once more and fails only if it fails again: one
noisy sample on a shared machine is not a regression.  What is in the baseline but
cannot run here (a backend with no runtime) is reported as not checked, with the reason;
what runs here but is not in the baseline (a plug-in method installed beside the suite)
is reported as new until ``--update`` writes the current figures into the baseline file
(entries not measured now are kept).

Reports: ``--junit FILE`` (JUnit XML, one test case per check, failures with their
figures), ``--json FILE`` (every check and its figures); with ``GITHUB_STEP_SUMMARY``
set (GitHub Actions), the summary as markdown appended to that file.  Exit status: 0
pass, 1 regression, 2 bad input or no baseline.

Quick set (CI, under a minute on 2 cores): the combined scene at 160² px, N = 120 on the
whole raster, 20 iterations, seeds 0 and 1 (spread over seeds 0-4); the mosaic of
samples/small.png with 150 tiles, seed 0 (spread over seeds 0-4); Lloyd steps at 512² px,
N = 2000, l2 and linf.  Full set: 320² px, N = 400, seeds 0-2 (spread 0-5); the mosaic of
samples/shapes.png with 1000 tiles, seeds 0-1 (spread 0-4); Lloyd steps at 1024²,
N = 4000, all six metrics.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from compact_distributions.backends import REFERENCE as REFERENCE_BACKEND
from compact_distributions.backends import variant_metrics
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.evaluate import MEASURES
from compact_distributions.cvt.metrics import PAPER_METRICS, make_metric
from compact_distributions.cvt.validate import json_object, name_list

from .. import options
from ..sweep import InProcessExecutor

CKDTREE = "ckdtree"  # the common CPU tool NumPy is timed against

BASELINE_FILE = Path(__file__).resolve().parents[1] / "regress_baseline.json"
FORMAT = 2  # the baseline file's layout: measures and speed, group by group

# the measures of cvt.evaluate.MEASURES that are guarded, and which way is better
GUARDED = {"coverage": "higher", "overlap": "lower", "size_fidelity": "lower", "direction_fidelity": "lower"}
# the mosaic's measures (cvt.evaluate's colour_error and straddling_tiles): (better, unit)
MOSAIC_GUARDED = {
    "coverage": ("higher", "share"),
    "colour_error": ("lower", "ΔE*ab"),
    "straddling": ("lower", "share"),
}
# the smallest difference a tolerance may be, per unit: rounding, not a regression
RESOLUTION = {"share": 0.002, "log2": 0.005, "degrees": 0.1, "ΔE*ab": 0.05, "px": 0.05}
SPREAD_Z = 3.0  # standard errors of the checked mean
SLOWDOWN = 2.0  # a speed ratio's part that may double
SPEED_SLACK = 0.05  # ... plus this share of the Lloyd time (timer noise on small problems)
WHOLE = "whole-method time"  # the whole-method speed check's measure
MOSAIC_WHOLE = "whole time"
LLOYD_STEP = "Lloyd step time"

SETS = {
    "quick": {
        "runs": {
            "scene": "combined",
            "size": 160,
            "n_elements": 120,
            "iterations": 20,
            "seeds": [0, 1],
            "spread_seeds": 5,
        },
        "mosaic": {
            "picture": "small.png",
            "n_elements": 150,
            "iterations": 20,
            "seeds": [0],
            "spread_seeds": 5,
        },
        "speed": {
            "size": 512,
            "n_elements": 2000,
            "metrics": [m for m in PAPER_METRICS if make_metric(m).minkowski_p in (2, math.inf)],
            "warmup": 1,
            "repeats": 7,
        },
    },
    "full": {
        "runs": {
            "scene": "combined",
            "size": 320,
            "n_elements": 400,
            "iterations": 20,
            "seeds": [0, 1, 2],
            "spread_seeds": 6,
        },
        "mosaic": {
            "picture": "shapes.png",
            "n_elements": 1000,
            "iterations": 20,
            "seeds": [0, 1],
            "spread_seeds": 5,
        },
        "speed": {
            "size": 1024,
            "n_elements": 4000,
            "metrics": list(PAPER_METRICS),
            "warmup": 1,
            "repeats": 7,
        },
    },
}


def tolerance_rule() -> dict:
    """How the tolerances of the baseline file are chosen (written into it)."""
    return {
        "measures": f"max(resolution of the unit, {SPREAD_Z:g} × sd over the spread seeds / √(seeds checked))",
        "resolution": dict(RESOLUTION),
        "spread_z": SPREAD_Z,
        "speed": f"fail when ratio - floor > slowdown × (baseline - floor) + slack; slowdown {SLOWDOWN:g}, "
        f"slack {SPEED_SLACK:g} (floor 1 for a whole time over its own Lloyd time, else 0; "
        "Lloyd steps: slack 0)",
    }


def unit_of(measure: str) -> str:
    """The unit of a guarded measure (cvt.evaluate.MEASURES, or the mosaic's)."""
    if measure in MEASURES:
        return MEASURES[measure][1]
    return MOSAIC_GUARDED[measure][1]


def tolerance_of(sd: float, checked: int, unit: str) -> float:
    """The tolerance of a figure (the rule of the module docstring).

    Parameters
    ----------
    sd : float
        The sample standard deviation of the figure over the spread seeds (NaN: unknown).
    checked : int
        How many seeds the check averages.
    unit : str
        The figure's unit, a key of :data:`RESOLUTION`.

    Returns
    -------
    float
        ``max(RESOLUTION[unit], SPREAD_Z * sd / sqrt(checked))``.
    """
    spread = SPREAD_Z * sd / math.sqrt(max(1, checked)) if math.isfinite(sd) else 0.0
    return float(max(RESOLUTION[unit], spread))


def figure_of(by_seed: dict, check_seeds: list[int], unit: str, better: str, spread: bool) -> dict | None:
    """One measure's figure from its value per seed.

    Parameters
    ----------
    by_seed : dict
        Seed -> value (None or NaN where it was not measured).
    check_seeds : list of int
        The seeds whose mean the check compares.
    unit : str
        The measure's unit (a key of :data:`RESOLUTION`).
    better : {"higher", "lower"}
        Which way the measure improves.
    spread : bool
        Also the sd over every seed and the tolerance (an update).

    Returns
    -------
    dict or None
        ``mean`` (over ``check_seeds``; NaN if one of them has no finite value),
        ``values``, ``seeds``, ``better``, ``unit``, and where ``spread``: ``sd``,
        ``spread_seeds``, ``tolerance``.  None when no seed has a finite value (the
        measure does not apply, as a circle's direction), or, for an update, when one of
        them has none (a figure that is not always measured cannot be guarded).
    """
    seeds = sorted(by_seed)
    values = [math.nan if by_seed[s] is None else float(by_seed[s]) for s in seeds]
    finite = [v for v in values if math.isfinite(v)]
    if not finite or (spread and len(finite) < len(values)):
        return None
    checked = [math.nan if by_seed.get(s) is None else float(by_seed[s]) for s in check_seeds]
    out = {
        "mean": float(np.mean(checked)) if checked else math.nan,
        "values": [round(v, 6) for v in values],
        "seeds": seeds,
        "better": better,
        "unit": unit,
    }
    if spread:
        sd = float(np.std(finite, ddof=1)) if len(finite) > 1 else math.nan
        out.update(sd=sd, spread_seeds=len(finite), tolerance=tolerance_of(sd, len(check_seeds), unit))
    return out


def speed_figure(
    values: list[float], floor: float, per: str, slack: float = SPEED_SLACK, pick: str = "min", **extra
) -> dict:
    """A speed figure and its rule's constants.

    Parameters
    ----------
    values : list of float
        The ratios measured (one per seed or repeat).
    floor : float
        The part of the ratio that is its own denominator (1 for a whole time over its
        own Lloyd time, else 0): the rule lets the rest double.
    per : str
        What the ratio divides by, in words ("its Lloyd time").
    slack : float
        What the rest may grow beyond double (a share of the denominator).
    pick : {"min", "median"}
        Which of ``values`` is the figure: a check keeps the fastest of its samples (the
        least disturbed), a baseline the median of its spread seeds (one fast outlier
        must not become the bar).
    **extra
        More fields to keep (the milliseconds of a Lloyd step pair).

    Returns
    -------
    dict
        ``ratio``, ``values``, ``per``, ``floor``, ``slowdown``, ``slack`` and ``extra``.
    """
    return {
        "ratio": float(min(values) if pick == "min" else np.median(values)),
        "values": [round(float(v), 4) for v in values],
        "per": per,
        "floor": float(floor),
        "slowdown": SLOWDOWN,
        "slack": float(slack),
        **extra,
    }


# ---------------------------------------------------------------------------------------
# the logic (pure: tested with fabricated figures in tests/test_regress.py)


@dataclass
class Check:
    """One check: a figure of a group (a run, the mosaic, a Lloyd step pair) against the
    baseline.  ``status``: pass, fail, new (not in the baseline) or not checked (not
    measured here)."""

    section: str
    group: str
    measure: str
    status: str
    message: str
    current: float | None = None
    baseline: float | None = None
    limit: float | None = None

    @property
    def name(self) -> str:
        return f"{self.group}: {self.measure}"


def _show(value: float, unit: str, diff: bool = False) -> str:
    if not math.isfinite(value):
        return repr(value)
    if unit == "share":
        return f"{100 * value:.2f} {'pp' if diff else '%'}"
    if unit == "degrees":
        return f"{value:.3f}°"
    if unit == "ΔE*ab":
        return f"{value:.3f} ΔE*ab"
    return f"{value:.4f}"


def judge_measure(section: str, group: str, measure: str, b: dict, c: dict) -> Check:
    """A measure's check: fail when the current mean is worse than the baseline's by
    more than its tolerance (the direction of "worse" is the figure's ``better``)."""
    unit, tol, base, cur = b["unit"], b["tolerance"], b["mean"], c.get("mean", math.nan)
    if cur is None or not math.isfinite(cur):
        return Check(
            section, group, measure, "fail", f"measured {cur!r}, not a finite number", None, base, tol
        )
    worse = (base - cur) if b["better"] == "higher" else (cur - base)
    limit = base - tol if b["better"] == "higher" else base + tol
    text = (
        f"{_show(cur, unit)} against the baseline's {_show(base, unit)} "
        f"(tolerance {_show(tol, unit, diff=True)}, {b['better']} is better)"
    )
    if worse > tol:
        return Check(
            section,
            group,
            measure,
            "fail",
            f"{_show(worse, unit, diff=True)} worse: {text}",
            cur,
            base,
            limit,
        )
    note = "; better by more than the tolerance (run --update to raise the bar)" if -worse > tol else ""
    return Check(section, group, measure, "pass", text + note, cur, base, limit)


def judge_speed(section: str, group: str, measure: str, b: dict, c: dict) -> Check:
    """A speed check: fail when ``ratio - floor > slowdown × (baseline - floor) + slack``."""
    floor, cur, base = b["floor"], c.get("ratio", math.nan), b["ratio"]
    limit = floor + b["slowdown"] * (base - floor) + b["slack"]
    per = b.get("per", "")
    if cur is None or not math.isfinite(cur):
        return Check(
            section, group, measure, "fail", f"measured {cur!r}, not a finite number", None, base, limit
        )
    beyond = f"the time beyond {per}" if floor else "the ratio"
    slack = f" + {b['slack']:g}" if b["slack"] else ""
    text = f"{cur:.3g}x {per}, baseline {base:.3g}x; limit {limit:.3g}x ({b['slowdown']:g}x {beyond}{slack})"
    if c.get("remeasured"):
        text += ", measured twice"
    if cur > limit:
        return Check(section, group, measure, "fail", f"slower: {text}", cur, base, limit)
    return Check(section, group, measure, "pass", text, cur, base, limit)


JUDGES = {"measures": judge_measure, "speed": judge_speed}


def compare(baseline: dict, current: dict) -> list[Check]:
    """Every check of ``current`` against ``baseline``.  Both are sections
    ``{"measures": {group: {"figures": {measure: figure}}}, "speed": {...}}``; a current
    group may say ``"failed": reason`` (it did not run), and ``current["unavailable"]``
    gives why a group of the baseline was not measured."""
    checks = []
    unavailable = current.get("unavailable", {})
    for section, judge in JUDGES.items():
        base, cur = baseline.get(section, {}), current.get(section, {})
        for group, b in base.items():
            c = cur.get(group)
            for measure, bf in b.get("figures", {}).items():
                if c is None:
                    why = unavailable.get(group, "not run here")
                    checks.append(
                        Check(
                            section, group, measure, "not checked", why, None, bf.get("mean", bf.get("ratio"))
                        )
                    )
                elif c.get("failed"):
                    checks.append(Check(section, group, measure, "fail", f"failed to run: {c['failed']}"))
                elif measure not in c.get("figures", {}):
                    checks.append(
                        Check(section, group, measure, "fail", "not measured (not a finite number)")
                    )
                else:
                    checks.append(judge(section, group, measure, bf, c["figures"][measure]))
            if c is not None:
                for measure in c.get("figures", {}).keys() - b.get("figures", {}).keys():
                    checks.append(_new(section, group, measure, c["figures"][measure]))
        for group in sorted(cur.keys() - base.keys()):
            c = cur[group]
            if c.get("failed"):
                checks.append(Check(section, group, "run", "fail", f"failed to run: {c['failed']}"))
            for measure, cf in c.get("figures", {}).items():
                checks.append(_new(section, group, measure, cf))
    return checks


def _new(section: str, group: str, measure: str, cf: dict) -> Check:
    value = cf.get("mean", cf.get("ratio"))
    shown = f"{value:.4g}" if isinstance(value, float) else repr(value)
    return Check(section, group, measure, "new", f"{shown} is not in the baseline (run --update)", value)


def merge(baseline: dict, current: dict) -> dict:
    """The baseline updated with the current groups; groups not measured now (or that
    failed to run) stay as they were."""
    out = {}
    for section in JUDGES:
        out[section] = dict(baseline.get(section, {}))
        out[section].update({g: c for g, c in current.get(section, {}).items() if not c.get("failed")})
    return out


# ---------------------------------------------------------------------------------------
# measuring: the method runs


def shapes_of(record, chosen=None) -> list[str]:
    """The shapes the record is compared on (all: the paper's five and its beyond_paper),
    those it can place, within ``chosen`` where given."""
    from compact_distributions.cvt.metrics import PAPER_SHAPES

    shapes = (
        list(record.compared_on) if record.compared_on is not None else [*PAPER_SHAPES, *record.beyond_paper]
    )
    shapes = [s for s in shapes if record.elements is None or s in record.elements]
    return [s for s in shapes if chosen is None or s in chosen]


def backends_of(record, backends: list[str], fastest: str) -> list[str]:
    """Where the record's runs go: every listed variant, the reference and the fastest,
    or the reference only (as its ``sweep_backends`` says), within ``backends``."""
    if record.sweep_backends == "every":
        return list(backends)
    wanted = [REFERENCE_BACKEND] + ([fastest] if record.sweep_backends == "fastest" else [])
    return [b for b in dict.fromkeys(wanted) if b in backends]


def method_specs(run_cfg: dict, methods: list[str], backends: list[str], fastest: str, seeds, shapes=None):
    """The runs of the measures: every method (with each of its sweep variants) on its
    shapes and backends, for ``seeds``, on the set's scene."""
    from compact_distributions.cvt.registry import get_method

    from ..runs import RunSpec

    specs = []
    for method in methods:
        rec = get_method(method)
        for element in shapes_of(rec, shapes):
            option_sets = [{}] + [
                dict(v.options) for v in rec.sweep_variants if v.elements is None or element in v.elements
            ]
            for opts in option_sets:
                for b in backends_of(rec, backends, fastest):
                    specs += [
                        RunSpec(
                            "regress",
                            method,
                            b,
                            element,
                            run_cfg["size"],
                            run_cfg["size"],
                            run_cfg["n_elements"],
                            run_cfg["iterations"],
                            s,
                            options=opts,
                            scene=run_cfg["scene"],
                            measures=True,
                        )
                        for s in seeds
                    ]
    return specs


def group_of(spec) -> str:
    """The name of a run's group (its seeds together): label/backend/element/scene."""
    return f"{spec.label}/{spec.backend}/{spec.element}/{spec.scene}"


def _paper_method() -> str | None:
    from compact_distributions.cvt.registry import methods

    return next((m.name for m in methods().values() if m.role == "paper"), None)


def summarise_runs(specs, rows, check_seeds, spread: bool) -> tuple[dict, dict, dict]:
    """(measures, speed, unavailable) sections from the runs: each group's guarded
    measures, and on the reference backend its whole-method ratio (module docstring)."""
    by_key = {r["key"]: r for r in rows}
    groups: dict[str, list] = {}
    for spec in specs:
        groups.setdefault(group_of(spec), []).append(spec)
    paper = _paper_method()
    paper_rows = {
        (r["backend"], r["element"], r["seed"]): r
        for r in rows
        if r["method"] == paper and not r["options"] and r["status"] == "ok"
    }
    measures, speed, unavailable = {}, {}, {}
    for group, gspecs in groups.items():
        first = gspecs[0]
        meta = {
            "kind": "method",
            "method": first.method,
            "backend": first.backend,
            "element": first.element,
            "scene": first.scene,
            "options": dict(first.options),
        }
        grows = [by_key[s.key] for s in gspecs]
        bad = [r for r in grows if r["status"] == "failed"]
        if bad:
            measures[group] = {**meta, "failed": bad[0]["reason"], "figures": {}}
            continue
        if any(r["status"] != "ok" for r in grows):
            unavailable[group] = next(r["reason"] for r in grows if r["status"] != "ok")
            continue
        figures = {}
        for measure, better in GUARDED.items():
            fig = figure_of(
                {r["seed"]: r.get(measure) for r in grows}, check_seeds, unit_of(measure), better, spread
            )
            if fig is not None:
                figures[measure] = fig
        measures[group] = {**meta, "figures": figures}
        if first.backend != REFERENCE_BACKEND:
            continue
        timed = [r for r in grows if spread or r["seed"] in check_seeds]
        if all(r["lloyd_seconds"] > 0 for r in timed):
            samples = [
                {
                    "whole": r["method_seconds"],
                    "lloyd": r["lloyd_seconds"],
                    "stages": r.get("stage_seconds", {}),
                }
                for r in timed
            ]
            figures = timing_figures(samples, WHOLE, spread)
        else:  # no Lloyd iterations: against the paper method's whole time on the same problem
            pairs = [(r, paper_rows.get((r["backend"], r["element"], r["seed"]))) for r in timed]
            ratios = [r["method_seconds"] / p["method_seconds"] for r, p in pairs if p is not None]
            pick = "median" if spread else "min"
            figures = {WHOLE: speed_figure(ratios, 0.0, f"{paper}'s whole time", pick=pick)} if ratios else {}
        if figures:
            speed[group] = {**meta, "figures": figures}
    return measures, speed, unavailable


class StagesExecutor(InProcessExecutor):
    """The in-process executor, each row given the stage times its method recorded
    (every ``NAME_seconds`` of the Distribution's ``extra``, as result.json's
    ``stage_seconds``)."""

    def run(self, items, on_start=None):
        for i, (status, value) in super().run(items, on_start):
            if status == "ok":
                value["row"]["stage_seconds"] = {
                    k.removesuffix("_seconds"): float(v)
                    for k, v in value.get("extra", {}).items()
                    if k.endswith("_seconds") and isinstance(v, (int, float)) and not isinstance(v, bool)
                }
            yield i, (status, value)


def measure_runs(specs, unavailable, quiet) -> list[dict]:
    """The rows of ``specs`` run here (not stored), with their stage times."""
    from ..sweep import run_sweep

    return run_sweep(
        specs, out=".", store=False, quiet=quiet, unavailable=dict(unavailable), executor=StagesExecutor()
    )


def timing_figures(samples: list[dict], whole: str, spread: bool) -> dict:
    """The speed figures of a group: its whole time and each stage over its Lloyd time.

    Parameters
    ----------
    samples : list of dict
        One per run: ``whole`` (s), ``lloyd`` (s, > 0) and ``stages`` (name -> s).
    whole : str
        The whole time's measure name.
    spread : bool
        The samples are the spread seeds of an update (the median is kept), not the
        checked seeds (the fastest is kept).

    Returns
    -------
    dict
        Measure name -> speed figure (:func:`speed_figure`); a stage every run timed.
    """
    if not samples:
        return {}
    pick = "median" if spread else "min"
    per = "its Lloyd time"
    figures = {whole: speed_figure([x["whole"] / x["lloyd"] for x in samples], 1.0, per, pick=pick)}
    stages = [k for k in samples[0]["stages"] if k != "lloyd" and all(k in x["stages"] for x in samples)]
    for stage in stages:
        ratios = [x["stages"][stage] / x["lloyd"] for x in samples]
        figures[f"{stage} time"] = speed_figure(ratios, 0.0, per, pick=pick)
    return figures


# ---------------------------------------------------------------------------------------
# measuring: the mosaic


def mosaic_once(mcfg: dict, seed: int) -> dict:
    """``cvtbench mosaic`` of the set's picture on the reference backend, seed ``seed``,
    into a temporary folder: its result.json and the command's whole time (s)."""
    import json

    from .cli import build_parser
    from .mosaic import SAMPLES_DIR

    with tempfile.TemporaryDirectory(prefix="cvtbench-regress-") as tmp:
        argv = [
            "mosaic",
            str(SAMPLES_DIR / mcfg["picture"]),
            "--elements",
            str(mcfg["n_elements"]),
            "--iterations",
            str(mcfg["iterations"]),
            "--seed",
            str(seed),
            "--backend",
            REFERENCE_BACKEND,
            "--quiet",
            "--out",
            str(Path(tmp) / "mosaic"),
        ]
        args = build_parser().parse_args(argv)
        args.argv = argv
        t0 = time.perf_counter()
        args.func(args)
        whole = time.perf_counter() - t0
        result = json.loads((Path(tmp) / "mosaic" / "result.json").read_text())
    result["whole_seconds"] = whole
    return result


def mosaic_group(mcfg: dict, result: dict) -> str:
    return f"mosaic {mcfg['picture']}/{result['method']}/{result['backend']}/{result['element']}"


def measure_mosaic(mcfg: dict, seeds, check_seeds, spread: bool) -> tuple[dict, dict]:
    """(measures, speed) of the mosaic check: its measures over ``seeds``, its whole time
    and each stage over its Lloyd time (the fastest of the checked seeds)."""
    try:
        results = {s: mosaic_once(mcfg, s) for s in seeds}
        # the first mosaic of a process pays for its imports: the first checked seed is
        # timed once more, and each figure keeps the faster of the two
        timed = dict(results)
        timed[check_seeds[0]] = faster(results[check_seeds[0]], mosaic_once(mcfg, check_seeds[0]))
    except (KeyboardInterrupt, MemoryError):
        raise
    except Exception as exc:
        group = f"mosaic {mcfg['picture']}"
        meta = {"kind": "mosaic", "backend": REFERENCE_BACKEND}
        return {group: {**meta, "failed": f"{type(exc).__name__}: {exc}", "figures": {}}}, {}
    first = results[seeds[0]]
    group = mosaic_group(mcfg, first)
    meta = {
        "kind": "mosaic",
        "method": first["method"],
        "backend": first["backend"],
        "element": first["element"],
        "picture": mcfg["picture"],
    }
    figures = {}
    for measure, (better, unit) in MOSAIC_GUARDED.items():
        fig = figure_of({s: r.get(measure) for s, r in results.items()}, check_seeds, unit, better, spread)
        if fig is not None:
            figures[measure] = fig
    return {group: {**meta, "figures": figures}}, {
        group: {**meta, "figures": mosaic_speed(timed, check_seeds, spread)}
    }


def faster(a: dict, b: dict) -> dict:
    """Two mosaic results of one seed as one: each time the smaller of the two (the
    whole time, each stage, Lloyd)."""
    out = dict(a)
    out["whole_seconds"] = min(a["whole_seconds"], b["whole_seconds"])
    out["lloyd_seconds"] = min(a["lloyd_seconds"], b["lloyd_seconds"])
    out["stage_seconds"] = {k: min(v, b["stage_seconds"].get(k, v)) for k, v in a["stage_seconds"].items()}
    return out


def mosaic_speed(results: dict, check_seeds, spread: bool = False) -> dict:
    """The mosaic's whole time and each stage's over its Lloyd time (the fastest of the
    checked seeds; for an update the median over every seed)."""
    runs = [r for s, r in results.items() if spread or s in check_seeds]
    samples = [
        {"whole": r["whole_seconds"], "lloyd": r["lloyd_seconds"], "stages": r["stage_seconds"]}
        for r in runs
        if r["lloyd_seconds"] > 0
    ]
    return timing_figures(samples, MOSAIC_WHOLE, spread) if len(samples) == len(runs) else {}


# ---------------------------------------------------------------------------------------
# measuring: Lloyd steps


def speed_key(backend: str, reference: str, metric: str, n: int, size: int) -> str:
    return f"{backend} vs {reference}, {metric}, N={n}, {size}²"


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
    return speed_figure(
        [b_ms / ref_ms],
        0.0,
        f"{reference}'s step",
        slack=0.0,
        ms=round(b_ms, 3),
        reference_ms=round(ref_ms, 3),
    )


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


def measure_speed(cfg, backends, unavailable, quiet, only=None) -> tuple[dict, dict]:
    """(speed, unavailable): each pair's ratio (``only``: those groups alone)."""
    from tqdm import tqdm

    from ..sweep import BackendCache

    sp = cfg["speed"]
    n, size = sp["n_elements"], sp["size"]
    out, skipped = {}, {}
    cache = BackendCache()
    pairs = [p for p in speed_pairs(cfg, backends) if only is None or speed_key(*p, n, size) in only]
    try:
        for backend, ref, metric in tqdm(pairs, desc="speed", unit="pair", disable=quiet, file=sys.stderr):
            key = speed_key(backend, ref, metric, n, size)
            meta = {"kind": "lloyd", "backend": backend, "reference": ref, "metric": metric}
            if backend in unavailable or ref in unavailable:
                skipped[key] = unavailable.get(backend) or unavailable.get(ref)
                continue
            try:
                out[key] = {
                    **meta,
                    "figures": {LLOYD_STEP: measure_speed_pair(backend, ref, metric, n, size, sp, cache)},
                }
            except (KeyboardInterrupt, MemoryError):
                raise
            except Exception as exc:
                out[key] = {**meta, "failed": f"{type(exc).__name__}: {exc}", "figures": {}}
                cache.close()
    finally:
        cache.close()
    return out, skipped


# ---------------------------------------------------------------------------------------
# reports


def counts(checks: list[Check]) -> dict:
    out = {"checks": len(checks), "pass": 0, "fail": 0, "new": 0, "not checked": 0}
    for c in checks:
        out[c.status] += 1
    return out


def junit_xml(checks: list[Check], mode: str, elapsed: float) -> str:
    """JUnit XML: one test case per check; a failure carries its figures, a new or
    unchecked figure is skipped with its reason."""
    import xml.etree.ElementTree as ET

    n = counts(checks)
    suites = ET.Element(
        "testsuites",
        name="cvtbench regress",
        tests=str(n["checks"]),
        failures=str(n["fail"]),
        errors="0",
        skipped=str(n["new"] + n["not checked"]),
        time=f"{elapsed:.3f}",
    )
    suite = ET.SubElement(
        suites,
        "testsuite",
        name=f"cvtbench regress ({mode})",
        tests=str(n["checks"]),
        failures=str(n["fail"]),
        errors="0",
        skipped=str(n["new"] + n["not checked"]),
        time=f"{elapsed:.3f}",
    )
    for c in checks:
        case = ET.SubElement(suite, "testcase", classname=f"regress.{c.section}", name=c.name, time="0")
        figures = f"current {c.current!r}, baseline {c.baseline!r}, limit {c.limit!r}"
        if c.status == "fail":
            ET.SubElement(
                case, "failure", message=f"{c.name}: {c.message}", type="regression"
            ).text = f"{c.name}: {c.message}\n{figures}"
        elif c.status in ("new", "not checked"):
            ET.SubElement(case, "skipped", message=f"{c.status}: {c.message}")
        else:
            ET.SubElement(case, "system-out").text = f"{c.message}\n{figures}"
    ET.indent(suites)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(suites, encoding="unicode") + "\n"


def json_report(checks: list[Check], mode: str, baseline: Path, elapsed: float) -> dict:
    return {
        "mode": mode,
        "baseline": str(baseline),
        "passed": not any(c.status == "fail" for c in checks),
        "elapsed_seconds": round(elapsed, 3),
        "counts": counts(checks),
        "checks": [{"name": c.name, **asdict(c)} for c in checks],
    }


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def markdown_summary(checks: list[Check], mode: str, elapsed: float) -> str:
    """The summary for a CI page (GitHub's job summary): the verdict, the failures and
    what was not checked as tables, every check folded below."""
    n = counts(checks)
    verdict = "FAIL" if n["fail"] else "PASS"
    lines = [
        f"## cvtbench regress ({mode}): {verdict}",
        "",
        f"{n['checks']} checks: {n['pass']} passed, {n['fail']} failed, {n['new']} new, "
        f"{n['not checked']} not checked ({elapsed:.0f} s)",
        "",
    ]
    for status, title in (
        ("fail", "Regressions"),
        ("new", "New (not in the baseline)"),
        ("not checked", "Not checked"),
    ):
        rows = [c for c in checks if c.status == status]
        if rows:
            lines += [f"### {title}", "", "| check | figures |", "|---|---|"]
            lines += [f"| {_cell(c.name)} | {_cell(c.message)} |" for c in rows]
            lines.append("")
    lines += ["<details><summary>every check</summary>", "", "| status | check | figures |", "|---|---|---|"]
    lines += [f"| {c.status} | {_cell(c.name)} | {_cell(c.message)} |" for c in checks]
    lines += ["", "</details>", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------
# the baseline file (fail closed: a figure that is missing or not finite never passes)


def _finite(value, low=None, high=None) -> bool:
    return (
        isinstance(value, (int, float))
        and not isinstance(value, bool)
        and math.isfinite(value)
        and (low is None or value >= low)
        and (high is None or value <= high)
    )


# the figures each entry must hold, finite and in range: name -> (low, high)
REQUIRED_FIGURES = {
    "measures": {"mean": (None, None), "tolerance": (0.0, None)},
    "speed": {"ratio": (0.0, None), "floor": (0.0, None), "slowdown": (1.0, None), "slack": (0.0, None)},
}


def check_figures(section: dict, where: str) -> None:
    """Fail closed: every figure of every group of ``section`` holds its numbers as
    finite numbers in range and says which way is better (a missing key, NaN, an
    infinity or a string is InputError naming the group): a comparison with NaN is
    false, so a broken figure would pass."""
    for kind, required in REQUIRED_FIGURES.items():
        groups = section.get(kind, {})
        if not isinstance(groups, dict):
            raise InputError(f"{where}: '{kind}' is not an object")
        for group, entry in groups.items():
            figures = entry.get("figures") if isinstance(entry, dict) else None
            if not isinstance(figures, dict):
                raise InputError(f"{where}: {kind} {group!r} has no object 'figures', got {entry!r}")
            for measure, fig in figures.items():
                at = f"{where}: {kind} {group!r}, {measure!r}"
                if not isinstance(fig, dict):
                    raise InputError(f"{at} is not an object, got {fig!r}")
                for name, (low, high) in required.items():
                    value = fig.get(name)
                    if not _finite(value, low, high):
                        state = "is missing" if name not in fig else f"is {value!r}"
                        bound = f" >= {low:g}" if low is not None else ""
                        raise InputError(f"{at}: {name!r} {state}, not a finite number{bound}")
                if kind == "measures" and fig.get("better") not in ("higher", "lower"):
                    raise InputError(f"{at}: 'better' is {fig.get('better')!r}, not 'higher' or 'lower'")
                if kind == "measures" and fig.get("unit") not in RESOLUTION:
                    raise InputError(
                        f"{at}: 'unit' is {fig.get('unit')!r}, not one of {', '.join(RESOLUTION)}"
                    )
                values = fig.get("values", [])
                if not isinstance(values, list) or not all(_finite(v) for v in values):
                    raise InputError(f"{at}: 'values' holds {values!r}, not finite numbers")


def load_baseline(path: Path) -> dict:
    """The baseline file: a json object of format FORMAT whose sections ("quick",
    "full") hold objects 'measures' and 'speed', every figure checked."""
    if not path.exists():
        raise InputError(f"no regression baseline at {path}; create it with `cvtbench regress --update`")
    data = json_object(path, "regression baseline")
    for mode in SETS:
        section = data.get(mode)
        if section is None:
            continue
        if not (isinstance(section, dict) and all(isinstance(section.get(k, {}), dict) for k in JUDGES)):
            raise InputError(
                f"regression baseline {path}: its {mode!r} section is not an object with "
                "'measures' and 'speed' objects"
            )
        if data.get("format") != FORMAT:
            raise InputError(
                f"regression baseline {path} is of format {data.get('format')!r}, not {FORMAT}; "
                f"make it again with `cvtbench regress {'--quick ' if mode == 'quick' else ''}--update`"
            )
        check_figures(section, f"regression baseline {path}, {mode!r}")
    return data


def _report_path(value, option: str) -> Path | None:
    """A --junit/--json file: its folder must exist or be makeable, and it no folder."""
    from ..outputs import folder_problem

    if value is None:
        return None
    path = Path(value)
    if path.is_dir():
        raise InputError(f"{option} {value} is a folder, not a file")
    _, problem = folder_problem(Path(os.path.realpath(path)).parent, option, path.parent)
    if problem:
        raise InputError(problem)
    return path


def _write_report(path: Path, text: str) -> None:
    from ..outputs import atomic_write

    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, text)


# ---------------------------------------------------------------------------------------
# command


def add_parser(sub):
    p = sub.add_parser(
        "regress",
        help="fail when a measure, a method's whole time, the mosaic or a Lloyd step got worse than the baseline",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--quick", action="store_true", help="the CI set (under a minute)")
    p.add_argument("--update", action="store_true", help="write the current figures into the baseline file")
    p.add_argument("--baseline", default=None, help=f"baseline file (default {BASELINE_FILE})")
    options.add_list_options(p, "methods", "backends", "shapes")
    p.add_argument("--no-speed", action="store_true", help="no timing checks")
    p.add_argument(
        "--no-coverage", action="store_true", help="no method runs (their measures and whole time)"
    )
    p.add_argument("--no-mosaic", action="store_true", help="no mosaic check")
    p.add_argument("--junit", default=None, metavar="FILE", help="also write the checks as JUnit XML")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the checks as json")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def _asked(baseline: dict, args, methods, backends, shapes) -> dict:
    """The baseline's groups this invocation measures: a --methods/--backends/--shapes
    subset or a --no-... switch is not a regression of what it leaves out.  Without
    --methods, the groups of a method that is not installed here stay (not checked)."""
    if args.methods is None:
        methods = [*methods, *(g.get("method") for s in JUDGES for g in baseline.get(s, {}).values())]
        methods = [m for m in dict.fromkeys(methods) if m]

    def wanted(section: str, g: dict) -> bool:
        kind = g.get("kind")
        if g.get("backend") not in backends:
            return False
        if kind == "lloyd":
            return not args.no_speed
        if kind == "mosaic":
            return not args.no_mosaic and (section == "measures" or not args.no_speed)
        return (
            not args.no_coverage
            and (section == "measures" or not args.no_speed)
            and g.get("method") in methods
            and (shapes is None or g.get("element") in shapes)
        )

    return {s: {k: g for k, g in baseline.get(s, {}).items() if wanted(s, g)} for s in JUDGES}


def measure(cfg, args, methods, backends, shapes, unavailable, fastest, spread: bool) -> dict:
    """Everything this invocation measures, as a section of the baseline file."""
    current: dict = {"measures": {}, "speed": {}, "unavailable": {}}
    rcfg, mcfg = cfg["runs"], cfg["mosaic"]
    if not args.no_coverage:
        seeds = list(range(rcfg["spread_seeds"])) if spread else rcfg["seeds"]
        specs = method_specs(rcfg, methods, backends, fastest, seeds, shapes)
        rows = measure_runs(specs, unavailable, args.quiet)
        meas, speed, skipped = summarise_runs(specs, rows, rcfg["seeds"], spread)
        current["measures"].update(meas)
        if not args.no_speed:
            current["speed"].update(speed)
        current["unavailable"].update(skipped)
    if not args.no_mosaic and REFERENCE_BACKEND in backends:
        seeds = list(range(mcfg["spread_seeds"])) if spread else mcfg["seeds"]
        meas, speed = measure_mosaic(mcfg, seeds, mcfg["seeds"], spread)
        current["measures"].update(meas)
        if not args.no_speed:
            current["speed"].update(speed)
    if not args.no_speed:
        speed, skipped = measure_speed(cfg, backends, unavailable, args.quiet)
        current["speed"].update(speed)
        current["unavailable"].update(skipped)
    return current


def remeasure(cfg, args, current: dict, failing: set[str], backends, unavailable) -> None:
    """Measure the failing speed groups once more and keep each figure's faster value."""
    again: dict = {}
    rcfg, mcfg = cfg["runs"], cfg["mosaic"]
    groups = {g: current["speed"][g] for g in failing if g in current["speed"]}
    runs = {g for g, e in groups.items() if e.get("kind") == "method"}
    if runs:
        names = list(dict.fromkeys(groups[g]["method"] for g in runs))
        specs = [
            s
            for s in method_specs(rcfg, names, [REFERENCE_BACKEND], REFERENCE_BACKEND, rcfg["seeds"])
            if group_of(s) in runs
        ]
        rows = measure_runs(specs, unavailable, args.quiet)
        again.update(summarise_runs(specs, rows, rcfg["seeds"], False)[1])
    if any(e.get("kind") == "mosaic" for e in groups.values()):
        again.update(measure_mosaic(mcfg, mcfg["seeds"], mcfg["seeds"], False)[1])
    lloyd = {g for g, e in groups.items() if e.get("kind") == "lloyd"}
    if lloyd:
        again.update(measure_speed(cfg, backends, unavailable, args.quiet, only=lloyd)[0])
    for g in groups:
        new = again.get(g, {}).get("figures", {})
        for measure_name, fig in current["speed"][g]["figures"].items():
            if measure_name in new and new[measure_name]["ratio"] < fig["ratio"]:
                fig.update(new[measure_name])
            fig["remeasured"] = True


def run(args) -> int:
    from compact_distributions.baselines import method_names
    from compact_distributions.cvt.registry import unavailable_methods
    from compact_distributions.cvt.shapes import ELEMENT_SHAPES

    from ..outputs import atomic_write, dumps, folder_problem
    from ..report import provenance
    from ..table2 import sweep_backends, variant_backend

    t0 = time.perf_counter()
    mode = "quick" if args.quick else "full"
    cfg = SETS[mode]
    path = Path(args.baseline) if args.baseline else BASELINE_FILE
    if args.update:
        _, problem = folder_problem(Path(os.path.realpath(path)).parent, "--baseline", path.parent)
        if problem or path.is_dir() or (path.exists() and not path.is_file()):
            raise InputError(problem or f"--baseline {path} is not a file")
    junit, json_path = _report_path(args.junit, "--junit"), _report_path(args.json, "--json")
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
    shapes = name_list(args.shapes, "--shapes", list(ELEMENT_SHAPES)) or None
    backends, unavailable = sweep_backends(args.backends)
    fastest = variant_backend(unavailable)

    current = measure(cfg, args, methods, backends, shapes, unavailable, fastest, spread=args.update)
    asked = _asked(baseline, args, methods, backends, shapes)
    missing = unavailable_methods()
    for section in JUDGES:
        for group, g in asked[section].items():
            if g.get("kind") == "method" and g.get("method") not in all_methods:
                why = missing.get(g["method"], "not installed here")
                current["unavailable"].setdefault(group, f"method {g['method']!r}: {why}")
            elif g.get("backend") in unavailable:
                current["unavailable"].setdefault(group, unavailable[g["backend"]])
    checks = compare(asked, current)
    failing = {
        c.group for c in checks if c.status == "fail" and c.section == "speed" and c.current is not None
    }
    if failing and not args.update:
        remeasure(cfg, args, current, failing, backends, unavailable)
        checks = compare(asked, current)
    elapsed = time.perf_counter() - t0

    print_groups(current, asked)
    if args.update:
        run_failures = [c for c in checks if c.status == "fail" and c.message.startswith("failed to run")]
        merged = merge(baseline, current)
        merged["set"] = dict(cfg)
        merged["provenance"] = provenance()
        baseline_all[mode] = merged
        baseline_all["format"] = FORMAT
        baseline_all["tolerances"] = tolerance_rule()
        atomic_write(path, dumps(baseline_all))
        for c in run_failures:
            print(f"FAILED: {c.name}: {c.message}", file=sys.stderr)
        print(
            f"updated {path} ({mode}; {len(current['measures'])} measured and {len(current['speed'])} "
            f"timed groups; {elapsed:.0f} s)"
        )
        return 1 if run_failures else 0

    for c in checks:
        if c.status in ("new", "not checked") or "better by more" in c.message:
            print(f"note: {c.status if c.status != 'pass' else 'improved'}: {c.name}: {c.message}")
    text_reports(checks, mode, path, elapsed, junit, json_path)
    failures = [c for c in checks if c.status == "fail"]
    n = counts(checks)
    if failures:
        for c in failures:
            print(f"REGRESSION: {c.name}: {c.message}", file=sys.stderr)
        print(
            f"cvtbench regress: {len(failures)} regression(s) against {path} ({mode}, {elapsed:.0f} s)",
            file=sys.stderr,
        )
        return 1
    print(
        f"regress ({mode}): no regression against {path}: {n['pass']} checks passed, {n['new']} new, "
        f"{n['not checked']} not checked ({elapsed:.0f} s)"
    )
    return 0


def text_reports(checks, mode, path, elapsed, junit, json_path) -> None:
    """The --junit and --json files, and GitHub's job summary where it is set."""
    from ..outputs import dumps

    if junit is not None:
        _write_report(junit, junit_xml(checks, mode, elapsed))
    if json_path is not None:
        _write_report(json_path, dumps(json_report(checks, mode, path, elapsed)))
    summary = os.environ.get("GITHUB_STEP_SUMMARY")
    if summary:
        try:
            with open(summary, "a", encoding="utf-8") as fh:
                fh.write(markdown_summary(checks, mode, elapsed))
        except OSError as exc:  # the summary is a courtesy: the verdict stands without it
            print(
                f"warning: could not append to GITHUB_STEP_SUMMARY {summary}: {exc.strerror}", file=sys.stderr
            )


def print_groups(current: dict, asked: dict) -> None:
    """One line per measured group: its figures, the baseline's in brackets."""
    for section in JUDGES:
        for group, entry in sorted(current[section].items()):
            if entry.get("failed"):
                print(f"{section:<8} {group}: failed to run: {entry['failed']}")
                continue
            base = asked[section].get(group, {}).get("figures", {})
            parts = []
            for name, fig in entry["figures"].items():
                b = base.get(name)
                if section == "measures":
                    unit = fig.get("unit", "share")
                    parts.append(
                        f"{name} {_show(fig['mean'], unit)}" + (f" [{_show(b['mean'], unit)}]" if b else "")
                    )
                else:
                    parts.append(f"{name} {fig['ratio']:.3g}x" + (f" [{b['ratio']:.3g}x]" if b else ""))
            print(f"{section:<8} {group}: " + ", ".join(parts))


__all__ = [
    "CKDTREE",
    "BASELINE_FILE",
    "FORMAT",
    "GUARDED",
    "MOSAIC_GUARDED",
    "RESOLUTION",
    "SPREAD_Z",
    "SLOWDOWN",
    "SPEED_SLACK",
    "WHOLE",
    "MOSAIC_WHOLE",
    "LLOYD_STEP",
    "SETS",
    "Check",
    "tolerance_rule",
    "unit_of",
    "tolerance_of",
    "figure_of",
    "speed_figure",
    "judge_measure",
    "judge_speed",
    "compare",
    "merge",
    "shapes_of",
    "backends_of",
    "method_specs",
    "group_of",
    "summarise_runs",
    "StagesExecutor",
    "measure_runs",
    "timing_figures",
    "mosaic_once",
    "mosaic_group",
    "measure_mosaic",
    "mosaic_speed",
    "faster",
    "speed_key",
    "measure_speed_pair",
    "speed_pairs",
    "measure_speed",
    "counts",
    "junit_xml",
    "json_report",
    "markdown_summary",
    "REQUIRED_FIGURES",
    "check_figures",
    "load_baseline",
    "add_parser",
    "measure",
    "remeasure",
    "run",
    "text_reports",
    "print_groups",
]
