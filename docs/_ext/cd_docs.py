"""The site's generated pages: written at build time from what the suite ships.

Before Sphinx reads a page, this writes markdown into ``docs/generated/`` (ignored by
git, excluded from the page list, pulled into pages by MyST's ``include``):

- ``commands.md``: every ``cvtbench`` command from the argparse parsers themselves
  (``compact_distributions.bench.commands.cli.build_parser()``), so the options are
  written once, in the code;
- ``result_schema.md``: the fields of result.json from the shipped JSON schema
  (``bench/result.schema.json``);
- ``methods.md``: every method record of the registry (name, role, paper, options, the
  paper's Table 2 figures) with its callable's API entry;
- ``shapes.md``: the shape table (``cvt.metrics.SHAPES``);
- ``report_*.md``: the reports' tables from ``reports/*.csv`` (and ``reports/gpu/*.csv``
  where that folder exists), each row's method linked to its API entry and its paper;
  the report figures (``reports/*.png``) are copied beside them.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import shutil
from pathlib import Path

__all__ = ["setup", "write_pages", "md_escape", "method_link", "CHEN2019"]

DOCS = Path(__file__).resolve().parent.parent
ROOT = DOCS.parent
OUT = DOCS / "generated"
CHEN2019 = (
    "Chen, Yang & Yang, Computation of Compact Distributions of Discrete Elements, Algorithms 12(2):41, 2019",
    "https://doi.org/10.3390/a12020041",
)

_SPECIAL = re.compile(r"([\\`*_\[\]<>|$~#])")


def md_escape(text) -> str:
    """``text`` as literal markdown (one line: table cells and paragraphs)."""
    return _SPECIAL.sub(r"\\\1", " ".join(str(text).split()))


def _code(text) -> str:
    text = str(text)
    fence = "``" if "`" in text else "`"
    return f"{fence}{text}{fence}" if fence == "`" else f"{fence} {text} {fence}"


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell.replace("\n", " ") for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def _write(name: str, text: str) -> None:
    """Write only on a change, so that Sphinx re-reads only the pages that changed."""
    path = OUT / name
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


# --------------------------------------------------------------------- commands
def _default_text(action: argparse.Action) -> str:
    if action.default in (None, argparse.SUPPRESS) or isinstance(
        action, (argparse._StoreTrueAction, argparse._StoreFalseAction, argparse._VersionAction)
    ):
        return ""
    if isinstance(action.default, (list, tuple)):
        return _code(",".join(map(str, action.default)))
    return _code(action.default)


def _option_cell(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    if not action.option_strings:
        return _code(action.metavar or action.dest)
    formatter = parser._get_formatter()
    return ", ".join(_code(part) for part in formatter._format_action_invocation(action).split(", "))


def _help_cell(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    text = parser._get_formatter()._expand_help(action) if action.help else ""
    if action.choices and not isinstance(action.choices, dict) and "{" not in text:
        text += " (one of: " + ", ".join(map(str, action.choices)) + ")"
    return md_escape(text)


def _parser_section(parser: argparse.ArgumentParser, title: str, label: str, level: int) -> str:
    out = [f"({label})=", f"{'#' * level} {_code(title)}", ""]
    if parser.description:
        if parser.formatter_class is argparse.RawDescriptionHelpFormatter:
            out += ["```text", parser.description.strip("\n"), "```", ""]
        else:
            out += [md_escape(parser.description), ""]
    out += ["```text", parser.format_usage().strip(), "```", ""]
    for group in parser._action_groups:
        actions = [
            a
            for a in group._group_actions
            if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))
            and a.help != argparse.SUPPRESS
        ]
        if not actions:
            continue
        out += [f"**{md_escape(group.title or 'options')}**", ""]
        if group.description:
            out += [md_escape(group.description), ""]
        rows = [[_option_cell(parser, a), _default_text(a), _help_cell(parser, a)] for a in actions]
        out += [_table(["option", "default", "meaning"], rows)]
    return "\n".join(out) + "\n"


def commands_page() -> str:
    """The reference of every ``cvtbench`` command, from the parsers."""
    from compact_distributions.bench.commands.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {choice.dest: choice.help for choice in sub._choices_actions}
    text = [
        "<!-- generated by docs/_ext/cd_docs.py from cli.build_parser(): do not edit -->",
        "",
        "| command | what it does |",
        "|---|---|",
    ]
    text += [
        f"| {{ref}}`cvtbench {name} <cmd-{name}>` | {md_escape(helps.get(name, ''))} |"
        for name in sub.choices
    ]
    text.append("")
    text.append(_parser_section(parser, "cvtbench", "cmd-cvtbench", 2))
    for name, p in sub.choices.items():
        text.append(_parser_section(p, f"cvtbench {name}", f"cmd-{name}", 2))
    return "\n".join(text)


# --------------------------------------------------------------------- result.json
def _schema_type(spec: dict, defs: dict) -> str:
    if "$ref" in spec:
        name = spec["$ref"].rsplit("/", 1)[-1]
        return _schema_type(defs[name], defs)
    if "const" in spec:
        return _code(json.dumps(spec["const"]))
    if "enum" in spec:
        return " \\| ".join(_code(json.dumps(v)) for v in spec["enum"])
    kind = spec.get("type", "any")
    kinds = kind if isinstance(kind, list) else [kind]
    words = []
    for k in kinds:
        if k == "array" and "items" in spec:
            words.append(f"array of {_schema_type(spec['items'], defs)}")
        elif k == "object" and isinstance(spec.get("additionalProperties"), dict):
            words.append(f"object of {_schema_type(spec['additionalProperties'], defs)}")
        else:
            words.append(k)
    return " or ".join(words)


def _schema_bounds(spec: dict) -> str:
    parts = []
    for key, sign in (
        ("minimum", "≥"),
        ("exclusiveMinimum", ">"),
        ("maximum", "≤"),
        ("exclusiveMaximum", "<"),
    ):
        if key in spec:
            parts.append(f"{sign} {spec[key]}")
    if "minItems" in spec and spec.get("minItems") == spec.get("maxItems"):
        parts.append(f"{spec['minItems']} items")
    if "pattern" in spec:
        parts.append(_code(spec["pattern"]))
    items = spec.get("items")
    if isinstance(items, dict) and "pattern" in items:
        parts.append(_code(items["pattern"]))
    return ", ".join(parts)


def schema_page() -> str:
    """result.json's fields as the shipped schema declares them."""
    from importlib.resources import files

    schema = json.loads(files("compact_distributions.bench").joinpath("result.schema.json").read_text())
    defs = schema.get("$defs", {})
    required = set(schema.get("required", ()))
    mosaic = set(schema.get("then", {}).get("required", ()))
    rows = []
    for name, spec in schema["properties"].items():
        written = "run, mosaic" if name in required else ("mosaic" if name in mosaic else "when present")
        rows.append(
            [
                _code(name),
                _schema_type(spec, defs),
                _schema_bounds(spec),
                written,
                md_escape(spec.get("description", "")),
            ]
        )
    return (
        "<!-- generated by docs/_ext/cd_docs.py from bench/result.schema.json: do not edit -->\n\n"
        f"Schema: {md_escape(schema.get('title', ''))} ({_code(schema.get('$schema', ''))}).\n\n"
        + _table(["field", "type", "bounds", "written by", "the schema's description"], rows)
    )


