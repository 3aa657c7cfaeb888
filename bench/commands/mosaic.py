"""`cvtbench mosaic IMAGE --out DIR`: a picture turned into a mosaic (paper §4.1).

Tile sizes follow a density map and tile directions a field, both extracted from the
picture (cvt/mosaic/image_fields.py); the picture's strong edges are walls that no tile
crosses; a method places the tiles (--method); each tile is filled with the geometric
median, in CIELAB, of the picture under it, on a grout-coloured background.

DIR/mosaic.svg    the mosaic: grout background, one filled tile per placed site
DIR/mosaic.png    the same, rendered (antialiased) at the raster size times --png-scale
DIR/result.json   the run, in the one result.json schema of `cvtbench run` (backend,
                  device, metric, aspect, size, sites, angles, scales, iterations,
                  energy, seconds, element, gap, coverage, overlap, placed, elements
                  (outlines), ...) plus image, colours, grout, contrast, colour_error,
                  straddling, edge_threshold, walls and edge_pixels
DIR/sites.csv     x,y,angle_deg,scale per site
DIR/compare_WHAT.png  with --compare: original and the mosaic without and with the field,
                  the density or the walls, or with each method (ours, ours-compact,
                  hausner2001)

The paper's Figures 18-19 from the sample pictures (into reports/figures/) are part of
`cvtbench figures`.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.validate import real_number, whole_number

from .. import options
from ..panels import panel_grid

DEFAULT_OUT = "out/mosaic"


# --compare WHAT: the make_mosaic option that the panels switch off and on
COMPARE = {"field": "use_field", "density": "use_density", "edges": "edges", "method": "method"}
COMPARE_METHODS = ("ours", "ours-compact", "hausner2001")


def add_parser(sub):
    p = sub.add_parser(
        "mosaic",
        help="turn a picture into a mosaic (density and direction from the picture)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    # read once the parser is wanted (cvtbench --help lists the command without them)
    from compact_distributions.cvt.mosaic.image_fields import DEFAULT_EDGE_THRESHOLD
    from compact_distributions.cvt.mosaic.pipeline import DEFAULT_ELEMENTS, DEFAULT_METHOD

    p.add_argument(
        "image", metavar="IMAGE", help="the picture: PNG, JPEG, ... (grey, RGB, RGBA, palette, 16-bit)"
    )
    p.add_argument(
        "--elements", default=str(DEFAULT_ELEMENTS), help=f"number of elements N (default {DEFAULT_ELEMENTS})"
    )
    options.add_shape_options(p)
    p.add_argument(
        "--size",
        default=None,
        help=f"{options.SIZE_HELP}; default the picture's size with the long side capped at 1024",
    )
    options.add_backend_options(p)
    p.add_argument(
        "--gap", default=None, help="grout width in pixels (default 5%% of the mean element spacing)"
    )
    p.add_argument("--grout", default="#383838", help="grout colour: a name or #rrggbb (default #383838)")
    p.add_argument(
        "--contrast",
        default=None,
        help="densest / sparsest cell area of the density map, 1 to 100 (default 3; 1 = uniform)",
    )
    p.add_argument("--no-field", action="store_true", help="all elements at angle 0 (no direction field)")
    p.add_argument("--no-density", action="store_true", help="one element size everywhere (no density map)")
    p.add_argument(
        "--no-edges", action="store_true", help="strong edges are not walls (tiles may cross them)"
    )
    p.add_argument(
        "--no-cut",
        action="store_true",
        help="keep every tile whole (by default the ours-compact tiles beside a wall are cut to fit it)",
    )
    p.add_argument(
        "--cut",
        choices=("auto", "exact", "straight"),
        default=None,
        help="how tiles are cut to a wall: exact (what is free, by shapely differences), straight "
        "(convex tiles, straight cuts: about a third of the time, 1-1.5 points less coverage) "
        "or auto (default: exact for small mosaics, straight above "
        "compact_distributions.cvt.mosaic.cutting.EXACT_TILES tiles)",
    )
    p.add_argument(
        "--edge-threshold",
        default=None,
        help=f"contrast of a strong edge in ΔE*ab (CIELAB; default {DEFAULT_EDGE_THRESHOLD:g}): "
        "strong edges are walls, and the straddling measure counts tiles across them",
    )
    options.add_method_option(p, default=DEFAULT_METHOD)
    options.add_run_options(p)
    p.add_argument(
        "--png-scale", default="1", help="mosaic.png size relative to the raster, 0.01 to 100 (default 1)"
    )
    p.add_argument(
        "--compare",
        choices=list(COMPARE),
        default=None,
        help="also write compare_WHAT.png: original | without | with the field, the density or "
        "the edge walls; method: original | ours | ours-compact | hausner2001",
    )
    options.add_output_options(p, DEFAULT_OUT)
    options.add_memory_option(p)
    p.set_defaults(func=run)


def _say(quiet: bool, text: str) -> None:
    if not quiet:
        print(text, file=sys.stderr, flush=True)


def mosaic_options(args) -> dict:
    """make_mosaic keyword arguments from the parsed command line (validated; the
    raster size is not among them: it depends on the picture, see :func:`run`)."""
    from compact_distributions.baselines import get_method
    from compact_distributions.cvt.lloyd import MAX_ITERATIONS
    from compact_distributions.cvt.metrics import ASPECT_RANGE
    from compact_distributions.cvt.mosaic.image_fields import (
        CONTRAST_RANGE,
        DEFAULT_CONTRAST,
        DEFAULT_EDGE_THRESHOLD,
    )
    from compact_distributions.cvt.mosaic.render import parse_colour
    from compact_distributions.cvt.placement.fit import parse_gap
    from compact_distributions.cvt.problem import MAX_SEED
    from compact_distributions.cvt.shapes import shape_record

    return dict(
        method=get_method(args.method),
        method_options=options.method_options(args, args.method),
        edges=not args.no_edges,
        cut=_cut(args),
        edge_threshold=(
            DEFAULT_EDGE_THRESHOLD
            if args.edge_threshold is None
            else real_number(args.edge_threshold, "--edge-threshold", above=0)
        ),
        n_elements=whole_number(args.elements, "--elements", minimum=1),
        # any shape `run` takes, the user's polygon:FILE too (read and checked here)
        metric=None if args.metric is None else _metric_name(args.metric),
        element=None if args.element is None else shape_record(args.element, "--element").name,
        aspect=None if args.aspect is None else real_number(args.aspect, "--aspect", *ASPECT_RANGE),
        gap=None if args.gap is None else parse_gap(args.gap, "--gap"),
        use_field=not args.no_field,
        use_density=not args.no_density,
        iterations=whole_number(args.iterations, "--iterations", minimum=0, maximum=MAX_ITERATIONS),
        seed=whole_number(args.seed, "--seed", minimum=0, maximum=MAX_SEED),
        contrast=DEFAULT_CONTRAST
        if args.contrast is None
        else real_number(args.contrast, "--contrast", *CONTRAST_RANGE),
        grout=parse_colour(args.grout, "--grout"),
        progress=options.progress_printer(args.quiet),
        memory_limit=args.memory_limit,
    )


def _cut(args):
    """``make_mosaic``'s ``cut`` from ``--no-cut`` and ``--cut``."""
    if args.no_cut and args.cut is not None:
        raise InputError(f"--cut {args.cut} and --no-cut exclude each other")
    return False if args.no_cut else args.cut


