"""`cvtbench run`: one CVT (or baseline) run, written to ``--out DIR``.

DIR/result.json  the run: backend, device, metric, aspect, size, sites, angles, scales,
                 iterations, energy and seconds per iteration, versions, command, ...
DIR/sites.csv    x,y (pixel units), angle_deg, scale per site, in input order
DIR/cells.png    the final cells in distinct colours
DIR/elements.svg one closed path per placed element (viewBox in pixel units)
DIR/elements.png the same elements as a picture

result.json also holds the placement: ``element``, ``gap``, ``coverage``, ``overlap``
(cvt/evaluate.py), ``placed``, ``skipped``, ``empty_cells``, the smallest and
largest element area, and ``elements`` (per site its outline as [[x, y], ...], or null).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass

import numpy as np

from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.fields import DensityMap, DirectionField, angles_from_grey
from compact_distributions.cvt.metrics import DEFAULT_ELEMENT, Metric, make_metric
from compact_distributions.cvt.problem import Grid, Problem, parse_size
from compact_distributions.cvt.shapes import resolve_shapes
from compact_distributions.cvt.validate import whole_number

from .. import options

DEFAULT_SIZE = "512"
DEFAULT_ELEMENTS = 1000


def add_problem_arguments(p: argparse.ArgumentParser) -> None:
    """The options that define a Problem."""
    options.add_shape_options(p, default_element=DEFAULT_ELEMENT)
    p.add_argument("--elements", default=None, help=f"number of elements N (default {DEFAULT_ELEMENTS})")
    p.add_argument(
        "--size",
        default=DEFAULT_SIZE,
        help="raster: WxH, or N for the long side (the other side follows the aspect of the first "
        f"picture given: --density, --region or a --field image; square without one) (default {DEFAULT_SIZE})",
    )
    p.add_argument("--init", metavar="SITES.CSV", help="start from these sites (columns x,y in pixels)")
    p.add_argument(
        "--density", metavar="IMAGE", help="density image (bright = dense = small cells); resampled to --size"
    )
    p.add_argument(
        "--field",
        metavar="FIELD",
        help="direction field: constant:DEG, radial, circular, wave:PERIOD, or a grey "
        "image (0..255 -> 0..180 degrees)",
    )
    p.add_argument(
        "--region",
        metavar="MASK_IMAGE",
        help="region mask image (light or opaque = inside); resampled to --size",
    )


CHUNK_BYTES = 1 << 20  # streamed reads: what is held of a file while it is sized


def count_csv_rows(path, limit: int | None = None) -> int:
    """The data rows of the CSV ``path`` (its lines less the header), counted in a
    streamed pass that holds a megabyte at a time and stops as soon as there are more
    than ``limit``: a file is sized before anything is built from it."""
    if not os.path.isfile(path):
        raise InputError(
            f"init file not found: {path}" if not os.path.exists(path) else f"init file {path} is not a file"
        )
    lines, last = 0, b"\n"
    try:
        with open(path, "rb") as fh:
            while chunk := fh.read(CHUNK_BYTES):
                lines += chunk.count(b"\n")
                last = chunk[-1:]
                if limit is not None and lines - 1 > limit:
                    raise InputError(
                        f"init file {path} holds more sites than the raster has pixels ({limit})"
                    )
    except OSError as exc:
        raise InputError(f"cannot read init file {path}: {exc.strerror or exc}") from None
    return max(0, lines + (last != b"\n") - 1)


def read_sites_csv(path, max_sites: int | None = None) -> np.ndarray:
    """Sites (N, 2) from a CSV with columns x and y (pixels); a UTF-8 byte-order mark,
    as spreadsheets write it, is accepted.  The file is sized first
    (:func:`count_csv_rows`: more rows than ``max_sites`` is refused before any is
    parsed), then parsed whole by pandas' C reader."""
    import pandas as pd

    count_csv_rows(path, max_sites)
    try:
        df = pd.read_csv(path, encoding="utf-8-sig", dtype=str, keep_default_na=False, skip_blank_lines=True)
    except (UnicodeDecodeError, pd.errors.ParserError):
        raise InputError(f"init file {path} is not a text CSV file") from None
    except pd.errors.EmptyDataError:
        raise InputError(f"init file {path} needs columns x and y, found none") from None
    except OSError as exc:
        raise InputError(f"cannot read init file {path}: {exc.strerror or exc}") from None
    df.columns = [str(c).strip() for c in df.columns]
    if "x" not in df.columns or "y" not in df.columns:
        raise InputError(f"init file {path} needs columns x and y, found {list(df.columns) or 'none'}")
    if not len(df):
        raise InputError(f"init file {path} has no sites")
    text = df[["x", "y"]].apply(lambda c: c.str.strip())
    xy = text.apply(lambda c: pd.to_numeric(c, errors="coerce"))
    # a NaN written as such is a number that is not finite (refused below), not a typo
    bad = (
        (xy.isna() & ~text.apply(lambda c: c.str.lower().isin(["nan", "+nan", "-nan"])))
        .any(axis=1)
        .to_numpy()
    )
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(
            f"init file {path}, line {k + 2}: x and y must be numbers, got "
            f"{df['x'].iloc[k]!r}, {df['y'].iloc[k]!r}"
        )
    pts = xy.to_numpy(dtype=np.float64)
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        raise InputError(f"init file {path}, line {int(np.argmax(bad)) + 2}: NaN or infinite coordinate")
    return pts


