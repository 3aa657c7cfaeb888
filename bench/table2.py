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
  inside its cell to grow it) on every shape on the reference backend;
* beyond the paper's five shapes, the shapes a method's record names in
  ``beyond_paper`` (``ours-compact``: hexagon, octagon), for that method only.

Coverage and overlap are those of :func:`compact_distributions.cvt.evaluate.evaluate`; time is the
whole method's wall time (``Distribution.method_seconds``: problem to placed elements,
as the paper's "average time" of its synthesis), with the Lloyd iterations' part
(``lloyd_seconds``) and the median ms per iteration beside it.  The paper's
figures stand beside ours on the square rows; the paper gives neither N nor its raster.

Writes ``OUT/table2.md``, ``OUT/table2.csv``, ``OUT/table2.png`` (one effect picture
per method: seed 0, the top-left corner of the region with about 250 elements) and ``OUT/raw/table2*/``.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from compact_distributions.backends import REFERENCE as REFERENCE_BACKEND
from compact_distributions.backends import fall_back, variant_metrics, variant_names, variant_status
from compact_distributions.cvt.metrics import REFERENCE_SHAPE
from compact_distributions.cvt.registry import get_method, method_names
from compact_distributions.cvt.shapes import PAPER_SHAPES
from compact_distributions.cvt.validate import name_list, one_of

from . import options
from .runs import RunSpec

FULL = {"size": 1024, "n_elements": 4000, "iterations": 20, "seeds": 5}
QUICK = {"size": 256, "n_elements": 250, "iterations": 20, "seeds": 2}

COLUMNS = [
    "method",
    "backend",
    "element",
    "metric",
    "width",
    "height",
    "n_elements",
    "iterations",
    "seeds",
    "runs",
    "coverage_mean",
    "coverage_sd",
    "overlap_mean",
    "overlap_sd",
    "method_seconds_mean",
    "method_seconds_sd",
    "lloyd_seconds_mean",
    "ms_per_iteration",
    "placed_mean",
    "empty_cells_mean",
    "coverage_at_1pct_overlap",
    "energy_gap_mean",
    "energy_gap_note",
    "paper_coverage",
    "paper_time",
    "status",
    "reason",
    "device",
    "hosts",
    "host_slots",
]


# the columns of Table 2's markdown (the report and the documentation's page)
MARKDOWN_COLUMNS = (
    "method",
    "backend",
    "element",
    "coverage",
    "overlap",
    "coverage at ≤ 1 % overlap",
    "time",
    "Lloyd",
    "ms/it",
    "energy above converged",
    "runs",
    "paper coverage",
    "paper time",
)


