"""`cvtbench`: the command line of the suite.

Each subcommand lives in its own module with ``add_parser(subparsers)``; the module
sets ``func`` on its parser.  Errors in user input print one line and exit with 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from compact_distributions.cvt.errors import BackendUnavailable, InputError

# subcommand modules, in the order `cvtbench --help` lists them
SUBCOMMANDS = ["compact_distributions.bench.run_cmd", "compact_distributions.bench.info_cmd", "compact_distributions.bench.figures_cmd", "compact_distributions.bench.table2", "compact_distributions.bench.mosaic_cmd", "compact_distributions.bench.backends_cmd", "compact_distributions.bench.regress_cmd", "compact_distributions.bench.reproduce_cmd"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cvtbench",
        description="Compact distributions of discrete elements (Chen, Yang & Yang 2019): "
        "CVTs under shape metrics on NumPy, OpenCL and GL backends, with baselines and reports.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in SUBCOMMANDS:
        importlib.import_module(name).add_parser(sub)
    return parser


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = argv
    try:
        return int(args.func(args) or 0)
    except (InputError, BackendUnavailable) as exc:
        print(f"cvtbench: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("cvtbench: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