@dataclass
class ProblemOptions:
    """The problem options of the command line, checked, before any file is read."""

    width: int
    height: int
    n_elements: int
    metric: Metric
    element: str
    seed: int
    init: np.ndarray | None
    density: str | None  # image paths
    region: str | None
    field_file: str | None
    field_name: str | None  # a named field's spec
    init_file: str | None = None  # read by load_init once the memory is known to fit
    elements_given: int | None = None  # --elements as given


def parse_problem_options(args) -> ProblemOptions:
    """Every problem option checked (the init CSV sized, images not yet): InputError
    with a one-line message naming the option."""
    from compact_distributions.cvt.fields import FIELD_HELP, parse_field_spec
    from compact_distributions.cvt.mosaic.images import open_picture, upright_size
    from compact_distributions.cvt.mosaic.pipeline import raster_size
    from compact_distributions.cvt.problem import MAX_SEED

    w, h = parse_size(args.size, "--size")
    metric_name, element = resolve_shapes(
        args.metric, args.element, DEFAULT_ELEMENT, ("--metric", "--element")
    )
    metric = make_metric(metric_name, args.aspect, option="--aspect")
    seed = whole_number(args.seed, "--seed", minimum=0, maximum=MAX_SEED)
    field_file = field_name = None
    if args.field is not None:
        kind, _ = parse_field_spec(args.field, "--field")
        if kind is not None:
            field_name = args.field
        elif os.path.isfile(args.field):
            field_file = args.field
        else:
            raise InputError(f"--field {args.field!r} is neither a field nor an image file; use {FIELD_HELP}")
    shown = None  # the first picture's size as it is shown: a single --size follows its aspect
    for option, path in (("--density", args.density), ("--region", args.region), ("--field", field_file)):
        if path is not None:
            with open_picture(path, option) as header:  # exists, is a picture, is no bomb: before any work
                shown = upright_size(header) if shown is None else shown
    if shown is not None:
        w, h = raster_size(*shown, args.size, "--size")
    n = None if args.elements is None else whole_number(args.elements, "--elements", minimum=1, maximum=w * h)
    # the init file is sized here (a streamed row count) and read only once the run's
    # memory for that many sites is known to fit (:func:`load_init`)
    rows = count_csv_rows(args.init, w * h) if args.init else None
    given = n
    n = rows if rows is not None else (DEFAULT_ELEMENTS if n is None else n)
    return ProblemOptions(
        w,
        h,
        n,
        metric,
        element,
        seed,
        None,
        args.density,
        args.region,
        field_file,
        field_name,
        args.init,
        given,
    )


def load_init(opts: ProblemOptions) -> None:
    """Read the init file the options name into ``opts.init`` (after the memory check)."""
    if opts.init_file is None:
        return
    opts.init = read_sites_csv(opts.init_file, max_sites=opts.width * opts.height)
    if opts.elements_given is not None and len(opts.init) != opts.elements_given:
        raise InputError(
            f"--elements {opts.elements_given} but init file {opts.init_file} holds {len(opts.init)} sites"
        )
    opts.n_elements = len(opts.init)  # blank lines were counted as rows when it was sized


def build_problem(opts: ProblemOptions) -> Problem:
    """The Problem, with its images read and resampled to the raster."""
    from compact_distributions.cvt.mosaic.images import load_grey, load_mask

    w, h = opts.width, opts.height
    mask = load_mask(opts.region, w, h, name="--region") if opts.region else None
    density = DensityMap(load_grey(opts.density, w, h, name="--density")[0]) if opts.density else None
    field = None
    if opts.field_file:
        grey, full = load_grey(opts.field_file, w, h, name="--field")
        field = DirectionField.from_angles(
            angles_from_grey(grey, full, f"--field {opts.field_file}"), spec=opts.field_file
        )
    elif opts.field_name:
        field = DirectionField.named(opts.field_name, w, h, name="--field")
    return Problem(Grid(w, h, mask), opts.n_elements, opts.metric, density, field, opts.seed, opts.init)


def _write_cells(path, labels, sites) -> None:
    """cells.png: the cells in distinct colours, the sites dark, a band of rows at a time."""
    from compact_distributions.cvt.mosaic.render import CellRows

    from ..outputs import write_png

    write_png(path, CellRows(labels, len(sites), sites))


