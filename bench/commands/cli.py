"""`cvtbench`: the command line of the suite.

Each subcommand lives in its own module with ``add_parser(subparsers)``; the module
sets ``func`` on its parser.  Errors in user input print one line and exit with 2; a
command that could not finish for another reason (a plug-in that failed, runs of a sweep
that failed, a lost cluster) prints one line and exits with 1 (``--verbose`` adds the
traceback).
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import sys
import traceback

from compact_distributions.cvt.errors import BackendUnavailable, InputError, RunAborted
from compact_distributions.cvt.quiet import configure as configure_output

# subcommand modules, in the order `cvtbench --help` lists them
SUBCOMMANDS = [
    "compact_distributions.bench.commands.run",
    "compact_distributions.bench.commands.info",
    "compact_distributions.bench.commands.figures",
    "compact_distributions.bench.commands.table2",
    "compact_distributions.bench.commands.table3",
    "compact_distributions.bench.commands.mosaic",
    "compact_distributions.bench.commands.backends",
    "compact_distributions.bench.commands.pipeline",
    "compact_distributions.bench.commands.converge",
    "compact_distributions.bench.commands.regress",
    "compact_distributions.bench.commands.reproduce",
]


class Parser(argparse.ArgumentParser):
    """argparse with the suite's one-line errors (the usage is under --help)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("compact-distributions")
    except PackageNotFoundError:
        return "0+unknown"


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="cvtbench",
        description="Compact distributions of discrete elements (Chen, Yang & Yang 2019): "
        "CVTs under shape metrics on NumPy, OpenCL and GL backends, with baselines and reports.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in SUBCOMMANDS:
        importlib.import_module(name).add_parser(sub)
    for p in sub.choices.values():  # every command: the same pair, third-party output off by default
        p.add_argument(
            "--verbose",
            action="store_true",
            help="also show the warnings and log records of the libraries the suite uses",
        )
        if "--quiet" not in p._option_string_actions:
            p.add_argument("--quiet", action="store_true", help="no progress output")
    return parser


def _say(text: str) -> None:
    """One line on stderr, if anyone still reads it."""
    try:
        print(text, file=sys.stderr, flush=True)
    except OSError:
        pass


def _silence(stream) -> None:
    """Point a stream whose reader is gone at /dev/null, so that the interpreter's last
    flush does not fail again."""
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), stream.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def main(argv=None) -> int:
    # a closed standard stream (`cvtbench info >&-`) reads as None: write nowhere instead
    for name in ("stdout", "stderr"):
        if getattr(sys, name) is None:
            setattr(sys, name, open(os.devnull, "w"))
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        args.argv = argv
        configure_output(verbose=args.verbose)
        code = int(args.func(args) or 0)
        sys.stdout.flush()  # a broken pipe shows here, not in the interpreter's last flush
        return code
    except (InputError, BackendUnavailable) as exc:
        _say(f"cvtbench: error: {exc}")
        return 2
    except RunAborted as exc:  # a plug-in that failed (PluginError), a lost cluster, failed runs
        if "--verbose" in argv:  # the traceback of what went wrong, then the one line
            traceback.print_exception(exc.__cause__ or exc, file=sys.stderr)
        _say(f"cvtbench: {exc}")
        return 1
    except KeyboardInterrupt:
        _say("cvtbench: interrupted")
        return 130
    except SystemExit as exc:  # --help, or an argparse error (its one line is on stderr)
        try:
            sys.stdout.flush()
        except OSError:
            _silence(sys.stdout)
        return exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    except BrokenPipeError:  # the reader left (`cvtbench info | head -1`): end quietly
        _silence(sys.stdout)
        return 141  # what a shell reports for a program ended by SIGPIPE
    except OSError as exc:
        if exc.errno not in (errno.ENOSPC, errno.EIO, errno.EBADF) or exc.filename:
            raise
        _silence(sys.stdout)
        _say(f"cvtbench: error: cannot write the output ({exc.strerror})")
        return 1


__all__ = ["SUBCOMMANDS", "Parser", "build_parser", "main"]


if __name__ == "__main__":
    sys.exit(main())
