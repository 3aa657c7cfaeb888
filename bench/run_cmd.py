"""`cvtbench run`: one CVT (or baseline) run, written to ``--out DIR``.

DIR/result.json  the run: backend, device, metric, aspect, size, sites, angles, scales,
                 iterations, energy and seconds per iteration, versions, command, ...
DIR/sites.csv    x,y (pixel units), angle_deg, scale per site, in input order
DIR/cells.png    the final cells in distinct colours
DIR/elements.svg one closed path per placed element (viewBox in pixel units)
DIR/elements.png the same elements as a picture

result.json also holds the placement: ``element``, ``gap``, ``coverage``, ``overlap``
(bench/evaluate.py), ``placed``, ``skipped``, ``empty_cell_count``, the smallest and
largest element area, and ``elements`` (per site its outline as [[x, y], ...], or null).
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time

import numpy as np

from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.fields import DensityMap, DirectionField, angles_from_grey
from compact_distributions.cvt.metrics import METRIC_NAMES, make_metric
from compact_distributions.cvt.placement import check_shape, element_for, parse_gap, place_elements
from compact_distributions.cvt.problem import Grid, Problem, default_site_count, parse_size
from compact_distributions.cvt.shapes import ELEMENT_SHAPES

DEFAULT_SIZE = "512"
DEFAULT_SITES = 1000


def add_problem_arguments(p: argparse.ArgumentParser, sites_default=DEFAULT_SITES) -> None:
    """The options that define a Problem (shared by run, mosaic, ...)."""
    p.add_argument("--metric", default="l2", help=f"distance: {', '.join(METRIC_NAMES)} (default l2)")
    p.add_argument("--aspect", type=str, default=None,
                   help="axial scale β for linf-axial and l2-axial (default 0.5); > 0")
    p.add_argument("--sites", type=str, default=None,
                   help=f"number of sites N (default {sites_default})")
    p.add_argument("--size", default=DEFAULT_SIZE, help=f"raster W or WxH in pixels (default {DEFAULT_SIZE})")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
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


def _parse_sites(text, default: int) -> int:
    if text is None:
        return default
    try:
        n = int(text)
    except ValueError:
        raise InputError(f"--sites must be a whole number >= 1, got {text!r}") from None
    if n < 1:
        raise InputError(f"--sites must be >= 1, got {n}")
    return n


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
    n = _parse_sites(args.sites, sites_default if sites_default else default_site_count(w, h))
    if init is not None and args.sites is not None and len(init) != n:
        raise InputError(f"--sites {n} but init file {args.init} holds {len(init)} sites")
    return Problem(grid, n, metric, density, field, args.seed, init)


def add_parser(sub):
    p = sub.add_parser("run", help="run one CVT (Lloyd relaxation) and write result.json",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--backend", default="numpy", help="numpy (reference), opencl or gl (default numpy)")
    p.add_argument("--method", default="ours", help="ours (default) or a baseline name")
    p.add_argument("--device", default=None,
                   help="OpenCL device as PLATFORM[:DEVICE] indices, like PYOPENCL_CTX (opencl backend)")
    p.add_argument("--gl-mode", default="cone", choices=["cone", "exact"],
                   help="gl backend: cone (paper's cones and pyramids) or exact (per-fragment metric)")
    add_problem_arguments(p)
    p.add_argument("--iterations", type=str, default="20", help="Lloyd iterations (default 20; 0 allowed)")
    p.add_argument("--element", metavar="SHAPE", default=None,
                   help=f"element placed in each cell: {', '.join(ELEMENT_SHAPES)} "
                   "(default: the metric's own shape)")
    p.add_argument("--gap", metavar="G", default="0",
                   help="grout: width in pixels of the joint between elements (default 0)")
    p.add_argument("--out", default="out/run", help="output folder (default out/run)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run)


def _parse_iterations(text) -> int:
    try:
        k = int(text)
    except ValueError:
        raise InputError(f"--iterations must be a whole number >= 0, got {text!r}") from None
    if k < 0:
        raise InputError(f"--iterations must be >= 0, got {k}")
    return k


def _progress(quiet: bool):
    if quiet:
        return None
    start = time.perf_counter()

    def report(k, total, energy):
        el = time.perf_counter() - start
        end = "\n" if k == total or not sys.stderr.isatty() else ""
        if sys.stderr.isatty() or k == total or k % max(1, total // 10) == 0:
            print(f"\riteration {k}/{total}  energy {energy:.4g} px²  {el:.1f} s", end=end,
                  file=sys.stderr, flush=True)

    return report


def run(args) -> int:
    from compact_distributions.backends import create_backend

    from .methods import get_method
    from .outputs import cells_image, command_line, machine, staged_dir, versions, write_json, write_sites_csv

    iterations = _parse_iterations(args.iterations)
    element = None if args.element is None else check_shape(args.element)
    gap = parse_gap(args.gap)
    problem = problem_from_args(args)
    method = get_method(args.method)
    backend = create_backend(args.backend, **backend_options(args))
    try:
        dist = method(problem, backend, iterations, progress=_progress(args.quiet),
                      element=element, gap=gap)
        labels = dist.labels
        if labels is None:
            labels = backend.label(dist.sites, dist.scales, dist.angles, problem.metric, problem.grid)
        device = backend.device()
    finally:
        backend.close()
    shape = dist.extra.get("element") or element_for(problem.metric, element)[0]
    elements = dist.elements
    if elements is None:  # a method that leaves placement to us: the same rule as ours
        shape, turn = element_for(problem.metric, element)
        elements = place_elements(labels, dist.sites, dist.angles + turn, dist.scales, shape,
                                  problem.metric.aspect, problem.grid, gap)
    from .evaluate import evaluate, region_polygon
    from .svg import element_coordinates, elements_png, elements_svg

    region = region_polygon(problem.grid)
    ev = evaluate(elements, problem.grid, region=region, labels=labels)
    result = build_result(args, problem, dist, backend.name, device)
    result.update(element=shape, gap=gap, **ev.as_dict())
    result.update(versions=versions(), machine=machine(), command=command_line(args.argv))
    result["elements"] = element_coordinates(elements)
    g = problem.grid
    svg_region = None if g.mask is None else region
    with staged_dir(args.out) as tmp:
        write_json(tmp / "result.json", result)
        write_sites_csv(tmp / "sites.csv", dist.sites, dist.angles, dist.scales)
        cells_image(labels, len(dist.sites), dist.sites).save(tmp / "cells.png")
        (tmp / "elements.svg").write_text(elements_svg(elements, g.width, g.height, region=svg_region))
        elements_png(elements, g.width, g.height, region_mask=g.mask).save(tmp / "elements.png")
    if not args.quiet:
        mean = np.median(dist.seconds) * 1000 if dist.seconds else float("nan")
        print(f"wrote {args.out}/result.json, sites.csv, cells.png, elements.svg, elements.png  "
              f"({len(dist.sites)} sites, {dist.iterations} iterations, median {mean:.1f} ms/iteration; "
              f"{shape}s: coverage {ev.coverage:.2%}, overlap {ev.overlap:.3%}, "
              f"{ev.skipped} skipped)", file=sys.stderr)
    return 0


def backend_options(args) -> dict:
    """Constructor options of the chosen backend taken from the command line."""
    if args.backend == "opencl" and args.device is not None:
        return {"device": args.device}
    if args.backend == "gl":
        return {"mode": args.gl_mode}
    return {}


def build_result(args, problem: Problem, dist, backend_name: str, device: str) -> dict:
    """The result.json contract (field names are stable; later issues add fields)."""
    g = problem.grid
    return {
        "method": dist.method,
        "backend": backend_name,
        "device": device,
        "metric": problem.metric.name,
        "aspect": problem.metric.aspect,
        "size": [g.width, g.height],
        "n_sites": len(dist.sites),
        "seed": problem.seed,
        "init": getattr(args, "init", None),
        "density": getattr(args, "density", None),
        "field": getattr(args, "field", None),
        "region": getattr(args, "region", None),
        "region_pixels": g.pixel_count,
        "iterations": dist.iterations,
        "sites": dist.sites,
        "angles": dist.angles,
        "scales": dist.scales,
        "energy": dist.energy,
        "seconds": dist.seconds,
        "total_seconds": dist.total_seconds,
        "setup_seconds": dist.setup_seconds,
        "median_ms_per_iteration": (float(np.median(dist.seconds)) * 1000 if dist.seconds else None),
        "empty_cells": dist.empty,
        "empty_sites": dist.empty_sites,
        "extra": dist.extra,
    }


