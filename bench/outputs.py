"""Writing results: atomically (no half-written output) and in the shared formats."""

from __future__ import annotations

import json
import os
import platform
import shutil
import sys
import tempfile
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

import numpy as np

PACKAGES = ("numpy", "scipy", "shapely", "pandas", "matplotlib", "pillow", "pyopencl",
            "moderngl")


def versions() -> dict:
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    try:
        out["compact-distributions"] = metadata.version("compact-distributions")
    except metadata.PackageNotFoundError:
        pass
    return out


def machine() -> dict:
    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count()}


@contextmanager
def staged_dir(out_dir):
    """Yield a temporary folder beside ``out_dir``; on success move its files into
    ``out_dir`` (created if needed), on any error remove it: never a partial result."""
    out_dir = Path(out_dir)
    parent = out_dir.resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=parent))
    try:
        yield tmp
        out_dir.mkdir(parents=True, exist_ok=True)
        for f in tmp.iterdir():
            os.replace(f, out_dir / f.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path, text: str) -> None:
    """Write a file via a temporary sibling and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; a report is for everyone
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def to_jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def dumps(data: dict) -> str:
    """JSON with one top-level key per line and each value compact (site lists stay short)."""
    data = to_jsonable(data)
    body = ",\n".join(f" {json.dumps(k)}: {json.dumps(v)}" for k, v in data.items())
    return "{\n" + body + "\n}\n"


def write_json(path, data) -> None:
    Path(path).write_text(dumps(data))


def write_sites_csv(path, sites, angles, scales) -> None:
    lines = ["x,y,angle_deg,scale"]
    for (x, y), a, s in zip(sites, angles, scales, strict=True):
        lines.append(f"{x:.6f},{y:.6f},{np.degrees(a):.6f},{s:.6f}")
    Path(path).write_text("\n".join(lines) + "\n")


def label_colours(n: int, seed: int = 12345) -> np.ndarray:
    """(n + 1, 3) uint8: distinct, well-spread colours per label; the last one (for -1,
    outside the region) is black."""
    rng = np.random.default_rng(seed)
    hue = (np.arange(n) * 0.618033988749895) % 1.0
    sat = 0.45 + 0.35 * rng.random(n)
    val = 0.70 + 0.30 * rng.random(n)
    import matplotlib.colors as mcolors

    rgb = mcolors.hsv_to_rgb(np.stack([hue, sat, val], axis=1))
    out = np.zeros((n + 1, 3), dtype=np.uint8)
    out[:n] = np.round(rgb * 255).astype(np.uint8)
    return out


def cells_image(labels: np.ndarray, n_sites: int, sites=None):
    """The cells in distinct colours (PIL image); sites drawn as dark dots if given."""
    from PIL import Image

    pal = label_colours(n_sites)
    rgb = pal[np.where(labels >= 0, labels, n_sites)]
    if sites is not None:
        h, w = labels.shape
        j = np.clip(np.floor(sites[:, 0]).astype(int), 0, w - 1)
        i = np.clip(np.floor(sites[:, 1]).astype(int), 0, h - 1)
        rgb[i, j] = (20, 20, 20)
    return Image.fromarray(rgb, mode="RGB")


def command_line(argv=None) -> str:
    import shlex

    argv = sys.argv[1:] if argv is None else argv
    return "cvtbench " + shlex.join(argv)