def problem_set(
    quick: bool,
    seeds: int | None,
    methods: list[str],
    backends: list[str],
    shapes: list[str] | None = None,
    variant_backend: str = REFERENCE_BACKEND,
    method_options: dict | None = None,
) -> list[RunSpec]:
    """The runs of Table 2 (see the module docstring), as each method's record asks:
    on the shapes it is compared on, on every variant of ``backends`` (available or not:
    unavailable ones become skipped rows), on ``variant_backend`` (the fastest) or on the
    reference, and again with each of its sweep variants.  Seed 0 of each row group also
    measures the coverage-overlap curve.

    Parameters
    ----------
    quick : bool
        The quick set (:data:`QUICK`) instead of the full one (:data:`FULL`).
    seeds : int or None
        Seeds 0..seeds-1 (None: the set's default).
    methods : list of str
        The methods, by name.
    backends : list of str
        The backend variants of the methods swept over every backend.
    shapes : list of str or None, optional
        The element shapes (None: the paper's five, and the shapes beyond them that a
        method's record names in ``beyond_paper``, for that method only).
    variant_backend : str, optional
        The backend of the methods swept on the fastest one.
    method_options : dict or None, optional
        Option name -> value, as given on the command line, for every method that
        declares the option.

    Returns
    -------
    list of RunSpec
    """
    cfg = QUICK if quick else FULL
    k = cfg["seeds"] if seeds is None else seeds
    suite = "table2-quick" if quick else "table2"
    records = [get_method(m) for m in methods]
    chosen = shapes is not None
    if not chosen:  # the paper's shapes, then those some method is also compared on
        shapes = list(dict.fromkeys([*PAPER_SHAPES, *(s for rec in records for s in rec.beyond_paper)]))
    specs = []

    def add(method, backend, element, picture_first, options, curve=True):
        for s in range(k):
            specs.append(
                RunSpec(
                    suite,
                    method,
                    backend,
                    element,
                    cfg["size"],
                    cfg["size"],
                    cfg["n_elements"],
                    cfg["iterations"],
                    s,
                    picture=picture_first and s == 0,
                    options=options,
                    curve=curve and s == 0,
                )
            )

    for element in shapes:
        for rec in records:
            if (
                (rec.compared_on is not None and element not in rec.compared_on)
                or (rec.elements is not None and element not in rec.elements)
                or (not chosen and element not in PAPER_SHAPES and element not in rec.beyond_paper)
            ):
                continue
            given = options.options_for(rec, method_options)
            if rec.sweep_backends == "every":
                for b in backends:
                    first = b == backends[0]
                    add(rec.name, b, element, picture_first=first, options=given, curve=first)
                continue
            backend = variant_backend if rec.sweep_backends == "fastest" else REFERENCE_BACKEND
            add(rec.name, backend, element, picture_first=True, options=given)
            for variant in rec.sweep_variants:
                if variant.elements is None or element in variant.elements:
                    add(
                        rec.name,
                        backend,
                        element,
                        picture_first=variant.pictured,
                        options={**given, **variant.options},
                    )
    return specs


def aggregate(rows: list[dict]):
    """One line per (method, backend, element): mean ± sd over the seeds that ran."""
    import pandas as pd

    from .converged import gap_columns
    from .report import fail_closed, group_status, host_slots_of, sample_sd, with_columns

    df = pd.DataFrame(rows)
    df["base"] = df["method"]
    if "label" in df:  # a run with another tile budget or option is a line of its own
        df["method"] = df["label"].fillna(df["method"])
    out = []
    fail_closed(df, ("coverage", "overlap"))
    for (method, backend, element), g in df.groupby(["method", "backend", "element"], sort=False):
        ok = g[g["status"] == "ok"]
        first = g.iloc[0]
        # the paper's figures stand on the square rows of a method run with its defaults
        paper = (
            get_method(first["base"]).paper_table2
            if element == REFERENCE_SHAPE and method == first["base"]
            else None
        )
        rec = {
            "method": method,
            "backend": backend,
            "element": element,
            "metric": first["metric"],
            "width": first["width"],
            "height": first["height"],
            "n_elements": first["n_elements"],
            "iterations": first["iterations"],
            "seeds": len(g),
            "runs": len(ok),
            "paper_coverage": paper[0] if paper else np.nan,
            "paper_time": paper[1] if paper else "",
        }
        if len(ok):
            rec.update(
                coverage_mean=float(ok["coverage"].mean()),
                coverage_sd=sample_sd(ok, "coverage"),
                overlap_mean=float(ok["overlap"].mean()),
                overlap_sd=sample_sd(ok, "overlap"),
                method_seconds_mean=float(ok["method_seconds"].mean()),
                method_seconds_sd=sample_sd(ok, "method_seconds"),
                lloyd_seconds_mean=float(ok["lloyd_seconds"].mean()),
                ms_per_iteration=float(ok["ms_per_iteration"].median()),
                placed_mean=float(ok["placed"].mean()),
                empty_cells_mean=float(ok["empty_cells"].mean()),
                coverage_at_1pct_overlap=(
                    float(ok["coverage_at_1pct_overlap"].mean())
                    if "coverage_at_1pct_overlap" in ok
                    else np.nan
                ),
                host_slots=host_slots_of(ok),
                **gap_columns(ok),
            )
        rec.update(group_status(g, ok))
        out.append(rec)
    return with_columns(pd.DataFrame(out), COLUMNS)


