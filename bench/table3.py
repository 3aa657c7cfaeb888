"""`cvtbench table3`: beyond coverage: density, direction and region, with fidelity measures.

Table 2 follows the paper (a square, uniform density, no field, one measure); the paper's
method exists for the other case (§3.3, Figures 14-15): sizes that follow a density,
directions that follow a field, regions of any shape.  Table 3 measures how well every
method does that, on the standard scenes of :mod:`.scenes`:

* ``density``: the whole square, a radial density gradient of contrast 3 (dense centre);
* ``field``: the whole square, a circular field;
* ``region``: a five-pointed star (not convex);
* ``combined``: a ring, the radial density and the circular field at once;

every method on the shapes its record compares it on (squares for the baselines, the
paper's comparison; ours and its variants on every element shape (rectangle and ellipse β = 0.5, triangle, circle); full: 512x512 px, about
N = 1000 elements on the whole raster (a region holds its share), 20 Lloyd iterations,
seeds 0..4; quick: 192x192 px, N = 150, seeds 0..1.

Every measure of :data:`compact_distributions.cvt.evaluate.MEASURES` (coverage, overlap,
coverage at ≤ 1 % overlap, size fidelity, direction fidelity, grout mean and CV), mean ±
sd over the seeds.  The same sweep engine as Table 2 (resume, ``--force``, Dask with
``--scheduler``/``--workers``).  Writes ``OUT/table3.md``, ``OUT/table3.csv``,
``OUT/table3_tradeoff.png`` (coverage against size and direction fidelity, one point per
seed) and ``OUT/raw/table3*/``.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

from compact_distributions.backends import REFERENCE as REFERENCE_BACKEND
from compact_distributions.cvt.evaluate import MEASURES
from compact_distributions.cvt.metrics import REFERENCE_SHAPE
from compact_distributions.cvt.registry import get_method, method_names
from compact_distributions.cvt.shapes import PAPER_SHAPES
from compact_distributions.cvt.validate import name_list, one_of

from . import options
from .runs import RunSpec
from .scenes import SCENE_TEXT, SCENES
from .table2 import label_record

FULL = {"size": 512, "n_elements": 1000, "iterations": 20, "seeds": 5}
QUICK = {"size": 192, "n_elements": 150, "iterations": 20, "seeds": 2}
SUITE = {False: "table3", True: "table3-quick"}

MEASURE_COLUMNS = [c for m in MEASURES for c in (f"{m}_mean", f"{m}_sd")]
COLUMNS = (
    [
        "scene",
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
    ]
    + MEASURE_COLUMNS
    + ["energy_gap_mean", "energy_gap_note", "method_seconds_mean", "status", "reason", "device", "hosts"]
)


def problem_set(
    quick: bool,
    seeds: int,
    methods: list[str],
    shapes: list[str],
    scenes: list[str],
    variant_backend: str,
    method_options: dict | None = None,
) -> list[RunSpec]:
    """The runs of Table 3 (module docstring), scene by scene: each method on the shapes
    its record says it is compared on, on the fast variant backend unless its record
    keeps it on the reference.

    Parameters
    ----------
    quick : bool
        The quick set (:data:`QUICK`) instead of the full one (:data:`FULL`).
    seeds : int
        Seeds 0..seeds-1.
    methods : list of str
        The methods, by name.
    shapes : list of str
        The element shapes.
    scenes : list of str
        The scenes of :mod:`.scenes`.
    variant_backend : str
        The backend of the methods not kept on the reference.
    method_options : dict or None, optional
        Option name -> value, as given on the command line (``--tolerance``,
        ``--accelerate``, ...), for every method that declares the option.

    Returns
    -------
    list of RunSpec
    """
    cfg = QUICK if quick else FULL
    specs = []
    records = {m: get_method(m) for m in methods}
    given = {m: options.options_for(rec, method_options) for m, rec in records.items()}
    for scene in scenes:
        for element in shapes:
            for method in methods:
                rec = records[method]
                if (rec.compared_on is not None and element not in rec.compared_on) or (
                    rec.elements is not None and element not in rec.elements
                ):
                    continue
                backend = REFERENCE_BACKEND if rec.sweep_backends == "reference" else variant_backend
                specs += [
                    RunSpec(
                        SUITE[quick],
                        method,
                        backend,
                        element,
                        cfg["size"],
                        cfg["size"],
                        cfg["n_elements"],
                        cfg["iterations"],
                        s,
                        curve=True,
                        scene=scene,
                        measures=True,
                        options=given[method],
                    )
                    for s in range(seeds)
                ]
    return specs


def aggregate(rows: list[dict]):
    """One line per (scene, method, backend, element): every measure's mean ± sd over the
    seeds that ran."""
    import pandas as pd

    from .converged import gap_columns
    from .report import fail_closed, group_status, sample_sd, with_columns

    df = fail_closed(pd.DataFrame(rows), ("coverage", "overlap"))
    if "label" in df:  # a run with options (--accelerate, ...) is a line of its own
        df["method"] = df["label"].fillna(df["method"])
    out = []
    for (scene, method, backend, element), g in df.groupby(
        ["scene", "method", "backend", "element"], sort=False
    ):
        ok = g[g["status"] == "ok"]
        first = g.iloc[0]
        rec = {
            "scene": scene,
            "method": method,
            "backend": backend,
            "element": element,
            "metric": first["metric"],
            "width": first["width"],
            "height": first["height"],
            "iterations": first["iterations"],
            "seeds": len(g),
            "runs": len(ok),
        }
        if len(ok):
            for m in MEASURES:
                values = ok[m].astype(float)
                rec[f"{m}_mean"] = float(values.mean())
                rec[f"{m}_sd"] = sample_sd(ok.assign(**{m: values}), m)
            rec.update(
                n_elements=int(ok["n_elements"].iloc[0]),
                method_seconds_mean=float(ok["method_seconds"].mean()),
                **gap_columns(ok),
            )
        rec.update(group_status(g, ok))
        out.append(rec)
    return with_columns(pd.DataFrame(out), COLUMNS)


def _fmt(measure: str, mean, sd) -> str:
    """A measure's mean ± sd in its unit (MEASURES)."""
    from .report import fmt_pct

    if mean is None or (isinstance(mean, float) and math.isnan(mean)):
        return "—"
    unit = MEASURES[measure][1]
    if unit == "share" and measure != "grout_cv":
        return fmt_pct(mean, sd, digits=2 if measure == "overlap" else 1)
    spec = {"degrees": ".2f", "px": ".2f"}.get(unit, ".3f")
    text = f"{mean:{spec}}" + ("" if sd is None or math.isnan(sd) else f" ± {sd:{spec}}")
    return text + ("°" if unit == "degrees" else "")


