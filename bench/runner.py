"""Running a benchmark sweep: one (method, backend, problem, seed) at a time.

Every report of ``bench/`` (Table 2, regression) is a list of :class:`RunSpec`; this
module turns one spec into one row (a flat dict, one line of the report's table) and
keeps that row, with the run's sites and timings, as raw json under
``<out>/raw/<suite>/<key>.json``.  Why a file per run: a sweep of many minutes can be
interrupted (Ctrl-C) and resumed, a run whose json exists, made by the same code on the
same host (:func:`made_by`), is read back instead of run again (``force`` re-runs it), and the report is always made from what is on disk, so it
never mixes two half sweeps.  Each json is written atomically (temp file + rename): the
file exists only when the run finished.

Backend *variants* name a backend and its constructor options (``gl-cone`` is the GL
backend in its cone mode); the variants offered are those of the registry that
``backends.probe_all()`` reports available at run time, so the sweeps grow with the
backends that exist.  Unavailable ones give rows with ``status`` "skipped" and the
reason, never a silent gap.

Elements: a method that returns ``Distribution.elements`` keeps its own; otherwise the
elements come from :func:`cvt.placement.place_elements` on the final label raster, and
coverage from :func:`bench.evaluate.evaluate` (the suite's one definition).
"""

from __future__ import annotations

import hashlib
import json
import platform
import sys
import time
import traceback
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from compact_distributions.cvt.errors import BackendUnavailable

# element shape -> the metric whose unit ball it is (cvt/shapes.py documents the pairing)
ELEMENT_METRIC = {"square": "linf", "rectangle": "linf-axial", "ellipse": "l2-axial",
                  "triangle": "triangle", "circle": "l2"}
DEFAULT_ASPECT = 0.5  # β of rectangles and ellipses (the metrics' default)

