"""`cvtbench backends`: milliseconds per Lloyd iteration for every backend, side by side.

What is timed: one whole Lloyd iteration as :func:`cvt.lloyd.lloyd` runs it (angles and
scales at the sites, the backend's labels and integer moments, the centroids), on
uniform random sites of seed 0 that then move as Lloyd moves them.  Each configuration
runs ``warmup`` iterations first (kernel builds, buffer allocation), then ``repeats``
timed ones; the report gives their median.  The NumPy reference backend is the unit
(``x numpy`` = NumPy's time / this backend's time, higher is faster); the ``ckdtree``
backend (scipy's cKDTree + np.bincount, the common CPU tool; l2, l1 and linf only) is
an extra reference row.

Full sweep: every backend variant (numpy, opencl, gl-cone, gl-exact, ckdtree) x N in
{1000, 4000, 16000} x raster {512, 1024, 2048} x the six metrics, 1 warm-up + 3 timed
iterations.  Quick: N in {1000, 4000} x raster {256, 512, 1024} x l2, linf and
triangle, 1 + 3.

Writes ``OUT/backends.md``, ``.csv``, ``.png`` (log-log: time against N and against
pixels) and one raw json per configuration under ``OUT/raw/backends*/``, through the
sweep engine of ``cvtbench table2`` (resumable: a configuration whose json exists is
read back unless --force).  ``--from-benchmark-json``
builds the same report from a pytest-benchmark ``--benchmark-json`` file instead.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from compact_distributions.backends import REFERENCE, variant_metrics, variant_names, variant_status
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.metrics import METRIC_NAMES, PAPER_METRICS, SHAPES
from compact_distributions.cvt.validate import json_object, name_list, one_of, whole_number

from .. import options
from ..timing import time_lloyd

FULL = {
    "sites": [1000, 4000, 16000],
    "sizes": [512, 1024, 2048],
    "metrics": list(PAPER_METRICS),
    "warmup": 1,
    "repeats": 3,
}
QUICK = {
    "sites": [1000, 4000],
    "sizes": [256, 512, 1024],
    # one ball of each build: a circle, a square, a triangle (the paper's shapes that β
    # does not stretch)
    "metrics": [shape.metric for shape in SHAPES.values() if shape.paper and not shape.axial],
    "warmup": 1,
    "repeats": 3,
}

MAX_REPEATS = 1000

COLUMNS = [
    "backend",
    "metric",
    "n_elements",
    "size",
    "pixels",
    "ms_per_iteration",
    "ms_min",
    "ms_max",
    "repeats",
    "warmup",
    "x_numpy",
    "status",
    "reason",
    "device",
    "host",
]


@dataclass(frozen=True)
class TimingSpec:
    """One timed configuration of a sweep spec (see bench/sweep.py)."""

    suite: str
    backend: str  # a backend variant
    metric: str
    n_elements: int
    size: int
    warmup: int
    repeats: int

    @property
    def key(self) -> str:
        return (
            f"{self.backend}__{self.metric}__{self.size}__n{self.n_elements}__w{self.warmup}r{self.repeats}"
        )

    def describe(self) -> str:
        return f"{self.backend} {self.metric} N={self.n_elements} {self.size}²"

    def params(self) -> dict:
        return {
            "backend": self.backend,
            "metric": self.metric,
            "n_elements": self.n_elements,
            "size": self.size,
            "pixels": self.size * self.size,
            "warmup": self.warmup,
            "repeats": self.repeats,
            "ms_per_iteration": np.nan,
            "ms_min": np.nan,
            "ms_max": np.nan,
            "device": "",
        }

    def memory_estimate(self):
        from compact_distributions.cvt.resources import run_estimate

        from ..sweep import memory_class

        return run_estimate(
            self.size,
            self.size,
            self.n_elements,
            memory_class(self.backend),
            placement=False,
            pictures=False,
            what=f"timing {self.describe()}",
        )

    def execute(self, backend) -> dict:
        from ..outputs import machine, versions

        secs = time_lloyd(backend, self.metric, self.n_elements, self.size, self.warmup, self.repeats)
        ms = np.asarray(secs) * 1000
        row = {
            "key": self.key,
            **self.params(),
            "status": "ok",
            "reason": "",
            "ms_per_iteration": float(np.median(ms)),
            "ms_min": float(ms.min()),
            "ms_max": float(ms.max()),
            "device": backend.device(),
        }
        return {
            "row": row,
            "seconds": secs,
            "spec": asdict(self),
            "machine": machine(),
            "versions": versions(),
        }


def sweep_specs(cfg: dict, variants: list[str], suite: str) -> list[TimingSpec]:
    specs = []
    for b in variants:
        computes = variant_metrics(b)
        for metric in cfg["metrics"]:
            if computes is not None and metric not in computes:
                continue
            for size in cfg["sizes"]:
                for n in cfg["sites"]:
                    specs.append(TimingSpec(suite, b, metric, n, size, cfg["warmup"], cfg["repeats"]))
    return specs


def with_ratios(rows: list[dict]):
    """DataFrame of the rows with ``x_numpy`` = NumPy's median / this median, per
    (metric, N, size, host): measured in the same sweep on the same host, so never across
    machines (NaN where NumPy ran on another host)."""
    import pandas as pd

    df = pd.DataFrame(rows)
    for c in COLUMNS:
        if c not in df:
            df[c] = np.nan
    df["host"] = df["host"].astype(object).fillna("")  # an all-missing column comes as float
    ref = df[(df["backend"] == REFERENCE) & (df["status"] == "ok")]
    ref = ref.set_index(["metric", "n_elements", "size", "host"])["ms_per_iteration"]
    idx = list(zip(df["metric"], df["n_elements"], df["size"], df["host"], strict=True))
    df["x_numpy"] = [
        float(ref.get(k, np.nan)) / m if m and m == m else np.nan
        for k, m in zip(idx, df["ms_per_iteration"], strict=True)
    ]
    return df[COLUMNS]


def render_markdown(
    df, prov: dict, command: str, quick: bool, cfg: dict, elapsed: float, cached: int, plotted: bool = True
) -> str:
    from ..report import header_markdown, markdown_table, several_hosts

    notes = [
        "what is timed: one Lloyd iteration (angles/scales at the sites, labels + integer moments on the "
        "backend, centroids) on uniform random sites of seed 0, whole square raster; "
        f"{cfg['warmup']} warm-up + {cfg['repeats']} timed iterations, median",
        "x numpy = NumPy reference time / this time (higher is faster), measured in the same sweep; "
        "ckdtree = scipy cKDTree query + np.bincount (l2, l1, linf only): the common CPU tool",
        f"grid: N in {cfg['sites']}, raster {cfg['sizes']} px square, metrics {', '.join(cfg['metrics'])}",
        f"this command took {elapsed:.0f} s ({cached} configurations read back from raw/)",
    ]
    if quick:
        notes.insert(0, "**QUICK**: a small subset of the full sweep")
    text = header_markdown(
        "Backends: ms per Lloyd iteration" + (" (QUICK)" if quick else ""), prov, command, notes
    )
    ok = df[df["status"] == "ok"]
    order = [b for b in dict.fromkeys(df["backend"]) if b in set(ok["backend"])]
    cols = ["metric", "N", "raster"] + [f"{b} ms" if b == "numpy" else f"{b} ms (x numpy)" for b in order]
    by_host = several_hosts(ok["host"])  # a line from several machines says which ran what
    if by_host:
        cols.append("host")
        text += (
            "\nThese timings come from several hosts (each configuration ran alone on its host); "
            "x numpy compares with NumPy on the same host only.\n"
        )
    body = []
    for (metric, n, size), g in ok.groupby(["metric", "n_elements", "size"], sort=False):
        cells = []
        by = {r["backend"]: r for _, r in g.iterrows()}
        for b in order:
            r = by.get(b)
            if r is None:
                cells.append("")
            elif b == "numpy":
                cells.append(f"{r['ms_per_iteration']:.3g}")
            else:
                cells.append(
                    f"{r['ms_per_iteration']:.3g} ({r['x_numpy']:.2g}x)"
                    if r["x_numpy"] == r["x_numpy"]
                    else f"{r['ms_per_iteration']:.3g}"
                )
        body.append(
            [metric, n, f"{size}²"]
            + cells
            + ([", ".join(sorted({str(r["host"]) for r in by.values()}))] if by_host else [])
        )
    text += "\n" + markdown_table(cols, body)
    gm = (
        ok[ok["backend"] != "numpy"]
        .groupby("backend", sort=False)["x_numpy"]
        .apply(lambda s: float(np.exp(np.log(s.dropna()).mean())) if s.notna().any() else np.nan)
    )
    if len(gm):
        text += (
            "\nGeometric mean speed-up over NumPy: "
            + ", ".join(f"{b} {v:.2g}x" for b, v in gm.items())
            + "\n"
        )
    bad = df[df["status"] != "ok"].drop_duplicates(subset=["backend", "status", "reason"])
    if len(bad):
        text += "\n## Not measured\n\n" + markdown_table(
            ["backend", "status", "reason"],
            [[r["backend"], r["status"], r["reason"]] for _, r in bad.iterrows()],
        )
    text += (
        "\nPlot: `backends.png`; raw" if plotted else "\nRaw"
    ) + " json per configuration under `raw/`.\n"
    return text


def render_plot(df, path: Path) -> bool:
    """log-log: ms against N (middle raster) and against pixels (middle N); l2 solid,
    the other metrics' median dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..report import save_figure

    ok = df[df["status"] == "ok"]
    if ok.empty:
        path.unlink(missing_ok=True)  # a plot of another sweep must not pass for this one's
        return False
    sizes, ns = sorted(ok["size"].unique()), sorted(ok["n_elements"].unique())
    size_mid, n_mid = sizes[len(sizes) // 2], ns[len(ns) // 2]
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.3), dpi=110, layout="constrained")
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (b, g) in enumerate(ok.groupby("backend", sort=False)):
        c = colours[k % len(colours)]
        for ax, fixed, var, fixed_val in (
            (axes[0], "size", "n_elements", size_mid),
            (axes[1], "n_elements", "pixels", n_mid),
        ):
            sub = g[g[fixed] == fixed_val]
            l2 = sub[sub["metric"] == PAPER_METRICS[0]].sort_values(var)  # the paper's first, l2
            if len(l2):
                ax.plot(l2[var], l2["ms_per_iteration"], "o-", color=c, label=f"{b} (l2)")
            other = sub[sub["metric"] != PAPER_METRICS[0]].groupby(var)["ms_per_iteration"].median()
            if len(other):
                ax.plot(
                    other.index, other.values, "s--", color=c, alpha=0.7, label=f"{b} (other metrics, median)"
                )
    axes[0].set(
        xscale="log",
        yscale="log",
        xlabel="N (sites)",
        ylabel="ms per Lloyd iteration",
        title=f"time vs N at {size_mid}² px",
    )
    axes[1].set(
        xscale="log",
        yscale="log",
        xlabel="pixels",
        ylabel="ms per Lloyd iteration",
        title=f"time vs pixels at N = {n_mid}",
    )
    from matplotlib.ticker import NullFormatter

    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.xaxis.set_minor_formatter(NullFormatter())
    axes[1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0)
    save_figure(fig, path)
    plt.close(fig)
    return True