# --------------------------------------------------------------------- methods and shapes
def _records():
    from compact_distributions.cvt.registry import methods

    return methods()


def api_target(record) -> str:
    """The documented name of a method record's callable."""
    run = record.run
    return f"{run.__module__}.{run.__qualname__}"


def method_link(label: str, records: dict) -> str:
    """A report row's method label (``hausner2001 δ=0.85``) linked to its callable's API
    entry and its paper (the method's entry on the Methods page)."""
    name = str(label).split(" ")[0]
    record = records.get(name)
    if record is None:
        return md_escape(label)
    rest = md_escape(str(label)[len(name) :])
    return f"{{py:func}}`{name} <{api_target(record)}>`{rest} ({{ref}}`paper <method-{name}>`)"


SWEEPS = {"every": "every backend", "fastest": "the fastest backend", "reference": "the NumPy reference"}


def _paper(record) -> str:
    """A record's paper as markdown: the citation with its year, or the paper this suite
    reproduces (ours and its extensions), linked to its DOI."""
    if record.paper:
        year = f" ({record.year})" if record.year and str(record.year) not in record.paper else ""
        return md_escape(record.paper + year)
    what = "the paper's method as published" if record.role == "paper" else "ours, beyond the paper"
    return f"[{md_escape(CHEN2019[0])}]({CHEN2019[1]}) ({what})"


