"""`cvtbench reproduce`: every table and figure of the suite, in one command.

Runs, in order, `cvtbench table2`, `cvtbench table3`, `cvtbench backends`, `cvtbench pipeline`,
`cvtbench converge` and `cvtbench figures` (which
includes the mosaic Figures 18-19), each into the same report folder, then writes ``OUT/reproduce.md``: what ran, how long each part took, and
the machine, devices, versions and commit.  ``--quick`` runs the quick form of each
(under 5 minutes on 2 cores) into ``reports/quick``; the full form writes ``reports``.
Like its parts it resumes: runs whose raw json exists are read back unless --force.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .. import options


def add_parser(sub):
    p = sub.add_parser(
        "reproduce",
        help="table2 + table3 + backends + pipeline + converge + figures into reports/",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    options.add_sweep_options(p, "the quick form of every part (< 5 min on 2 cores)")
    options.add_seeds_option(p, "table2's and table3's: default 5; quick 2")
    options.add_cluster_options(p, exclusive=True)
    options.add_memory_option(p)
    p.set_defaults(func=run)


def requests(args, out: Path, scheduler: str | None) -> list[tuple[str, object, object]]:
    """(name, work function, typed request) of each part, from reproduce's own options."""
    from ..table2 import FULL, QUICK, Table2Request, table2
    from ..table3 import Table3Request, table3
    from .backends import BackendsRequest, backends
    from .converge import ConvergeRequest, converge
    from .figures import FiguresRequest, figures
    from .pipeline import PipelineRequest, pipeline

    common = dict(
        quick=bool(args.quick),
        force=bool(args.force),
        quiet=bool(args.quiet),
        scheduler=scheduler,
        memory_limit=args.memory_limit,
    )
    seeds = options.seeds_value(args.seeds, (QUICK if args.quick else FULL)["seeds"])
    quick = " --quick" if args.quick else ""
    return [
        (
            "table2",
            table2,
            Table2Request(
                out=out,
                **common,
                exclusive=bool(args.exclusive),
                seeds=seeds,
                command=f"cvtbench table2{quick} --out {out}",
            ),
        ),
        (
            "table3",
            table3,
            Table3Request(
                out=out,
                **common,
                seeds=int(args.seeds) if args.seeds else None,
                command=f"cvtbench table3{quick} --out {out}",
            ),
        ),
        (
            "backends",
            backends,
            BackendsRequest(out=out, **common, command=f"cvtbench backends{quick} --out {out}"),
        ),
        (
            "pipeline",
            pipeline,
            PipelineRequest(out=out, **common, command=f"cvtbench pipeline{quick} --out {out}"),
        ),
        (
            "converge",
            converge,
            ConvergeRequest(out=out, **common, command=f"cvtbench converge{quick} --out {out}"),
        ),
        (
            "figures",
            figures,
            FiguresRequest(
                out=out / "figures",
                quick=bool(args.quick),
                quiet=bool(args.quiet),
                command=f"cvtbench figures{quick} --out {out / 'figures'}",
            ),
        ),
    ]


def run(args) -> int:
    from ..cluster import chosen, scheduler_address
    from ..outputs import command_line, report_folder
    from ..table2 import prepare as prepare_table2
    from ..table3 import check as prepare_table3
    from .backends import prepare as prepare_backends
    from .converge import prepare as prepare_converge
    from .figures import prepare as prepare_figures
    from .pipeline import prepare as prepare_pipeline

    chosen(args)  # bad cluster options fail before anything starts
    out = options.report_out(args)
    # every part's options, its output folder and the memory of its runs are checked
    # before the first one starts
    checks = {
        "table2": prepare_table2,
        "table3": prepare_table3,
        "backends": prepare_backends,
        "pipeline": prepare_pipeline,
        "converge": prepare_converge,
        "figures": prepare_figures,
    }
    for name, _, request in requests(args, out, None):
        checks[name](request)
    cmd = command_line(getattr(args, "argv", None) or ["reproduce"] + (["--quick"] if args.quick else []))
    # with --workers one local cluster serves every part
    with report_folder(out, command=cmd), scheduler_address(args) as address:
        return _run_parts(requests(args, out, address), out, cmd, args.quick)


def _run_parts(parts, out: Path, cmd: str, quick: bool) -> int:
    from ..report import header_markdown, markdown_table, provenance, write_markdown

    results = []
    t_all = time.perf_counter()
    status = 0
    for name, work, request in parts:
        print(f"reproduce: {name} ...", file=sys.stderr)
        t0 = time.perf_counter()
        try:
            rc = int(work(request) or 0)
            note = f"exit status {rc}" if rc else f"`{request.command}`"
        except KeyboardInterrupt:
            raise
        except Exception as exc:  # one broken part must not hide the others' results
            rc, note = 1, f"{type(exc).__name__}: {exc}"
            print(f"reproduce: {name} failed: {note}", file=sys.stderr)
        results.append((name, "ok" if rc == 0 else "failed", time.perf_counter() - t0, note))
        status = status or rc
    total = time.perf_counter() - t_all
    text = header_markdown(
        "Reproduce" + (" (QUICK)" if quick else ""),
        provenance(),
        cmd,
        [
            f"total: {total:.0f} s on this machine (runs read back from raw/ take ~0 s; "
            "--force for a cold run)"
        ],
    )
    text += "\n" + markdown_table(
        ["part", "status", "seconds", "command / note"],
        [[n, s, f"{t:.0f}", note] for n, s, t, note in results],
    )
    write_markdown(out / "reproduce.md", text)
    print(f"reproduce: done in {total:.0f} s; summary in {out}/reproduce.md", file=sys.stderr)
    return status


__all__ = ["add_parser", "requests", "run"]
