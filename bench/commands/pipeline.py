"""`cvtbench pipeline`: how the cost of the whole method grows with N, stage by stage.

Each configuration is a real command run in its own process, as a user runs it:
``cvtbench run --method ours-compact --element square`` (20 Lloyd iterations) and
``cvtbench mosaic samples/scene.jpg`` (2000-tile defaults scaled to N), for N in
{1000, 4000, 16 000, 64 000} (quick: {1000, 4000}) on a raster that grows with N (about
16 px per element, as Table 2: 512², 1024², 2048², 4096²), on each backend asked for.
From each run it keeps the whole command's wall time and peak memory (the process's
maximum resident set, from ``os.wait4``) and the wall time of every stage that
``result.json`` records in ``stage_seconds`` (a mosaic's picture analysis, Lloyd, final
labels, fit, compaction, cutting, fills, evaluation, writing).

Writes ``OUT/pipeline.md``, ``OUT/pipeline.csv`` and ``OUT/pipeline.png`` (log-log:
seconds against N per stage, and peak memory against N), and ``OUT/raw/pipeline*/``;
like every sweep it resumes, and ``--force`` redoes stored runs.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from compact_distributions.backends import first_available, variant_names, variant_status
from compact_distributions.cvt.metrics import REFERENCE_SHAPE
from compact_distributions.cvt.validate import name_list, one_of, whole_number

from .. import options

# what a row runs: `cvtbench run --method ours-compact`, or `cvtbench mosaic`
WORKLOADS = ("ours-compact", "mosaic")
FULL_ELEMENTS = (1000, 4000, 16000, 64000)
QUICK_ELEMENTS = (1000, 4000)
DEFAULT_BACKENDS = ("opencl",)
MAX_ELEMENTS = 1_000_000
# the stages drawn, in pipeline order (result.json's stage_seconds keys)
STAGES = ("picture", "lloyd", "final_label", "fit", "compaction", "cutting", "fills", "evaluation", "writing")
COLUMNS = [
    "workload",
    "backend",
    "n_elements",
    "size",
    "whole_seconds",
    "peak_mb",
    "bytes_per_pixel",
    *(f"{s}_seconds" for s in STAGES),
    "method_seconds",
    "coverage",
    "overlap",
    "status",
    "reason",
    "device",
    "host",
]
SAMPLE = "scene.jpg"


def raster_side(n: int) -> int:
    """The square raster side for ``n`` elements: 512² per 1000 (about 16 px cells, as
    Table 2), a multiple of 64 (1024 for 4000, 2048 for 16 000, 4096 for 64 000)."""
    return max(64, int(64 * round(8 * math.sqrt(n / 1000))))


# Runs a Python child that reports its own peak resident memory as it exits: the kernel's
# high-water mark of the process after exec (VmHWM).  The rusage of a forked child also
# counts the parent's pages it shared before exec, so it would add this process's size.
PEAK_LAUNCHER = """
import atexit, runpy, sys
report, mode, target = sys.argv[1], sys.argv[2], sys.argv[3]
def _report():
    try:
        with open("/proc/self/status") as f:
            kb = next(line for line in f if line.startswith("VmHWM:")).split()[1]
    except (OSError, StopIteration):
        import resource
        kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with open(report, "w") as f:
        f.write(str(kb))
atexit.register(_report)
sys.argv = [target, *sys.argv[4:]]
if mode == "-m":
    runpy.run_module(target, run_name="__main__", alter_sys=True)
else:
    exec(compile(target, "<string>", "exec"), {"__name__": "__main__"})