def label_record(label: str):
    """The method record of a report row (its label is the name, then its options).

    Parameters
    ----------
    label : str
        A row's method, as :attr:`.runs.RunSpec.label` names it.

    Returns
    -------
    Method
    """
    return get_method(str(label).split(" ")[0])


def _every_backend(label: str) -> bool:
    return label_record(label).sweep_backends == "every"


def _equal_overlap_ranking(sq) -> list[str]:
    """The sentence that ranks the reference shape's rows at 1 % overlap (none without
    those figures)."""
    from .report import fmt_pct

    lines = []
    fair = sq[sq["coverage_at_1pct_overlap"].notna()] if "coverage_at_1pct_overlap" in sq else sq.iloc[0:0]
    fair = fair[
        [
            not _every_backend(m) or b == REFERENCE_BACKEND
            for m, b in zip(fair["method"], fair["backend"], strict=True)
        ]
    ]
    if len(fair):
        ranked = fair.sort_values("coverage_at_1pct_overlap", ascending=False)
        lines.append(
            "- At equal overlap (every method's elements scaled about their centres until the overlap "
            "is 1 %, `coverage_overlap.csv`, `coverage_overlap.png`) the squares rank: "
            + ", ".join(
                f"{r['method']} {fmt_pct(r['coverage_at_1pct_overlap'])}" for _, r in ranked.iterrows()
            )
            + "."
        )
    return lines


def discussion(table) -> str:
    """How the measured ordering compares with the paper's, and how the methods rank at
    equal overlap: every sentence is computed from the rows at hand and the methods'
    records (which is the paper's method, which the baselines, what the paper measured)."""
    from .report import fmt_pct, fmt_seconds

    sq = table[(table["element"] == REFERENCE_SHAPE) & table["status"].isin(["ok", "partial"])]
    # one row per method: those swept over every backend by their reference backend's row
    cov = {
        r["method"]: r
        for _, r in sq.iterrows()
        if not _every_backend(r["method"]) or r["backend"] == REFERENCE_BACKEND
    }
    role = {m: label_record(m).role for m in cov}
    paper_method = next((m for m in cov if role[m] == "paper" and m == label_record(m).name), None)
    if paper_method is None:
        return ""

    def c(name):
        r = cov.get(name)
        return (
            f"{fmt_pct(r['coverage_mean'])} (overlap {fmt_pct(r['overlap_mean'], digits=2)})"
            if r is not None
            else "not run"
        )

    plain = [m for m in cov if m == label_record(m).name]  # each method with its default options
    lines = ["", "## How this compares with the paper", ""]
    in_paper = sorted(
        (m for m in plain if role[m] in ("paper", "baseline") and label_record(m).paper_table2),
        key=lambda m: label_record(m).paper_table2[0],
    )
    measured = sorted(in_paper, key=lambda m: cov[m]["coverage_mean"])
    same = measured == in_paper
    extensions = [m for m in plain if role[m] == "extension"]
    baselines = [m for m in plain if role[m] not in ("paper", "extension")]
    lines.append(
        "- The paper's order ("
        + " < ".join(f"{m} {fmt_pct(label_record(m).paper_table2[0])}" for m in in_paper)
        + ") is "
        + ("reproduced" if same else "**not** reproduced")
        + f" by the paper's own placement: "
        f"{paper_method} covers {c(paper_method)}"
        + "".join(f"; {m} {c(m)}" for m in extensions)
        + "; the baselines: "
        + ", ".join(f"{m} {c(m)}" for m in baselines)
        + "."
    )
    baseline_rows = [m for m in cov if role[m] not in ("paper", "extension")]
    for m in extensions:
        rc = cov[m]
        beaten = [b for b in baseline_rows if rc["coverage_mean"] > cov[b]["coverage_mean"]]
        if len(beaten) < len(baseline_rows) or rc["overlap_mean"] >= 1e-4:
            continue  # said only of an extension that beats every baseline row at no overlap
        lines.append(
            f"- {m} ({label_record(m).summary}) covers {c(m)}, more than every baseline row, and none of its "
            "elements overlap; the paper's "
            + fmt_pct(label_record(paper_method).paper_table2[0])
            + " "
            + (
                "is passed"
                if rc["coverage_mean"] > label_record(paper_method).paper_table2[0]
                else "is not reached"
            )
            + "."
        )
    smaller = [
        f"{name} {c(name)}"
        for name in cov
        if name != label_record(name).name and label_record(name).fixed_size
    ]
    if smaller:
        lines.append(
            "- The fixed-size baselines' coverage at their default tile budget is bought with overlap, which "
            "they allow and we count; with smaller tiles: " + "; ".join(smaller) + ". The paper gives "
            "neither its tile sizes nor how it treats overlap."
        )
    lines += _equal_overlap_ranking(sq)
    per_backend = sq[sq["method"] == paper_method]
    fast = [
        f"{r['backend']} {fmt_seconds(r['lloyd_seconds_mean'])}"
        for _, r in per_backend.iterrows()
        if r["status"] == "ok"
    ]
    if fast:
        lines.append(
            f"- Time for the 20 iterations of {paper_method} (mean over seeds): "
            + ", ".join(fast)
            + f"; the paper reports {label_record(paper_method).paper_table2[1]} on a GPU (N not stated)."
        )
    return "\n".join(lines) + "\n"


