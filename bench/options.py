"""Command-line options shared by the subcommands: one definition each, so that the same
option has the same name, type and meaning in every command (``--element`` is a shape,
``--elements N`` a count, ``--shapes`` a list of shapes, ``--backend`` a backend or
variant name).  Values arrive as strings and are parsed by
:mod:`compact_distributions.cvt.validate`, which the Python API uses too.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

from compact_distributions.backends import REGISTRY, VARIANTS, create_backend, resolve
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.metrics import DEFAULT_ELEMENT, ELEMENT_METRIC, METRIC_NAMES
from compact_distributions.cvt.shapes import ELEMENT_SHAPES
from compact_distributions.cvt.validate import whole_number

BACKEND_NAMES = list(dict.fromkeys([*REGISTRY, *VARIANTS]))
SIZE_HELP = (
    "raster: WxH, or N for the long side (the other side follows the picture's aspect; "
    "square when there is no picture)"
)


# ------------------------------------------------------------------ one run
def add_backend_options(p, default: str = "numpy") -> None:
    p.add_argument(
        "--backend",
        default=default,
        help=f"{', '.join(BACKEND_NAMES)} (default {default}; numpy is the float64 reference; gl is gl-cone)",
    )
    p.add_argument(
        "--gl-mode",
        default=None,
        choices=["cone", "exact"],
        help="gl backend: cone (the paper's cones and pyramids, default) or exact (per-fragment "
        "metric); the same as --backend gl-cone / gl-exact",
    )
    p.add_argument(
        "--device",
        default=None,
        help="OpenCL device as PLATFORM[:DEVICE] indices, like PYOPENCL_CTX (opencl backend)",
    )


def backend_choice(args) -> tuple[str, dict]:
    """(registry name, constructor options) from --backend, --gl-mode and --device."""
    name, options = resolve(args.backend)
    if args.gl_mode is not None:
        if name != "gl":
            raise InputError(f"--gl-mode is for the gl backend, not {args.backend!r}")
        if options.get("mode", args.gl_mode) != args.gl_mode:
            raise InputError(f"--backend {args.backend} and --gl-mode {args.gl_mode} disagree")
        options["mode"] = args.gl_mode
    if args.device is not None:
        if name != "opencl":
            raise InputError(f"--device is for the opencl backend, not {args.backend!r}")
        options["device"] = args.device
    return name, options


def open_backend(args):
    """The backend the options name, started (BackendUnavailable if it cannot start)."""
    name, options = backend_choice(args)
    return create_backend(name, **options)


def add_shape_options(p, default_element: str = DEFAULT_ELEMENT) -> None:
    """``--metric``, ``--element`` (either implies the other; neither: ``default_element``)
    and ``--aspect``."""
    p.add_argument(
        "--metric",
        default=None,
        help=f"Lloyd distance: {', '.join(METRIC_NAMES)} (default: the element's own; neither "
        f"given: {ELEMENT_METRIC[default_element]})",
    )
    p.add_argument(
        "--element",
        metavar="SHAPE",
        default=None,
        help=f"element placed in each cell: {', '.join(ELEMENT_SHAPES)} (default: the metric's own; "
        f"neither given: {default_element}s)",
    )
    p.add_argument(
        "--aspect",
        default=None,
        help="β of rectangles and ellipses and of the axial metrics (default 0.5); > 0",
    )


def add_method_option(p, default: str = "ours", several: bool = False) -> None:
    """``--method`` (or, with ``several``, nothing: the sweeps have ``--methods``) and one
    option per distinct option that a registered method declares, with its help; which
    method takes it is checked by :func:`method_options`."""
    from compact_distributions.cvt.registry import methods

    records = methods()
    if not several:
        p.add_argument(
            "--method",
            default=default,
            help="; ".join(f"{m.name}: {m.summary}" if m.summary else m.name for m in records.values())
            + f" (cvtbench info lists them; default {default})",
        )
    seen = {}
    for m in records.values():
        for opt in m.options:
            if opt.name in seen:
                seen[opt.name].append(m.name)
                continue
            seen[opt.name] = [m.name]
            dest = f"method_option_{opt.name}"
            if opt.kind is bool:
                p.add_argument(opt.flag, dest=dest, action="store_true", default=None, help=opt.help)
            else:
                p.add_argument(opt.flag, dest=dest, default=None, metavar=opt.name.upper(), help=opt.help)
    for action in p._actions:  # say which methods take each option
        name = (action.dest or "").removeprefix("method_option_")
        if action.dest.startswith("method_option_") and name in seen:
            action.help = f"{action.help} [--method {' / '.join(seen[name])}]"


def given_method_options(args) -> dict:
    """The method options set on the command line, by option name (unset ones left out)."""
    return {
        k.removeprefix("method_option_"): v
        for k, v in vars(args).items()
        if k.startswith("method_option_") and v is not None
    }


def options_for(record, given: dict | None) -> dict:
    """The options of ``given`` (name -> value, as a sweep's command line sets them for
    every method) that ``record`` declares, parsed (``--NAME`` in messages).

    Parameters
    ----------
    record : Method
        The method's record.
    given : dict or None
        Option name -> value.

    Returns
    -------
    dict
        Option name -> parsed value, for the options the method declares.
    """
    return record.parse_options({k: v for k, v in (given or {}).items() if record.option(k)}, flags=True)


def check_method_options(given: dict, methods: list[str]) -> None:
    """InputError where an option of a sweep's command line is declared by none of the
    methods it runs (it would change nothing).

    Parameters
    ----------
    given : dict
        Option name -> value, as set on the command line.
    methods : list of str
        The methods the sweep runs.
    """
    from compact_distributions.cvt.registry import get_method

    for name in given:
        if not any(get_method(m).option(name) for m in methods):
            raise InputError(
                f"--{name.replace('_', '-')} is an option of none of --methods {','.join(methods)}"
            )


def method_options(args, method=None) -> dict:
    """The method's own keywords from the command line, checked against ``method`` (the
    record, default ``--method``'s): an option it does not declare is refused."""
    from compact_distributions.cvt.registry import get_method

    method = get_method(args.method if method is None else method)
    return method.parse_options(given_method_options(args), flags=True)