def rows_from_benchmark_json(path) -> list[dict]:
    """Rows from a pytest-benchmark json of tests/benchmarks (the Lloyd-step cases)."""
    data = json_object(path, "--from-benchmark-json")
    rows = []
    try:
        for b in data.get("benchmarks", []):
            info = b.get("extra_info", {})
            if info.get("kind") != "lloyd-step":
                continue
            st = b["stats"]
            rows.append(
                {
                    "backend": info["backend"],
                    "metric": info["metric"],
                    "n_elements": info["n_elements"],
                    "size": info["size"],
                    "pixels": info["size"] ** 2,
                    "ms_per_iteration": st["median"] * 1000,
                    "ms_min": st["min"] * 1000,
                    "ms_max": st["max"] * 1000,
                    "repeats": st["rounds"],
                    "warmup": 0,
                    "status": "ok",
                    "reason": "",
                    "device": info.get("device", ""),
                }
            )
    except (AttributeError, KeyError, TypeError) as exc:
        raise InputError(
            f"--from-benchmark-json {path}: not a pytest-benchmark json ({type(exc).__name__}: {exc})"
        ) from None
    if not rows:
        raise InputError(
            f"{path} holds no lloyd-step benchmarks (run pytest tests/benchmarks "
            "--benchmark-enable --benchmark-json FILE)"
        )
    return rows


