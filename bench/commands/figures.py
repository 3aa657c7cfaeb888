"""`cvtbench figures`: regenerate the pictures of the paper's Figures 3, 14 and 15.

fig03_metrics.png   the six metrics' CVTs side by side, cells coloured (paper Figure 3)
fig14_elements.png  squares, rectangles, ellipses, triangles, elements of varying size
                    (a radial density) and of varying direction (a circular field)
                    (paper Figure 14 a-f), each panel captioned with its coverage
fig14_more_shapes.png  beyond the paper's shapes: hexagons and octagons under a radial
                    density and a circular field (as Figure 14 e-f)
fig15_regions.png   elements in regions that are not rectangles: a star and a ring
                    (paper Figure 15)
fig18_*.png, fig19_*.png  mosaics of the sample pictures without and with the direction
                    field (Figure 18) and the density (Figure 19)

Every panel is a real run of the suite: Lloyd relaxation (ours, 20 iterations, ~400
sites by default) on the chosen backend, the elements placed by cvt.placement and the
coverage measured by cvt/evaluate.py.  Seeds are fixed, so the pictures are
reproducible.  Files are written atomically (temporary file, then a rename).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from compact_distributions.cvt.fields import DensityMap, DirectionField
from compact_distributions.cvt.metrics import SHAPES, make_metric
from compact_distributions.cvt.problem import Grid, Problem

from .. import options
from ..panels import panel_grid, png_bytes

DEFAULT_OUT = "reports/figures"


@dataclass
class Settings:
    size: int  # panel raster side, px
    sites: int
    iterations: int
    scale: float  # drawing scale of a panel
    fewer_mosaic_elements: int = 1  # divides the elements of the mosaic figures


FULL = Settings(size=256, sites=400, iterations=20, scale=1.5)
QUICK = Settings(size=96, sites=60, iterations=4, scale=1.0, fewer_mosaic_elements=8)


def add_parser(sub):
    p = sub.add_parser(
        "figures",
        help="regenerate the figures (paper Figures 3, 14, 15) as PNG",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--quick", action="store_true", help="small rasters, few sites and iterations (a smoke test, seconds)"
    )
    options.add_backend_options(p)
    options.add_output_options(p, DEFAULT_OUT)
    p.set_defaults(func=run)


# ------------------------------------------------------------------ problems
def radial_density(size: int) -> DensityMap:
    """Dense (small elements) at the centre, sparse (large) at the rim."""
    yy, xx = np.mgrid[0:size, 0:size] + 0.5
    r = np.hypot(xx - size / 2, yy - size / 2) / (size / 2 * math.sqrt(2))
    return DensityMap(0.08 + (1.0 - r) ** 3)


def star_mask(size: int, points: int = 5, inner: float = 0.45) -> np.ndarray:
    """A five-pointed star filling most of the raster (True inside)."""
    import shapely

    k = np.arange(2 * points)
    radius = np.where(k % 2 == 0, 0.48, 0.48 * inner) * size
    t = -math.pi / 2 + k * math.pi / points
    star = shapely.Polygon(np.stack([size / 2 + radius * np.cos(t), size / 2 + radius * np.sin(t)], 1))
    yy, xx = np.mgrid[0:size, 0:size] + 0.5
    return shapely.contains_xy(star, xx, yy)


def ring_mask(size: int) -> np.ndarray:
    yy, xx = np.mgrid[0:size, 0:size] + 0.5
    r = np.hypot(xx - size / 2, yy - size / 2)
    return (r < 0.48 * size) & (r > 0.18 * size)


def panel_problem(st: Settings, metric: str, *, density=None, field=None, mask=None, seed=1) -> Problem:
    grid = Grid(st.size, st.size, mask)
    n = st.sites if mask is None else max(1, round(st.sites * grid.pixel_count / st.size**2))
    fld = None if field is None else DirectionField.named(field, st.size, st.size)
    return Problem(grid, n, make_metric(metric), density, fld, seed)


# ------------------------------------------------------------------ figures
def _elements_panel(problem: Problem, backend, st: Settings, element=None):
    """Run ours, place the elements, return (picture, coverage, the distribution)."""
    from compact_distributions.cvt.evaluate import evaluate, region_polygon
    from compact_distributions.cvt.mosaic.render import PAPER, draw_elements
    from compact_distributions.cvt.placement.ours import run_ours

    dist = run_ours(problem, backend, iterations=st.iterations, element=element)
    g = problem.grid
    ev = evaluate(dist.elements, g, region=region_polygon(g), labels=dist.labels)
    img = draw_elements(
        dist.elements,
        g.width,
        g.height,
        region_colour=PAPER,
        region_mask=g.mask,
        scale=st.scale,
        supersample=2,
    )
    return img, ev, dist


def figure_metrics(backend, st: Settings):
    from PIL import Image

    from compact_distributions.cvt.mosaic.render import cells_image
    from compact_distributions.cvt.placement.ours import run_ours

    names = [
        ("l2", "(a) L2"),
        ("l1", "(b) L1 (Manhattan)"),
        ("linf", "(c) L∞ (Chebyshev)"),
        ("linf-axial", "(d) L∞, axial β=0.5"),
        ("l2-axial", "(e) L2, axial β=0.5"),
        ("triangle", "(f) triangle (equidistant line)"),
    ]
    panels, caps = [], []
    for metric, cap in names:
        problem = panel_problem(st, metric)
        dist = run_ours(problem, backend, iterations=st.iterations)
        side = round(st.size * st.scale)
        panels.append(
            cells_image(dist.labels, len(dist.sites), dist.sites).resize((side, side), Image.NEAREST)
        )
        caps.append(cap)
    title = (
        f"Figure 3: CVTs under the six metrics ({st.sites} sites, {st.iterations} "
        "Lloyd iterations, cells coloured, sites dark)"
    )
    return panel_grid(panels, caps, 3, title)


def figure_elements(backend, st: Settings):
    runs = [
        ("(a) squares", panel_problem(st, "linf"), None),
        ("(b) rectangles β=0.5", panel_problem(st, "linf-axial"), None),
        ("(c) ellipses β=0.5", panel_problem(st, "l2-axial"), None),
        ("(d) triangles", panel_problem(st, "triangle"), None),
        ("(e) sizes: radial density", panel_problem(st, "linf", density=radial_density(st.size)), None),
        ("(f) directions: circular field", panel_problem(st, "linf-axial", field="circular"), None),
    ]
    panels, caps = [], []
    for cap, problem, element in runs:
        img, ev, _ = _elements_panel(problem, backend, st, element)
        panels.append(img)
        caps.append(f"{cap}: coverage {ev.coverage:.1%}")
    title = f"Figure 14: compact distributions of elements ({st.sites} sites, {st.iterations} iterations)"
    return panel_grid(panels, caps, 3, title)


def figure_more_shapes(backend, st: Settings):
    """Hexagons and octagons, each with the radial density and the circular field."""
    runs = [
        (f"({chr(97 + k)}) {shape}s: radial density, circular field", shape)
        for k, shape in enumerate(s.name for s in SHAPES.values() if not s.paper)
    ]
    panels, caps = [], []
    for cap, shape in runs:
        problem = panel_problem(st, shape, density=radial_density(st.size), field="circular")
        img, ev, _ = _elements_panel(problem, backend, st)
        panels.append(img)
        caps.append(f"{cap}: coverage {ev.coverage:.1%}")
    title = f"Beyond the paper's shapes ({st.sites} sites, {st.iterations} iterations)"
    return panel_grid(panels, caps, 2, title)


def figure_regions(backend, st: Settings):
    runs = [
        ("(a) squares in a star", panel_problem(st, "linf", mask=star_mask(st.size))),
        (
            "(b) ellipses in a ring, circular field",
            panel_problem(st, "l2-axial", mask=ring_mask(st.size), field="circular"),
        ),
        (
            "(c) triangles in a star, radial field",
            panel_problem(st, "triangle", mask=star_mask(st.size), field="radial"),
        ),
    ]
    panels, caps = [], []
    for cap, problem in runs:
        img, ev, _ = _elements_panel(problem, backend, st)
        panels.append(img)
        caps.append(f"{cap}: {ev.coverage:.1%}")
    return panel_grid(panels, caps, 3, "Figure 15: elements in regions that are not rectangles")


FIGURES = {
    "fig03_metrics.png": figure_metrics,
    "fig14_elements.png": figure_elements,
    "fig14_more_shapes.png": figure_more_shapes,
    "fig15_regions.png": figure_regions,
}


@dataclass(frozen=True)
class FiguresRequest:
    """``cvtbench figures``, typed: the folder, the quick form, progress, the backend
    (registry name and its constructor options) and the command line the folder records."""

    out: Path
    quick: bool = False
    quiet: bool = False
    backend: str = "numpy"
    backend_options: dict = field(default_factory=dict)
    command: str | None = None

    @classmethod
    def from_args(cls, args) -> FiguresRequest:
        name, backend_options = options.backend_choice(args)
        return cls(
            Path(args.out),
            bool(args.quick),
            bool(args.quiet),
            name,
            backend_options,
            options.command_text(getattr(args, "argv", None)),
        )


def prepare(req: FiguresRequest) -> dict:
    """The options and the output folder checked before anything is drawn."""
    from compact_distributions.backends import resolve

    from ..outputs import check_folder

    check_folder(req.out)
    resolve(req.backend, **req.backend_options)
    return {"out": req.out, "settings": QUICK if req.quick else FULL}


def run(args) -> int:
    return figures(FiguresRequest.from_args(args))


def figures(req: FiguresRequest) -> int:
    """Draw every figure into ``req.out`` (what ``cvtbench figures`` does)."""
    from compact_distributions.backends import create_backend

    from ..outputs import atomic_write, report_folder
    from .mosaic import write_paper_figures

    plan = prepare(req)
    out, st = plan["out"], plan["settings"]
    with (
        report_folder(out, command=req.command or "cvtbench figures" + (" --quick" if req.quick else "")),
        create_backend(req.backend, **req.backend_options) as backend,
    ):
        for name, make in FIGURES.items():
            t0 = time.perf_counter()
            data = png_bytes(make(backend, st))
            atomic_write(out / name, data)
            if not req.quiet:
                print(
                    f"wrote {out / name} ({len(data) // 1024} KB, {time.perf_counter() - t0:.1f} s)",
                    file=sys.stderr,
                )
        write_paper_figures(
            out, backend, iterations=st.iterations, fewer=st.fewer_mosaic_elements, quiet=req.quiet
        )
    return 0


__all__ = [
    "DEFAULT_OUT",
    "Settings",
    "FULL",
    "QUICK",
    "add_parser",
    "radial_density",
    "star_mask",
    "ring_mask",
    "panel_problem",
    "figure_metrics",
    "figure_elements",
    "figure_more_shapes",
    "figure_regions",
    "FIGURES",
    "FiguresRequest",
    "prepare",
    "run",
    "figures",
]