def methods_page() -> str:
    """Every method record of the registry, with its callable's documentation."""
    records = _records()
    out = ["<!-- generated by docs/_ext/cd_docs.py from the method registry: do not edit -->", ""]
    rows = [[f"{{ref}}`{n} <method-{n}>`", r.role, md_escape(r.summary)] for n, r in records.items()]
    out += [_table(["method", "role", "summary"], rows)]
    for name, r in records.items():
        out += [
            f"(method-{name})=",
            f"## {_code(name)}",
            "",
            md_escape(r.summary),
            "",
            f"Paper: {_paper(r)}.",
            "",
        ]
        facts = [
            ["role", r.role],
            ["fixed-size tiles", "yes" if r.fixed_size else "no"],
            ["shapes it places", ", ".join(r.elements) if r.elements else "every shape"],
            ["compared on", ", ".join(r.compared_on) if r.compared_on else "every shape"],
            ["sweeps run it on", SWEEPS[r.sweep_backends]],
        ]
        if r.paper_table2:
            coverage, seconds = r.paper_table2
            facts.append(["the paper's Table 2", f"{100 * coverage:.1f} % coverage, {seconds}"])
        out += [_table(["record", ""], [[k, md_escape(v)] for k, v in facts])]
        if r.options:
            rows = [[_code(o.flag), o.kind.__name__, _code(o.default), md_escape(o.help)] for o in r.options]
            out += ["Options:", "", _table(["option", "type", "default", "meaning"], rows)]
        # autodoc writes reStructuredText, which MyST reads only inside eval-rst
        out += ["```{eval-rst}", f".. autofunction:: {api_target(r)}", "```", ""]
    return "\n".join(out)


def shapes_page() -> str:
    """The shape table, one row per record of ``cvt.metrics.SHAPES``."""
    from compact_distributions.cvt.metrics import SHAPES

    rows = []
    for s in SHAPES.values():
        geometry = (
            f"regular, {s.sides} sides, first vertex at {s.phase:g}°"
            if s.sides
            else ("curved" if s.curved else f"{len(s.vertices or ())} vertices")
        )
        rows.append(
            [
                _code(s.name),
                _code(s.metric),
                str(s.symmetry),
                f"{math.degrees(s.side_period):g}°",
                f"{s.packing:.3g}",
                "yes" if s.axial else "no",
                geometry,
                str(s.compaction_rounds),
            ]
        )
    header = [
        "shape",
        "metric",
        "symmetry",
        "side period",
        "packing",
        "β stretches it",
        "geometry",
        "compaction rounds",
    ]
    return "<!-- generated by docs/_ext/cd_docs.py from cvt.metrics.SHAPES: do not edit -->\n\n" + _table(
        header, rows
    )


# --------------------------------------------------------------------- reports
def _frame(path: Path):
    import pandas as pd

    return pd.read_csv(path, keep_default_na=True)


def _ok(frame):
    return frame[frame["status"].isin(["ok", "partial"])] if "status" in frame else frame


def _num(value, spec: str = ".3g") -> str:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return "—"
    return "—" if math.isnan(v) else f"{v:{spec}}"


def provenance(path: Path) -> str:
    """The header bullets (machine, commit, devices, versions, ...) of the markdown report
    written beside ``path`` by the same command, or nothing."""
    md = path.with_suffix(".md")
    if not md.exists():
        return ""
    lines = md.read_text(encoding="utf-8").splitlines()
    start = next((k for k, line in enumerate(lines) if line.startswith("- ")), None)
    if start is None:
        return ""
    end = next((k for k in range(start, len(lines)) if not lines[k].startswith(("- ", "  "))), len(lines))
    generated = next((line for line in lines[:start] if line.startswith("Generated by")), "")
    body = (generated + "\n\n" if generated else "") + "\n".join(lines[start:end])
    return f":::{{dropdown}} How this report was made: machine, commit, devices, versions\n{body}\n:::\n\n"


def _discussion(text: str) -> str:
    """A report's computed discussion, its headings one level down (under the page's)."""
    return re.sub(r"^## ", "### ", text, flags=re.M)