"""


def run_measured(python_args: list[str]) -> tuple[int, str, float, int]:
    """Run ``python -m MODULE ARGS...`` or ``python -c CODE`` (``python_args``): (exit
    status, its standard error, wall seconds, its own peak resident bytes)."""
    with tempfile.TemporaryDirectory(prefix="cvtbench-peak-") as tmp:
        report = Path(tmp) / "peak_kb"
        t0 = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-c", PEAK_LAUNCHER, str(report), *python_args],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        seconds = time.perf_counter() - t0
        peak = int(report.read_text()) * 1024 if report.exists() else -1
    return done.returncode, done.stderr.decode(errors="replace"), seconds, peak


@dataclass(frozen=True)
class PipelineSpec:
    """One configuration: a ``workload`` with ``n_elements`` on ``backend``."""

    suite: str
    workload: str
    backend: str
    n_elements: int
    size: int

    @property
    def key(self) -> str:
        return f"{self.workload}__{self.backend}__n{self.n_elements}__{self.size}"

    def describe(self) -> str:
        return f"{self.workload} {self.backend} N={self.n_elements} {self.size}²"

    def params(self) -> dict:
        return {
            "workload": self.workload,
            "backend": self.backend,
            "n_elements": self.n_elements,
            "size": self.size,
        }

    def memory_estimate(self):
        from compact_distributions.cvt.resources import mosaic_estimate, run_estimate

        from ..sweep import memory_class

        if self.workload == "mosaic":
            return mosaic_estimate(
                self.size, self.size, self.n_elements, memory_class(self.backend), element=REFERENCE_SHAPE
            )
        from compact_distributions.baselines import get_method

        return run_estimate(
            self.size,
            self.size,
            self.n_elements,
            memory_class(self.backend),
            element=REFERENCE_SHAPE,
            method=get_method(self.workload),
            what=f"the run {self.describe()}",
        )

    def argv(self, out: Path) -> list[str]:
        """The command line of this configuration, writing into ``out``."""
        common = ["--elements", str(self.n_elements), "--backend", self.backend, "--quiet", "--out", str(out)]
        if self.workload == "mosaic":
            from .mosaic import SAMPLES_DIR

            return ["mosaic", str(SAMPLES_DIR / SAMPLE), "--size", str(self.size), *common]
        return [
            "run",
            "--method",
            self.workload,
            "--element",
            REFERENCE_SHAPE,
            "--size",
            str(self.size),
            *common,
        ]

    def execute(self, backend) -> dict:
        """Run the command in a process of its own (its peak memory is its own)."""
        from ..outputs import machine, versions

        with tempfile.TemporaryDirectory(prefix="cvtbench-pipeline-") as tmp:
            out = Path(tmp) / "out"
            code, err, whole, peak = run_measured(
                ["-m", "compact_distributions.bench.commands.cli", *self.argv(out)]
            )
            if code != 0:
                raise RuntimeError(
                    f"`cvtbench {' '.join(self.argv(out))}` exited {code}: {err.strip()[-300:]}"
                )
            result = json.loads((out / "result.json").read_text())
        stages = result.get("stage_seconds", {})
        row = {
            "key": self.key,
            **self.params(),
            "status": "ok",
            "reason": "",
            "whole_seconds": whole,
            "peak_mb": peak / 2**20,
            "bytes_per_pixel": peak / self.size**2,
            **{f"{s}_seconds": float(stages[s]) if s in stages else np.nan for s in STAGES},
            "method_seconds": float(result["method_seconds"]),
            "coverage": float(result["coverage"]),
            "overlap": float(result["overlap"]),
            "device": result["device"],
        }
        return {
            "row": row,
            "stage_seconds": stages,
            "spec": asdict(self),
            "machine": machine(),
            "versions": versions(),
        }


@dataclass(frozen=True)
class PipelineRequest(options.SweepRequest):
    """``cvtbench pipeline``, typed: the workloads, backend variants and element counts
    to run (None: the defaults)."""

    workloads: tuple[str, ...] | None = None
    backends: tuple[str, ...] | None = None
    elements: tuple[int, ...] | None = None
    extra: dict = field(default_factory=dict)

    @classmethod
    def from_args(cls, args) -> PipelineRequest:
        counts = name_list(args.elements, "--elements")
        return cls(
            **cls.common(args),
            workloads=options.as_tuple(name_list(args.workloads, "--workloads", WORKLOADS)),
            backends=options.as_tuple(name_list(args.backends, "--backends", variant_names())),
            elements=None
            if counts is None
            else tuple(whole_number(c, "--elements", minimum=16, maximum=MAX_ELEMENTS) for c in counts),
        )


def add_parser(sub):
    p = sub.add_parser(
        "pipeline",
        help="time every stage of ours-compact and of a mosaic over N (reports/pipeline.md)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    options.add_sweep_options(p, f"N in {', '.join(map(str, QUICK_ELEMENTS))} only")
    p.add_argument("--workloads", default=None, help=f"comma list of {', '.join(WORKLOADS)} (default both)")
    # the option's name before 0.2; kept for one release
    p.add_argument("--kinds", dest="workloads", default=None, help=argparse.SUPPRESS)
    p.add_argument(
        "--backends",
        default=None,
        help=f"comma list of backend variants (default {', '.join(DEFAULT_BACKENDS)}, else numpy)",
    )
    p.add_argument(
        "--elements",
        default=None,
        help=f"comma list of element counts (default {', '.join(map(str, FULL_ELEMENTS))})",
    )
    options.add_memory_option(p)
    p.set_defaults(func=run)


def prepare(req: PipelineRequest) -> dict:
    """Every option, the report folder and each configuration's memory checked first."""
    from ..outputs import check_folder
    from ..sweep import check_memory

    check_folder(req.out)
    status = variant_status()
    workloads = [one_of(w, "--workloads", WORKLOADS) for w in req.workloads or WORKLOADS]
    default = req.backends or [first_available(DEFAULT_BACKENDS, status)]
    backends = [one_of(b, "--backends", variant_names()) for b in default]
    counts = list(req.elements or (QUICK_ELEMENTS if req.quick else FULL_ELEMENTS))
    suite = "pipeline-quick" if req.quick else "pipeline"
    specs = [
        PipelineSpec(suite, k, b, n, raster_side(n)) for k in workloads for b in backends for n in counts
    ]
    check_memory(specs, req.memory_limit, lower="leave it out (fewer or smaller --elements)")
    return {"specs": specs, "unavailable": {v: text for v, (ok, text) in status.items() if not ok}}


