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
import csv
import os
import sys
from dataclasses import dataclass

import numpy as np

from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.fields import DensityMap, DirectionField, angles_from_grey
from compact_distributions.cvt.metrics import METRIC_NAMES, Metric, make_metric
from compact_distributions.cvt.problem import Grid, Problem, parse_size
from compact_distributions.cvt.validate import one_of, whole_number

from . import options

DEFAULT_SIZE = "512"
DEFAULT_ELEMENTS = 1000


def add_problem_arguments(p: argparse.ArgumentParser) -> None:
    """The options that define a Problem."""
    options.add_shape_options(p)
    p.add_argument("--elements", default=None, help=f"number of sites N (default {DEFAULT_ELEMENTS})")
    p.add_argument("--size", default=DEFAULT_SIZE, help=f"{options.SIZE_HELP} (default {DEFAULT_SIZE})")
    p.add_argument("--init", metavar="SITES.CSV", help="start from these sites (columns x,y in pixels)")
    p.add_argument("--density", metavar="IMAGE",
                   help="density image (bright = dense = small cells); resampled to --size")
    p.add_argument("--field", metavar="FIELD",
                   help="direction field: constant:DEG, radial, circular, wave:PERIOD, or a grey "
                   "image (0..255 -> 0..180 degrees)")
    p.add_argument("--region", metavar="MASK_IMAGE",
                   help="region mask image (light or opaque = inside); resampled to --size")


def read_sites_csv(path, max_sites: int | None = None) -> np.ndarray:
    """Sites (N, 2) from a CSV with columns x and y (pixels); a UTF-8 byte-order mark,
    as spreadsheets write it, is accepted.  More rows than ``max_sites`` is an error
    found while reading, before the rows are all held."""
    if not os.path.isfile(path):
        raise InputError(f"init file not found: {path}" if not os.path.exists(path)
                         else f"init file {path} is not a file")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.DictReader(fh)
            cols = [c.strip() for c in (reader.fieldnames or [])]
            if "x" not in cols or "y" not in cols:
                raise InputError(f"init file {path} needs columns x and y, found {cols or 'none'}")
            reader.fieldnames = cols
            xs, ys = [], []
            for line, row in enumerate(reader, start=2):
                try:
                    xs.append(float(row["x"]))
                    ys.append(float(row["y"]))
                except (TypeError, ValueError):
                    raise InputError(
                        f"init file {path}, line {line}: x and y must be numbers, got "
                        f"{row.get('x')!r}, {row.get('y')!r}") from None
                if max_sites is not None and len(xs) > max_sites:
                    raise InputError(f"init file {path} holds more sites than the raster has pixels ({max_sites})")
    except (UnicodeDecodeError, csv.Error):
        raise InputError(f"init file {path} is not a text CSV file") from None
    except OSError as exc:
        raise InputError(f"cannot read init file {path}: {exc.strerror or exc}") from None
    if not xs:
        raise InputError(f"init file {path} has no sites")
    pts = np.column_stack([np.array(xs, dtype=np.float64), np.array(ys, dtype=np.float64)])
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
    seed: int
    init: np.ndarray | None
    density: str | None  # image paths
    region: str | None
    field_file: str | None
    field_name: str | None  # a named field's spec


def parse_problem_options(args) -> ProblemOptions:
    """Every problem option checked (the init CSV read, images not yet): InputError
    with a one-line message naming the option."""
    from compact_distributions.cvt.fields import FIELD_HELP, parse_field_spec
    from compact_distributions.cvt.images import open_picture
    from compact_distributions.cvt.problem import MAX_SEED

    w, h = parse_size(args.size, "--size")
    metric = make_metric(one_of(args.metric, "--metric", METRIC_NAMES), args.aspect, option="--aspect")
    n = None if args.elements is None else whole_number(args.elements, "--elements", minimum=1, maximum=w * h)
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
    for option, path in (("--density", args.density), ("--region", args.region), ("--field", field_file)):
        if path is not None:
            with open_picture(path, option):  # exists, is a picture, is no bomb: known before any work
                pass
    init = read_sites_csv(args.init, max_sites=w * h) if args.init else None
    if init is not None and n is not None and len(init) != n:
        raise InputError(f"--elements {n} but init file {args.init} holds {len(init)} sites")
    n = len(init) if init is not None else (DEFAULT_ELEMENTS if n is None else n)
    return ProblemOptions(w, h, n, metric, seed, init, args.density, args.region, field_file, field_name)