def table2_page(path: Path, records: dict) -> str:
    from compact_distributions.bench.report import fmt_pct, fmt_seconds
    from compact_distributions.bench.table2 import discussion

    frame = _ok(_frame(path))
    rows = []
    for _, r in frame.iterrows():
        paper = isinstance(r.get("paper_time"), str) and r["paper_time"]
        rows.append(
            [
                method_link(r["method"], records),
                _code(r["backend"]),
                r["element"],
                fmt_pct(r["coverage_mean"], r["coverage_sd"]),
                fmt_pct(r["overlap_mean"], r["overlap_sd"], digits=2),
                fmt_pct(r["coverage_at_1pct_overlap"]),
                fmt_seconds(r["method_seconds_mean"]),
                fmt_seconds(r["lloyd_seconds_mean"]),
                _num(r["ms_per_iteration"]),
                fmt_pct(r.get("energy_gap_mean"), digits=2),  # absent from reports made before it
                f"{r['runs']}/{r['seeds']}",
                fmt_pct(r["paper_coverage"]) if paper else "",
                md_escape(r["paper_time"]) if paper else "",
            ]
        )
    from compact_distributions.bench.table2 import MARKDOWN_COLUMNS

    header = list(MARKDOWN_COLUMNS)
    first = frame.iloc[0]
    return (
        f"<!-- generated by docs/_ext/cd_docs.py from {path.relative_to(ROOT)}: do not edit -->\n\n"
        f"{first['width']}x{first['height']} px, N = {first['n_elements']}, {first['iterations']} Lloyd "
        f"iterations, {first['seeds']} seeds; {len(frame)} rows.\n\n"
        + _table(header, rows)
        + _gap_notes(frame)
        + _discussion(discussion(_frame(path)))
    )


def _gap_notes(frame) -> str:
    """What "energy above converged" is and why a row has none (the reports' own notes),
    or nothing for a report made before the column."""
    from compact_distributions.bench.converged import gap_notes

    if "energy_gap_note" not in frame:
        return ""
    return "\n" + "".join(f"- {md_escape(n)}\n" for n in gap_notes(frame, ["method", "backend"]))


def table3_page(path: Path, records: dict) -> str:
    from compact_distributions.bench.report import fmt_pct
    from compact_distributions.bench.table3 import _fmt, discussion
    from compact_distributions.cvt.evaluate import MEASURES

    frame = _ok(_frame(path))
    out = [f"<!-- generated by docs/_ext/cd_docs.py from {path.relative_to(ROOT)}: do not edit -->", ""]
    measures = [m for m in MEASURES if f"{m}_mean" in frame]
    for scene, group in frame.groupby("scene", sort=False):
        first = group.iloc[0]
        out += [
            f"({'table3-' + scene})=",
            f"### {scene}",
            "",
            f"{first['width']}x{first['height']} px, N = {first['n_elements']}, {first['seeds']} seeds.",
            "",
        ]
        rows = [
            [method_link(r["method"], records), _code(r["backend"]), r["element"]]
            + [md_escape(_fmt(m, r[f"{m}_mean"], r.get(f"{m}_sd"))) for m in measures]
            + [fmt_pct(r.get("energy_gap_mean"), digits=2), f"{r['runs']}/{r['seeds']}"]
            for _, r in group.iterrows()
        ]
        heads = [
            "method",
            "backend",
            "element",
            *[_code(m) for m in measures],
            "energy above converged",
            "runs",
        ]
        out.append(_table(heads, rows))
    return "\n".join(out) + "\n" + _gap_notes(frame) + _discussion(discussion(_frame(path)))


def backends_page(path: Path, records: dict) -> str:
    """ms per Lloyd iteration: one row per metric, N and raster, one column per backend
    (its ``x numpy`` ratio beside it, measured in the same sweep)."""
    frame = _frame(path)
    backends = list(dict.fromkeys(frame["backend"]))
    cells = {}
    for _, r in frame.iterrows():
        key = (r["metric"], int(r["n_elements"]), int(r["size"]))
        if r["status"] == "ok":
            ratio = "" if r["backend"] == "numpy" else f" ({_num(r['x_numpy'], '.2g')}x)"
            cells[key, r["backend"]] = _num(r["ms_per_iteration"]) + ratio
        else:
            cells[key, r["backend"]] = md_escape(r["status"])
    keys = list(dict.fromkeys(k for k, _ in cells))
    rows = [
        [_code(m), str(n), f"{size}²"] + [cells.get(((m, n, size), b), "") for b in backends]
        for m, n, size in keys
    ]
    return (
        f"<!-- generated by docs/_ext/cd_docs.py from {path.relative_to(ROOT)}: do not edit -->\n\n"
        + _table(
            [
                "metric",
                "N",
                "raster",
                *[f"{_code(b)} ms" + ("" if b == "numpy" else " (x numpy)") for b in backends],
            ],
            rows,
        )
    )


