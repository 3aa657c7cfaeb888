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
import gc
import importlib
import os
import sys
import traceback
from collections.abc import Iterator
from contextlib import contextmanager

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


# the interpreter's first-generation threshold while a command runs: the commands make
# and drop many small containers (vertex lists, rows of text, colour tuples) while the
# imports have left tens of thousands of objects, and a first generation this large
# spares most of the full collections that walk them all
GC_FIRST_GENERATION = 10_000


@contextmanager
def _fewer_collections() -> Iterator[None]:
    """The garbage collector's first generation at least :data:`GC_FIRST_GENERATION`
    objects inside the block, as it was after."""
    before = gc.get_threshold()
    gc.set_threshold(max(before[0], GC_FIRST_GENERATION), *before[1:])
    try:
        yield
    finally:
        gc.set_threshold(*before)


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


class _Listed(Exception):
    """Raised by :class:`_HelpOnly` with the name and help a command's parser declares."""


class _HelpOnly:
    """Stands in for argparse's subparsers in a command's ``add_parser``: it records the
    command's name and one-line help and stops that call there, so that ``cvtbench
    --help`` lists every command without building its options (nor loading what they
    read, such as the method registry)."""

    def add_parser(self, name: str, **kwargs):
        raise _Listed(name, kwargs.get("help"))


def command_help(module: str) -> tuple[str, str | None]:
    """The name and one-line help of the command that ``module`` defines, read from its
    ``add_parser`` call without building its parser.

    Parameters
    ----------
    module : str
        A module of :data:`SUBCOMMANDS`.

    Returns
    -------
    tuple of (str, str or None)
        The command's name and its help.
    """
    try:
        importlib.import_module(module).add_parser(_HelpOnly())
    except _Listed as listed:
        return listed.args
    raise RuntimeError(f"{module}.add_parser never called add_parser")  # a programming error


def _chosen(argv) -> str | None:
    """The command that ``argv`` names: its first word that is no option (the top-level
    options, -h and --version, take no value), if it is a command's name."""
    word = next((a for a in argv if not a.startswith("-")), None)
    return word if word in {m.rsplit(".", 1)[1] for m in SUBCOMMANDS} else None


def build_parser(argv=None) -> argparse.ArgumentParser:
    """The parser of ``cvtbench``.

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments it will parse.  Given, only the parser of the command they name is
        built (the others are listed by their help alone, as ``--help`` shows them), so
        that one command loads only what its own options need; not given, every
        command's parser is built (what the documentation reads).

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = Parser(
        prog="cvtbench",
        description="Compact distributions of discrete elements (Chen, Yang & Yang 2019): "
        "CVTs under shape metrics on NumPy, OpenCL and GL backends, with baselines and reports.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    chosen = None if argv is None else _chosen(argv)
    for module in SUBCOMMANDS:
        if argv is None or module.rsplit(".", 1)[1] == chosen:
            importlib.import_module(module).add_parser(sub)
        elif chosen is None:  # --help, no command or an unknown one: the list of commands
            name, text = command_help(module)
            sub.add_parser(name, help=text)
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
        parser = build_parser(argv)
        args = parser.parse_args(argv)
        args.argv = argv
        configure_output(verbose=args.verbose)
        with _fewer_collections():
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


__all__ = [
    "SUBCOMMANDS",
    "GC_FIRST_GENERATION",
    "Parser",
    "build_parser",
    "command_help",
    "main",
]


if __name__ == "__main__":
    sys.exit(main())