def _lead(row, others: dict, column: str) -> str:
    """How far ``row`` is ahead of the best of ``others`` (method -> row) in ``column``."""
    best = max(others, key=lambda m: others[m][column])
    return f"{100 * (row[column] - others[best][column]):+.1f} points against {best}"


def discussion(table) -> str:
    """What the measures show, every sentence computed from the rows at hand: where a
    method buys coverage by giving up the density or the field.  Each extension of the
    paper's method (its record's role) is set against the paper's method."""
    lines = ["", "## What the measures show", ""]
    ok = table[table["status"].isin(["ok", "partial"])]
    sq = ok[ok["element"] == REFERENCE_SHAPE]
    row = {(r["scene"], r["method"]): r for _, r in sq.iterrows()}
    role = {m: label_record(m).role for m in dict.fromkeys(sq["method"])}
    paper = next((m for m, r in role.items() if r == "paper"), None)
    extensions = [m for m, r in role.items() if r == "extension"]
    for scene in dict.fromkeys(sq["scene"]):
        ours = row.get((scene, paper))
        for name in extensions:
            ext = row.get((scene, name))
            if ours is None or ext is None:
                continue
            ratio = ext["size_fidelity_mean"] / ours["size_fidelity_mean"]
            others = {m: r for (s, m), r in row.items() if s == scene and m != name}
            lines.append(
                f"- {scene}: {name}'s size error {ext['size_fidelity_mean']:.3f} against {paper}'s "
                f"{ours['size_fidelity_mean']:.3f} ({ratio:.2f}x"
                + ("" if ratio <= 1.1 else f": its sizes spread more about the target than {paper}'s")
                + f"), coverage {100 * ext['coverage_mean']:.1f} % ({_lead(ext, others, 'coverage_mean')}; at ≤ 1 % "
                f"overlap {_lead(ext, others, 'coverage_at_1pct_overlap_mean')}), direction error "
                f"{ext['direction_fidelity_mean']:.2f}°."
            )
    lines.append(
        "- ours-compact caps its sizes only under a density (`cvt.placement.ours.density_caps`): under a "
        "uniform density (the field and region scenes) each element grows by the room around it, "
        "which is what buys Table 2's coverage and what the size error counts."
    )
    flat = [(m, r["size_fidelity_mean"]) for (s, m), r in row.items() if s == "density"]
    if flat:
        lines.append(
            "- Under the density, squares' size error (0: every area follows 1/density, 1: an RMS "
            "factor of 2): "
            + ", ".join(f"{m} {v:.3f}" for m, v in sorted(flat, key=lambda x: x[1]))
            + ". The fixed-size baselines size each tile by the density exactly and pay in overlap."
        )
    turned = [(m, r["direction_fidelity_mean"]) for (s, m), r in row.items() if s == "field"]
    if turned:
        lines.append(
            "- Under the circular field, squares' mean angle to the field: "
            + ", ".join(f"{m} {v:.2f}°" for m, v in sorted(turned, key=lambda x: x[1]))
            + "."
        )
    tight = [m for m in dict.fromkeys(ok["method"]) if label_record(m).tight]
    for name in tight:
        dirs = ok[(ok["method"] == name) & ok["direction_fidelity_mean"].notna()]
        if len(dirs):
            worst = dirs.loc[dirs["direction_fidelity_mean"].idxmax()]
            lines.append(
                f"- {name}'s largest direction error over every scene and shape: "
                f"{worst['direction_fidelity_mean']:.2f}° ({worst['element']}, {worst['scene']})."
            )
    lines.append(
        "- `table3_tradeoff.png`: coverage against size error (density scene) and against "
        "direction error (field scene), one point per seed, squares; hollow markers: the "
        "combined scene."
    )
    return "\n".join(lines) + "\n"


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
    pictured: bool,
) -> str:
    from .converged import gap_notes
    from .report import fmt_pct, fmt_seconds, header_markdown, markdown_table

    title = "Table 3: density, direction and region" + (" (QUICK: small raster, 2 seeds)" if quick else "")
    notes = [f"scene `{s}`: {SCENE_TEXT[s]}" for s in dict.fromkeys(table["scene"])]
    notes += [
        f"{cfg['size']}x{cfg['size']} px, N = {cfg['n_elements']} elements on the whole raster (a region holds "
        f"its share), {cfg['iterations']} Lloyd iterations, seeds 0..{seeds - 1}; each method on the shapes its "
        "record compares it on (the baselines on squares; rectangle and ellipse β = 0.5)",
        "the baselines on the NumPy reference backend, the others on the OpenCL backend where it is "
        "available (else NumPy)",
        "measures (cvt.evaluate, formulas on the documentation's measures page, docs/guide/measures.md): "
        + "; ".join(f"{m}: {text}" for m, (text, _) in MEASURES.items()),
        *gap_notes(table, ["method", "backend"]),
        f"this command took {fmt_seconds(elapsed)}; {cached} of {total} runs were read back from raw/ "
        "(run with --force to redo them)",
    ]
    text = header_markdown(title, prov, command, notes)
    heads = [
        "coverage",
        "overlap",
        "coverage at ≤ 1 % overlap",
        "size error",
        "direction error",
        "grout mean (px)",
        "grout CV",
        "energy above converged",
    ]
    for scene in dict.fromkeys(table["scene"]):
        part = table[table["scene"] == scene]
        body = [
            [r["method"], r["element"]]
            + [_fmt(m, r[f"{m}_mean"], r[f"{m}_sd"]) for m in MEASURES]
            + [fmt_pct(r["energy_gap_mean"], digits=2), f"{r['runs']}/{r['seeds']}"]
            for _, r in part.iterrows()
            if r["status"] in ("ok", "partial")
        ]
        n = part["n_elements"].dropna()
        text += f"\n## {scene}: {SCENE_TEXT[scene]}" + (f" (N = {int(n.iloc[0])})" if len(n) else "") + "\n\n"
        text += markdown_table(["method", "element"] + heads + ["runs"], body)
    missing = table[table["status"] != "ok"]
    if len(missing):
        text += "\n## Not run, failed or partial\n\n" + markdown_table(
            ["scene", "method", "backend", "element", "status", "reason"],
            [
                [r["scene"], r["method"], r["backend"], r["element"], r["status"], r["reason"]]
                for _, r in missing.iterrows()
            ],
        )
    text += discussion(table)
    if pictured:
        text += "\n![coverage against size and direction fidelity](table3_tradeoff.png)\n"
    return text


