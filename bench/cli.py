"""`cvtbench`: the command line of the suite.

Each subcommand lives in its own module with ``add_parser(subparsers)``; the module
sets ``func`` on its parser.  Errors in user input print one line and exit with 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from cvt.errors import BackendUnavailable, InputError

# subcommand modules, in the order `cvtbench --help` lists them
SUBCOMMANDS = ["bench.run_cmd", "bench.info_cmd", "bench.figures_cmd", "bench.table2", "bench.mosaic_cmd", "bench.backends_cmd", "bench.regress_cmd", "bench.reproduce_cmd"]


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