def _metric_name(text: str) -> str:
    """``--metric``: a metric's name, or ``polygon:FILE`` (the file read and checked)."""
    from compact_distributions.cvt.metrics import POLYGON_PREFIX
    from compact_distributions.cvt.shapes import resolve_shapes, shape_record

    if text.startswith(POLYGON_PREFIX):
        return shape_record(text, "--metric").metric
    return resolve_shapes(text, None, names=("--metric", "--element"))[0]


def mosaic_result_json(
    args, m, ran_on, stage_seconds: dict | None = None, measured: dict | None = None
) -> dict:
    """result.json of a mosaic (the schema of bench/results.py); ``measured``: its
    fidelity measures where they were taken already (else taken here)."""
    import dataclasses

    from compact_distributions.cvt.evaluate import empty_cells, evaluate
    from compact_distributions.cvt.mosaic.render import hex_colour, hex_colours
    from compact_distributions.cvt.problem import Grid

    from ..outputs import command_line
    from ..results import build_result

    # coverage of the whole picture (wall pixels count as grout), as make_mosaic measured it
    if m.evaluation is None:
        ev = evaluate(m.polygons, Grid(m.width, m.height), labels=m.labels)
    else:
        empty = None if m.labels is None else empty_cells(m.labels, len(m.polygons))
        ev = dataclasses.replace(m.evaluation, empty_cells=empty)
    sources = {
        "density": "picture" if m.problem.density is not None else None,
        "field": "picture" if m.problem.field is not None else None,
        "region": "picture less its strong edges" if m.walls else None,
    }
    return build_result(
        "mosaic",
        m.problem,
        m.to_distribution(),
        ev,
        ran_on,
        element=m.element,
        gap=m.gap,
        command=command_line(getattr(args, "argv", None)),
        sources=sources,
        method_options=m.method_options,
        stage_seconds=stage_seconds,
        placed=m.polygons,
        image=m.source,
        colours=hex_colours(m.colours),
        grout=hex_colour(m.grout),
        contrast=m.contrast,
        colour_error=m.colour_error if np.isfinite(m.colour_error) else None,
        straddling=m.straddling,
        edge_threshold=m.edge_threshold,
        walls=m.walls,
        edge_pixels=int(m.edges.sum()),
        measured=measured,
    )