def render_tradeoff(rows: list[dict], path: Path) -> bool:
    """Coverage against size error (density scene) and direction error (field scene), per
    method one point per seed, squares; the combined scene hollow.  False when there is
    nothing to draw."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    from .report import save_figure

    df = pd.DataFrame([r for r in rows if r.get("status") == "ok" and r.get("element") == REFERENCE_SHAPE])
    panels = [
        ("size_fidelity", "density", "size error: RMS log2(area / target)"),
        ("direction_fidelity", "field", "direction error: mean angle to the field (°)"),
    ]
    if df.empty or not df["scene"].isin([p[1] for p in panels] + ["combined"]).any():
        path.unlink(missing_ok=True)  # a figure of another sweep must not pass for this one's
        return False
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), dpi=110, layout="constrained")
    colours = plt.get_cmap("tab10").colors
    methods = [m for m in method_names() if m in set(df["method"])]  # the registry's order
    labelled = set()
    for ax, (measure, scene, label) in zip(axes, panels, strict=True):
        for k, method in enumerate(methods):
            for sc, filled in ((scene, True), ("combined", False)):
                g = df[(df["method"] == method) & (df["scene"] == sc)]
                if g.empty:
                    continue
                ax.scatter(
                    g[measure],
                    100 * g["coverage"],
                    s=28,
                    marker="os^vD<>P"[k % 8],
                    facecolors=colours[k % 10] if filled else "none",
                    edgecolors=colours[k % 10],
                    label=None if method in labelled else method,
                )
                labelled.add(method)
        ax.set(
            xlabel=label,
            ylabel="coverage (% of the region)",
            title=f"{scene} scene (filled) and combined scene (hollow)",
        )
        ax.grid(True, alpha=0.3)
    fig.legend(fontsize=7, loc="outside right center")
    fig.suptitle("Coverage against fidelity, squares, one point per seed (better: up and left)", fontsize=10)
    save_figure(fig, path)
    plt.close(fig)
    return True


def prepare(args) -> dict:
    """The argparse options as :func:`run_table3`'s arguments, every one checked (the
    folder and the memory too) before anything runs, as ``cvtbench reproduce`` asks."""
    from .cluster import chosen

    kwargs = {
        "out": options.report_out(args),
        "quick": args.quick,
        "seeds": args.seeds,
        "methods": name_list(args.methods, "--methods", method_names()),
        "shapes": options.shape_names(args.shapes),
        "scenes": name_list(args.scenes, "--scenes", list(SCENES)),
        "force": args.force,
        "quiet": args.quiet,
        "scheduler": args.scheduler,
        "workers": args.workers,
        "memory_limit": args.memory_limit,
        "method_options": options.given_method_options(args),
    }
    chosen(args)
    plan(
        kwargs["out"],
        quick=args.quick,
        seeds=args.seeds,
        methods=kwargs["methods"],
        shapes=kwargs["shapes"],
        scenes=kwargs["scenes"],
        memory_limit=args.memory_limit,
        method_options=kwargs["method_options"],
    )
    return kwargs


def plan(
    out,
    *,
    quick: bool = False,
    seeds=None,
    methods=None,
    shapes=None,
    scenes=None,
    memory_limit=None,
    method_options: dict | None = None,
) -> dict:
    """Every argument checked, the report folder and each run's memory too, before
    anything runs or is written: the runs of Table 3 and what they need."""
    from .outputs import check_folder
    from .sweep import check_memory
    from .table2 import sweep_backends, variant_backend

    cfg = QUICK if quick else FULL
    k = options.seeds_value(seeds, cfg["seeds"])
    methods = [one_of(m, "--methods", method_names()) for m in (methods or method_names())]
    shapes = options.shape_names(shapes or PAPER_SHAPES)
    scenes = [one_of(s, "--scenes", list(SCENES)) for s in (scenes or SCENES)]
    options.check_method_options(method_options or {}, methods)
    check_folder(out)
    _, unavailable = sweep_backends(None)
    variant = variant_backend(unavailable)
    specs = problem_set(quick, k, methods, shapes, scenes, variant, method_options)
    check_memory(specs, memory_limit, lower="run the --quick set, or fewer --methods, --shapes or --scenes")
    return {"cfg": cfg, "seeds": k, "specs": specs, "unavailable": unavailable, "variant": variant}


def run_table3(
    out,
    *,
    quick: bool = False,
    seeds: int | str | None = None,
    methods: list[str] | None = None,
    shapes: list[str] | None = None,
    scenes: list[str] | None = None,
    force: bool = False,
    quiet: bool = False,
    scheduler: str | None = None,
    workers: int | str | None = None,
    memory_limit=None,
    command: str | None = None,
    method_options: dict | None = None,
):
    """Run Table 3 into the folder ``out`` and return its table (a DataFrame); where a run
    failed, the report is written and :class:`.sweep.RunsFailed` raised naming it.

    ``quick``: the small set; ``seeds``: K (seeds 0..K-1; default 5, quick 2);
    ``methods``, ``shapes``, ``scenes``: subsets (default all); ``force``: re-run stored
    runs; ``scheduler`` / ``workers``: a Dask cluster's address, or N local worker
    processes; ``memory_limit``: as ``--memory-limit``; ``method_options``: option name ->
    value for every method that declares it (``--tolerance``, ``--accelerate``, as
    ``cvtbench table2`` takes them).  Bad arguments raise InputError before anything is
    written."""
    from .cluster import chosen, executor_for
    from .converged import run_converged
    from .outputs import report_folder
    from .report import provenance, write_csv, write_markdown, written_files
    from .sweep import check_runs, run_sweep

    t0 = time.perf_counter()
    out = Path(out)
    cluster = SimpleNamespace(scheduler=scheduler, workers=workers)
    chosen(cluster)  # bad cluster options fail before anything starts
    p = plan(
        out,
        quick=quick,
        seeds=seeds,
        methods=methods,
        shapes=shapes,
        scenes=scenes,
        memory_limit=memory_limit,
        method_options=method_options,
    )
    command = command or "cvtbench table3" + (" --quick" if quick else "")
    with report_folder(out, command=command):
        with executor_for(cluster) as executor:
            sweep = dict(force=force, quiet=quiet, unavailable=p["unavailable"], executor=executor)
            rows = run_sweep(p["specs"], out, **sweep)
            converged = run_converged(
                p["specs"], rows, out, p["variant"], f"{SUITE[quick]}-converged", **sweep
            )
        table = aggregate(rows)
        elapsed = time.perf_counter() - t0
        cached = sum(1 for r in rows if r.get("cached"))
        pictured = render_tradeoff(rows, out / "table3_tradeoff.png")
        md = render_markdown(
            table, provenance(), command, quick, p["cfg"], p["seeds"], elapsed, cached, len(rows), pictured
        )
        write_csv(out / "table3.csv", table)
        write_markdown(out / "table3.md", md)
        written = written_files(out, ["table3.md", "table3.csv", "table3_tradeoff.png"])
    if not quiet:
        print(f"wrote {out}/{', '.join(written)} in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    # the report is written; a failed run (or converged run) still fails the command
    check_runs(p["specs"], rows, "table3")
    check_runs(*converged, "table3's converged runs")
    return table


@dataclass(frozen=True)
class Table3Request(options.SweepRequest):
    """``cvtbench table3``, typed (what ``reproduce`` hands it): seeds, the methods,
    shapes and scenes to run (None: all), and method options (name -> value, for every
    method that declares them)."""

    seeds: int | None = None
    methods: tuple[str, ...] | None = None
    shapes: tuple[str, ...] | None = None
    scenes: tuple[str, ...] | None = None
    method_options: dict = field(default_factory=dict)


def check(req: Table3Request) -> dict:
    """Every field checked, the folder and each run's memory too (:func:`plan`)."""
    return plan(
        req.out,
        quick=req.quick,
        seeds=req.seeds,
        methods=req.methods,
        shapes=req.shapes,
        scenes=req.scenes,
        memory_limit=req.memory_limit,
        method_options=req.method_options,
    )


def table3(req: Table3Request) -> int:
    """Run Table 3 as ``req`` asks (what ``cvtbench table3`` does)."""
    run_table3(
        req.out,
        quick=req.quick,
        seeds=req.seeds,
        methods=req.methods,
        shapes=req.shapes,
        scenes=req.scenes,
        force=req.force,
        quiet=req.quiet,
        scheduler=req.scheduler,
        workers=req.workers,
        memory_limit=req.memory_limit,
        command=req.command,
        method_options=req.method_options,
    )
    return 0


__all__ = ["Table3Request", "table3", "problem_set", "aggregate", "run_table3", "plan"]