def _problem_notes(methods: list[str]) -> list[str]:
    """What the problem set runs, said from the methods' records."""
    records = [get_method(m) for m in methods]
    where = {
        "every": "every available backend",
        "fastest": "the OpenCL backend where it is available (else NumPy)",
        "reference": "the NumPy reference backend",
    }
    notes = []
    for key, text in where.items():
        names = [r.name for r in records if r.sweep_backends == key]
        if names:
            notes.append(f"{', '.join(names)}: on {text}")
    for r in records:
        shapes = "every element shape" if r.compared_on is None else ", ".join(r.compared_on)
        if r.beyond_paper:
            shapes += f" (by default the paper's five and {', '.join(r.beyond_paper)})"
        extra = (
            "; also "
            + "; ".join(
                r.label(dict(v.options)) + (f" on {', '.join(v.elements)}" if v.elements else "")
                for v in r.sweep_variants
            )
            if r.sweep_variants
            else ""
        )
        notes.append(f"{r.name}: {shapes}{extra}" + (f" ({r.paper})" if r.paper else ""))
    return notes


def _table_rows(table, shared, by_host: bool) -> list[list]:
    """Table 2's rows as text: the runs that finished (``shared``: their time was taken
    beside other runs; ``by_host``: add the host)."""
    from .report import fmt_pct, fmt_seconds

    body = []
    for k, r in table.iterrows():
        if r["status"] not in ("ok", "partial"):
            continue
        body.append(
            [
                r["method"],
                r["backend"],
                r["element"],
                fmt_pct(r["coverage_mean"], r["coverage_sd"]),
                fmt_pct(r["overlap_mean"], r["overlap_sd"], digits=2),
                fmt_pct(r["coverage_at_1pct_overlap"]),
                fmt_seconds(r["method_seconds_mean"]) + (" ‡" if shared[k] else ""),
                fmt_seconds(r["lloyd_seconds_mean"]),
                f"{r['ms_per_iteration']:.3g}",
                fmt_pct(r["energy_gap_mean"], digits=2),
                f"{r['runs']}/{r['seeds']}",
                fmt_pct(r["paper_coverage"]) if r["paper_time"] else "",
                r["paper_time"] or "",
            ]
            + ([r["hosts"]] if by_host else [])
        )
    return body


