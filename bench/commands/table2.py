"""``cvtbench table2``: the paper's Table 2 regenerated (the sweep and the report are
:mod:`compact_distributions.bench.table2`)."""

from __future__ import annotations

import argparse

from .. import options
from ..table2 import Table2Request, table2
from ..table2 import __doc__ as TABLE2_DOC


def add_parser(sub):
    p = sub.add_parser(
        "table2",
        help="regenerate the paper's Table 2 into reports/",
        description=TABLE2_DOC,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    options.add_sweep_options(p, "small version (256² px, N=250, 2 seeds): < 2 min")
    options.add_seeds_option(p)
    options.add_list_options(p, "methods", "backends", "shapes")
    options.add_method_option(p, several=True)
    options.add_cluster_options(p, exclusive=True)
    options.add_memory_option(p)
    p.set_defaults(func=run)


def run(args) -> int:
    return table2(Table2Request.from_args(args))


__all__ = ["add_parser", "run"]