# variant name -> (registry name, constructor options); registry names not listed here
# are offered as themselves with no options (a new backend shows up without an edit)
VARIANTS = {
    "numpy": ("numpy", {}),
    "opencl": ("opencl", {}),
    "gl-cone": ("gl", {"mode": "cone"}),
    "gl-exact": ("gl", {"mode": "exact"}),
}
REFERENCE_BACKEND = "numpy"


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep; ``key`` names its raw json."""

    suite: str  # e.g. "table2", "table2-quick": the raw/ sub-folder
    method: str
    backend: str  # a variant name (see VARIANTS)
    element: str
    width: int
    height: int
    n_sites: int
    iterations: int
    seed: int
    aspect: float = DEFAULT_ASPECT
    gap: float = 0.0
    picture: bool = False  # also save an effect picture beside the raw json
    delta: float | None = None  # tile budget δ of a fixed-size baseline (None: its default)

    @property
    def metric(self) -> str:
        return ELEMENT_METRIC[self.element]

    @property
    def key(self) -> str:
        gap = f"__gap{self.gap:g}" if self.gap else ""
        delta = f"__d{self.delta:g}" if self.delta is not None else ""
        return (f"{self.method}__{self.backend}__{self.element}__{self.width}x{self.height}"
                f"__n{self.n_sites}__it{self.iterations}__s{self.seed}{gap}{delta}")

    @property
    def label(self) -> str:
        """The method as reports name it: with its tile budget where one was set."""
        return self.method if self.delta is None else f"{self.method} δ={self.delta:g}"

    def params(self) -> dict:
        d = asdict(self)
        d.pop("picture")
        d["metric"] = self.metric
        return d


# ---------------------------------------------------------------------------------------
# backends


def backend_variants() -> dict[str, tuple[bool, str]]:
    """variant -> (available, device text or the reason it is unavailable)."""
    from compact_distributions.backends import probe_all

    out: dict[str, tuple[bool, str]] = {}
    for name, ok, text in probe_all():
        variants = [v for v, (reg, _) in VARIANTS.items() if reg == name] or [name]
        for v in variants:
            out[v] = (ok, text)
    return out


def variant_options(variant: str) -> tuple[str, dict]:
    return VARIANTS.get(variant, (variant, {}))


def create_variant(variant: str):
    from compact_distributions.backends import create_backend

    name, options = variant_options(variant)
    return create_backend(name, **options)


class BackendCache:
    """Keeps at most one live backend: consecutive runs on the same variant share it (a
    kernel is compiled once), and switching variants closes the old one first (several
    live moderngl contexts would steal each other's current-context state)."""

    def __init__(self):
        self.variant: str | None = None
        self.backend = None

    def get(self, variant: str):
        if variant != self.variant:
            self.close()
            self.backend = create_variant(variant)
            self.variant = variant
        return self.backend

    def close(self):
        if self.backend is not None:
            try:
                self.backend.close()
            finally:
                self.backend, self.variant = None, None


# ---------------------------------------------------------------------------------------
# one run


def build_problem(spec: RunSpec):
    from compact_distributions.cvt.metrics import make_metric
    from compact_distributions.cvt.problem import Grid, Problem

    aspect = spec.aspect if spec.metric.endswith("-axial") else None
    return Problem(Grid(spec.width, spec.height), spec.n_sites, make_metric(spec.metric, aspect),
                   seed=spec.seed)


def execute(spec: RunSpec, backend=None, picture_path: Path | None = None,
            keep_sites: bool = True) -> dict:
    """Run ``spec`` and return its raw record (params, row fields, sites, timings).

    ``backend``: a live backend of ``spec.backend`` (created and closed here if None).
    ``keep_sites``: store the final sites (sweeps keep them for seed 0 only: a json of
    4000 sites is ~60 kB, and the digest already tells whether two runs agree)."""
    from compact_distributions.bench.evaluate import evaluate
    from compact_distributions.bench.methods import get_method

    from .outputs import machine, versions

    problem = build_problem(spec)
    method = get_method(spec.method)
    own = backend is None
    if own:
        backend = create_variant(spec.backend)
    try:
        t0 = time.perf_counter()
        budget = {} if spec.delta is None else {"delta": spec.delta}
        dist = method(problem, backend, spec.iterations, element=spec.element, gap=spec.gap, **budget)
        wall = time.perf_counter() - t0
        device = backend.device()
        t1 = time.perf_counter()
        elements = dist.elements
        labels = dist.labels
        if elements is None:
            from compact_distributions.cvt.placement import place_elements

            if labels is None:
                labels = backend.label(dist.sites, dist.scales, dist.angles, problem.metric, problem.grid)
            elements = place_elements(labels, dist.sites, dist.angles, dist.scales, spec.element,
                                      spec.aspect, problem.grid, gap=spec.gap)
        placement_seconds = time.perf_counter() - t1
        if "placement_seconds" in dist.extra:  # the method placed its own elements and timed it
            placement_seconds = float(dist.extra["placement_seconds"])
    finally:
        if own:
            backend.close()
    ev = evaluate(elements, problem.grid)
    if picture_path is not None:
        effect_picture(elements, problem.grid).save(picture_path)
    secs = list(map(float, dist.seconds))
    row = {
        "key": spec.key, **spec.params(), "label": spec.label, "status": "ok", "reason": "",
        "device": device,
        "coverage": ev.coverage, "overlap": ev.overlap, "placed": ev.elements, "skipped": ev.skipped,
        "empty_cells": int(dist.empty[-1]) if dist.empty else 0,
        "total_seconds": float(dist.total_seconds), "setup_seconds": float(dist.setup_seconds),
        "wall_seconds": wall, "placement_seconds": placement_seconds,
        "ms_per_iteration": float(np.median(secs) * 1000) if secs else None,
        "final_energy": float(dist.energy[-1]) if dist.energy else None,
    }
    record = {"row": row, "sites_sha1": sites_digest(dist.sites), "energy": dist.energy,
              "seconds": secs, "empty_per_iteration": list(dist.empty), "extra": dist.extra,
              "machine": machine(), "versions": versions()}
    if keep_sites:
        # 0.01 px is far below a pixel; angles/scales only where they vary (a field, a density)
        record["sites"] = np.round(dist.sites, 2)
        for name in ("angles", "scales"):
            v = np.asarray(getattr(dist, name), dtype=np.float64)
            record[name] = np.round(v, 5) if len(v) and np.ptp(v) > 0 else (float(v[0]) if len(v) else None)
    return record


def sites_digest(sites) -> str:
    """sha1 of the float64 sites: equal digests = bit-identical runs (across backends too)."""
    return hashlib.sha1(np.ascontiguousarray(sites, dtype=np.float64).tobytes()).hexdigest()


PICTURE_ELEMENTS = 250  # about this many elements in an effect picture, to stay legible


def picture_crop(n_sites: int) -> float:
    """Side fraction of the region shown in an effect picture: about PICTURE_ELEMENTS
    elements (the whole region for small problems)."""
    return float(min(1.0, np.sqrt(PICTURE_ELEMENTS / max(1, n_sites))))


def effect_picture(elements, grid, side: int = 512, crop: float | None = None):
    """The top-left ``crop`` fraction of the region (default :func:`picture_crop`) with its
    elements drawn (PIL image, ``side`` px): dark background, elements in a colour-blind
    safe palette, 2x supersampled."""
    from PIL import Image, ImageDraw

    if crop is None:
        crop = picture_crop(len(elements))

    cw, ch = grid.width * crop, grid.height * crop
    scale = 2 * side / max(cw, ch)
    size = (int(round(cw * scale)), int(round(ch * scale)))
    img = Image.new("RGB", size, (40, 40, 46))
    draw = ImageDraw.Draw(img)
    if grid.mask is not None:
        m = Image.fromarray(np.where(grid.mask, 70, 40).astype(np.uint8))
        img.paste(m.resize((int(grid.width * scale), int(grid.height * scale))).convert("RGB"))
    palette = [(230, 159, 0), (86, 180, 233), (0, 158, 115), (240, 228, 66), (213, 94, 0),
               (204, 121, 167), (0, 114, 178)]
    for k, e in enumerate(elements):
        if e is None or e.is_empty:
            continue
        for poly in getattr(e, "geoms", [e]):
            xy = np.asarray(poly.exterior.coords)
            if xy[:, 0].min() > cw or xy[:, 1].min() > ch:
                continue
            draw.polygon([tuple(p) for p in (xy * scale)], fill=palette[k % len(palette)])
    return img.resize((size[0] // 2, size[1] // 2), Image.LANCZOS)


# ---------------------------------------------------------------------------------------
# sweeps


def raw_path(out: Path, spec: RunSpec) -> Path:
    return Path(out) / "raw" / spec.suite / f"{spec.key}.json"


def picture_path(out: Path, spec: RunSpec) -> Path:
    return Path(out) / "raw" / spec.suite / f"{spec.key}.png"


def skipped_row(spec: RunSpec, reason: str, status: str = "skipped") -> dict:
    return {"key": spec.key, **spec.params(), "label": spec.label, "status": status, "reason": reason}


def run_sweep(specs: list[RunSpec], out, force: bool = False, store: bool = True,
              quiet: bool = False, unavailable: dict[str, str] | None = None) -> list[dict]:
    """Run every spec (cached raw json read back unless ``force``) and return the rows.

    ``unavailable`` maps a backend variant to the reason it cannot run: its specs become
    "skipped" rows.  A run that raises becomes a "failed" row with the error (and no
    json, so the next sweep retries it).  Ctrl-C stops the sweep; finished runs stay on
    disk, so the same command resumes.  ``store=False`` (regression checks) neither reads
    nor writes raw json."""
    from tqdm import tqdm


    unavailable = unavailable or {}
    # group by backend so that each backend is created once and at most one is alive
    order = sorted(range(len(specs)), key=lambda i: (specs[i].backend, i))
    rows: dict[int, dict] = {}
    cache = BackendCache()
    bar = tqdm(order, desc="runs", unit="run", disable=quiet, file=sys.stderr, dynamic_ncols=True,
               mininterval=0.5)
    try:
        for i in bar:
            spec = specs[i]
            path = raw_path(out, spec)
            bar.set_postfix_str(f"{spec.method}/{spec.backend} {spec.element} "
                                f"{spec.width}x{spec.height} N={spec.n_sites} seed {spec.seed}")
            if spec.backend in unavailable:
                rows[i] = skipped_row(spec, unavailable[spec.backend])
                continue
            if store and not force:
                stored = read_stored(path)
                if stored is not None:
                    rows[i] = {**stored, "cached": True}
                    continue
            try:
                backend = cache.get(spec.backend)
                pic = picture_path(out, spec) if (spec.picture and store) else None
                if pic is not None:
                    pic.parent.mkdir(parents=True, exist_ok=True)
                record = execute(spec, backend, pic, keep_sites=(spec.seed == 0))
            except BackendUnavailable as exc:
                unavailable[spec.backend] = str(exc)
                rows[i] = skipped_row(spec, str(exc))
                continue
            except (KeyboardInterrupt, MemoryError):
                raise
            except Exception as exc:  # one broken method must not sink the sweep
                last = traceback.extract_tb(exc.__traceback__)[-1]
                rows[i] = skipped_row(spec, f"{type(exc).__name__}: {exc} "
                                      f"({Path(last.filename).name}:{last.lineno})", status="failed")
                cache.close()  # a failed backend may be in a bad state
                continue
            rows[i] = record["row"]
            if store:
                write_stored(path, record)
    except KeyboardInterrupt:
        done = sum(1 for r in rows.values() if r.get("status") == "ok")
        print(f"\ninterrupted: {done} of {len(specs)} runs are stored under {Path(out) / 'raw'}; "
              "run the same command again to resume", file=sys.stderr)
        raise
    finally:
        bar.close()
        cache.close()
    return [rows[i] for i in range(len(specs))]


@lru_cache(maxsize=1)
def made_by() -> dict:
    """What a stored run must share with this process to be read back instead of re-run:
    the same source code (a hash of every .py and .cl file of the four packages) on the
    same host.  So a sweep resumes after Ctrl-C, but a fresh clone, a code change or
    another machine computes its own figures instead of reusing committed ones."""
    root = Path(__file__).resolve().parent.parent
    digest = hashlib.sha1()
    for pkg in ("cvt", "backends", "baselines", "bench"):
        for f in sorted((root / pkg).rglob("*")):
            if f.suffix in (".py", ".cl") and f.is_file():
                digest.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes())
    return {"code": digest.hexdigest()[:16], "host": platform.node()}


def read_stored(path: Path) -> dict | None:
    """The row of a stored run, or None when there is none, it is unreadable, or other
    code or another host made it (then the caller runs it again)."""
    try:
        stored = json.loads(Path(path).read_text())
        return stored["row"] if stored.get("made_by") == made_by() else None
    except (OSError, ValueError, KeyError):
        return None


def write_stored(path: Path, record: dict) -> None:
    """Store a run's record (with its :func:`made_by`) atomically."""
    from .outputs import atomic_write_text, dumps

    atomic_write_text(path, dumps({**record, "made_by": made_by()}))


def fingerprint(specs: list[RunSpec]) -> str:
    """Short hash of a problem set (recorded in reports, to tell two sets apart)."""
    text = "\n".join(s.key for s in specs)
    return hashlib.sha1(text.encode()).hexdigest()[:10]


def parse_list(text: str | None, allowed=None, what: str = "value") -> list[str] | None:
    """'a,b' -> ['a', 'b'] (None stays None); InputError on a name not in ``allowed``."""
    from compact_distributions.cvt.errors import InputError

    if text is None:
        return None
    items = [t.strip() for t in str(text).split(",") if t.strip()]
    if not items:
        raise InputError(f"empty {what} list {text!r}")
    if allowed is not None:
        for t in items:
            if t not in allowed:
                raise InputError(f"unknown {what} {t!r}; choose from {', '.join(allowed)}")
    return items


def parse_positive_int(text, what: str) -> int:
    from compact_distributions.cvt.errors import InputError

    try:
        k = int(text)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be a whole number >= 1, got {text!r}") from None
    if k < 1:
        raise InputError(f"{what} must be >= 1, got {k}")
    return k


__all__ = ["RunSpec", "ELEMENT_METRIC", "VARIANTS", "REFERENCE_BACKEND", "backend_variants",
           "execute", "run_sweep", "BackendCache", "effect_picture"]
