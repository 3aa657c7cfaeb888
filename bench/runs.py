"""One method run as a sweep spec (Table 2 and the regression checks): the problem, the
method and the backend variant, and the record a run leaves (its row in the report, its
sites, timings and, for the first seed, an effect picture).

Coverage and overlap come from :func:`compact_distributions.cvt.evaluate.evaluate`, the
suite's one definition, on the elements the method placed.
"""

from __future__ import annotations

import hashlib
import io
import re
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from compact_distributions.cvt.metrics import DEFAULT_ASPECT
from compact_distributions.cvt.shapes import shape_record


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep; ``key`` names its raw json."""

    suite: str  # e.g. "table2", "table2-quick": the raw/ sub-folder
    method: str
    backend: str  # a backend variant name
    element: str
    width: int
    height: int
    n_elements: int
    iterations: int
    seed: int
    aspect: float = DEFAULT_ASPECT
    gap: float = 0.0
    picture: bool = False  # also keep an effect picture beside the raw json
    # the method's own options, as (name, value) pairs in any order (those of its record;
    # a mapping is accepted and frozen)
    options: tuple = ()
    curve: bool = False  # also measure the coverage-overlap curve (elements scaled)
    scene: str | None = None  # a standard problem of bench/scenes.py (None: the whole square)
    measures: bool = False  # also the fidelity measures (cvt.evaluate.fidelity)

    def __post_init__(self):
        opts = self.options.items() if isinstance(self.options, dict) else self.options
        object.__setattr__(self, "options", tuple(sorted((str(k), v) for k, v in opts)))

    @property
    def metric(self) -> str:
        return shape_record(self.element).metric

    @property
    def method_record(self):
        from compact_distributions.cvt.registry import get_method

        return get_method(self.method)

    @property
    def key(self) -> str:
        """The name of the run's raw json: the problem, then the options its method's
        record names (in the record's order)."""
        gap = f"__gap{self.gap:g}" if self.gap else ""
        scene = f"{self.scene}__" if self.scene else ""
        return (
            f"{scene}{self.method}__{self.backend}__{element_key(self.element)}__{self.width}x{self.height}"
            f"__n{self.n_elements}__it{self.iterations}__s{self.seed}{gap}"
            f"{self.method_record.key(dict(self.options))}"
        )

    @property
    def label(self) -> str:
        """The method as reports name it: with its options where set (its record's labels)."""
        return self.method_record.label(dict(self.options))

    def describe(self) -> str:
        return (
            f"{self.method}/{self.backend} {self.element} {self.width}x{self.height} "
            f"N={self.n_elements} seed {self.seed}"
        )

    def params(self) -> dict:
        d = asdict(self)
        d.pop("picture")
        d.pop("curve")
        d.pop("measures")
        return {**d, "options": dict(self.options), "metric": self.metric, "label": self.label}

    def memory_estimate(self):
        from compact_distributions.cvt.resources import run_estimate

        from .sweep import memory_class

        return run_estimate(
            self.width,
            self.height,
            self.n_elements,
            memory_class(self.backend),
            element=self.element,
            pictures=self.picture,
            method=self.method_record,
            what=f"the run {self.describe()}",
        )

    def problem(self):
        from compact_distributions.cvt.metrics import make_metric
        from compact_distributions.cvt.problem import Grid, Problem

        aspect = self.aspect if self.metric.endswith("-axial") else None
        if self.scene is not None:
            from .scenes import scene_problem

            return scene_problem(
                self.scene, self.width, self.n_elements, make_metric(self.metric, aspect), self.seed
            )
        return Problem(
            Grid(self.width, self.height), self.n_elements, make_metric(self.metric, aspect), seed=self.seed
        )

    def execute(self, backend) -> dict:
        """Run the spec on ``backend``; the record keeps the final sites for seed 0 only
        (a json of 4000 sites is ~60 kB, and the digest already tells whether two runs
        agree)."""
        from compact_distributions.cvt.evaluate import (
            coverage_at_overlap,
            coverage_overlap_curve,
            evaluate,
            fidelity,
            region_polygon,
        )

        from .outputs import machine, versions

        problem = self.problem()
        method = self.method_record
        options = method.parse_options(dict(self.options))
        # the record times the whole method (Distribution.method_seconds)
        dist = method(
            problem, backend, iterations=self.iterations, element=self.element, gap=self.gap, **options
        )
        region = region_polygon(problem.grid)
        ev = evaluate(dist.elements, problem.grid, region=region)
        if not (np.isfinite(ev.coverage) and np.isfinite(ev.overlap)):  # fail closed: no row from it
            raise ValueError(
                f"{self.describe()}: coverage {ev.coverage!r}, overlap {ev.overlap!r} are not finite"
            )
        secs = list(map(float, dist.seconds))
        row = {
            "key": self.key,
            **self.params(),
            "status": "ok",
            "reason": "",
            "device": backend.device(),
            "coverage": ev.coverage,
            "overlap": ev.overlap,
            "placed": ev.elements,
            "skipped": ev.skipped,
            "empty_cells": int(dist.empty[-1]) if dist.empty else 0,
            "method_seconds": float(dist.method_seconds),
            "lloyd_seconds": float(dist.lloyd_seconds),
            "setup_seconds": float(dist.setup_seconds),
            "placement_seconds": float(dist.extra.get("placement_seconds", 0.0)),
            "ms_per_iteration": float(np.median(secs) * 1000) if secs else None,
            "final_energy": float(dist.energy[-1]) if dist.energy else None,
            "sites_sha1": sites_digest(dist.sites),  # which replay of its Lloyd it is (bench.converged)
        }
        if self.curve:
            curve = coverage_overlap_curve(dist.elements, problem.grid, region=region)
            row["coverage_at_1pct_overlap"] = coverage_at_overlap(curve, 0.01)
            row["coverage_overlap"] = curve  # [[factor, coverage, overlap], ...]
        if self.measures:
            row.update(fidelity(dist.elements, problem, self.element, problem.metric.aspect))
            row["n_elements"] = problem.n_elements
        record = {
            "row": row,
            "sites_sha1": row["sites_sha1"],
            "energy": dist.energy,
            "seconds": secs,
            "empty_cells_per_iteration": list(dist.empty),
            "extra": dist.extra,
            "machine": machine(),
            "versions": versions(),
        }
        if self.seed == 0:
            # 0.01 px is far below a pixel; angles/scales only where they vary (a field, a density)
            record["sites"] = np.round(dist.sites, 2)
            for name in ("angles", "scales"):
                v = np.asarray(getattr(dist, name), dtype=np.float64)
                record[name] = (
                    np.round(v, 5) if len(v) and np.ptp(v) > 0 else (float(v[0]) if len(v) else None)
                )
        if self.picture:
            buf = io.BytesIO()
            effect_picture(dist.elements, problem.grid).save(buf, format="PNG")
            record["picture_png"] = buf.getvalue()
        return record


def element_key(element: str) -> str:
    """The element's part of a run's key (a file name): a built-in shape's name; for the
    user's ``polygon:FILE``, the file's stem and a digest of its unit ball, so that the
    key holds no path and a changed file is a new run."""
    from compact_distributions.cvt.metrics import POLYGON_PREFIX

    if not element.startswith(POLYGON_PREFIX):
        return element
    ball = np.asarray(shape_record(element).vertices, dtype=np.float64)
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "-", Path(element[len(POLYGON_PREFIX) :]).stem).strip("-.") or "file"
    return f"polygon-{stem[:40]}-{hashlib.sha1(ball.tobytes()).hexdigest()[:10]}"


