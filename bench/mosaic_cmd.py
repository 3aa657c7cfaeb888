"""`cvtbench mosaic IMAGE --out DIR`: a picture turned into a mosaic (paper §4.1).

Element sizes follow a density map and element directions a field, both extracted from
the picture (cvt/image_fields.py); each element is filled with the picture's mean colour
under it, on a grout-coloured background.

DIR/mosaic.svg    the mosaic: grout background, one filled element per placed site
DIR/mosaic.png    the same, rendered (antialiased) at the raster size times --png-scale
DIR/result.json   the run, with the field names of `cvtbench run` (backend, device,
                  metric, aspect, size, sites, angles, scales, iterations, energy,
                  seconds, ...) plus image, element, elements (placed), colours,
                  coverage and overlap (bench.evaluate), gap, grout
DIR/sites.csv     x,y,angle_deg,scale per site
DIR/compare_field.png or compare_density.png  with --compare: original | without | with

The paper's Figures 18-19 from the sample pictures (into reports/figures/):
    .venv/bin/python -m bench.mosaic_cmd reports/figures
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.metrics import METRIC_NAMES
from compact_distributions.cvt.shapes import ELEMENT_SHAPES

DEFAULT_OUT = "out/mosaic"


def add_parser(sub):
    from compact_distributions.cvt.mosaic import DEFAULT_ELEMENTS

    p = sub.add_parser("mosaic", help="turn a picture into a mosaic (density and direction from the picture)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("image", metavar="IMAGE", help="the picture: PNG, JPEG, ... (grey, RGB, RGBA, palette, 16-bit)")
    p.add_argument("--out", default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    p.add_argument("--elements", default=str(DEFAULT_ELEMENTS),
                   help=f"number of elements N (default {DEFAULT_ELEMENTS})")
    p.add_argument("--metric", default=None,
                   help=f"Lloyd distance: {', '.join(METRIC_NAMES)} (default: the element's own)")
    p.add_argument("--element", default=None,
                   help=f"element shape: {', '.join(ELEMENT_SHAPES)} (default: the metric's own; "
                   "neither given: square)")
    p.add_argument("--aspect", default=None, help="β of rectangles and ellipses (default 0.5)")
    p.add_argument("--size", default=None,
                   help="raster: N = long side in pixels (aspect kept) or WxH; default the "
                   "picture's size with the long side capped at 1024")
    p.add_argument("--backend", default="numpy", help="numpy (default), opencl or gl")
    p.add_argument("--device", default=None, help="OpenCL device PLATFORM[:DEVICE] (opencl backend)")
    p.add_argument("--gl-mode", default="cone", choices=["cone", "exact"], help="gl backend mode")
    p.add_argument("--gap", default=None,
                   help="grout width in pixels (default 5%% of the mean element spacing)")
    p.add_argument("--grout", default="#383838", help="grout colour: a name or #rrggbb (default #383838)")
    p.add_argument("--contrast", default=None,
                   help="densest / sparsest cell area of the density map (default 3; 1 = uniform)")
    p.add_argument("--no-field", action="store_true", help="all elements at angle 0 (no direction field)")
    p.add_argument("--no-density", action="store_true", help="one element size everywhere (no density map)")
    p.add_argument("--iterations", default="20", help="Lloyd iterations (default 20; 0 allowed)")
    p.add_argument("--seed", default="0", help="random seed (default 0)")
    p.add_argument("--png-scale", default="1", help="mosaic.png size relative to the raster (default 1)")
    p.add_argument("--compare", choices=["field", "density"], default=None,
                   help="also write compare_field.png / compare_density.png: original | without | with")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run)


def _number(text, name, kind=float, minimum=None):
    try:
        value = kind(text)
    except (TypeError, ValueError):
        what = "a whole number" if kind is int else "a number"
        raise InputError(f"--{name} must be {what}, got {text!r}") from None
    if kind is float and not np.isfinite(value):
        raise InputError(f"--{name} must be finite, got {text!r}")
    if minimum is not None and value < minimum:
        raise InputError(f"--{name} must be >= {minimum}, got {text!r}")
    return value


def _say(quiet: bool, text: str) -> None:
    if not quiet:
        print(text, file=sys.stderr, flush=True)


def mosaic_options(args) -> dict:
    """make_mosaic keyword arguments from the parsed command line (validated)."""
    from compact_distributions.cvt.image_fields import DEFAULT_CONTRAST

    from .run_cmd import _progress, backend_options

    opts = dict(
        n_elements=_number(args.elements, "elements", int, 1),
        metric=args.metric, element=args.element, aspect=args.aspect, size=args.size,
        gap=None if args.gap is None else _number(args.gap, "gap", float, 0),
        use_field=not args.no_field, use_density=not args.no_density,
        iterations=_number(args.iterations, "iterations", int, 0),
        seed=_number(args.seed, "seed", int, 0),
        contrast=DEFAULT_CONTRAST if args.contrast is None else _number(args.contrast, "contrast", float, 1),
        grout=args.grout,
    )
    if args.backend != "numpy":
        from compact_distributions.backends import create_backend

        opts["backend"] = create_backend(args.backend, **backend_options(args))
    opts["progress"] = _progress(args.quiet)
    return opts


def mosaic_result_json(args, m) -> dict:
    """result.json: `cvtbench run`'s fields (bench.run_cmd.build_result) plus the mosaic's."""
    from compact_distributions.bench.evaluate import evaluate
    from compact_distributions.cvt.mosaic import hex_colour

    from .outputs import command_line, machine, versions
    from .run_cmd import build_result

    dist = m.to_distribution()
    result = build_result(args, m.problem, dist, m.backend, m.device)
    ev = evaluate(m.polygons, m.problem.grid)
    result.update(
        density="picture" if m.problem.density is not None else None,
        field="picture" if m.problem.field is not None else None,
        image=m.source,
        element=m.element,
        elements=ev.elements,
        colours=[hex_colour(c) for c in m.colours],
        gap=m.gap,
        grout=hex_colour(m.grout),
        contrast=m.contrast,
        **ev.as_dict(),
    )
    result.update(versions=versions(), machine=machine(), command=command_line(getattr(args, "argv", None)))
    return result


def run(args) -> int:
    from compact_distributions.cvt.mosaic import make_mosaic, picture_array

    from .outputs import staged_dir, write_json, write_sites_csv

    png_scale = _number(args.png_scale, "png-scale", float, 0.01)
    t0 = time.perf_counter()
    _say(args.quiet, f"reading {args.image}")
    picture, _ = picture_array(args.image)  # fails early, before any work, on a bad file
    opts = mosaic_options(args)
    backend = opts.get("backend")
    try:
        _say(args.quiet, f"mosaic of {opts['n_elements']} elements, {opts['iterations']} iterations "
             f"on {getattr(backend, 'name', 'numpy')}")
        m = make_mosaic(picture, **opts)
        m.source = args.image
        comparison = None
        if args.compare:
            _say(args.quiet, f"comparison run without the {args.compare}")
            other = dict(opts, progress=None)
            other["use_field" if args.compare == "field" else "use_density"] = False
            without = make_mosaic(picture, **other)
            comparison = comparison_figure(m.picture, without, m, args.compare)
    finally:
        if backend is not None:
            backend.close()
    _say(args.quiet, f"placed {m.placed} of {len(m.sites)} elements, coverage {m.coverage:.3f}; writing {args.out}")
    result = mosaic_result_json(args, m)
    with staged_dir(args.out) as tmp:
        (tmp / "mosaic.svg").write_text(m.svg())
        m.render(scale=png_scale).save(tmp / "mosaic.png")
        write_json(tmp / "result.json", result)
        write_sites_csv(tmp / "sites.csv", m.sites, m.angles, m.scales)
        if comparison is not None:
            comparison.save(tmp / f"compare_{args.compare}.png")
    _say(args.quiet, f"wrote {args.out}/mosaic.svg, mosaic.png, result.json, sites.csv "
         f"({time.perf_counter() - t0:.1f} s)")
    return 0


# ----------------------------------------------------------------- figures 18-19

def comparison_figure(picture: np.ndarray, without, with_, what: str, scale: float = 1.0):
    """original | without | with, side by side with captions (a PIL image)."""
    from PIL import Image, ImageDraw, ImageFont

    panels = [Image.fromarray(np.round(picture * 255).astype(np.uint8), "RGB"),
              without.render(scale=1.0), with_.render(scale=1.0)]
    if scale != 1.0:
        panels = [p.resize((round(p.width * scale), round(p.height * scale)), Image.Resampling.LANCZOS)
                  for p in panels]
    names = {"field": ("original", "without the direction field", "with the direction field"),
             "density": ("original", "without size variation", "with size variation (density)")}[what]
    pad, caption = 8, 26
    w, h = panels[0].width, panels[0].height
    canvas = Image.new("RGB", (3 * w + 4 * pad, h + caption + 2 * pad), "white")
    draw = ImageDraw.Draw(canvas)
    try:
        font = ImageFont.load_default(size=16)
    except TypeError:  # Pillow < 10.1: fixed-size bitmap font
        font = ImageFont.load_default()
    for k, (panel, name) in enumerate(zip(panels, names, strict=True)):
        x = pad + k * (w + pad)
        canvas.paste(panel, (x, pad + caption))
        draw.text((x, pad), name, fill=(20, 20, 20), font=font)
    return canvas


# (figure, sample, what, make_mosaic options): the paper's Figures 18 and 19 re-made from
# our own pictures.  Figure 18 isolates the field (no density in either panel), Figure 19
# the density (the field on in both, as in the paper's mosaics).
PAPER_FIGURES = [
    ("fig18_field_shapes.png", "shapes.png", "field", dict(n_elements=1800, element="square", use_density=False)),
    ("fig18_field_leaf.png", "leaf.png", "field", dict(n_elements=1500, element="rectangle", use_density=False)),
    ("fig19_density_rings.png", "rings.png", "density", dict(n_elements=1200, element="square")),
    ("fig19_density_shapes.png", "shapes.png", "density", dict(n_elements=1200, element="circle")),
]


def write_paper_figures(out_dir, samples_dir=None, iterations: int = 20) -> list[Path]:
    """Re-make Figures 18-19 (original | without | with) from the sample pictures."""
    from compact_distributions.cvt.mosaic import make_mosaic, picture_array

    samples_dir = Path(samples_dir or Path(__file__).resolve().parent.parent / "samples")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, sample, what, opts in PAPER_FIGURES:
        picture, _ = picture_array(samples_dir / sample)
        key = "use_field" if what == "field" else "use_density"
        with_ = make_mosaic(picture, iterations=iterations, **dict(opts, **{key: True}))
        without = make_mosaic(picture, iterations=iterations, **dict(opts, **{key: False}))
        path = out_dir / name
        tmp = path.with_name(f".{path.name}.tmp")  # never a half-written figure
        comparison_figure(with_.picture, without, with_, what).save(tmp, format="PNG", optimize=True)
        os.replace(tmp, path)
        print(f"{path}: {opts['element']} x {opts['n_elements']}, coverage without "
              f"{without.coverage:.3f}, with {with_.coverage:.3f}", file=sys.stderr)
        written.append(path)
    return written


if __name__ == "__main__":
    write_paper_figures(sys.argv[1] if len(sys.argv) > 1 else "reports/figures")