def add_parser(sub):
    p = sub.add_parser(
        "run",
        help="run one CVT (Lloyd relaxation), place the elements and write result.json",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    options.add_backend_options(p)
    options.add_method_option(p)
    add_problem_arguments(p)
    options.add_run_options(p)
    p.add_argument(
        "--gap",
        metavar="G",
        default="0",
        help="grout: width in pixels of the joint between elements (default 0)",
    )
    options.add_output_options(p, "out/run")
    options.add_memory_option(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from compact_distributions.backends import backend_class
    from compact_distributions.baselines import get_method
    from compact_distributions.cvt.evaluate import evaluate, region_polygon
    from compact_distributions.cvt.lloyd import MAX_ITERATIONS
    from compact_distributions.cvt.placement.fit import parse_gap
    from compact_distributions.cvt.resources import run_estimate

    from ..outputs import (
        COMMAND_OUTPUTS,
        Beside,
        OutputFolder,
        command_line,
        write_result_json,
    )
    from ..results import RanOn, build_result

    # every option is checked, and the memory it asks for, before anything is computed
    iterations = whole_number(args.iterations, "--iterations", minimum=0, maximum=MAX_ITERATIONS)
    gap = parse_gap(args.gap, "--gap")
    method = get_method(args.method)
    extra = options.method_options(args, method)
    opts = parse_problem_options(args)
    element = opts.element
    backend_name, _ = options.backend_choice(args)
    run_estimate(
        opts.width,
        opts.height,
        opts.n_elements,
        backend_class(backend_name),
        element=element,
        density=bool(opts.density),
        field=bool(opts.field_file),
        region=bool(opts.region),
        method=method,
    ).check(args.memory_limit, lower="use a smaller --size or fewer --elements")
    load_init(opts)
    with OutputFolder(args.out, "--out", COMMAND_OUTPUTS) as tmp, Beside() as beside:
        problem = build_problem(opts)
        with options.open_backend(args) as backend:
            dist = method(
                problem,
                backend,
                iterations=iterations,
                progress=options.progress_printer(args.quiet),
                element=element,
                gap=gap,
                **extra,
            )
            if dist.labels is not None:  # needs only the labels: drawn beside what follows
                beside.run(_write_cells, tmp / "cells.png", dist.labels, dist.sites)
            t0 = time.perf_counter()
            region = region_polygon(problem.grid)
            ev = evaluate(dist.elements, problem.grid, region=region, labels=dist.labels)
            evaluation_seconds = time.perf_counter() - t0
            sources = {k: getattr(args, k) for k in ("init", "density", "field", "region")}
            ran_on = RanOn.of(backend)
        shape = dist.extra.get("element", element)
        # the other files first, so that result.json (written last) holds their writing time
        t0 = time.perf_counter()
        measured, measures_seconds = _write_files(tmp, beside, dist, problem, region, shape)
        stages = {
            "evaluation": evaluation_seconds,
            "writing": time.perf_counter() - t0,
            "measures": measures_seconds,  # on its thread, beside the files
        }
        result = build_result(
            "run",
            problem,
            dist,
            ev,
            ran_on,
            element=shape,
            gap=gap,
            command=command_line(args.argv),
            sources=sources,
            method_options=extra,
            stage_seconds=stages,
            measured=measured,
        )
        # written once the pictures are, the time waited for them counted as writing
        write_result_json(tmp / "result.json", result, beside)
    if not args.quiet:
        mean = np.median(dist.seconds) * 1000 if dist.seconds else float("nan")
        print(
            f"wrote {args.out}/result.json, sites.csv, cells.png, elements.svg, elements.png  "
            f"({len(dist.sites)} elements, {dist.iterations} iterations, median {mean:.1f} ms/iteration; "
            f"{result['element']}s: coverage {ev.coverage:.2%}, overlap {ev.overlap:.3%}, "
            f"{ev.skipped} skipped)",
            file=sys.stderr,
        )
    return 0


def _write_files(tmp, beside, dist, problem, region, shape):
    """sites.csv, elements.svg and elements.png (deflated ``beside``) of ``dist``, with
    its fidelity measures taken on a thread of their own meanwhile (Delaunay and GEOS let
    go of the GIL); the measures and the seconds they took."""
    from compact_distributions.cvt.evaluate import timed_fidelity
    from compact_distributions.cvt.mosaic.render import PAPER, draw_elements, svg_lines
    from compact_distributions.cvt.threads import on_its_own_thread

    from ..outputs import write_lines, write_png, write_sites_csv

    g = problem.grid
    with on_its_own_thread(timed_fidelity, dist.elements, problem, shape) as measures:
        write_sites_csv(tmp / "sites.csv", dist.sites, dist.angles, dist.scales)
        write_lines(
            tmp / "elements.svg",
            svg_lines(dist.elements, g.width, g.height, region=None if g.mask is None else region),
        )
        # drawn as its rows are read, and deflated, beside the measures
        picture = draw_elements(
            dist.elements, g.width, g.height, region_colour=PAPER, region_mask=g.mask, as_rows=True
        )
        beside.run(write_png, tmp / "elements.png", picture)
        del picture
        return measures()


__all__ = [
    "DEFAULT_SIZE",
    "DEFAULT_ELEMENTS",
    "add_problem_arguments",
    "CHUNK_BYTES",
    "count_csv_rows",
    "read_sites_csv",
    "ProblemOptions",
    "parse_problem_options",
    "load_init",
    "build_problem",
    "add_parser",
    "run",
]