PNG_SCALE_RANGE = (0.01, 100.0)


def run(args) -> int:
    from compact_distributions.backends import backend_class
    from compact_distributions.cvt.evaluate import timed_fidelity
    from compact_distributions.cvt.mosaic.images import open_picture, upright_size
    from compact_distributions.cvt.mosaic.pipeline import (
        make_mosaic,
        picture_array,
        raster_size,
        resolve_shapes,
    )
    from compact_distributions.cvt.resources import mosaic_estimate
    from compact_distributions.cvt.threads import on_its_own_thread

    from ..outputs import (
        COMMAND_OUTPUTS,
        Beside,
        OutputFolder,
        write_lines,
        write_png,
        write_result_json,
        write_sites_csv,
    )
    from ..results import RanOn

    # every option, the picture's header and the memory it all asks for are checked first
    t0 = time.perf_counter()
    png_scale = real_number(args.png_scale, "--png-scale", *PNG_SCALE_RANGE)
    opts = mosaic_options(args)
    _, element = resolve_shapes(opts["metric"], opts["element"])
    with open_picture(args.image, "IMAGE") as header:
        pw, ph = upright_size(header)
    w, h = raster_size(pw, ph, args.size, "--size")
    if opts["n_elements"] > w * h:
        raise InputError(
            f"--elements {opts['n_elements']} do not fit in a {w}x{h} raster (from a {pw}x{ph} "
            f"picture); use fewer --elements or a larger --size"
        )
    name, _ = options.backend_choice(args)
    mosaic_estimate(
        w,
        h,
        opts["n_elements"],
        backend_class(name),
        element=element,
        png_scale=png_scale,
        compare=args.compare is not None,
    ).check(args.memory_limit, lower="use a smaller --size, fewer --elements or a smaller --png-scale")
    opts["size"] = (w, h)
    with OutputFolder(args.out, "--out", COMMAND_OUTPUTS) as tmp, Beside() as beside:
        # make_mosaic resamples the picture to the raster (opts["size"]) itself: an
        # enlarged picture need not then be held while the method runs
        rgb, _ = picture_array(args.image, at_least=(w, h), memory_limit=args.memory_limit, name="IMAGE")
        _say(
            args.quiet, f"read {args.image}: {pw}x{ph} px, as {w}x{h} (read at {rgb.shape[1]}x{rgb.shape[0]})"
        )
        with options.open_backend(args) as backend:
            _say(
                args.quiet,
                f"mosaic of {opts['n_elements']} elements, {opts['iterations']} iterations "
                f"on {backend.variant}",
            )
            m = make_mosaic(rgb, backend, **opts)
            m.source = args.image
            comparison = None
            if args.compare:
                _say(args.quiet, f"comparison runs for --compare {args.compare}")
                comparison = compare_figure(rgb, backend, dict(opts, progress=None), args.compare, m)
            ran_on = RanOn.of(backend)
        # the backend's buffers are let go before the files are written
        _say(
            args.quiet,
            f"{m.method}: placed {m.placed} of {len(m.sites)} tiles, coverage {m.coverage:.3f}, "
            f"colour error {m.colour_error:.2f} ΔE*ab, straddling {100 * m.straddling:.1f} %; writing {args.out}",
        )
        # the other files first, so that result.json (written last) holds their writing time
        t_write = time.perf_counter()
        # the fidelity measures on a thread of their own meanwhile (Delaunay and GEOS let
        # go of the GIL)
        with on_its_own_thread(timed_fidelity, m.polygons, m.problem, m.element) as measures:
            # drawn and deflated beside the rest, in bands (never whole)
            beside.run(write_png, tmp / "mosaic.png", m.render(scale=png_scale, as_rows=True))
            write_lines(tmp / "mosaic.svg", m.svg_lines())
            write_sites_csv(tmp / "sites.csv", m.sites, m.angles, m.scales)
            measured, measures_seconds = measures()
        stages = {"writing": time.perf_counter() - t_write, "measures": measures_seconds}
        result = mosaic_result_json(args, m, ran_on, stages, measured)
        # written once the picture is, the time waited for it counted as writing
        write_result_json(tmp / "result.json", result, beside)
        if comparison is not None:
            comparison.save(tmp / f"compare_{args.compare}.png")
    _say(
        args.quiet,
        f"wrote {args.out}/mosaic.svg, mosaic.png, result.json, sites.csv ({time.perf_counter() - t0:.1f} s)",
    )
    return 0


