"""`cvtbench reproduce`: every table and figure of the suite, in one command.

Runs, in order, `cvtbench table2`, `cvtbench table3`, `cvtbench backends` and `cvtbench figures` (which
includes the mosaic Figures 18-19), each into the same report folder, then writes ``OUT/reproduce.md``: what ran, how long each part took, and
the machine, devices, versions and commit.  ``--quick`` runs the quick form of each
(under 5 minutes on 2 cores) into ``reports/quick``; the full form writes ``reports``.
Like its parts it resumes: runs whose raw json exists are read back unless --force.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path

from . import options


def add_parser(sub):
    p = sub.add_parser("reproduce", help="table2 + table3 + backends + figures into reports/",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    options.add_sweep_options(p, "the quick form of every part (< 5 min on 2 cores)")
    options.add_seeds_option(p, "table2's and table3's: default 5; quick 2")
    options.add_cluster_options(p, exclusive=True)
    options.add_memory_option(p)
    p.set_defaults(func=run)


def _sub_args(module_name: str, argv: list[str]):
    """Parse ``argv`` with the subcommand's own parser, so its defaults apply; options
    the subcommand does not have are dropped (with their values)."""
    mod = importlib.import_module(module_name)
    parser = argparse.ArgumentParser(prog="cvtbench")
    sub = parser.add_subparsers(dest="command")
    mod.add_parser(sub)
    p = sub.choices[next(iter(sub.choices))]
    known = set(p._option_string_actions)
    kept, i = [argv[0]], 1
    while i < len(argv):
        opt = argv[i]
        action = p._option_string_actions.get(opt)
        if action is not None:
            takes_value = action.nargs != 0
        else:
            takes_value = i + 1 < len(argv) and not argv[i + 1].startswith("--")
        if opt in known:
            kept.append(opt)
            if takes_value:
                kept.append(argv[i + 1])
        i += 2 if takes_value else 1
    args = parser.parse_args(kept)
    args.argv = kept
    return args


def run(args) -> int:
    from .cluster import chosen, scheduler_address
    from .outputs import command_line, report_folder

    chosen(args)  # bad cluster options fail before anything starts
    out = options.report_out(args)
    # every part's options, its output folder and the memory of its runs are checked
    # before the first one starts
    options.seeds_value(args.seeds, 1)
    for _, module, argv in _parts(args, out, None):
        importlib.import_module(module).prepare(_sub_args(module, argv))
    cmd = command_line(getattr(args, "argv", None) or ["reproduce"] + (["--quick"] if args.quick else []))
    # with --workers one local cluster serves every part
    with report_folder(out, command=cmd), scheduler_address(args) as address:
        parsed = [(name, _sub_args(module, argv)) for name, module, argv in _parts(args, out, address)]
        return _run_parts(parsed, out, cmd, args.quick)


def _parts(args, out: Path, address: str | None) -> list:
    """(name, module, argv) of each part."""
    common = (["--quick"] if args.quick else []) + (["--force"] if args.force else []) + \
        (["--quiet"] if args.quiet else []) + (["--scheduler", address] if address else []) + \
        (["--memory-limit", args.memory_limit] if args.memory_limit is not None else [])
    return [
        ("table2", "compact_distributions.bench.table2", ["table2", "--out", str(out)] + common
         + (["--seeds", str(args.seeds)] if args.seeds else []) + (["--exclusive"] if args.exclusive else [])),
        ("table3", "compact_distributions.bench.table3", ["table3", "--out", str(out)] + common
         + (["--seeds", str(args.seeds)] if args.seeds else [])),
        ("backends", "compact_distributions.bench.backends_cmd", ["backends", "--out", str(out)] + common),
        ("figures", "compact_distributions.bench.figures_cmd",
         ["figures", "--out", str(out / "figures")] + [a for a in common if a != "--force"]),
    ]


def _run_parts(parsed, out: Path, cmd: str, quick: bool) -> int:
    from .outputs import command_line
    from .report import header_markdown, markdown_table, provenance, write_markdown

    results = []
    t_all = time.perf_counter()
    status = 0
    for name, sub_args in parsed:
        print(f"reproduce: {name} ...", file=sys.stderr)
        t0 = time.perf_counter()
        try:
            rc = int(sub_args.func(sub_args) or 0)
            note = f"exit status {rc}" if rc else "`" + command_line(sub_args.argv) + "`"
        except KeyboardInterrupt:
            raise
        except Exception as exc:  # one broken part must not hide the others' results
            rc, note = 1, f"{type(exc).__name__}: {exc}"
            print(f"reproduce: {name} failed: {note}", file=sys.stderr)
        results.append((name, "ok" if rc == 0 else "failed", time.perf_counter() - t0, note))
        status = status or rc
    total = time.perf_counter() - t_all
    text = header_markdown("Reproduce" + (" (QUICK)" if quick else ""), provenance(), cmd,
                           [f"total: {total:.0f} s on this machine (runs read back from raw/ take ~0 s; "
                            "--force for a cold run)"])
    text += "\n" + markdown_table(["part", "status", "seconds", "command / note"],
                                  [[n, s, f"{t:.0f}", note] for n, s, t, note in results])
    write_markdown(out / "reproduce.md", text)
    print(f"reproduce: done in {total:.0f} s; summary in {out}/reproduce.md", file=sys.stderr)
    return status
