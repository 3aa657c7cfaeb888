"""Wall time of `cvtbench table2 --quick` in-process against `--workers 2` (a local Dask
cluster of two worker processes), each a cold command from a fresh process with --force,
as a user runs them; writes the result to reports/cluster.md.

    python tests/benchmarks/cluster_speedup.py [--workers 2] [--out reports/cluster.md]

Measured once per mode: the machine is shared, so the load average before each command
goes into the report with the times.  Both commands must give the same coverage and
overlap columns; the script says whether they did.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from compact_distributions.bench.outputs import command_line
from compact_distributions.bench.report import header_markdown, markdown_table, provenance, write_markdown

ROOT = Path(__file__).resolve().parents[2]
COLUMNS = ["method", "backend", "element", "coverage_mean", "coverage_sd", "overlap_mean", "overlap_sd"]


def timed(argv: list[str]) -> tuple[float, tuple[float, float, float]]:
    """(wall seconds of the command, load average just before it)."""
    load = os.getloadavg()
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0, load


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "reports" / "cluster.md"))
    args = ap.parse_args()
    exe = shutil.which("cvtbench", path=str(Path(sys.executable).parent)) or "cvtbench"
    base = ["table2", "--quick", "--force", "--quiet"]
    modes = [("in-process", []), (f"--workers {args.workers}", ["--workers", str(args.workers)])]
    results, tables = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name, extra in modes:
            out = Path(tmp) / name.strip("-").replace(" ", "")
            argv = base + ["--out", str(out)] + extra
            wall, load = timed([exe] + argv)
            results.append((name, command_line(argv[: -2 - len(extra)] + extra), wall, load))
            tables.append(pd.read_csv(out / "table2.csv")[COLUMNS])
            print(f"{name}: {wall:.1f} s (load {load[0]:.2f})", file=sys.stderr)
    same = tables[0].equals(tables[1])
    ratio = results[0][2] / results[1][2]
    text = header_markdown(
        "Sweeps on a local Dask cluster: table2 --quick",
        provenance(),
        "python tests/benchmarks/cluster_speedup.py"
        + (f" --workers {args.workers}" if args.workers != 2 else ""),
        [
            f"each command cold, in a fresh process, with --force (every run recomputed), into a temporary folder; "
            f"the --workers time includes starting the cluster and the imports in its {args.workers} worker processes",
            f"{os.cpu_count()} CPUs; load average (1, 5, 15 min) just before each command as shown: the machine is "
            "shared with other work, so the ratio holds for that load only",
            f"coverage and overlap columns of the two table2.csv: {'identical' if same else 'DIFFERENT'}",
        ],
    )
    text += "\n" + markdown_table(
        ["mode", "command", "wall time", "load before"],
        [
            [name, f"`{cmd}`", f"{wall:.1f} s", ", ".join(f"{x:.2f}" for x in load)]
            for name, cmd, wall, load in results
        ],
    )
    text += (
        f"\nSpeed-up of `--workers {args.workers}` over in-process: **{ratio:.2f}x** "
        f"(in-process wall time / cluster wall time).\n"
    )
    write_markdown(args.out, text)
    print(f"speed-up {ratio:.2f}x; wrote {args.out}", file=sys.stderr)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