def pipeline_page(path: Path, records: dict) -> str:
    from compact_distributions.bench.commands.pipeline import growth_exponent
    from compact_distributions.bench.report import fmt_seconds

    frame = _frame(path)
    stages = [
        c[: -len("_seconds")]
        for c in frame.columns
        if c.endswith("_seconds") and c not in ("whole_seconds", "method_seconds")
    ]
    rows = []
    for _, r in frame.iterrows():
        workload = str(r["workload"])
        first = method_link(workload, records) if workload in records else f"{_code('cvtbench ' + workload)}"
        rows.append(
            [
                first,
                _code(r["backend"]),
                str(r["n_elements"]),
                f"{r['size']}²",
                fmt_seconds(r["whole_seconds"]),
                f"{_num(r['peak_mb'], '.0f')} MB",
            ]
            + [fmt_seconds(r[f"{s}_seconds"]) for s in stages]
            + [_num(r["coverage"], ".3f")]
        )
    growth = []
    for (workload, backend), group in frame[frame["status"] == "ok"].groupby(
        ["workload", "backend"], sort=False
    ):
        parts = [
            f"{stage} {growth_exponent(group['n_elements'], group[column]):.2f}"
            for stage, column in [("whole", "whole_seconds")] + [(s, f"{s}_seconds") for s in stages]
            if group[column].notna().sum() >= 2
        ]
        growth.append([md_escape(workload), _code(backend), ", ".join(parts)])
    return (
        f"<!-- generated by docs/_ext/cd_docs.py from {path.relative_to(ROOT)}: do not edit -->\n\n"
        + _table(
            ["what", "backend", "N", "raster", "whole command", "peak memory", *stages, "coverage"], rows
        )
        + "\n### How each stage grows with N\n\nThe slope of log(seconds) against log(N) over the rows run "
        "(1 = linear):\n\n" + _table(["what", "backend", "exponent"], growth)
    )


REPORTS = {  # page -> (csv, the page's table, the figures beside it)
    "table2": ("table2.csv", table2_page, ("table2.png", "coverage_overlap.png")),
    "table3": ("table3.csv", table3_page, ("table3_tradeoff.png",)),
    "backends": ("backends.csv", backends_page, ("backends.png",)),
    "pipeline": ("pipeline.csv", pipeline_page, ("pipeline.png",)),
}


def report_pages(records: dict) -> list[str]:
    """Write the tables of ``reports/`` and ``reports/gpu/`` (where it exists) and copy
    their figures; return the pages written."""
    written = []
    figures = OUT / "figures"
    figures.mkdir(exist_ok=True)
    for folder, prefix in ((ROOT / "reports", "report"), (ROOT / "reports" / "gpu", "gpu")):
        for page, (csv, make, pngs) in REPORTS.items():
            if not (folder / csv).exists():
                _write(
                    f"{prefix}_{page}.md",
                    f"No {_code(str((folder / csv).relative_to(ROOT)))} in this checkout.\n",
                )
                continue
            pictures = ""
            for png in pngs:
                if (folder / png).exists():
                    shutil.copyfile(folder / png, figures / f"{prefix}_{png}")
                    if prefix == "gpu":  # the GPU page shows what its folder holds
                        pictures += f"![{png}](../generated/figures/{prefix}_{png})\n\n"
            _write(f"{prefix}_{page}.md", pictures + provenance(folder / csv) + make(folder / csv, records))
            written.append(f"{prefix}_{page}")
    for png in (ROOT / "reports" / "figures").glob("*.png"):
        shutil.copyfile(png, figures / png.name)
    _write("has_gpu.txt", "yes\n" if (ROOT / "reports" / "gpu").is_dir() else "no\n")
    return written


# --------------------------------------------------------------------- sphinx
def write_pages(app=None) -> None:
    """Write every generated page (Sphinx calls it when the builder starts)."""
    import os

    os.environ["COLUMNS"] = "88"  # argparse's usage lines, the same on every machine
    OUT.mkdir(exist_ok=True)
    records = _records()
    _write("commands.md", commands_page())
    _write("result_schema.md", schema_page())
    _write("methods.md", methods_page())
    _write("shapes.md", shapes_page())
    report_pages(records)


def setup(app):
    app.connect("builder-inited", write_pages)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