def run(args) -> int:
    return pipeline(PipelineRequest.from_args(args))


def pipeline(req: PipelineRequest) -> int:
    """Run every configuration and write the report (what ``cvtbench pipeline`` does)."""
    import pandas as pd

    from ..outputs import report_folder
    from ..report import provenance, write_csv, write_markdown, written_files
    from ..sweep import check_runs, run_sweep

    t0 = time.perf_counter()
    plan = prepare(req)
    cmd = req.command or "cvtbench pipeline" + (" --quick" if req.quick else "")
    with report_folder(req.out, command=cmd):
        # runs are timed one at a time: each owns the machine while it runs
        rows = run_sweep(
            plan["specs"], req.out, force=req.force, quiet=req.quiet, unavailable=plan["unavailable"]
        )
        table = pd.DataFrame(rows)
        for c in COLUMNS:
            if c not in table:
                table[c] = np.nan
        table = table[COLUMNS]
        elapsed = time.perf_counter() - t0
        plotted = render_plot(table, req.out / "pipeline.png")
        write_csv(req.out / "pipeline.csv", table)
        write_markdown(req.out / "pipeline.md", render_markdown(table, provenance(), cmd, elapsed, plotted))
        written = written_files(req.out, ["pipeline.md", "pipeline.csv", "pipeline.png"])
    print(f"wrote {req.out}/{', '.join(written)} ({elapsed:.0f} s)", file=sys.stderr)
    check_runs(plan["specs"], rows, "pipeline")  # a failed configuration fails the command
    return 0


def growth_exponent(n, seconds) -> float:
    """The slope of log(seconds) against log(N) (least squares): 1 is linear growth."""
    n, seconds = np.asarray(n, dtype=float), np.asarray(seconds, dtype=float)
    ok = np.isfinite(seconds) & (seconds > 0)
    if ok.sum() < 2 or np.ptp(n[ok]) == 0:
        return float("nan")
    return float(np.polyfit(np.log(n[ok]), np.log(seconds[ok]), 1)[0])