# ----------------------------------------------------------------- figures 18-19


def measures_line(m) -> str:
    # plain ASCII: the default bitmap font has no Δ
    return (
        f"coverage {m.coverage:.3f}, colour error {m.colour_error:.1f} dE,\n"
        f"straddling {100 * m.straddling:.1f} %, {m.placed} tiles"
    )


def comparison_figure(picture: np.ndarray, without, with_, what: str, scale: float = 1.0):
    """original | without | with, side by side with captions (a PIL image)."""
    from PIL import Image

    names = {
        "field": ("without the direction field", "with the direction field"),
        "density": ("without size variation", "with size variation (density)"),
        "edges": ("edges not walls (--no-edges)", "strong edges as walls"),
    }[what]
    panels = [
        Image.fromarray(np.round(picture * 255).astype(np.uint8), "RGB"),
        without.render(),
        with_.render(),
    ]
    captions = ["original\n", f"{names[0]}\n{measures_line(without)}", f"{names[1]}\n{measures_line(with_)}"]
    return panel_grid(panels, captions, scale=scale)


def compare_methods(picture, backend, opts: dict, done=None):
    """Mosaics of ``picture`` by each method of COMPARE_METHODS: a list of (caption, mosaic)."""
    from compact_distributions.cvt.mosaic.pipeline import make_mosaic

    out = []
    for name in COMPARE_METHODS:
        if done is not None and done.method == name:
            m = done
        else:  # the options given on the command line belong to the method they were given for
            m = make_mosaic(picture, backend, **dict(opts, method=name, method_options=None))
        out.append((name, m))
    return out


def compare_figure(picture, backend, opts: dict, what: str, done=None):
    """The --compare figure: original | without | with (field, density, edges), or
    original | one mosaic per method (``method``).  ``done``: the mosaic already made
    with ``opts``, reused where a panel asks for the same."""
    from PIL import Image

    from compact_distributions.cvt.mosaic.pipeline import make_mosaic

    if what == "method":
        runs = compare_methods(picture, backend, opts, done)
        first = runs[0][1]
        panels = [Image.fromarray(np.round(first.picture * 255).astype(np.uint8), "RGB")]
        panels += [m.render() for _, m in runs]
        captions = ["original\n"] + [f"{c}\n{measures_line(m)}" for c, m in runs]
        return panel_grid(panels, captions)
    key = COMPARE[what]
    on = bool(opts.get(key, True))
    with_ = done if done is not None and on else make_mosaic(picture, backend, **dict(opts, **{key: True}))
    without = (
        done if done is not None and not on else make_mosaic(picture, backend, **dict(opts, **{key: False}))
    )
    return comparison_figure(with_.picture, without, with_, what)