def build_problem(opts: ProblemOptions) -> Problem:
    """The Problem, with its images read and resampled to the raster."""
    from compact_distributions.cvt.images import load_grey, load_mask

    w, h = opts.width, opts.height
    mask = load_mask(opts.region, w, h, name="--region") if opts.region else None
    density = DensityMap(load_grey(opts.density, w, h, name="--density")[0]) if opts.density else None
    field = None
    if opts.field_file:
        grey, full = load_grey(opts.field_file, w, h, name="--field")
        field = DirectionField.from_angles(angles_from_grey(grey, full, f"--field {opts.field_file}"),
                                           spec=opts.field_file)
    elif opts.field_name:
        field = DirectionField.named(opts.field_name, w, h, name="--field")
    return Problem(Grid(w, h, mask), opts.n_elements, opts.metric, density, field, opts.seed, opts.init)


def add_parser(sub):
    p = sub.add_parser("run", help="run one CVT (Lloyd relaxation), place the elements and write result.json",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    options.add_backend_options(p)
    options.add_method_option(p)
    add_problem_arguments(p)
    options.add_run_options(p)
    p.add_argument("--gap", metavar="G", default="0",
                   help="grout: width in pixels of the joint between elements (default 0)")
    options.add_output_options(p, "out/run")
    options.add_memory_option(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from compact_distributions.backends import backend_class
    from compact_distributions.baselines import get_method
    from compact_distributions.cvt.evaluate import evaluate, region_polygon
    from compact_distributions.cvt.lloyd import MAX_ITERATIONS
    from compact_distributions.cvt.placement import parse_gap
    from compact_distributions.cvt.render import PAPER, cells_image, draw_elements, svg_lines
    from compact_distributions.cvt.resources import run_estimate
    from compact_distributions.cvt.shapes import check_shape

    from .outputs import COMMAND_OUTPUTS, OutputFolder, command_line, write_json, write_lines, write_sites_csv
    from .results import build_result

    # every option is checked, and the memory it asks for, before anything is computed
    iterations = whole_number(args.iterations, "--iterations", minimum=0, maximum=MAX_ITERATIONS)
    element = None if args.element is None else check_shape(args.element)
    gap = parse_gap(args.gap, "--gap")
    method = get_method(args.method)
    extra = options.method_options(args)
    opts = parse_problem_options(args)
    backend_name, _ = options.backend_choice(args)
    run_estimate(opts.width, opts.height, opts.n_elements, backend_class(backend_name), element=element,
                 density=bool(opts.density), field=bool(opts.field_file), region=bool(opts.region)).check(
        args.memory_limit, lower="use a smaller --size or fewer --elements")
    with OutputFolder(args.out, "--out", COMMAND_OUTPUTS) as tmp:
        problem = build_problem(opts)
        with options.open_backend(args) as backend:
            dist = method(problem, backend, iterations=iterations,
                          progress=options.progress_printer(args.quiet), element=element, gap=gap, **extra)
            region = region_polygon(problem.grid)
            ev = evaluate(dist.elements, problem.grid, region=region, labels=dist.labels)
            sources = {k: getattr(args, k) for k in ("init", "density", "field", "region")}
            result = build_result("run", problem, dist, ev, backend, element=dist.extra["element"], gap=gap,
                                  command=command_line(args.argv), sources=sources)
        g = problem.grid
        write_json(tmp / "result.json", result)
        write_sites_csv(tmp / "sites.csv", dist.sites, dist.angles, dist.scales)
        if dist.labels is not None:
            cells_image(dist.labels, len(dist.sites), dist.sites).save(tmp / "cells.png")
        write_lines(tmp / "elements.svg", svg_lines(dist.elements, g.width, g.height,
                                                    region=None if g.mask is None else region))
        draw_elements(dist.elements, g.width, g.height, region_colour=PAPER,
                      region_mask=g.mask).save(tmp / "elements.png")
    if not args.quiet:
        mean = np.median(dist.seconds) * 1000 if dist.seconds else float("nan")
        print(f"wrote {args.out}/result.json, sites.csv, cells.png, elements.svg, elements.png  "
              f"({len(dist.sites)} sites, {dist.iterations} iterations, median {mean:.1f} ms/iteration; "
              f"{result['element']}s: coverage {ev.coverage:.2%}, overlap {ev.overlap:.3%}, "
              f"{ev.skipped} skipped)", file=sys.stderr)
    return 0