def render_markdown(
    table,
    prov: dict,
    command: str,
    quick: bool,
    cfg: dict,
    seeds: int,
    elapsed: float,
    cached: int,
    total: int,
    pictured: bool = True,
    methods: list[str] | None = None,
) -> str:
    from .converged import gap_notes
    from .report import fmt_seconds, header_markdown, markdown_table, several_hosts

    title = "Table 2, regenerated" + (
        " (QUICK: small raster, 2 seeds; not the paper's scale)" if quick else ""
    )
    notes = [
        f"problem set: square region, whole {cfg['size']}x{cfg['size']} px raster, N = {cfg['n_elements']} "
        f"sites, {cfg['iterations']} Lloyd iterations, seeds 0..{seeds - 1}, no density, no direction "
        "field; rectangle and ellipse β = 0.5",
        *_problem_notes(methods or list(dict.fromkeys(str(m).split(" ")[0] for m in table["method"]))),
        "baselines with a tile budget δ: tiles of the area of a square of side δ·sqrt(area/N)",
        "coverage at ≤ 1 % overlap (seed 0): every element scaled about its centre by 0.80 ... 1.20, "
        "evaluated alike, the largest coverage whose overlap is at most 1 % (interpolated)",
        "coverage and overlap: cvt.evaluate (area of the union of the elements inside the region / "
        "area of the region; overlap: summed element area minus union area, / region area)",
        "time: the whole method's wall time, problem to placed elements (Lloyd, final labels, fit, "
        "compaction; everything a baseline does), mean over seeds; Lloyd: the Lloyd iterations' part of it; "
        "ms/it: median per Lloyd iteration",
        "paper: Table 2 of Chen, Yang & Yang 2019 (C++/OpenGL on a GPU; N and raster not stated); "
        "shown on the square rows",
        *gap_notes(table, ["method", "backend"]),
        f"this command took {fmt_seconds(elapsed)}; {cached} of {total} runs were read back from "
        "raw/ (run with --force to redo them)",
    ]
    text = header_markdown("Table 2" if not quick else title, prov, command, notes)
    if quick:
        text += f"\n**{title}**\n"
    cols = list(MARKDOWN_COLUMNS)
    by_host = several_hosts(table["hosts"])  # rows from several machines say which
    shared = table["host_slots"].fillna(1) > 1  # times taken beside other runs of the sweep
    body = _table_rows(table, shared, by_host)
    text += "\n" + markdown_table(cols + (["host"] if by_host else []), body)
    if shared.any():
        text += (
            f"\n‡ time taken while up to {int(table['host_slots'].max())} runs of this sweep shared the "
            "host (--workers or --scheduler without --exclusive): compare it only with times taken the "
            "same way; coverage and overlap do not depend on it.\n"
        )
    missing = table[~table["status"].isin(["ok"])]
    if len(missing):
        text += "\n## Not run, failed or partial\n\n"
        text += markdown_table(
            ["method", "backend", "element", "status", "reason"],
            [
                [r["method"], r["backend"], r["element"], r["status"], r["reason"]]
                for _, r in missing.iterrows()
            ],
        )
    text += discussion(table)
    if pictured:
        text += (
            "\nThe picture `table2.png` shows one effect picture per method (seed 0, the top-left "
            "corner of the region, about 250 elements); the raw json"
        )
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
            out.append(
                {
                    "method": r.get("label") or r["method"],
                    "backend": r["backend"],
                    "element": r["element"],
                    "seed": r["seed"],
                    "factor": factor,
                    "coverage": coverage,
                    "overlap": overlap,
                }
            )
    if not out:
        return pd.DataFrame(
            columns=["method", "backend", "element", "factor", "coverage", "overlap", "seeds"]
        )
    df = pd.DataFrame(out)
    return (
        df.groupby(["method", "backend", "element", "factor"], sort=False)
        .agg(coverage=("coverage", "mean"), overlap=("overlap", "mean"), seeds=("seed", "nunique"))
        .reset_index()
    )