def add_run_options(p, iterations: int = 20, seed_help: str = "random seed (default 0)") -> None:
    p.add_argument(
        "--iterations",
        default=str(iterations),
        help=f"Lloyd iterations (default {iterations}; 0 allowed); with --tolerance, their cap",
    )
    p.add_argument("--seed", default="0", help=seed_help)


def add_output_options(p, out_default: str) -> None:
    p.add_argument("--out", default=out_default, help=f"output folder (default {out_default})")
    p.add_argument("--quiet", action="store_true", help="no progress output")


def progress_printer(quiet: bool):
    """A Lloyd progress callback ``(k, total, energy)`` that prints to stderr (None when
    quiet): one updating line on a terminal, ten lines otherwise."""
    if quiet:
        return None
    start = time.perf_counter()

    def report(k, total, energy):
        elapsed = time.perf_counter() - start
        tty = sys.stderr.isatty()
        if tty or k == total or k % max(1, total // 10) == 0:
            print(
                f"\riteration {k}/{total}  energy {energy:.4g} px²  {elapsed:.1f} s",
                end="\n" if k == total or not tty else "",
                file=sys.stderr,
                flush=True,
            )

    return report


# ------------------------------------------------------------------ sweeps
def report_out(args) -> Path:
    """A sweep's report folder: ``--out``, else reports (reports/quick with --quick)."""
    return Path(args.out) if args.out else (Path("reports/quick") if args.quick else Path("reports"))


@dataclass(frozen=True)
class SweepRequest:
    """What every sweep command is asked, typed: the report folder, the quick form, redo
    stored runs, progress, where the runs go (a Dask ``scheduler`` address, or a local
    cluster of ``workers`` processes, or neither: in-process; ``exclusive``: one run per
    host at a time), the memory limit, and the command line the reports record.  Each
    sweep command's work is a function of its request (a subclass), which
    ``cvtbench reproduce`` and the tests call directly; the argparse layer only builds it."""

    out: Path
    quick: bool = False
    force: bool = False
    quiet: bool = False
    scheduler: str | None = None
    workers: int | None = None
    exclusive: bool = False
    memory_limit: str | int | None = None
    command: str | None = None

    @staticmethod
    def common(args) -> dict:
        """The shared fields from a parsed command line."""
        workers = getattr(args, "workers", None)
        return dict(
            out=report_out(args),
            quick=bool(args.quick),
            force=bool(getattr(args, "force", False)),
            quiet=bool(args.quiet),
            scheduler=getattr(args, "scheduler", None),
            workers=None if workers is None else whole_number(workers, "--workers", minimum=1),
            exclusive=bool(getattr(args, "exclusive", False)),
            memory_limit=getattr(args, "memory_limit", None),
            command=command_text(getattr(args, "argv", None)),
        )


def as_tuple(items) -> tuple | None:
    """A parsed list option as a request field (None stays None: the default)."""
    return None if items is None else tuple(items)


def command_text(argv) -> str | None:
    """The command line a report records (None: the request's own)."""
    from .outputs import command_line

    return command_line(argv) if argv else None


def add_sweep_options(p, quick_help: str) -> None:
    p.add_argument("--quick", action="store_true", help=quick_help)
    p.add_argument("--force", action="store_true", help="re-run runs whose raw json exists")
    p.add_argument(
        "--out", default=None, help="report folder (default reports, or reports/quick with --quick)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def add_cluster_options(p, exclusive: bool = False) -> None:
    """Where a sweep's runs go: a Dask cluster (--scheduler), a local one (--workers), or
    in-process (neither).  ``exclusive``: also offer --exclusive (table2's time columns)."""
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="run on the Dask cluster of this scheduler, e.g. tcp://10.0.0.5:8786 (needs the cluster extra)",
    )
    p.add_argument(
        "--workers",
        metavar="N",
        default=None,
        help="run on a local Dask cluster of N worker processes (needs the cluster extra)",
    )
    if exclusive:
        p.add_argument(
            "--exclusive",
            action="store_true",
            help="with --scheduler/--workers: each run has its host to itself, so its time is "
            "not shared with other runs (fewer runs at once)",
        )


def add_seeds_option(p, default_text: str = "default 5; quick 2") -> None:
    p.add_argument(
        "--seeds", default=None, help=f"number of seeds K (1 to 1000): seeds 0..K-1 ({default_text})"
    )


def add_list_options(p, *names: str) -> None:
    """Comma-list options of the sweeps: methods, backends, shapes, metrics."""
    helps = {
        "methods": "comma list of methods (default: all registered)",
        "backends": "comma list of backend variants (default: every variant that computes every metric)",
        "shapes": f"comma list of element shapes ({', '.join(ELEMENT_SHAPES)}, or polygon:FILE; default the paper's five)",
        "metrics": f"comma list of metrics ({', '.join(METRIC_NAMES)})",
    }
    for name in names:
        p.add_argument(f"--{name}", default=None, help=helps[name])


def shape_names(items, name: str = "--shapes") -> list[str] | None:
    """Element shapes of a sweep, checked as ``run --element`` checks one: a built-in
    shape's name or the user's ``polygon:FILE`` (read and checked now), else InputError
    naming ``name``; a comma list (text) or a sequence; None stays None."""
    from compact_distributions.cvt.shapes import shape_record
    from compact_distributions.cvt.validate import name_list

    if items is None:
        return None
    listed = name_list(items, name) if isinstance(items, str) else list(items)
    return [shape_record(s, name).name for s in listed]


MAX_SEEDS = 1000


def seeds_value(text, default: int) -> int:
    return default if text is None else whole_number(text, "--seeds", minimum=1, maximum=MAX_SEEDS)


# ------------------------------------------------------------------ memory
def add_memory_option(p) -> None:
    p.add_argument(
        "--memory-limit",
        metavar="SIZE",
        default=None,
        help="memory this command may plan to use, e.g. 8G or 512M (default: what the machine "
        "has available now); a configuration estimated to need more is refused before it starts",
    )


__all__ = [
    "BACKEND_NAMES",
    "SIZE_HELP",
    "add_backend_options",
    "backend_choice",
    "open_backend",
    "add_shape_options",
    "add_method_option",
    "given_method_options",
    "options_for",
    "check_method_options",
    "method_options",
    "add_run_options",
    "add_output_options",
    "progress_printer",
    "report_out",
    "SweepRequest",
    "as_tuple",
    "command_text",
    "add_sweep_options",
    "add_cluster_options",
    "add_seeds_option",
    "add_list_options",
    "shape_names",
    "MAX_SEEDS",
    "seeds_value",
    "add_memory_option",
]
