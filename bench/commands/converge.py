"""`cvtbench converge`: how fast Lloyd's energy falls, plain and accelerated.

Each problem runs, in one process one after the other, on one backend (OpenCL where it
starts, else NumPy): plain Lloyd for K iterations (and one more, which measures the
energy of the K-th iteration's sites) and accelerated Lloyd (``--accelerate``,
:mod:`compact_distributions.cvt.accelerate`) for K iterations, twice each in turn (each
keeps its faster run: the runs are equal but for their times), then both with
``--tolerance 1e-4`` under a cap.  Problems: Table 2's (its five shapes on the whole
square, no density), a density picture (``samples/scene.jpg``) with squares (linf) and
circles (l2), matplotlib's sample photograph ``grace_hopper.jpg`` (the picture whose
wandering energy the convergence issue reports; full only, where matplotlib has it) and
squares at N = 64 000 on 4096² (full only).  Full: 1024², N = 4000, K = 200, cap 2000.
Quick (CI): 128², N = 64, K = 40, cap 400, no photograph and no 64 000.

From each problem it keeps the energy after every iteration against the iteration and
against the wall time at which that energy was known (plain Lloyd's iteration k measures
the energy of the sites it starts from; accelerated Lloyd's, of those it ends with), the
time accelerated Lloyd takes to reach the energy plain Lloyd has after K iterations
against the time of plain's K iterations, each tolerance run's iterations and why it
stopped, and how far plain Lloyd's 20 iterations (the paper's setting) and K iterations
are above the lowest energy any of its runs reached.

Writes ``OUT/converge.md`` (the summary), ``OUT/converge.csv`` (one row per problem),
``OUT/converge_curves.csv`` (problem, variant, iteration, seconds, energy) and
``OUT/converge.png`` (energy against time and against iterations, one row of panels per
problem), and ``OUT/raw/converge*/``; like every sweep it resumes, and ``--force`` redoes
stored runs.  Times are ratios within one process; other work on the machine moves them.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from compact_distributions.backends import first_available, variant_names, variant_status
from compact_distributions.cvt.metrics import PAPER_SHAPES, SHAPES
from compact_distributions.cvt.problem import MAX_SEED
from compact_distributions.cvt.validate import one_of, whole_number

from .. import options

TOLERANCE = 1e-4
TIMED_RUNS = 2  # of plain and of accelerated Lloyd, alternately; each keeps its fastest
DEFAULT_BACKENDS = ("opencl",)
TABLE2_SHAPES = PAPER_SHAPES
PICTURE = "scene.jpg"  # samples/
PHOTOGRAPH = "grace_hopper.jpg"  # matplotlib's sample data
# squares (linf) and circles (l2): the shapes of the Minkowski norms the targets name
PICTURE_ELEMENTS = tuple(s.name for s in SHAPES.values() if s.minkowski_p in (2.0, math.inf))
TARGET_PICTURE = 0.4  # the targets: time ratio on a density picture ...
TARGET_TABLE2 = 0.5  # ... and on average over Table 2's problems


@dataclass(frozen=True)
class Settings:
    size: int
    n_elements: int
    iterations: int  # K
    cap: int  # of the tolerance runs
    big: tuple[int, int] | None  # (N, side) of the large problem
    photograph: bool


FULL = Settings(1024, 4000, 200, 2000, (64000, 4096), True)
QUICK = Settings(128, 64, 40, 400, None, False)


def picture_path(picture: str) -> Path | None:
    """The file of a density picture of this report (None where it is not here)."""
    if picture == PHOTOGRAPH:
        try:
            import matplotlib.cbook as cbook

            path = Path(cbook.get_sample_data(PHOTOGRAPH, asfileobj=False))
        except (ImportError, OSError, ValueError):
            return None
    else:
        from .mosaic import SAMPLES_DIR

        path = SAMPLES_DIR / picture
    return path if path.is_file() else None


@dataclass(frozen=True)
class ConvergeSpec:
    """One problem: plain and accelerated Lloyd, K iterations and to a tolerance."""

    suite: str
    name: str  # how the report calls the problem
    element: str
    size: int
    n_elements: int
    seed: int
    iterations: int
    cap: int
    tolerance: float
    backend: str
    picture: str | None = None  # a density picture, by name
    group: str = "table2"  # table2, picture or large: the report's targets read it

    @property
    def key(self) -> str:
        picture = f"__{Path(self.picture).stem}" if self.picture else ""
        return (
            f"{self.element}{picture}__{self.backend}__{self.size}__n{self.n_elements}"
            f"__it{self.iterations}__cap{self.cap}__tol{self.tolerance:g}__s{self.seed}"
        )

    def describe(self) -> str:
        return f"{self.name} {self.backend} N={self.n_elements} {self.size}²"

    def params(self) -> dict:
        return {k: v for k, v in asdict(self).items() if k != "suite"}

    def memory_estimate(self):
        from compact_distributions.cvt.registry import get_method
        from compact_distributions.cvt.resources import run_estimate

        from ..sweep import memory_class

        return run_estimate(
            self.size,
            self.size,
            self.n_elements,
            memory_class(self.backend),
            element=self.element,
            density=self.picture is not None,
            placement=False,
            pictures=False,
            method=get_method("ours"),
            what=f"the problem {self.describe()}",
        )

    def problem(self):
        from compact_distributions.cvt.fields import DensityMap
        from compact_distributions.cvt.metrics import make_metric
        from compact_distributions.cvt.mosaic.images import load_grey
        from compact_distributions.cvt.problem import Grid, Problem
        from compact_distributions.cvt.shapes import shape_record

        density = None
        if self.picture is not None:
            path = picture_path(self.picture)
            if path is None:
                raise FileNotFoundError(f"density picture {self.picture} is not on this machine")
            density = DensityMap(load_grey(path, self.size, self.size, name="density")[0])
        metric = make_metric(shape_record(self.element).metric)
        return Problem(Grid(self.size, self.size), self.n_elements, metric, density, seed=self.seed)

    def execute(self, backend) -> dict:
        from compact_distributions.cvt.lloyd import lloyd

        from ..outputs import machine, versions

        problem = self.problem()
        k = self.iterations
        lloyd(problem, backend, 1)  # programs built and caches warm before anything is timed
        # plain, accelerated, plain, accelerated: each keeps its less disturbed run (the
        # runs are equal but for their times, which other work on the machine moves)
        runs = [
            lloyd(problem, backend, k + 1) if i % 2 == 0 else lloyd(problem, backend, k, accelerate=True)
            for i in range(2 * TIMED_RUNS)
        ]
        plain = min(runs[0::2], key=lambda r: sum(r.seconds))  # its last iteration measures the K-th sites
        fast = min(runs[1::2], key=lambda r: sum(r.seconds))
        plain_tol = lloyd(problem, backend, self.cap, tolerance=self.tolerance)
        fast_tol = lloyd(problem, backend, self.cap, tolerance=self.tolerance, accelerate=True)
        row = {
            "key": self.key,
            **self.params(),
            "status": "ok",
            "reason": "",
            "device": backend.device(),
            "metric": problem.metric.name,
            **summary(plain, fast, k),
            **{f"plain_tol_{n}": v for n, v in tolerance_run(plain_tol).items()},
            **{f"fast_tol_{n}": v for n, v in tolerance_run(fast_tol).items()},
        }
        lowest = min(min(run.energy) for run in (plain, fast, plain_tol, fast_tol) if run.energy)
        row["lowest_energy"] = lowest
        row["excess_20"] = plain.energy[20] / lowest - 1 if len(plain.energy) > 20 else np.nan
        row["excess_k"] = row["plain_energy_k"] / lowest - 1
        # the curves travel in the row, so that a stored run gives back its plot
        row["plain_energy"] = list(map(float, plain.energy))
        row["plain_seconds"] = np.cumsum(plain.seconds).tolist()
        row["fast_energy"] = list(map(float, fast.energy))
        row["fast_seconds"] = np.cumsum(fast.seconds).tolist()
        return {"row": row, "spec": asdict(self), "machine": machine(), "versions": versions()}


def summary(plain, fast, k: int) -> dict:
    """Plain Lloyd's energy after ``k`` iterations and the time of those iterations;
    when accelerated Lloyd first ended an iteration at or below that energy (its
    iterations and seconds, their ratio to plain's), and its own energy after ``k``.

    Parameters
    ----------
    plain : cvt.lloyd.LloydResult
        ``k + 1`` plain iterations (the last measures the energy of the k-th sites).
    fast : cvt.lloyd.LloydResult
        ``k`` accelerated iterations.
    k : int
        The iterations compared.

    Returns
    -------
    dict
    """
    target = float(plain.energy[k])
    plain_seconds = float(np.sum(plain.seconds[:k]))
    below = np.flatnonzero(np.asarray(fast.energy) <= target)
    reach = int(below[0]) + 1 if len(below) else None
    reach_seconds = float(np.sum(fast.seconds[:reach])) if reach else np.nan
    return {
        "plain_energy_k": target,
        "plain_seconds_k": plain_seconds,
        "fast_reach_iterations": reach if reach else np.nan,
        "fast_reach_seconds": reach_seconds,
        "time_ratio": reach_seconds / plain_seconds if reach and plain_seconds > 0 else np.nan,
        "fast_energy_k": float(fast.energy[-1]),
        "fast_seconds_k": float(np.sum(fast.seconds)),
        "fast_evaluations": fast.evaluations,
        "fast_fallbacks": fast.fallbacks,
    }


def tolerance_run(run) -> dict:
    """A tolerance run's iterations, why it stopped, its last and lowest energy, its time."""
    return {
        "iterations": run.iterations,
        "stopped_by": run.stopped_by,
        "energy": float(run.energy[-1]) if run.energy else np.nan,
        "lowest": float(min(run.energy)) if run.energy else np.nan,
        "seconds": float(np.sum(run.seconds)),
    }


@dataclass(frozen=True)
class ConvergeRequest(options.SweepRequest):
    """``cvtbench converge``, typed: the backend variant (None: OpenCL, else NumPy) and
    the seed of every problem."""

    backend: str | None = None
    seed: int = 0

    @classmethod
    def from_args(cls, args) -> ConvergeRequest:
        return cls(
            **cls.common(args),
            backend=None if args.backend is None else one_of(args.backend, "--backend", variant_names()),
            seed=whole_number(args.seed, "--seed", minimum=0, maximum=MAX_SEED),
        )


def add_parser(sub):
    p = sub.add_parser(
        "converge",
        help="energy against time and iterations, plain and accelerated Lloyd (reports/converge.md)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    options.add_sweep_options(p, "128² px, N = 64, 40 iterations, no photograph and no 64 000 (CI)")
    p.add_argument(
        "--backend",
        default=None,
        help=f"backend variant (default {', '.join(DEFAULT_BACKENDS)} where it starts, else numpy)",
    )
    p.add_argument("--seed", default="0", help="seed of every problem (default 0)")
    options.add_memory_option(p)
    p.set_defaults(func=run)


def problems(req: ConvergeRequest, backend: str) -> tuple[list[ConvergeSpec], list[str]]:
    """The specs of the request, and a note for each problem left out (its picture is
    not on this machine)."""
    st = QUICK if req.quick else FULL
    suite = "converge-quick" if req.quick else "converge"
    common = dict(
        suite=suite,
        seed=req.seed,
        iterations=st.iterations,
        cap=st.cap,
        tolerance=TOLERANCE,
        backend=backend,
    )
    specs = [
        ConvergeSpec(name=e, element=e, size=st.size, n_elements=st.n_elements, **common)
        for e in TABLE2_SHAPES
    ]
    left_out = []
    for picture in (PICTURE, PHOTOGRAPH) if st.photograph else (PICTURE,):
        if picture_path(picture) is None:
            left_out.append(f"{picture}: not on this machine")
            continue
        specs += [
            ConvergeSpec(
                name=f"{e}, density {picture}",
                element=e,
                size=st.size,
                n_elements=st.n_elements,
                picture=picture,
                group="picture",
                **common,
            )
            for e in PICTURE_ELEMENTS
        ]
    if st.big is not None:
        n, side = st.big
        specs.append(
            ConvergeSpec(
                name=f"square, N = {n}", element="square", size=side, n_elements=n, group="large", **common
            )
        )
    return specs, left_out


def prepare(req: ConvergeRequest) -> dict:
    """Every option, the report folder and each problem's memory checked first."""
    from ..outputs import check_folder
    from ..sweep import check_memory

    check_folder(req.out)
    status = variant_status()
    if req.backend is None:
        backend = first_available(DEFAULT_BACKENDS, status)
    else:
        backend = req.backend
    specs, left_out = problems(req, backend)
    check_memory(specs, req.memory_limit, lower="use --quick")
    unavailable = {v: text for v, (ok, text) in status.items() if not ok}
    return {"specs": specs, "left_out": left_out, "unavailable": unavailable}


def run(args) -> int:
    return converge(ConvergeRequest.from_args(args))


CURVES = ("plain_energy", "plain_seconds", "fast_energy", "fast_seconds")
COLUMNS = [
    "name",
    "element",
    "metric",
    "picture",
    "group",
    "size",
    "n_elements",
    "seed",
    "backend",
    "iterations",
    "plain_energy_k",
    "plain_seconds_k",
    "fast_reach_iterations",
    "fast_reach_seconds",
    "time_ratio",
    "fast_energy_k",
    "fast_seconds_k",
    "fast_evaluations",
    "fast_fallbacks",
    "cap",
    "tolerance",
    *(
        f"{v}_tol_{n}"
        for v in ("plain", "fast")
        for n in ("iterations", "stopped_by", "energy", "lowest", "seconds")
    ),
    "lowest_energy",
    "excess_20",
    "excess_k",
    "status",
    "reason",
    "device",
]


def converge(req: ConvergeRequest) -> int:
    """Run every problem and write the report (what ``cvtbench converge`` does)."""
    import pandas as pd

    from ..outputs import report_folder
    from ..report import provenance, write_csv, write_markdown, written_files
    from ..sweep import check_runs, run_sweep

    t0 = time.perf_counter()
    plan = prepare(req)
    cmd = req.command or "cvtbench converge" + (" --quick" if req.quick else "")
    names = ["converge.md", "converge.csv", "converge_curves.csv", "converge.png"]
    with report_folder(req.out, command=cmd):
        # one problem at a time, here: each times its runs against each other
        rows = run_sweep(
            plan["specs"], req.out, force=req.force, quiet=req.quiet, unavailable=plan["unavailable"]
        )
        table = pd.DataFrame([{c: r.get(c, np.nan) for c in COLUMNS} for r in rows])
        curves = curve_frame(rows)
        elapsed = time.perf_counter() - t0
        plotted = render_plot(rows, req.out / "converge.png")
        write_csv(req.out / "converge.csv", table)
        write_csv(req.out / "converge_curves.csv", curves)
        write_markdown(
            req.out / "converge.md",
            render_markdown(table, provenance(), cmd, elapsed, plotted, plan["left_out"], req.quick),
        )
        written = written_files(req.out, names)
    print(f"wrote {req.out}/{', '.join(written)} ({elapsed:.0f} s)", file=sys.stderr)
    check_runs(plan["specs"], rows, "converge")  # the report is written; a failed run still fails the command
    return 0


def curve_frame(rows: list[dict]):
    """The curves of the rows run, long form: name, variant, iteration, seconds, energy
    (iteration k: the energy known after k + 1 plain evaluations, or at the end of the
    k-th accelerated iteration; seconds: when it was known)."""
    import pandas as pd

    parts = []
    for r in rows:
        if r.get("status") != "ok":
            continue
        for variant, prefix, first in (("plain", "plain", 0), ("accelerated", "fast", 1)):
            energy = np.asarray(r[f"{prefix}_energy"], dtype=float)
            seconds = np.asarray(r[f"{prefix}_seconds"], dtype=float)
            parts.append(
                pd.DataFrame(
                    {
                        "name": r["name"],
                        "variant": variant,
                        "iteration": np.arange(first, first + len(energy)),
                        "seconds": seconds,
                        "energy": energy,
                    }
                )
            )
    columns = ["name", "variant", "iteration", "seconds", "energy"]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=columns)


def _fmt_ratio(x) -> str:
    return f"{x:.2f}x" if np.isfinite(x) else "not reached"


def render_markdown(
    table, prov: dict, command: str, elapsed: float, plotted: bool, left_out: list[str], quick: bool = False
) -> str:
    from ..report import fmt_seconds, header_markdown, markdown_table

    ok = table[table["status"] == "ok"]
    k = int(ok["iterations"].iloc[0]) if len(ok) else 0
    cap = int(ok["cap"].iloc[0]) if len(ok) else 0
    notes = [
        f"per problem, in one process: plain Lloyd {k} iterations (+1 that measures the energy of the {k}-th "
        f"sites) and accelerated Lloyd {k} iterations, {TIMED_RUNS} times each in turn (each keeps its fastest "
        f"run), then each with --tolerance {TOLERANCE:g} under a cap of {cap}",
        "energy: mean squared distance of a pixel to its site, px²; plain Lloyd's iteration k measures the sites "
        "it starts from, accelerated Lloyd's those it ends with (the first accelerated iteration also measures "
        "the start; a refused step costs one more evaluation)",
        f"reach: the accelerated iteration (and its cumulated seconds) that first ends at or below plain Lloyd's "
        f"energy after {k} iterations; ratio: those seconds over the seconds of plain's {k} iterations",
        "tolerance: the loop stops once its lowest energy improved by less than the tolerance (relative) over "
        "the last 20 iterations; the cap ends it otherwise",
        "above lowest: how far plain Lloyd's energy after 20 iterations (the paper's setting) and after "
        f"{k} is above the lowest energy any run of the problem reached",
        "times are within one process on a shared machine: other work moves them, ratios less",
        f"this command took {fmt_seconds(elapsed)}",
    ]
    notes += [f"left out: {n}" for n in left_out]
    text = header_markdown("Convergence: plain and accelerated Lloyd", prov, command, notes)

    def first(col):
        return ok.iloc[0][col] if len(ok) else ""

    text += f"\nBackend {first('backend')} ({first('device')}), seed {first('seed')}.\n\n"
    body = []
    for _, r in ok.iterrows():
        reach = (
            f"{int(r['fast_reach_iterations'])} it, {fmt_seconds(r['fast_reach_seconds'])}"
            if np.isfinite(r["fast_reach_iterations"])
            else "—"
        )
        body.append(
            [
                r["name"],
                f"{int(r['size'])}²",
                int(r["n_elements"]),
                f"{r['plain_energy_k']:.4g}",
                fmt_seconds(r["plain_seconds_k"]),
                reach,
                _fmt_ratio(r["time_ratio"]),
                f"{r['fast_energy_k']:.4g}",
                int(r["fast_fallbacks"]),
                f"{int(r['plain_tol_iterations'])} ({r['plain_tol_stopped_by']}), {r['plain_tol_lowest']:.4g}",
                f"{int(r['fast_tol_iterations'])} ({r['fast_tol_stopped_by']}), {r['fast_tol_lowest']:.4g}",
                f"{100 * r['excess_20']:.1f} % / {100 * r['excess_k']:.2f} %",
            ]
        )
    text += markdown_table(
        [
            "problem",
            "raster",
            "N",
            f"plain: energy after {k}",
            f"plain: {k} iterations",
            "accelerated reaches it",
            "time ratio",
            f"accelerated: energy after {k}",
            "refused steps",
            f"plain, tol {TOLERANCE:g}: iterations (why), lowest energy",
            f"accelerated, tol {TOLERANCE:g}: iterations (why), lowest energy",
            f"plain after 20 / {k} above lowest",
        ],
        body,
    )
    text += "\n## Against the targets\n\n"
    if quick:
        text += (
            f"The targets are for the full form ({FULL.size}², N = {FULL.n_elements}, K = {FULL.iterations}); "
            f"at {QUICK.size}², N = {QUICK.n_elements} these figures only show that every part runs.\n\n"
        )
    text += "\n".join(f"- {line}" for line in verdicts(ok, k, cap, judge=not quick)) + "\n"
    bad = table[table["status"] != "ok"]
    if len(bad):
        text += "\n## Not run or failed\n\n" + markdown_table(
            ["problem", "status", "reason"],
            [[r["name"], r["status"], r["reason"]] for _, r in bad.iterrows()],
        )
    if plotted:
        text += "\n![energy against time and against iterations](converge.png)\n"
    return text


def verdicts(ok, k: int, cap: int, judge: bool = True) -> list[str]:
    """The report's lines on the issue's targets, from the rows run (``judge``: say
    whether each is met)."""
    lines = []
    table2 = ok[ok["group"] == "table2"]
    if len(table2):
        ratios = table2["time_ratio"].to_numpy(dtype=float)
        reached = np.isfinite(ratios)
        # a problem where accelerated never reached plain's energy counts as 1 (no gain) in the mean
        mean = float(np.mean(np.where(reached, ratios, 1.0)))
        lines.append(
            f"Table 2's problems: accelerated Lloyd reaches plain's energy after {k} iterations in "
            f"{mean:.2f}x the time on average (target ≤ {TARGET_TABLE2}x; "
            + ", ".join(f"{n} {_fmt_ratio(x)}" for n, x in zip(table2["name"], ratios, strict=True))
            + ("; one not reached counts as 1x" if not reached.all() else "")
            + ")"
        )
    for picture, group in ok[ok["group"] == "picture"].groupby("picture", sort=False):
        parts = [f"{r['element']}s {_fmt_ratio(r['time_ratio'])}" for _, r in group.iterrows()]
        met = all(np.isfinite(x) and x <= TARGET_PICTURE for x in group["time_ratio"])
        verdict = f": {'met' if met else 'not met'}" if judge else ""
        lines.append(
            f"density picture {picture}: " + ", ".join(parts) + f" (target ≤ {TARGET_PICTURE}x{verdict})"
        )
    stopped = [
        (r["name"], v)
        for _, r in ok.iterrows()
        for v in ("plain", "fast")
        if r[f"{v}_tol_stopped_by"] != "tolerance"
    ]
    total = 2 * len(ok)
    lines.append(
        f"--tolerance {TOLERANCE:g}: {total - len(stopped)} of {total} runs stopped by the tolerance before the "
        f"cap of {cap}"
        + (
            ": "
            + ", ".join(
                f"{n} ({'plain' if v == 'plain' else 'accelerated'}) ran to the cap" for n, v in stopped
            )
            if stopped
            else ""
        )
    )
    return lines


def render_plot(rows: list[dict], path: Path) -> bool:
    """Per problem, energy against seconds and against iterations, plain and accelerated;
    the axis shows the energies from the 5th plain iteration down (the first ones are far above)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..report import save_figure

    ok = [r for r in rows if r.get("status") == "ok"]
    if not ok:
        path.unlink(missing_ok=True)
        return False
    fig, axes = plt.subplots(
        len(ok), 2, figsize=(10, 2.3 * len(ok) + 0.6), dpi=100, layout="constrained", squeeze=False
    )
    for (ax_t, ax_k), r in zip(axes, ok, strict=True):
        plain, fast = np.asarray(r["plain_energy"]), np.asarray(r["fast_energy"])
        target = r["plain_energy_k"]
        for ax, x_plain, x_fast, label in (
            (ax_t, r["plain_seconds"], r["fast_seconds"], "seconds"),
            (ax_k, np.arange(len(plain)), np.arange(1, len(fast) + 1), "iteration"),
        ):
            ax.plot(x_plain, plain, color="0.45", lw=1.2, label="plain")
            ax.plot(x_fast, fast, color="tab:red", lw=1.2, label="accelerated")
            ax.axhline(target, color="0.45", ls=":", lw=0.8)
            top = plain[min(5, len(plain) - 1)]
            low = min(plain.min(), fast.min())
            ax.set_ylim(low - 0.05 * (top - low + 1e-9), top)
            ax.set_xlabel(label)
            ax.grid(True, alpha=0.3)
        ax_t.set_ylabel("energy (px²)")
        ax_t.set_title(f"{r['name']}: against time", fontsize=9)
        ax_k.set_title(f"{r['name']}: against iterations", fontsize=9)
        ax_k.legend(fontsize=7)
    save_figure(fig, path)
    plt.close(fig)
    return True


__all__ = [
    "TOLERANCE",
    "TIMED_RUNS",
    "FULL",
    "QUICK",
    "Settings",
    "ConvergeSpec",
    "ConvergeRequest",
    "picture_path",
    "summary",
    "tolerance_run",
    "problems",
    "prepare",
    "converge",
    "curve_frame",
    "verdicts",
    "render_markdown",
    "render_plot",
    "add_parser",
    "run",
]