def sites_digest(sites) -> str:
    """sha1 of the float64 sites: equal digests = bit-identical runs (across backends too)."""
    return hashlib.sha1(np.ascontiguousarray(sites, dtype=np.float64).tobytes()).hexdigest()


PICTURE_ELEMENTS = 250  # about this many elements in an effect picture, to stay legible
PICTURE_PALETTE = np.array(
    [
        (230, 159, 0),
        (86, 180, 233),
        (0, 158, 115),
        (240, 228, 66),
        (213, 94, 0),
        (204, 121, 167),
        (0, 114, 178),
    ],
    dtype=np.uint8,
)  # colour-blind safe


def picture_crop(n_elements: int) -> float:
    """Side fraction of the region shown in an effect picture: about PICTURE_ELEMENTS
    elements (the whole region for small problems)."""
    return float(min(1.0, np.sqrt(PICTURE_ELEMENTS / max(1, n_elements))))


def effect_picture(elements, grid, side: int = 512, crop: float | None = None):
    """The top-left ``crop`` fraction of the region (default :func:`picture_crop`) with its
    elements drawn (PIL image, ``side`` px on its long side): dark background, the region
    lighter, elements in a colour-blind safe palette."""
    from compact_distributions.cvt.mosaic.render import draw_elements

    crop = picture_crop(len(elements)) if crop is None else crop
    cw, ch = grid.width * crop, grid.height * crop
    fills = PICTURE_PALETTE[np.arange(len(elements)) % len(PICTURE_PALETTE)]
    return draw_elements(
        elements,
        grid.width,
        grid.height,
        fills,
        background=(40, 40, 46),
        region_colour=None if grid.mask is None else (70, 70, 70),
        region_mask=grid.mask,
        scale=side / max(cw, ch),
        supersample=2,
        window=(0, 0, cw, ch),
    )


__all__ = [
    "RunSpec",
    "element_key",
    "sites_digest",
    "PICTURE_ELEMENTS",
    "PICTURE_PALETTE",
    "picture_crop",
    "effect_picture",
]
