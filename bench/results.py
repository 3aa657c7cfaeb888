"""The one ``result.json`` of every command that writes one (``cvtbench run``,
``cvtbench mosaic``).  Its JSON Schema ships beside this module as
``result.schema.json``; the documentation's result.json page lists the fields.

``kind`` says which command wrote it; ``elements`` is always the list of element
outlines (one per site, null where a site has no element) and ``placed`` their count.
The record holds the elements themselves (shapely polygons); :func:`bench.outputs.dumps`
and ``write_json`` turn each into its outline as they write it.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SCHEMA_FILE = Path(__file__).with_name("result.schema.json")


def schema() -> dict:
    """The result.json schema, with the metric and element names read from the shape table
    (the file itself names no shape: a new record needs no edit there)."""
    from compact_distributions.cvt.metrics import METRIC_NAMES, POLYGON_PREFIX, SHAPES

    out = json.loads(SCHEMA_FILE.read_text())
    users = {"type": "string", "pattern": f"^{POLYGON_PREFIX}."}
    for name, names in (("metric", METRIC_NAMES), ("element", tuple(SHAPES))):
        out["properties"][name] = {
            "description": out["properties"][name]["description"],
            "anyOf": [{"enum": list(names)}, users],
        }
    return out


def stages_of(dist) -> dict:
    """The wall time of each stage of a method's run: Lloyd, then every ``NAME_seconds``
    the method timed in its ``extra`` (final labels, fit, placement, compaction, cutting,
    ...), by NAME."""
    stages = {"lloyd": float(dist.lloyd_seconds)}
    for key, value in dist.extra.items():
        if key.endswith("_seconds") and isinstance(value, (int, float)):
            stages[key.removesuffix("_seconds")] = float(value)
    return stages


@dataclass(frozen=True)
class RanOn:
    """What result.json records of the backend that ran a method, taken while it was
    open: a command may then close it (and free its buffers) before writing."""

    variant: str
    device: str

    @classmethod
    def of(cls, backend) -> RanOn:
        """The record of an open backend."""
        return cls(backend.variant, backend.device())


def build_result(
    kind: str,
    problem,
    dist,
    evaluation,
    ran_on: RanOn,
    *,
    element: str,
    gap: float,
    command: str,
    sources: dict | None = None,
    method_options: dict | None = None,
    stage_seconds: dict | None = None,
    placed=None,
    measured: dict | None = None,
    **fields,
) -> dict:
    """The result.json record of one run: the problem, the method's Distribution, the
    evaluation (coverage, overlap, ...) of its elements, the backend that ran it
    (``ran_on``), plus
    the command's own ``fields`` (a mosaic's image, colours, ...); ``method_options`` are
    the method's own options as the user set them; ``stage_seconds`` the command's own
    stages (evaluation, writing, ...), added to the method's (:func:`stages_of`).  The
    fidelity measures (``cvt.evaluate.fidelity``) are taken of ``placed`` (default the
    Distribution's elements), and timed as the ``measures`` stage, unless the command
    took them already (``measured``; their time is then among the method's stages)."""
    from compact_distributions.cvt.evaluate import fidelity

    from .outputs import machine, versions

    # coverage at ≤ 1 % overlap stays a sweep measure (Tables 2 and 3): its scaled copies
    # cost tens of kB per element where elements are tiny and overlap when grown
    if measured is None:
        t0 = time.perf_counter()
        measured = fidelity(dist.elements if placed is None else placed, problem, element)
        stage_seconds = {**(stage_seconds or {}), "measures": time.perf_counter() - t0}
    measured = {k: _finite(v) for k, v in measured.items()}

    g = problem.grid
    sources = sources or {}
    record = {
        "kind": kind,
        "method": dist.method,
        "method_options": dict(method_options or {}),
        "backend": ran_on.variant,
        "device": ran_on.device,
        "metric": problem.metric.name,
        "aspect": problem.metric.aspect,
        "size": [g.width, g.height],
        "n_elements": len(dist.sites),
        "seed": problem.seed,
        "init": sources.get("init"),
        "density": sources.get("density"),
        "field": sources.get("field"),
        "region": sources.get("region"),
        "region_pixels": g.pixel_count,
        "iterations": dist.iterations,
        # a method whose loop is cvt.lloyd.lloyd says why it stopped; the others run their count
        "stopped_by": dist.extra.get("stopped_by", "iterations"),
        "sites": dist.sites,
        "angles": dist.angles,
        "scales": dist.scales,
        "energy": dist.energy,
        "seconds": dist.seconds,
        "method_seconds": dist.method_seconds,
        "lloyd_seconds": dist.lloyd_seconds,
        "setup_seconds": dist.setup_seconds,
        "stage_seconds": {**stages_of(dist), **(stage_seconds or {})},
        "ms_per_iteration": (float(np.median(dist.seconds)) * 1000 if dist.seconds else None),
        "empty_cells_per_iteration": dist.empty,
        "empty_sites": dist.empty_sites,
        "element": element,
        "gap": gap,
        **evaluation.as_dict(),
        **measured,
        "elements": dist.elements,  # outlines, converted one by one as the json is written
        "extra": dist.extra,
        **fields,
        "versions": versions(),
        "machine": machine(),
        "command": command,
    }
    return record


def _finite(value: float) -> float | None:
    """JSON has no NaN: a measure that does not apply (circles' direction) is null."""
    return float(value) if np.isfinite(value) else None


__all__ = ["SCHEMA_FILE", "schema", "stages_of", "RanOn", "build_result"]
