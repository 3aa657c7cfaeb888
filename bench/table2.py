"""`cvtbench table2`: the paper's Table 2 (coverage and time per method), regenerated.

The problem set (also written into the report):

* region: the whole square raster, no density, no direction field;
* full: 1024x1024 px, N = 4000 sites (cells of ~16 px), 20 Lloyd iterations, seeds
  0..K-1 (K = --seeds, default 5);
* quick: 256x256 px, N = 250 (the same cell size), 20 iterations, seeds 0..1;
* squares for every method (the paper's comparison): ours on every available backend,
  each baseline on the NumPy reference backend (their own loops decide how they use it);
* one row group per other element shape (rectangle β = 0.5, ellipse β = 0.5, triangle,
  circle) for our method on every available backend, each under the metric whose unit
  ball is that shape; variants of ours (``ours-fit``: the same cells, each element moved
  inside its cell to grow it) on every shape on the reference backend.

Coverage and overlap are those of :func:`compact_distributions.cvt.evaluate.evaluate`; time is the method's
own wall time (``Distribution.total_seconds``: the 20 iterations, setup and element
placement excluded, as the paper's "average time" of its synthesis).  The paper's
figures stand beside ours on the square rows; the paper gives neither N nor its raster.

Writes ``OUT/table2.md``, ``OUT/table2.csv``, ``OUT/table2.png`` (one effect picture
per method: seed 0, the top-left corner of the region with about 250 elements) and ``OUT/raw/table2*/``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from compact_distributions.backends import REFERENCE as REFERENCE_BACKEND
from compact_distributions.backends import variant_metrics, variant_names, variant_status
from compact_distributions.baselines import FIXED_SIZE as FIXED_SIZE_BASELINES
from compact_distributions.baselines import method_names
from compact_distributions.cvt.shapes import ELEMENT_SHAPES
from compact_distributions.cvt.validate import name_list

from . import options
from .runs import RunSpec

# the paper's Table 2 (coverage, time), by our method names
PAPER = {
    "fritzsche2005": (0.648, "1 min"),
    "smith2005": (0.681, "1 min"),
    "hu2016": (0.843, "10 min"),
    "ours": (0.856, "19 s"),
    "ours-fit": (0.856, "19 s"),  # ours with the element moved inside its cell (paper §3.4)
    "ours-compact": (0.856, "19 s"),  # ours, fitted, then compacted (beyond the paper)
}
ELEMENTS = list(ELEMENT_SHAPES)

# Fixed-size tile baselines also run with smaller tile budgets: their coverage at the
# default δ = 0.95 is bought with overlap, and the paper states neither its tile sizes
# nor how it counts overlap, so the report shows where they stand when tiles barely overlap.
SMALLER_BUDGETS = (0.85, 0.80)

FULL = {"size": 1024, "n_elements": 4000, "iterations": 20, "seeds": 5}
QUICK = {"size": 256, "n_elements": 250, "iterations": 20, "seeds": 2}

COLUMNS = ["method", "backend", "element", "metric", "width", "height", "n_elements", "iterations",
           "seeds", "runs", "coverage_mean", "coverage_sd", "overlap_mean", "overlap_sd",
           "time_mean_s", "time_sd_s", "ms_per_iteration", "placed_mean", "empty_cells_mean",
           "coverage_at_1pct_overlap", "paper_coverage", "paper_time", "status", "reason", "device", "hosts", "host_slots"]


def problem_set(quick: bool, seeds: int | None, methods: list[str], backends: list[str],
                elements: list[str] | None = None, variant_backend: str = REFERENCE_BACKEND) -> list[RunSpec]:
    """The runs of Table 2 (see the module docstring); ``backends`` are the variants
    to run ours on (available or not: unavailable ones become skipped rows), and
    ``variant_backend`` the one the variants of ours run on.  Seed 0 of every method's
    first row group also measures the coverage-overlap curve (each point is a full
    evaluation of 4000 elements: all seeds would double the sweep's time)."""
    cfg = QUICK if quick else FULL
    k = cfg["seeds"] if seeds is None else seeds
    suite = "table2-quick" if quick else "table2"
    elements = elements or ELEMENTS
    specs = []

    def add(method, backend, element, picture_first, delta=None, alternate=False, curve=True):
        for s in range(k):
            specs.append(RunSpec(suite, method, backend, element, cfg["size"], cfg["size"],
                                 cfg["n_elements"], cfg["iterations"], s, picture=picture_first and s == 0,
                                 delta=delta, alternate=alternate, curve=curve and s == 0))

    for element in elements:
        for method in methods:
            if method == "ours":
                for b in backends:
                    first = b == backends[0]
                    add(method, b, element, picture_first=first, curve=first)
            elif method.startswith("ours"):
                # variants of ours (another placement of the same cells) get every element
                add(method, variant_backend, element, picture_first=True)
                if method == "ours-compact" and element == "triangle":
                    add(method, variant_backend, element, picture_first=True, alternate=True)
            elif element == "square":  # baselines: the paper's comparison is on squares
                add(method, REFERENCE_BACKEND, element, picture_first=True)
    if "square" in elements:
        for method in methods:
            if method in FIXED_SIZE_BASELINES:
                for delta in SMALLER_BUDGETS:
                    add(method, REFERENCE_BACKEND, "square", picture_first=False, delta=delta)
    return specs


def _sd(frame, column: str) -> float:
    """Sample standard deviation over seeds (NaN with a single seed)."""
    return float(frame[column].std(ddof=1)) if len(frame) > 1 else np.nan


def aggregate(rows: list[dict]):
    """One line per (method, backend, element): mean ± sd over the seeds that ran."""
    import pandas as pd

    from .report import host_slots_of, hosts_of

    df = pd.DataFrame(rows)
    if "label" in df:  # a run with another tile budget or option is a line of its own
        df["method"] = df["label"].fillna(df["method"])
    out = []
    for (method, backend, element), g in df.groupby(["method", "backend", "element"], sort=False):
        ok = g[g["status"] == "ok"]
        first = g.iloc[0]
        paper = PAPER.get(method) if element == "square" else None
        rec = {
            "method": method, "backend": backend, "element": element, "metric": first["metric"],
            "width": first["width"], "height": first["height"], "n_elements": first["n_elements"],
            "iterations": first["iterations"], "seeds": len(g), "runs": len(ok),
            "paper_coverage": paper[0] if paper else np.nan, "paper_time": paper[1] if paper else "",
        }
        if len(ok):
            rec.update(
                coverage_mean=float(ok["coverage"].mean()), coverage_sd=_sd(ok, "coverage"),
                overlap_mean=float(ok["overlap"].mean()), overlap_sd=_sd(ok, "overlap"),
                time_mean_s=float(ok["total_seconds"].mean()), time_sd_s=_sd(ok, "total_seconds"),
                ms_per_iteration=float(ok["ms_per_iteration"].median()),
                placed_mean=float(ok["placed"].mean()), empty_cells_mean=float(ok["empty_cells"].mean()),
                coverage_at_1pct_overlap=(float(ok["coverage_at_1pct_overlap"].mean())
                                          if "coverage_at_1pct_overlap" in ok else np.nan),
                status="ok" if len(ok) == len(g) else "partial",
                reason="; ".join(sorted(set(g.loc[g["status"] != "ok", "reason"].astype(str)))),
                device=str(ok.iloc[0]["device"]), hosts=hosts_of(ok), host_slots=host_slots_of(ok),
            )
        else:
            rec.update(status=str(first["status"]), reason=str(first["reason"]), device="")
        out.append(rec)
    table = pd.DataFrame(out)
    for c in COLUMNS:
        if c not in table:
            table[c] = np.nan
    return table[COLUMNS]


def discussion(table) -> str:
    """How the measured ordering compares with the paper's, and how the methods rank at
    equal overlap: every sentence is computed from the rows at hand."""
    from .report import fmt_pct, fmt_seconds

    sq = table[(table["element"] == "square") & table["status"].isin(["ok", "partial"])]
    cov = {r["method"]: r for _, r in sq.iterrows() if r["method"] != "ours" or r["backend"] == REFERENCE_BACKEND}
    ours = {r["backend"]: r for _, r in sq[sq["method"] == "ours"].iterrows()}
    if "ours" not in cov:
        return ""

    def c(name):
        r = cov.get(name)
        return f"{fmt_pct(r['coverage_mean'])} (overlap {fmt_pct(r['overlap_mean'], digits=2)})" \
            if r is not None else "not run"

    lines = ["", "## How this compares with the paper", ""]
    paper_order = ["fritzsche2005", "smith2005", "hu2016", "ours"]
    measured = [m for m in sorted(paper_order, key=lambda m: cov[m]["coverage_mean"]) if m in cov] \
        if all(m in cov for m in paper_order) else []
    same = measured == paper_order
    lines.append(
        "- The paper's order (Fritzsche 64.8 % < Smith 68.1 % < Hu 84.3 % < ours 85.6 %) is "
        + ("reproduced" if same else "**not** reproduced") + f" by the paper's own placement: ours covers "
        f"{c('ours')}, ours-fit {c('ours-fit')}; Hu {c('hu2016')}; the fixed-size baselines Fritzsche "
        f"{c('fritzsche2005')}, Smith {c('smith2005')}, Hausner {c('hausner2001')}.")
    if "ours-compact" in cov:
        rc = cov["ours-compact"]
        others = [m for m in cov if not m.startswith("ours")]
        beaten = [m for m in others if rc["coverage_mean"] > cov[m]["coverage_mean"]]
        lines.append(
            f"- With compaction (ours-compact: the same cells, each element fitted in its cell, then "
            f"neighbours share their walls) ours covers {c('ours-compact')}, "
            + ("more than every baseline" if len(beaten) == len(others) else
               f"more than {len(beaten)} of the {len(others)} baseline rows")
            + (", and none of its elements overlap" if rc["overlap_mean"] < 1e-4 else "")
            + "; the paper's 85.6 % " + ("is passed" if rc["coverage_mean"] > 0.856 else "is not reached") + ".")
    smaller = [f"{name} {c(name)}" for name in cov if "δ=" in name]
    if smaller:
        lines.append(
            "- The fixed-size baselines' coverage at the default δ = 0.95 is bought with overlap, which "
            "they allow and we count; with smaller tiles: " + "; ".join(smaller) + ". The paper gives "
            "neither its tile sizes nor how it treats overlap.")
    fair = sq[sq["coverage_at_1pct_overlap"].notna()] if "coverage_at_1pct_overlap" in sq else sq.iloc[0:0]
    fair = fair[(fair["method"] != "ours") | (fair["backend"] == REFERENCE_BACKEND)]
    if len(fair):
        ranked = fair.sort_values("coverage_at_1pct_overlap", ascending=False)
        lines.append(
            "- At equal overlap (every method's elements scaled about their centres until the overlap "
            "is 1 %, `coverage_overlap.csv`, `coverage_overlap.png`) the squares rank: "
            + ", ".join(f"{r['method']} {fmt_pct(r['coverage_at_1pct_overlap'])}" for _, r in ranked.iterrows())
            + ".")
    fast = [f"{b} {fmt_seconds(r['time_mean_s'])}" for b, r in ours.items() if r["status"] == "ok"]
    if fast:
        lines.append("- Time for the 20 iterations of ours (mean over seeds): " + ", ".join(fast)
                     + "; the paper reports 19 s on a GPU (N not stated).")
    return "\n".join(lines) + "\n"


def render_markdown(table, prov: dict, command: str, quick: bool, cfg: dict, seeds: int,
                    elapsed: float, cached: int, total: int, pictured: bool = True) -> str:
    from .report import fmt_pct, fmt_seconds, header_markdown, markdown_table, several_hosts

    title = "Table 2, regenerated" + (" (QUICK: small raster, 2 seeds; not the paper's scale)" if quick else "")
    notes = [
        f"problem set: square region, whole {cfg['size']}x{cfg['size']} px raster, N = {cfg['n_elements']} "
        f"sites, {cfg['iterations']} Lloyd iterations, seeds 0..{seeds - 1}, no density, no direction "
        "field; squares for every method, every other element shape for ours, ours-fit and "
        "ours-compact (triangles also alternating); rectangle and ellipse β = 0.5",
        "fixed-size baselines (hausner2001, fritzsche2005, smith2005): tiles of the area of a square "
        "of side δ·sqrt(area/N), δ = 0.95 by default, and again with δ = "
        + " and ".join(f"{d:g}" for d in SMALLER_BUDGETS) + " (rows 'δ=...')",
        "ours runs on every available backend; ours-fit and ours-compact on the OpenCL backend where "
        "it is available (else NumPy); the baselines on the NumPy reference backend",
        "coverage at ≤ 1 % overlap (seed 0): every element scaled about its centre by 0.80 ... 1.20, "
        "evaluated alike, the largest coverage whose overlap is at most 1 % (interpolated)",
        "coverage and overlap: cvt.evaluate (area of the union of the elements inside the region / "
        "area of the region; overlap: summed element area minus union area, / region area)",
        "time: the method's wall time for its iterations (setup and element placement excluded), "
        "mean over seeds; ms/it: median per iteration",
        "paper: Table 2 of Chen, Yang & Yang 2019 (C++/OpenGL on a GPU; N and raster not stated); "
        "shown on the square rows",
        f"this command took {fmt_seconds(elapsed)}; {cached} of {total} runs were read back from "
        "raw/ (run with --force to redo them)",
    ]
    text = header_markdown("Table 2" if not quick else title, prov, command, notes)
    if quick:
        text += f"\n**{title}**\n"
    cols = ["method", "backend", "element", "coverage", "overlap", "coverage at ≤ 1 % overlap", "time",
            "ms/it", "runs", "paper coverage", "paper time"]
    by_host = several_hosts(table["hosts"])  # rows from several machines say which
    shared = table["host_slots"].fillna(1) > 1  # times taken beside other runs of the sweep
    body = []
    for k, r in table.iterrows():
        if r["status"] not in ("ok", "partial"):
            continue
        body.append([
            r["method"], r["backend"], r["element"],
            fmt_pct(r["coverage_mean"], r["coverage_sd"]), fmt_pct(r["overlap_mean"], r["overlap_sd"], digits=2),
            fmt_pct(r["coverage_at_1pct_overlap"]),
            fmt_seconds(r["time_mean_s"]) + (" ‡" if shared[k] else ""), f"{r['ms_per_iteration']:.3g}",
            f"{r['runs']}/{r['seeds']}",
            fmt_pct(r["paper_coverage"]) if r["paper_time"] else "", r["paper_time"] or "",
        ] + ([r["hosts"]] if by_host else []))
    text += "\n" + markdown_table(cols + (["host"] if by_host else []), body)
    if shared.any():
        text += (f"\n‡ time taken while up to {int(table['host_slots'].max())} runs of this sweep shared the "
                 "host (--workers or --scheduler without --exclusive): compare it only with times taken the "
                 "same way; coverage and overlap do not depend on it.\n")
    missing = table[~table["status"].isin(["ok"])]
    if len(missing):
        text += "\n## Not run, failed or partial\n\n"
        text += markdown_table(["method", "backend", "element", "status", "reason"],
                               [[r["method"], r["backend"], r["element"], r["status"], r["reason"]]
                                for _, r in missing.iterrows()])
    text += discussion(table)
    if pictured:
        text += ("\nThe picture `table2.png` shows one effect picture per method (seed 0, the top-left "
                 "corner of the region, about 250 elements); the raw json")
    else:
        text += "\nNo run made an effect picture, so there is no `table2.png`; the raw json"
    text += " of every run, with its sites and timings, is under `raw/`.\n"
    return text


def coverage_overlap_table(rows: list[dict]):
    """coverage_overlap.csv: per method line and scale factor, coverage and overlap (mean
    over the seeds) of the elements scaled about their centres."""
    import pandas as pd

    out = []
    for r in rows:
        for factor, coverage, overlap in r.get("coverage_overlap") or []:
            out.append({"method": r.get("label") or r["method"], "backend": r["backend"], "element": r["element"],
                        "seed": r["seed"], "factor": factor, "coverage": coverage, "overlap": overlap})
    if not out:
        return pd.DataFrame(columns=["method", "backend", "element", "factor", "coverage", "overlap", "seeds"])
    df = pd.DataFrame(out)
    return (df.groupby(["method", "backend", "element", "factor"], sort=False)
              .agg(coverage=("coverage", "mean"), overlap=("overlap", "mean"), seeds=("seed", "nunique"))
              .reset_index())


def render_coverage_overlap(curves, path: Path) -> bool:
    """One curve per method on squares: coverage against overlap as the elements are scaled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .report import save_figure

    sq = curves[curves["element"] == "square"]
    if sq.empty:
        return False
    fig, ax = plt.subplots(figsize=(8, 5.2), dpi=110, layout="constrained")
    colours = plt.get_cmap("tab20").colors
    for k, ((method, _backend), g) in enumerate(sq.groupby(["method", "backend"], sort=False)):
        g = g.sort_values("factor")
        ours = method.startswith("ours")
        ax.plot(100 * g["overlap"], 100 * g["coverage"], "os^vD<>"[k % 7] + ("-" if ours else "--"),
                ms=3.5, lw=2.2 if method == "ours-compact" else 1.1, color=colours[k % len(colours)], label=method)
        one = g[np.isclose(g["factor"], 1.0)]
        ax.plot(100 * one["overlap"], 100 * one["coverage"], "k.", ms=8)
    ax.axvline(1.0, color="grey", lw=0.8, ls=":")
    ax.set(xlabel="overlap (% of the region)", ylabel="coverage (% of the region)", xlim=(-0.5, 15),
           title="Squares at equal overlap: elements scaled 0.80-1.20 about their centres (black: as placed)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    save_figure(fig, path)
    plt.close(fig)
    return True


def render_picture(table, out: Path, suite_specs: list[RunSpec], path: Path) -> bool:
    """table2.png: squares of every method on the first row, then one row per other
    element with ours and its variants side by side (ours-compact beside ours).  Returns
    False when no picture exists (nothing ran)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    from .report import save_figure
    from .runs import picture_crop
    from .sweep import picture_path

    cov = {(r["method"], r["backend"], r["element"]): r["coverage_mean"] for _, r in table.iterrows()}
    panels = []
    for spec in suite_specs:
        p = picture_path(out, spec)
        if spec.picture and p.exists():
            panels.append((spec, p))
    if not panels:
        path.unlink(missing_ok=True)  # a picture of another sweep must not pass for this one's
        return False
    shapes = list(dict.fromkeys(spec.element for spec, _ in panels))
    rows = [[x for x in panels if x[0].element == shape] for shape in shapes]
    ncol = max(len(r) for r in rows)
    fig, axes = plt.subplots(len(rows), ncol, figsize=(2.6 * ncol, 3.1 * len(rows)), dpi=110,
                             squeeze=False, layout="constrained")
    for ax in axes.ravel():
        ax.axis("off")
    for i, row in enumerate(rows):
        for j, (spec, p) in enumerate(row):
            ax = axes[i][j]
            with Image.open(p) as im:
                ax.imshow(np.asarray(im.convert("RGB")))
            c = cov.get((spec.label, spec.backend, spec.element), np.nan)
            name = spec.label if spec.method != "ours" else f"ours ({spec.backend})"
            ax.set_title(f"{name}\n{spec.element}: {100 * c:.1f} %", fontsize=9)
    spec0 = panels[0][0]
    crop = picture_crop(spec0.n_elements)
    part = "the whole region" if crop >= 1 else f"top-left {crop * spec0.width:.0f}² px of {spec0.width}² px"
    fig.suptitle(f"Effect pictures (seed 0, {part}, N = {spec0.n_elements})", fontsize=10)
    save_figure(fig, path)
    plt.close(fig)
    return True


def add_parser(sub):
    p = sub.add_parser("table2", help="regenerate the paper's Table 2 into reports/",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    options.add_sweep_options(p, "small version (256² px, N=250, 2 seeds): < 2 min")
    options.add_seeds_option(p)
    options.add_list_options(p, "methods", "backends", "shapes")
    options.add_cluster_options(p, exclusive=True)
    options.add_memory_option(p)
    p.set_defaults(func=run)


def sweep_backends(text) -> tuple[list[str], dict[str, str]]:
    """The variants ``--backends`` names (default: every variant that computes every
    metric) and the reasons of those that cannot run here."""
    status = variant_status()
    default = [v for v in variant_names() if variant_metrics(v) is None]
    backends = name_list(text, "--backends", variant_names()) or default
    return backends, {v: text for v, (ok, text) in status.items() if not ok}


def variant_backend(unavailable: dict) -> str:
    """The backend the variants of ours run on: OpenCL where it runs (their Lloyd
    iterations are the same as ours'; OpenCL only makes them fast), else the reference."""
    return "opencl" if "opencl" not in unavailable else REFERENCE_BACKEND


def prepare(args) -> dict:
    """Every option checked, the report folder and the memory of each run too, before
    anything runs (``cvtbench reproduce`` checks all its parts this way)."""
    from .outputs import check_folder
    from .sweep import check_memory

    out = options.report_out(args)
    check_folder(out)
    cfg = QUICK if args.quick else FULL
    seeds = options.seeds_value(args.seeds, cfg["seeds"])
    all_methods = method_names()
    methods = name_list(args.methods, "--methods", all_methods) or all_methods
    if "ours" in methods:  # ours first, then the baselines in the paper's order
        methods = ["ours"] + [m for m in methods if m != "ours"]
    backends, unavailable = sweep_backends(args.backends)
    shapes = name_list(args.shapes, "--shapes", ELEMENTS)
    specs = problem_set(args.quick, seeds, methods, backends, shapes, variant_backend(unavailable))
    check_memory(specs, args.memory_limit, lower="run the --quick set, or fewer --methods or --shapes")
    return {"out": out, "cfg": cfg, "seeds": seeds, "specs": specs, "unavailable": unavailable}


def run(args) -> int:
    from .cluster import executor_for
    from .outputs import command_line, report_folder
    from .report import provenance, write_csv, write_markdown, written_files
    from .sweep import run_sweep

    t0 = time.perf_counter()
    plan = prepare(args)
    out, cfg, seeds, specs = plan["out"], plan["cfg"], plan["seeds"], plan["specs"]
    cmd = command_line(getattr(args, "argv", None) or ["table2"] + (["--quick"] if args.quick else []))
    with report_folder(out, command=cmd):
        with executor_for(args, exclusive=args.exclusive) as executor:
            rows = run_sweep(specs, out, force=args.force, quiet=args.quiet, unavailable=plan["unavailable"],
                             executor=executor)
        table = aggregate(rows)
        elapsed = time.perf_counter() - t0
        cached = sum(1 for r in rows if r.get("cached"))
        pictured = render_picture(table, out, specs, out / "table2.png")
        md = render_markdown(table, provenance(), cmd, args.quick, cfg, seeds, elapsed, cached, len(rows), pictured)
        curves = coverage_overlap_table(rows)
        if len(curves):
            write_csv(out / "coverage_overlap.csv", curves)
        if not (len(curves) and render_coverage_overlap(curves, out / "coverage_overlap.png")):
            for name in ("coverage_overlap.png",) if len(curves) else ("coverage_overlap.csv", "coverage_overlap.png"):
                (out / name).unlink(missing_ok=True)  # a stale view from an earlier sweep
        write_csv(out / "table2.csv", table)
        write_markdown(out / "table2.md", md)
        written = written_files(out, ["table2.md", "table2.csv", "table2.png", "coverage_overlap.csv",
                                      "coverage_overlap.png"])
    _print_summary(table, out, written)
    return 0


def _print_summary(table, out: Path, written: list[str]) -> None:
    from .report import fmt_pct, fmt_seconds

    for _, r in table.iterrows():
        if r["status"] in ("ok", "partial"):
            print(f"{r['method']:<14} {r['backend']:<9} {r['element']:<9} "
                  f"{fmt_pct(r['coverage_mean'], r['coverage_sd']):>16}  {fmt_seconds(r['time_mean_s'])}",
                  file=sys.stderr)
        else:
            print(f"{r['method']:<14} {r['backend']:<9} {r['element']:<9} {r['status']}: {r['reason']}",
                  file=sys.stderr)
    print(f"wrote {out}/{', '.join(written)}", file=sys.stderr)


__all__ = ["problem_set", "aggregate", "PAPER", "run"]