# (figure, sample, what, make_mosaic options): the paper's Figures 18 and 19 re-made from
# our own pictures.  Figure 18 isolates the field (no density in either panel), Figure 19
# the density (the field on in both, as in the paper's mosaics).
PAPER_FIGURES = [
    (
        "fig18_field_shapes.png",
        "shapes.png",
        "field",
        dict(n_elements=1800, element="square", use_density=False),
    ),
    (
        "fig18_field_leaf.png",
        "leaf.png",
        "field",
        dict(n_elements=1500, element="rectangle", use_density=False),
    ),
    ("fig19_density_rings.png", "rings.png", "density", dict(n_elements=1200, element="square")),
    ("fig19_density_shapes.png", "shapes.png", "density", dict(n_elements=1200, element="circle")),
]


SAMPLES_DIR = Path(__file__).resolve().parents[2] / "samples"
# the documentation's full-size mosaic and its comparisons: a photograph-like picture, defaults
SCENE = "scene.jpg"
SCENE_FIGURES = {
    "mosaic": "mosaic_scene.png",
    "edges": "mosaic_scene_edges.png",
    "method": "mosaic_scene_methods.png",
}


def write_paper_figures(
    out_dir, backend, samples_dir=None, iterations: int = 20, fewer: int = 1, quiet: bool = False
) -> list[Path]:
    """Re-make Figures 18-19 (original | without | with) from the sample pictures, and
    the documentation's mosaic of samples/scene.jpg (2000 tiles, the defaults) with its
    comparisons without walls and by method (``fewer``: divide the number of elements,
    for a quick smoke test)."""
    from compact_distributions.cvt.mosaic.pipeline import DEFAULT_ELEMENTS, make_mosaic, picture_array

    from ..outputs import atomic_path, atomic_write
    from ..panels import png_bytes

    samples_dir = Path(samples_dir or SAMPLES_DIR)
    out_dir = Path(out_dir)
    written = []

    def save(image, name, note, palette=False):
        path = out_dir / name
        if palette:  # a noisy photograph beside its mosaics: 256 colours keep it < 300 KB
            atomic_write(path, png_bytes(image, 256))
        else:
            with atomic_path(path) as tmp:
                image.save(tmp, format="PNG", optimize=True)
        if not quiet:
            print(f"wrote {path}: {note}", file=sys.stderr)
        written.append(path)

    for name, sample, what, opts in PAPER_FIGURES:
        picture, _ = picture_array(samples_dir / sample)
        key = COMPARE[what]
        opts = dict(opts, n_elements=max(1, opts["n_elements"] // fewer))
        with_ = make_mosaic(picture, backend, iterations=iterations, **dict(opts, **{key: True}))
        without = make_mosaic(picture, backend, iterations=iterations, **dict(opts, **{key: False}))
        save(
            comparison_figure(with_.picture, without, with_, what),
            name,
            f"{opts['element']} x {opts['n_elements']}, coverage without {without.coverage:.3f}, "
            f"with {with_.coverage:.3f}",
        )

    picture, _ = picture_array(samples_dir / SCENE)
    opts = dict(n_elements=max(1, DEFAULT_ELEMENTS // fewer), iterations=iterations)
    m = make_mosaic(picture, backend, **opts)
    save(m.render(), SCENE_FIGURES["mosaic"], f"{m.method}, {measures_line(m).replace(chr(10), ' ')}")
    for what in ("edges", "method"):
        save(
            compare_figure(picture, backend, opts, what, done=m),
            SCENE_FIGURES[what],
            f"--compare {what}",
            palette=True,
        )
    return written


__all__ = [
    "DEFAULT_OUT",
    "COMPARE",
    "COMPARE_METHODS",
    "add_parser",
    "mosaic_options",
    "mosaic_result_json",
    "PNG_SCALE_RANGE",
    "run",
    "measures_line",
    "comparison_figure",
    "compare_methods",
    "compare_figure",
    "PAPER_FIGURES",
    "SAMPLES_DIR",
    "SCENE",
    "SCENE_FIGURES",
    "write_paper_figures",
]
