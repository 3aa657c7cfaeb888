"""`cvtbench run`: one CVT (or baseline) run, written to ``--out DIR``.

DIR/result.json  the run: backend, device, metric, aspect, size, sites, angles, scales,
                 iterations, energy and seconds per iteration, versions, command, ...
DIR/sites.csv    x,y (pixel units), angle_deg, scale per site, in input order
DIR/cells.png    the final cells in distinct colours
DIR/elements.svg one closed path per placed element (viewBox in pixel units)
DIR/elements.png the same elements as a picture

result.json also holds the placement: ``element``, ``gap``, ``coverage``, ``overlap``
(cvt/evaluate.py), ``placed``, ``skipped``, ``empty_cell_count``, the smallest and
largest element area, and ``elements`` (per site its outline as [[x, y], ...], or null).
"""

from __future__ import annotations

import argparse
import csv
import os
import sys

import numpy as np

from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.fields import DensityMap, DirectionField, angles_from_grey
from compact_distributions.cvt.metrics import make_metric
from compact_distributions.cvt.problem import Grid, Problem, parse_size
from compact_distributions.cvt.validate import whole_number

from . import options

DEFAULT_SIZE = "512"
DEFAULT_SITES = 1000


def add_problem_arguments(p: argparse.ArgumentParser, sites_default=DEFAULT_SITES) -> None:
    """The options that define a Problem."""
    options.add_shape_options(p)
    p.add_argument("--sites", default=None, help=f"number of sites N (default {sites_default})")
    p.add_argument("--size", default=DEFAULT_SIZE, help=f"{options.SIZE_HELP} (default {DEFAULT_SIZE})")
    p.add_argument("--init", metavar="SITES.CSV", help="start from these sites (columns x,y in pixels)")
    p.add_argument("--density", metavar="IMAGE",
                   help="density image (bright = dense = small cells); resampled to --size")
    p.add_argument("--field", metavar="FIELD",
                   help="direction field: constant:DEG, radial, circular, wave:PERIOD, or a grey "
                   "image (0..255 -> 0..180 degrees)")
    p.add_argument("--region", metavar="MASK_IMAGE",
                   help="region mask image (light or opaque = inside); resampled to --size")


def read_sites_csv(path) -> np.ndarray:
    if not os.path.isfile(path):
        raise InputError(f"init file not found: {path}")
    try:
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            cols = [c.strip() for c in (reader.fieldnames or [])]
            if "x" not in cols or "y" not in cols:
                raise InputError(f"init file {path} needs columns x and y, found {cols or 'none'}")
            reader.fieldnames = cols
            rows = []
            for line, row in enumerate(reader, start=2):
                try:
                    rows.append((float(row["x"]), float(row["y"])))
                except (TypeError, ValueError):
                    raise InputError(
                        f"init file {path}, line {line}: x and y must be numbers, got "
                        f"{row.get('x')!r}, {row.get('y')!r}") from None
    except UnicodeDecodeError:
        raise InputError(f"init file {path} is not a text CSV file") from None
    if not rows:
        raise InputError(f"init file {path} has no sites")
    pts = np.array(rows, dtype=np.float64)
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        raise InputError(f"init file {path}, line {int(np.argmax(bad)) + 2}: NaN or infinite coordinate")
    return pts


def problem_from_args(args, sites_default=DEFAULT_SITES) -> Problem:
    """Build and validate the Problem; raises InputError with a one-line message."""
    from compact_distributions.cvt.images import load_grey, load_mask

    w, h = parse_size(args.size)
    metric = make_metric(args.metric, args.aspect)
    mask = load_mask(args.region, w, h) if args.region else None
    grid = Grid(w, h, mask)
    density = None
    if args.density:
        grey, _ = load_grey(args.density, w, h)
        density = DensityMap(grey)
    field = None
    if args.field:
        if os.path.exists(args.field):
            grey, full = load_grey(args.field, w, h)
            field = DirectionField.from_angles(angles_from_grey(grey, full), spec=args.field)
        else:
            field = DirectionField.named(args.field, w, h)
    init = read_sites_csv(args.init) if args.init else None
    n = sites_default if args.sites is None else whole_number(args.sites, "--sites", minimum=1)
    if init is not None and args.sites is not None and len(init) != n:
        raise InputError(f"--sites {n} but init file {args.init} holds {len(init)} sites")
    seed = whole_number(args.seed, "--seed", minimum=0)
    return Problem(grid, n, metric, density, field, seed, init)


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
    p.set_defaults(func=run)


def run(args) -> int:
    from compact_distributions.baselines import get_method
    from compact_distributions.cvt.evaluate import evaluate, region_polygon
    from compact_distributions.cvt.placement import parse_gap
    from compact_distributions.cvt.render import PAPER, cells_image, draw_elements, svg_document
    from compact_distributions.cvt.shapes import check_shape

    from .outputs import command_line, staged_dir, write_json, write_sites_csv
    from .results import build_result

    iterations = whole_number(args.iterations, "--iterations", minimum=0)
    element = None if args.element is None else check_shape(args.element)
    gap = parse_gap(args.gap, "--gap")
    problem = problem_from_args(args)
    method = get_method(args.method)
    extra = options.method_options(args)
    with options.open_backend(args) as backend:
        dist = method(problem, backend, iterations=iterations, progress=options.progress_printer(args.quiet),
                      element=element, gap=gap, **extra)
        region = region_polygon(problem.grid)
        ev = evaluate(dist.elements, problem.grid, region=region, labels=dist.labels)
        sources = {k: getattr(args, k) for k in ("init", "density", "field", "region")}
        result = build_result("run", problem, dist, ev, backend, element=dist.extra["element"], gap=gap,
                              command=command_line(args.argv), sources=sources)
    g = problem.grid
    with staged_dir(args.out) as tmp:
        write_json(tmp / "result.json", result)
        write_sites_csv(tmp / "sites.csv", dist.sites, dist.angles, dist.scales)
        if dist.labels is not None:
            cells_image(dist.labels, len(dist.sites), dist.sites).save(tmp / "cells.png")
        (tmp / "elements.svg").write_text(svg_document(dist.elements, g.width, g.height,
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
