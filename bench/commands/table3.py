"""``cvtbench table3``: Table 3 under density, direction and region (the sweep and the
report are :mod:`compact_distributions.bench.table3`)."""

from __future__ import annotations

import argparse

from .. import options
from ..table3 import SCENES, prepare, run_table3
from ..table3 import __doc__ as TABLE3_DOC


def add_parser(sub):
    p = sub.add_parser(
        "table3",
        help="Table 3: density, direction and region, with fidelity measures",
        description=TABLE3_DOC,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    options.add_sweep_options(p, "small version (192² px, N=150, 2 seeds)")
    options.add_seeds_option(p)
    options.add_list_options(p, "methods", "shapes")
    options.add_method_option(p, several=True)
    p.add_argument("--scenes", default=None, help=f"comma list of scenes (default all: {', '.join(SCENES)})")
    options.add_cluster_options(p)
    options.add_memory_option(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..outputs import command_line

    cmd = command_line(getattr(args, "argv", None) or ["table3"] + (["--quick"] if args.quick else []))
    run_table3(**prepare(args), command=cmd)
    return 0


__all__ = ["add_parser", "run"]