def add_parser(sub):
    p = sub.add_parser(
        "backends",
        help="ms per Lloyd iteration per backend, N, raster and metric",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    options.add_sweep_options(p, "small subset (N 1000/4000, 256²-1024², l2, linf, triangle)")
    options.add_list_options(p, "backends", "metrics")
    options.add_cluster_options(p)
    p.add_argument(
        "--elements", default=None, help="comma list of N (at most the pixels of the smallest raster)"
    )
    p.add_argument("--sizes", default=None, help="comma list of square raster sides (1 to 32768)")
    p.add_argument("--repeats", default=None, help="timed iterations per configuration (1 to 1000)")
    p.add_argument("--no-ckdtree", action="store_true", help="leave out the cKDTree reference row")
    p.add_argument(
        "--from-benchmark-json",
        metavar="FILE",
        default=None,
        help="build the report from a pytest-benchmark json instead of timing here",
    )
    options.add_memory_option(p)
    p.set_defaults(func=run)


def _int_list(text, what, maximum=None):
    items = name_list(text, what)
    return None if items is None else [whole_number(t, what, minimum=1, maximum=maximum) for t in items]


@dataclass(frozen=True)
class BackendsRequest(options.SweepRequest):
    """``cvtbench backends``, typed: the backend variants, metrics, raster sides and
    element counts to time (None: the set's own), timed iterations per configuration, no
    cKDTree, or a pytest-benchmark json to build the report from instead of timing."""

    backends: tuple[str, ...] | None = None
    metrics: tuple[str, ...] | None = None
    sizes: tuple[int, ...] | None = None
    elements: tuple[int, ...] | None = None
    repeats: int | None = None
    no_ckdtree: bool = False
    from_benchmark_json: str | None = None

    @classmethod
    def from_args(cls, args) -> BackendsRequest:
        from compact_distributions.cvt.problem import MAX_SIDE

        sizes = _int_list(args.sizes, "--sizes", MAX_SIDE)
        cfg = QUICK if args.quick else FULL
        counts = _int_list(args.elements, "--elements", min(sizes or cfg["sizes"]) ** 2)
        tup = options.as_tuple
        return cls(
            **cls.common(args),
            backends=tup(name_list(args.backends, "--backends", variant_names())),
            metrics=tup(name_list(args.metrics, "--metrics", METRIC_NAMES)),
            sizes=tup(sizes),
            elements=tup(counts),
            repeats=None
            if args.repeats is None
            else whole_number(args.repeats, "--repeats", minimum=1, maximum=MAX_REPEATS),
            no_ckdtree=bool(args.no_ckdtree),
            from_benchmark_json=args.from_benchmark_json,
        )


def prepare(req: BackendsRequest) -> dict:
    """Every option checked, the report folder and the memory of each configuration
    too, before anything runs (``cvtbench reproduce`` checks all its parts this way)."""
    from ..outputs import check_folder
    from ..sweep import check_memory

    out = req.out
    check_folder(out)
    cfg = dict(QUICK if req.quick else FULL)
    cfg["metrics"] = [one_of(m, "--metrics", METRIC_NAMES) for m in req.metrics or cfg["metrics"]]
    cfg["sizes"] = list(req.sizes or cfg["sizes"])
    cfg["sites"] = list(req.elements or cfg["sites"])
    if req.repeats is not None:
        cfg["repeats"] = req.repeats
    plan = {"out": out, "cfg": cfg, "specs": None}
    if req.from_benchmark_json:
        plan["rows"] = rows_from_benchmark_json(req.from_benchmark_json)
        return plan
    chosen = [one_of(b, "--backends", variant_names()) for b in req.backends or variant_names()]
    if req.no_ckdtree:
        chosen = [b for b in chosen if b != "ckdtree"]
    plan["specs"] = sweep_specs(cfg, chosen, "backends-quick" if req.quick else "backends")
    check_memory(plan["specs"], req.memory_limit, lower="leave it out (smaller --sizes or fewer --elements)")
    return plan


def run(args) -> int:
    return backends(BackendsRequest.from_args(args))


def backends(req: BackendsRequest) -> int:
    """Time every configuration and write the report (what ``cvtbench backends`` does)."""
    from ..cluster import executor_for
    from ..outputs import report_folder
    from ..report import provenance, write_csv, write_markdown, written_files
    from ..sweep import check_runs, run_sweep

    t0 = time.perf_counter()
    plan = prepare(req)
    out, cfg = plan["out"], plan["cfg"]
    cmd = req.command or "cvtbench backends" + (" --quick" if req.quick else "")
    with report_folder(out, command=cmd):
        if plan["specs"] is None:
            rows = plan["rows"]
        else:
            unavailable = {v: text for v, (ok, text) in variant_status().items() if not ok}
            # a timing never shares its host with another run of the sweep
            with executor_for(req, exclusive=True) as executor:
                rows = run_sweep(
                    plan["specs"],
                    out,
                    force=req.force,
                    quiet=req.quiet,
                    unavailable=unavailable,
                    executor=executor,
                )
        df = with_ratios(rows)
        elapsed = time.perf_counter() - t0
        cached = sum(1 for r in rows if r.get("cached"))
        plotted = render_plot(df, out / "backends.png")
        md = render_markdown(df, provenance(), cmd, req.quick, cfg, elapsed, cached, plotted)
        write_csv(out / "backends.csv", df)
        write_markdown(out / "backends.md", md)
        written = written_files(out, ["backends.md", "backends.csv", "backends.png"])
    print(f"wrote {out}/{', '.join(written)} ({elapsed:.0f} s)", file=sys.stderr)
    if plan["specs"] is not None:
        check_runs(plan["specs"], rows, "backends")  # a failed timing fails the command
    return 0


__all__ = [
    "FULL",
    "QUICK",
    "MAX_REPEATS",
    "COLUMNS",
    "TimingSpec",
    "sweep_specs",
    "with_ratios",
    "render_markdown",
    "render_plot",
    "rows_from_benchmark_json",
    "add_parser",
    "BackendsRequest",
    "prepare",
    "run",
    "backends",
]