def render_coverage_overlap(curves, path: Path) -> bool:
    """One curve per method on squares: coverage against overlap as the elements are scaled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .report import save_figure

    sq = curves[curves["element"] == REFERENCE_SHAPE]
    if sq.empty:
        return False
    fig, ax = plt.subplots(figsize=(8, 5.2), dpi=110, layout="constrained")
    colours = plt.get_cmap("tab20").colors
    for k, ((method, _backend), g) in enumerate(sq.groupby(["method", "backend"], sort=False)):
        g = g.sort_values("factor")
        record = label_record(method)
        ours = record.role in ("paper", "extension")
        ax.plot(
            100 * g["overlap"],
            100 * g["coverage"],
            "os^vD<>"[k % 7] + ("-" if ours else "--"),
            ms=3.5,
            lw=2.2 if record.tight else 1.1,
            color=colours[k % len(colours)],
            label=method,
        )
        one = g[np.isclose(g["factor"], 1.0)]
        ax.plot(100 * one["overlap"], 100 * one["coverage"], "k.", ms=8)
    ax.axvline(1.0, color="grey", lw=0.8, ls=":")
    ax.set(
        xlabel="overlap (% of the region)",
        ylabel="coverage (% of the region)",
        xlim=(-0.5, 15),
        title="Squares at equal overlap: elements scaled 0.80-1.20 about their centres (black: as placed)",
    )
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
    fig, axes = plt.subplots(
        len(rows), ncol, figsize=(2.6 * ncol, 3.1 * len(rows)), dpi=110, squeeze=False, layout="constrained"
    )
    for ax in axes.ravel():
        ax.axis("off")
    for i, row in enumerate(rows):
        for j, (spec, p) in enumerate(row):
            ax = axes[i][j]
            with Image.open(p) as im:
                ax.imshow(np.asarray(im.convert("RGB")))
            c = cov.get((spec.label, spec.backend, spec.element), np.nan)
            name = f"{spec.label} ({spec.backend})" if _every_backend(spec.method) else spec.label
            ax.set_title(f"{name}\n{spec.element}: {100 * c:.1f} %", fontsize=9)
    spec0 = panels[0][0]
    crop = picture_crop(spec0.n_elements)
    part = "the whole region" if crop >= 1 else f"top-left {crop * spec0.width:.0f}² px of {spec0.width}² px"
    fig.suptitle(f"Effect pictures (seed 0, {part}, N = {spec0.n_elements})", fontsize=10)
    save_figure(fig, path)
    plt.close(fig)
    return True


def sweep_backends(names) -> tuple[list[str], dict[str, str]]:
    """The variants ``names`` gives (a list, or ``--backends``' comma text; default: every
    variant that computes every metric) and the reasons of those that cannot run here."""
    status = variant_status()
    default = [v for v in variant_names() if variant_metrics(v) is None]
    if isinstance(names, str):
        names = name_list(names, "--backends", variant_names())
    backends = [one_of(b, "--backends", variant_names()) for b in names] if names else default
    return backends, {v: text for v, (ok, text) in status.items() if not ok}


def variant_backend(unavailable: dict) -> str:
    """The backend the variants of ours run on: OpenCL where it runs (their Lloyd
    iterations are the same as ours'; OpenCL only makes them fast), else the reference."""
    return "opencl" if "opencl" not in unavailable else fall_back("opencl", unavailable["opencl"])


@dataclass(frozen=True)
class Table2Request(options.SweepRequest):
    """``cvtbench table2``, typed: seeds (None: the set's default), the methods, backend
    variants and shapes to run (None: all), and method options (name -> value, for every
    method that declares them)."""

    seeds: int | None = None
    methods: tuple[str, ...] | None = None
    backends: tuple[str, ...] | None = None
    shapes: tuple[str, ...] | None = None
    method_options: dict = field(default_factory=dict)

    @classmethod
    def from_args(cls, args) -> Table2Request:
        cfg = QUICK if args.quick else FULL
        listed = {
            name: name_list(getattr(args, name), f"--{name}", choices)
            for name, choices in (("methods", method_names()), ("backends", variant_names()))
        }
        listed["shapes"] = options.shape_names(args.shapes)
        return cls(
            **cls.common(args),
            seeds=options.seeds_value(args.seeds, cfg["seeds"]),
            **{k: options.as_tuple(v) for k, v in listed.items()},
            method_options=options.given_method_options(args),
        )


def prepare(req: Table2Request) -> dict:
    """Every option checked, the report folder and the memory of each run too, before
    anything runs (``cvtbench reproduce`` checks all its parts this way)."""
    from .outputs import check_folder
    from .sweep import check_memory

    check_folder(req.out)
    cfg = QUICK if req.quick else FULL
    seeds = cfg["seeds"] if req.seeds is None else options.seeds_value(req.seeds, cfg["seeds"])
    all_methods = method_names()
    chosen = [one_of(m, "--methods", all_methods) for m in req.methods or all_methods]
    methods = [m for m in all_methods if m in chosen]  # the registry's order
    backends, unavailable = sweep_backends(req.backends)
    shapes = options.shape_names(req.shapes) if req.shapes else None
    options.check_method_options(req.method_options, methods)
    specs = problem_set(
        req.quick, seeds, methods, backends, shapes, variant_backend(unavailable), req.method_options
    )
    check_memory(specs, req.memory_limit, lower="run the --quick set, or fewer --methods or --shapes")
    return {
        "out": req.out,
        "cfg": cfg,
        "seeds": seeds,
        "specs": specs,
        "unavailable": unavailable,
        "variant": variant_backend(unavailable),
    }


def table2(req: Table2Request) -> int:
    """Run Table 2's sweep and write its report (what ``cvtbench table2`` does)."""
    from .cluster import executor_for
    from .converged import run_converged
    from .outputs import report_folder
    from .report import provenance, write_csv, write_markdown, written_files
    from .sweep import check_runs, run_sweep

    t0 = time.perf_counter()
    plan = prepare(req)
    out, cfg, seeds, specs = plan["out"], plan["cfg"], plan["seeds"], plan["specs"]
    cmd = req.command or "cvtbench table2" + (" --quick" if req.quick else "")
    with report_folder(out, command=cmd):
        with executor_for(req, exclusive=req.exclusive) as executor:
            sweep = dict(force=req.force, quiet=req.quiet, unavailable=plan["unavailable"], executor=executor)
            rows = run_sweep(specs, out, **sweep)
            suite = f"{specs[0].suite}-converged" if specs else ""
            converged = run_converged(specs, rows, out, plan["variant"], suite, **sweep)
        table = aggregate(rows)
        elapsed = time.perf_counter() - t0
        cached = sum(1 for r in rows if r.get("cached"))
        pictured = render_picture(table, out, specs, out / "table2.png")
        md = render_markdown(
            table,
            provenance(),
            cmd,
            req.quick,
            cfg,
            seeds,
            elapsed,
            cached,
            len(rows),
            pictured,
            methods=list(dict.fromkeys(spec.method for spec in specs)),
        )
        curves = coverage_overlap_table(rows)
        if len(curves):
            write_csv(out / "coverage_overlap.csv", curves)
        if not (len(curves) and render_coverage_overlap(curves, out / "coverage_overlap.png")):
            for name in (
                ("coverage_overlap.png",) if len(curves) else ("coverage_overlap.csv", "coverage_overlap.png")
            ):
                (out / name).unlink(missing_ok=True)  # a stale view from an earlier sweep
        write_csv(out / "table2.csv", table)
        write_markdown(out / "table2.md", md)
        written = written_files(
            out, ["table2.md", "table2.csv", "table2.png", "coverage_overlap.csv", "coverage_overlap.png"]
        )
    _print_summary(table, out, written)
    # the report is written; a failed run (or converged run) still fails the command
    check_runs(specs, rows, "table2")
    check_runs(*converged, "table2's converged runs")
    return 0


def _print_summary(table, out: Path, written: list[str]) -> None:
    from .report import fmt_pct, fmt_seconds

    for _, r in table.iterrows():
        if r["status"] in ("ok", "partial"):
            print(
                f"{r['method']:<14} {r['backend']:<9} {r['element']:<9} "
                f"{fmt_pct(r['coverage_mean'], r['coverage_sd']):>16}  {fmt_seconds(r['method_seconds_mean'])}",
                file=sys.stderr,
            )
        else:
            print(
                f"{r['method']:<14} {r['backend']:<9} {r['element']:<9} {r['status']}: {r['reason']}",
                file=sys.stderr,
            )
    print(f"wrote {out}/{', '.join(written)}", file=sys.stderr)


__all__ = [
    "MARKDOWN_COLUMNS",
    "Table2Request",
    "table2",
    "problem_set",
    "aggregate",
    "prepare",
    "discussion",
    "label_record",
]