def render_markdown(table, prov: dict, command: str, elapsed: float, plotted: bool) -> str:
    from ..report import fmt_seconds, header_markdown, markdown_table

    notes = [
        "each configuration is the whole command run in its own process: `cvtbench run --method ours-compact "
        "--element square` (20 Lloyd iterations) or `cvtbench mosaic samples/scene.jpg` resampled to the raster",
        "raster: 512² per 1000 elements, about 16 px cells (512² for N = 1000 ... 4096² for N = 64 000)",
        "whole: the command's wall time (start-up, reading, the method, evaluation, writing); peak: the "
        "process's own maximum resident memory (VmHWM after exec); stages: result.json's stage_seconds",
        "growth: the slope of log(seconds) against log(N) over the rows run (1 = linear)",
        f"this command took {fmt_seconds(elapsed)}",
    ]
    text = header_markdown("Pipeline: the whole method, stage by stage", prov, command, notes)
    ok = table[table["status"] == "ok"]
    cols = ["workload", "backend", "N", "raster", "whole", "peak", "B/px", *STAGES, "coverage"]
    body = [
        [
            r["workload"],
            r["backend"],
            int(r["n_elements"]),
            f"{int(r['size'])}²",
            fmt_seconds(r["whole_seconds"]),
            f"{r['peak_mb']:.0f} MB",
            f"{r['bytes_per_pixel']:.0f}",
            *(fmt_seconds(r[f"{s}_seconds"]) if np.isfinite(r[f"{s}_seconds"]) else "–" for s in STAGES),
            f"{100 * r['coverage']:.1f} %",
        ]
        for _, r in ok.iterrows()
    ]
    text += "\n" + markdown_table(cols, body)
    growth = []
    for (workload, backend), g in ok.groupby(["workload", "backend"], sort=False):
        parts = [f"whole {growth_exponent(g['n_elements'], g['whole_seconds']):.2f}"]
        parts += [
            f"{s} {e:.2f}"
            for s in STAGES
            if np.isfinite(e := growth_exponent(g["n_elements"], g[f"{s}_seconds"]))
        ]
        growth.append([workload, backend, ", ".join(parts)])
    if growth:
        text += "\n## How each stage grows with N\n\n" + markdown_table(
            ["workload", "backend", "exponent"], growth
        )
    bad = table[table["status"] != "ok"]
    if len(bad):
        text += "\n## Not run or failed\n\n" + markdown_table(
            ["workload", "backend", "N", "status", "reason"],
            [
                [r["workload"], r["backend"], r["n_elements"], r["status"], r["reason"]]
                for _, r in bad.iterrows()
            ],
        )
    if plotted:
        text += "\n![seconds and peak memory against N](pipeline.png)\n"
    return text


def render_plot(table, path: Path) -> bool:
    """Log-log: per workload and backend, seconds against N for each stage and the whole
    command; and peak memory against N."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..report import save_figure

    ok = table[table["status"] == "ok"]
    groups = list(ok.groupby(["workload", "backend"], sort=False))
    if not groups:
        path.unlink(missing_ok=True)
        return False
    fig, axes = plt.subplots(
        1,
        len(groups) + 1,
        figsize=(4.6 * (len(groups) + 1), 4.2),
        dpi=110,
        layout="constrained",
        squeeze=False,
    )
    for ax, ((workload, backend), g) in zip(axes[0], groups, strict=False):
        g = g.sort_values("n_elements")
        ax.plot(g["n_elements"], g["whole_seconds"], "k-o", lw=2, label="whole command")
        for s in STAGES:
            y = g[f"{s}_seconds"]
            if np.isfinite(y).any():
                ax.plot(g["n_elements"], y, "-o", ms=3, label=s)
        ax.set(
            xscale="log",
            yscale="log",
            xlabel="N (elements)",
            ylabel="seconds",
            title=f"{workload}, {backend}",
        )
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    mem = axes[0][-1]
    for (workload, backend), g in groups:
        g = g.sort_values("n_elements")
        mem.plot(g["n_elements"], g["peak_mb"], "-o", label=f"{workload}, {backend}")
    mem.set(xscale="log", yscale="log", xlabel="N (elements)", ylabel="peak memory (MB)", title="peak memory")
    mem.grid(True, which="both", alpha=0.3)
    mem.legend(fontsize=7)
    save_figure(fig, path)
    plt.close(fig)
    return True


__all__ = [
    "run_measured",
    "PEAK_LAUNCHER",
    "PipelineSpec",
    "PipelineRequest",
    "pipeline",
    "prepare",
    "raster_side",
    "growth_exponent",
    "run",
]
